"""Bad input: one clear line on stderr and exit code 2; process/report/--fail-if; smoke tests
of every command on the shipped sample log, in-process (Typer runner) and as a subprocess."""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.conftest import run_cli
from trackctl.cli.main import app
from trackctl.logs import Imu, LogReader, Vec3

runner = CliRunner()


def _one_line_error(proc_stderr: str, *needles: str) -> None:
    lines = [x for x in proc_stderr.strip().splitlines() if x.strip()]
    assert len(lines) == 1, proc_stderr
    assert lines[0].startswith("error: ")
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


def _cli(*args: str) -> tuple[int, str, str]:
    proc = run_cli(*args)
    return proc.returncode, proc.stdout.decode(), proc.stderr.decode()


def test_not_a_file(tmp_path: Path) -> None:
    code, _, err = _cli("info", str(tmp_path / "missing.mcap"))
    assert code == 2
    _one_line_error(err, "missing.mcap", "no such file")


def test_not_an_mcap(tmp_path: Path) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_text("hello")
    code, _, err = _cli("replay", str(bad))
    assert code == 2
    _one_line_error(err, "bad.mcap", "not an MCAP file")


def test_unknown_schema_on_stdin_is_rejected_and_others_kept(tmp_path: Path) -> None:
    out = tmp_path / "o.mcap"
    good = {
        "topic": "/x",
        "log_time_ns": 1,
        "schema": "trackctl.MetricReport",
        "message": {"timestamp": {"sec": 0, "nsec": 1}, "processor": "p", "metrics": {}},
    }
    bad = dict(good, schema="acme.Thing")
    data = (json.dumps(bad) + "\n" + json.dumps(good) + "\n").encode()
    proc = run_cli("record", str(out), "--stdin", input=data)
    assert proc.returncode == 0
    err = proc.stderr.decode()
    assert "<stdin>:1: topic /x: unknown schema 'acme.Thing'" in err
    assert json.loads(run_cli("info", str(out), "--json").stdout)["topics"]["/x"]["count"] == 1


def test_unknown_schema_in_a_log_names_topic_and_schema(tmp_path: Path) -> None:
    from mcap.writer import Writer

    path = tmp_path / "ros.mcap"
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("my_msgs/Blob", "flatbuffer", b"table Blob {}")
        cid = w.register_channel("/blob", "flatbuffer", sid)
        w.add_message(cid, 1, b"\x00\x01", 1)
        w.finish()
    code, _, err = _cli("replay", str(path), "--speed", "0")
    assert code == 2
    _one_line_error(err, "unknown schema 'my_msgs/Blob'", "flatbuffer")


def test_ros2_cdr_channels_decode(tmp_path: Path) -> None:
    """ROS 2 CDR with its ros2msg definition decodes (trackctl.logs.ros2); a CDR message that
    does not fit its definition is skipped with a warning, not a traceback."""
    from mcap.writer import Writer

    path = tmp_path / "ros.mcap"
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        cid = w.register_channel("/chatter", "cdr", sid)
        w.add_message(cid, 1, b"\x00\x01\x00\x00\x02\x00\x00\x00a\x00", 1)
        w.add_message(cid, 2, b"\x00\x01", 2)
        w.finish()
    code, out, err = _cli("replay", str(path), "--speed", "0", "--format", "jsonl")
    assert code == 0, err
    (line,) = [x for x in out.splitlines() if x.startswith("{")]
    assert '"message":{"data":"a"}' in line.replace(" ", "")
    assert "cannot decode" in err and "Traceback" not in err


def test_missing_required_topic(sample_log: Path, tmp_path: Path) -> None:
    from trackctl.errors import MissingTopicError
    from trackctl.logs import LogReader

    with pytest.raises(MissingTopicError, match="topic /cam7/image is missing; vm-track needs it"):
        LogReader(sample_log).require(["/cam7/image"], "vm-track")


def test_non_monotonic_csv(tmp_path: Path) -> None:
    csv = tmp_path / "IMU.csv"
    csv.write_text("t_s,ax,ay,az,gx,gy,gz\n1,0,0,9.8,0,0,0\n0.5,0,0,9.8,0,0,0\n")
    out = tmp_path / "o.mcap"
    code, _, err = _cli("record", str(out), "--imu", f"p1={csv}")
    assert code == 2
    _one_line_error(err, "IMU.csv: line 3, column t_s", "must not decrease")
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == ["IMU.csv"]


def test_nan_sensor_value(tmp_path: Path) -> None:
    csv = tmp_path / "ODOM.csv"
    csv.write_text("t_s,v_mps,omega_rps\n0,0.1,0\n0.1,NaN,0\n")
    code, _, err = _cli("record", str(tmp_path / "o.mcap"), "--odom", f"r1={csv}")
    assert code == 2
    _one_line_error(err, "ODOM.csv: line 3, column v_mps", "not a finite number")


def test_output_equal_to_input_is_refused(sample_log: Path, tmp_path: Path) -> None:
    log = tmp_path / "in.mcap"
    log.write_bytes(sample_log.read_bytes())
    code, _, err = _cli("process", str(log), "--with", "check", "--out", str(log))
    assert code == 2
    _one_line_error(err, "output path is the input log")
    assert log.read_bytes() == sample_log.read_bytes()


def test_unknown_processor(sample_log: Path, tmp_path: Path) -> None:
    code, _, err = _cli(
        "process", str(sample_log), "--with", "nope", "--out", str(tmp_path / "o.mcap")
    )
    assert code == 2
    _one_line_error(err, "unknown processor 'nope'", "check")


def test_bad_named_option(tmp_path: Path) -> None:
    code, _, err = _cli("record", str(tmp_path / "o.mcap"), "--video", "lobby.mp4")
    assert code == 2
    _one_line_error(err, "--video 'lobby.mp4': expected NAME=PATH")


def test_process_check_writes_input_plus_report(sample_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "checked.mcap"
    proc = run_cli(
        "process", str(sample_log), "--with", "check", "--out", str(out), "--json", check=True
    )
    obj = json.loads(proc.stdout)
    rep = obj["reports"][0]
    assert rep["processor"] == "check"
    assert rep["metrics"]["nonfinite_values"] == 0 and rep["metrics"]["nonmonotonic_stamps"] == 0
    info_in = json.loads(run_cli("info", str(sample_log), "--json").stdout)
    info_out = json.loads(run_cli("info", str(out), "--json").stdout)
    for topic, t in info_in["topics"].items():
        assert info_out["topics"][topic]["count"] == t["count"]
    assert info_out["topics"]["/metrics/check"]["schema"] == "trackctl.MetricReport"
    assert "metrics/check" in info_out["metadata"]
    report = json.loads(run_cli("report", str(out), "--json").stdout)
    assert report["reports"][0]["metrics"] == rep["metrics"]


def test_process_chain_and_fail_if(sample_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "o.mcap"
    ok = run_cli(
        "process",
        str(sample_log),
        "--with",
        "check,check",
        "--out",
        str(out),
        "--fail-if",
        "nonfinite_values>0",
        "--json",
    )
    assert ok.returncode == 0, ok.stderr.decode()
    assert len(json.loads(ok.stdout)["reports"]) == 2
    gate = run_cli("report", str(out), "--fail-if", "messages>=100")
    assert gate.returncode == 1
    assert "fail-if: messages=" in gate.stderr.decode()
    bad_key = run_cli("report", str(out), "--fail-if", "error_m_mean>0.5")
    assert bad_key.returncode == 2
    assert "has no metric 'error_m_mean'" in bad_key.stderr.decode()
    bad_expr = run_cli("report", str(out), "--fail-if", "error is large")
    assert bad_expr.returncode == 2


def test_check_finds_nan_written_by_a_foreign_tool(tmp_path: Path) -> None:
    from mcap.writer import Writer

    from trackctl.logs.codecs import codec_for_type

    codec = codec_for_type(Imu)
    path = tmp_path / "nan.mcap"
    with path.open("wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("trackctl.Imu", "jsonschema", codec.schema_data)
        cid = w.register_channel("/phone/p/imu", "json", sid)
        good = Imu(0, "phone/p", Vec3(0, 0, 9.8), Vec3(0, 0, 0)).to_json()
        bad = dict(good, accel_mps2={"x": float("nan"), "y": 0, "z": 9.8})
        w.add_message(cid, 0, json.dumps(good).encode(), 0)
        w.add_message(cid, 1, json.dumps(bad).encode(), 1)
        w.finish()
    proc = run_cli(
        "process",
        str(path),
        "--with",
        "check",
        "--out",
        str(tmp_path / "o.mcap"),
        "--json",
        "--fail-if",
        "nonfinite_values>0",
    )
    assert proc.returncode == 1
    metrics = json.loads(proc.stdout)["reports"][0]["metrics"]
    assert metrics["nonfinite_values"] == 1
    assert metrics["first_problem"] == "/phone/p/imu: accel_mps2.x = nan"


def test_report_csv(sample_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "o.mcap"
    run_cli("process", str(sample_log), "--with", "check", "--out", str(out), check=True)
    csv = tmp_path / "r.csv"
    run_cli("report", str(out), "--csv", str(csv), "--json", check=True)
    head = csv.read_text().splitlines()[0].split(",")
    assert head[:3] == ["processor", "t_ns", "messages"]


def test_report_on_a_log_without_reports(sample_log: Path) -> None:
    code, _, err = _cli("report", str(sample_log))
    assert code == 2
    _one_line_error(err, "holds no metric report")


# -- smoke: every command on the sample log, in-process through Typer's runner -------------


def _check_info(out: str, tmp: Path) -> None:
    assert out.splitlines()[0].split()[1:4] == ["1242", "messages,", "19.960"]
    assert "/phone/p1/imu" in out and "metadata robot/r1" in out


def _check_info_json(out: str, tmp: Path) -> None:
    info = json.loads(out)
    assert info["message_count"] == 1242 and len(info["topics"]) == 8
    assert info["topics"]["/rssi"]["count"] == 20 and info["topics"]["/rssi"]["rate_hz"] == 1.0


def _check_replay(out: str, tmp: Path) -> None:
    lines = [json.loads(line) for line in out.splitlines()]
    assert len(lines) == 20 and {line["topic"] for line in lines} == {"/rssi"}
    times = [line["log_time_ns"] for line in lines]
    assert times == sorted(times) and times[0] == 0 and times[-1] == 19_000_000_000


def _check_table(out: str, tmp: Path) -> None:
    row = next(line for line in out.splitlines() if line.strip().startswith("/rssi"))
    cells = [c.strip() for c in row.split("│")]
    assert cells[1] == "trackctl.RssiScan" and cells[2] == "20"


def _check_list(out: str, tmp: Path) -> None:
    names = [line.split()[0] for line in out.splitlines()]
    assert names == [
        "bridgeloc",
        "check",
        "dead-reckoning",
        "ev-match",
        "pdr",
        "smirror",
        "vm-track",
    ]


def _check_process(out: str, tmp: Path) -> None:
    reader = LogReader(tmp / "o.mcap")
    assert reader.topics()["/metrics/check"].count == 1
    assert reader.message_count == 1243  # the input's 1242 messages + the report
    assert re.search(r"messages\s+│\s+1242", out) and re.search(r"crc_errors\s+│\s+0", out)


def _check_simulate(out: str, tmp: Path) -> None:
    reader = LogReader(tmp / "d.mcap")
    assert reader.topics()["/phone/p1/imu"].count == 40  # 20 Hz for 2 s
    assert reader.end_ns is not None and reader.end_ns < 2_000_000_000


def _check_version(out: str, tmp: Path) -> None:
    from trackctl import __version__

    assert out.strip() == f"trackctl {__version__}"


@pytest.mark.parametrize(
    "args, check",
    [
        (["info", "{log}"], _check_info),
        (["info", "{log}", "--json"], _check_info_json),
        (["replay", "{log}", "--speed", "0", "--topics", "/rssi"], _check_replay),
        (
            ["replay", "{log}", "--speed", "0", "--format", "table", "--topics", "/rssi"],
            _check_table,
        ),
        (["process", "--list"], _check_list),
        (
            ["process", "{log}", "--with", "check", "--out", "{tmp}/o.mcap", "--quiet"],
            _check_process,
        ),
        (["simulate", "demo", "--out", "{tmp}/d.mcap", "--duration", "2"], _check_simulate),
        (["--version"], _check_version),
    ],
    ids=["info", "info-json", "replay", "replay-table", "list", "process", "simulate", "version"],
)
def test_commands_in_process(
    args: list[str], check: Callable[[str, Path], None], sample_log: Path, tmp_path: Path
) -> None:
    argv = [a.format(log=sample_log, tmp=tmp_path) for a in args]
    result = runner.invoke(app, argv)
    assert result.exit_code == 0, result.output
    check(result.stdout, tmp_path)


def test_json_options_print_exactly_one_object(sample_log: Path, tmp_path: Path) -> None:
    for argv in (
        ["info", str(sample_log), "--json"],
        ["process", "--list", "--json"],
        ["simulate", "demo", "--out", str(tmp_path / "d.mcap"), "--duration", "1", "--json"],
    ):
        result = runner.invoke(app, argv)
        assert result.exit_code == 0
        lines = result.stdout.strip().splitlines()
        assert len(lines) == 1 and isinstance(json.loads(lines[0]), dict)


def test_error_exit_code_in_process(tmp_path: Path) -> None:
    result = runner.invoke(app, ["info", str(tmp_path / "nope.mcap")])
    assert result.exit_code == 2
    assert "no such file" in result.output
