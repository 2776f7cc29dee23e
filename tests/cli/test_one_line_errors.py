"""Bad input reachable from the CLI: one line naming file/topic/field, exit 2, no traceback."""

from __future__ import annotations

import json
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.writer import Writer
from typer.testing import CliRunner

from tests.conftest import run_cli
from trackctl.cli.main import app

runner = CliRunner()


def _one_line_error(args: list[str], *expected: str) -> str:
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    errors = [line for line in res.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, res.stderr
    for text in expected:
        assert text in errors[0], errors[0]
    assert "Traceback" not in res.output
    return errors[0]


@pytest.fixture
def video(tmp_path: Path) -> Path:
    path = tmp_path / "v.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (64, 48))
    for _ in range(3):
        writer.write(np.zeros((48, 64, 3), np.uint8))
    writer.release()
    return path


OPENCV_HEAD = "%YAML:1.0\n---\nimage_width: 64\nimage_height: 48\n"


def _cv_matrix(name: str, rows: int, data: str) -> str:
    return f"{name}: !!opencv-matrix\n   rows: {rows}\n   cols: 1\n   dt: d\n   data: [ {data} ]\n"


K_OK = _cv_matrix("camera_matrix", 9, "50., 0., 32., 0., 50., 24., 0., 0., 1.")

BAD_CALIBRATIONS = {
    "text in a matrix": (
        OPENCV_HEAD + _cv_matrix("camera_matrix", 9, "abc, 0., 32., 0., 50., 24., 0., 0., 1."),
        "OpenCV cannot parse this calibration file",
    ),
    ".nan in a matrix": (
        OPENCV_HEAD + _cv_matrix("camera_matrix", 9, ".nan, 0., 32., 0., 50., 24., 0., 0., 1."),
        "field camera_matrix: holds a NaN",
    ),
    "empty file": ("", "empty calibration file"),
    "rvec of size 2": (
        OPENCV_HEAD + K_OK + _cv_matrix("rvec", 2, "0.1, 0.2") + _cv_matrix("tvec", 3, "1, 2, 3"),
        "field rvec: expected 3 numbers, got 2",
    ),
    "list-form matrix of 8 values": (
        "image_width: 64\nimage_height: 48\ncamera_matrix: [[50, 0, 32], [0, 50, 24], [0, 0]]\n",
        "field camera_matrix: expected 9 numbers",
    ),
    "not a mapping": ("- 1\n- 2\n", "expected a YAML mapping"),
}


@pytest.mark.parametrize("case", list(BAD_CALIBRATIONS))
def test_bad_calibration_files(tmp_path: Path, video: Path, case: str) -> None:
    text, expected = BAD_CALIBRATIONS[case]
    calib = tmp_path / "cam0.yaml"
    calib.write_text(text)
    out = tmp_path / "o.mcap"
    args = ["record", str(out), "--video", f"cam0={video}", "--calib", f"cam0={calib}"]
    _one_line_error(args, str(calib), expected)
    assert not out.exists()


def test_xml_without_opencv_storage(tmp_path: Path, video: Path) -> None:
    calib = tmp_path / "cam0.xml"
    calib.write_text('<?xml version="1.0"?>\n<foo><image_width>64</image_width></foo>\n')
    args = ["record", str(tmp_path / "o.mcap"), "--video", f"cam0={video}"]
    _one_line_error([*args, "--calib", f"cam0={calib}"], "no <opencv_storage> element")


def test_list_form_camera_matrix_is_accepted(tmp_path: Path, video: Path) -> None:
    calib = tmp_path / "cam0.yaml"
    calib.write_text(
        "image_width: 64\nimage_height: 48\ncamera_matrix: [[50, 0, 32], [0, 50, 24], [0, 0, 1]]\n"
        "distortion_coefficients: [0.01, 0, 0, 0, 0]\n"
    )
    out = tmp_path / "o.mcap"
    res = runner.invoke(
        app, ["record", str(out), "--video", f"cam0={video}", "--calib", f"cam0={calib}"]
    )
    assert res.exit_code == 0, res.output
    from trackctl.logs import LogReader

    (model,) = [m.message for m in LogReader(out).messages(["/cam0/camera_model"])]
    assert (model.fx_px, model.cx_px, model.distortion[0]) == (50.0, 32.0, 0.01)


@pytest.mark.parametrize(
    "args, expected",
    [
        (["--start", "5", "--end", "2"], "--end 2.0 is not after --start 5.0"),
        (["--start", "nan"], "--start nan: expected seconds >= 0"),
        (["--end", "-1"], "--end -1.0: expected seconds >= 0"),
        (["--topics", "/nope"], "no topic /nope; the log has: /cam0/calibration"),
        (["--udp", "999.1.1.1:99"], "--udp 999.1.1.1:99: cannot resolve the host"),
        (["--udp", "localhost:0"], "expected HOST:PORT"),
    ],
)
def test_replay_options_are_checked_before_any_output(
    sample_log: Path, args: list[str], expected: str
) -> None:
    res = runner.invoke(app, ["replay", str(sample_log), "--speed", "0", *args])
    assert res.exit_code == 2
    assert res.stdout == ""
    assert expected in res.stderr


def test_fail_if_syntax_error_before_the_run(sample_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "o.mcap"
    _one_line_error(
        ["process", str(sample_log), "--with", "check", "--out", str(out), "--fail-if", "x>>2"],
        "--fail-if: cannot parse 'x>>2'",
    )
    assert not out.exists()
    _one_line_error(
        ["vm-track", str(sample_log), "--fail-if", "idf1<<1"], "--fail-if: cannot parse"
    )
    _one_line_error(
        ["vm-track", str(sample_log), "--refine", "twice"],
        "--refine 'twice': expected auto or full",
    )


def _foreign_log(path: Path) -> None:
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        schema = w.register_schema("foo.Bar", "jsonschema", b"{}")
        channel = w.register_channel("/foo", "json", schema)
        w.add_message(channel, 1, b'{"a":1}', 1)
        w.add_message(channel, 2, b"\xff\xfe{", 2)
        w.add_message(channel, 3, b'{"a":NaN}', 3)
        w.add_message(channel, 4, b'{"a":3}', 4)
        w.finish()


def test_non_utf8_json_payload_of_another_tool_is_skipped_with_a_warning(tmp_path: Path) -> None:
    log = tmp_path / "foreign.mcap"
    _foreign_log(log)
    res = runner.invoke(app, ["replay", str(log), "--speed", "0"])
    assert res.exit_code == 0
    lines = [json.loads(line) for line in res.stdout.splitlines()]  # strict JSON, every line
    assert [line["message"]["a"] for line in lines] == [1, 3]
    assert "/foo at 2 ns: cannot decode foo.Bar" in res.stderr
    assert "/foo at 3 ns: cannot decode foo.Bar" in res.stderr
    check = runner.invoke(app, ["process", str(log), "--with", "check", "--json"])
    assert check.exit_code == 0
    assert json.loads(check.stdout)["reports"][0]["metrics"]["decode_errors"] == 1


def test_smirror_on_a_log_without_robot_metadata(sample_log: Path, tmp_path: Path) -> None:
    # demo.mcap's robot metadata lacks the LED keys: the defaults apply and are named, no crash;
    # its robot carries no LEDs, so no node ever finds it: never localized, never a made-up pose
    res = runner.invoke(app, ["smirror", str(sample_log), "--json", "-q"])
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout.splitlines()[0])
    assert report["system"] == "smirror" and report["fixes"] == 0
    assert report["localized_share"] == 0.0 and report["error_m_mean"] is None
    assert report["unlocalized_samples"] > 0
    assert "site defaults used: robot/r1 led_height_m=0.32" in res.output


def test_output_in_a_read_only_directory(sample_log: Path, tmp_path: Path) -> None:
    if os.geteuid() == 0:
        pytest.skip("root ignores directory permissions")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        _one_line_error(
            ["process", str(sample_log), "--with", "check", "--out", str(ro / "o.mcap")],
            "cannot create o.mcap.partial",
        )
    finally:
        ro.chmod(0o700)


def test_output_folder_missing(sample_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "nope" / "o.mcap"
    _one_line_error(
        ["process", str(sample_log), "--with", "check", "--out", str(out)], "does not exist"
    )


def test_errors_are_one_line_in_a_subprocess_too(tmp_path: Path) -> None:
    proc = run_cli("replay", str(tmp_path / "missing.mcap"))
    assert proc.returncode == 2
    assert proc.stderr.decode().count("\n") == 1 and b"no such file" in proc.stderr


def test_output_directory_not_writable_in_process(
    sample_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # root ignores directory permissions: simulate the EACCES a normal user gets
    import trackctl.logs.writer as writer_module

    real_open = os.open

    def deny(path: object, flags: int, *args: object) -> int:
        if str(path).endswith(".partial"):
            raise PermissionError(13, "Permission denied")
        return real_open(path, flags, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(writer_module.os, "open", deny)
    out = tmp_path / "o.mcap"
    _one_line_error(
        ["process", str(sample_log), "--with", "check", "--out", str(out)],
        "cannot create o.mcap.partial (Permission denied)",
    )
    assert not out.exists()


@pytest.mark.parametrize(
    "engine", ["local", pytest.param("spark", marks=pytest.mark.xdist_group("spark"))]
)
def test_ev_match_on_a_log_without_e_scenarios(
    sample_log: Path, tmp_path: Path, engine: str
) -> None:
    # the matcher's clean-up ran before anything was opened and masked the missing topic
    out = tmp_path / "ev.mcap"
    _one_line_error(
        ["ev-match", str(sample_log), "--out", str(out), "--engine", engine],
        str(sample_log),
        "/ev/e",
    )
    assert not out.exists()


def test_simulate_vm_with_a_bad_trajectory_row_is_one_line_and_writes_nothing(
    tmp_path: Path,
) -> None:
    scene = tmp_path / "scene.txt"
    scene.write_text("0\t1\t0.5\t2.0\n10\t1\t0.7\t2.0\n20\t1\t0,9\t2.0\n")
    out = tmp_path / "vm.mcap"
    _one_line_error(
        ["simulate", "vm", "--out", str(out), "--trajectories", str(scene), "--duration", "5"],
        str(scene),
        "row 3: x_m '0,9' is not a finite number",
    )
    assert not out.exists()
