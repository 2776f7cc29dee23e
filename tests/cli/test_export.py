"""``trackctl export``: in-process through Typer's CliRunner and once as a real subprocess."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.conftest import ROOT, run_cli
from trackctl.cli.main import app

runner = CliRunner()
DEMO = ROOT / "sample_logs" / "demo.mcap"


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def log(tmp_path: Path) -> Path:
    copy = tmp_path / "in" / "demo.mcap"
    copy.parent.mkdir()
    shutil.copyfile(DEMO, copy)
    return copy


def _one_line_error(args: list[str], *expected: str) -> str:
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    errors = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(errors) == 1 and errors[0].startswith("error: "), res.stderr
    for text in expected:
        assert text in errors[0], errors[0]
    return errors[0]


def test_writes_mot_with_ids_beside(log: Path, tmp_path: Path) -> None:
    out = tmp_path / "gt.txt"
    res = runner.invoke(
        app, ["export", str(log), "--topic", "/ground_truth", "--format", "mot", "--out", str(out),
              "--camera", "cam0", "--json"],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    assert summary["out"] == str(out) and summary["extra"] == [str(out) + ".ids.csv"]
    lines = out.read_text().splitlines()
    assert len(lines) == summary["rows"] > 0 and lines[0].startswith("1,1,")
    assert Path(summary["extra"][0]).read_text().startswith("mot_id,track_id\n")


def test_writes_tum_and_csv(log: Path, tmp_path: Path) -> None:
    for fmt, topic, more, rows in (
        ("tum", "/ground_truth", ["--robot", "r1"], 200),
        ("csv", "/rssi", [], 20),  # one reading per scan in demo.mcap
    ):
        out = tmp_path / f"out.{fmt}"
        args = ["export", str(log), "--topic", topic, "--format", fmt, "--out", str(out), *more]
        res = runner.invoke(app, args)
        assert res.exit_code == 0, res.output
        assert f"wrote {rows} rows from" in res.stderr, res.stderr
        assert len(out.read_text().splitlines()) == rows + (fmt == "csv")


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["--topic", "/nope", "--format", "mot"],
         ["demo.mcap: no topic /nope; topics it can export as mot: /ground_truth"]),
        (["--topic", "/rssi", "--format", "tum"],
         ["/rssi holds trackctl.RssiScan; tum export takes foxglove.PoseInFrame"]),
        (["--topic", "/ground_truth", "--format", "mot", "--camera", "cam7"],
         ["--camera cam7: no /cam7/camera_model; cameras with a model: cam0"]),
        (["--topic", "/ground_truth", "--format", "xml"], ["--format 'xml': expected mot, tum"]),
        (["--topic", "/ground_truth", "--format", "mot", "--person-height-m", "-1"],
         ["--person-height-m -1.0: expected metres > 0"]),
    ],
)  # fmt: skip
def test_bad_input_is_one_line_and_writes_nothing(
    log: Path, tmp_path: Path, extra: list[str], expected: list[str]
) -> None:
    before = _digest(log)
    out = tmp_path / "out" / "x.txt"
    out.parent.mkdir()
    _one_line_error(["export", str(log), *extra, "--out", str(out)], *expected)
    assert _digest(log) == before
    assert list(out.parent.iterdir()) == []  # no output, no temporary file left


def test_never_overwrites_the_input(log: Path) -> None:
    before = _digest(log)
    _one_line_error(
        ["export", str(log), "--topic", "/rssi", "--format", "csv", "--out", str(log)],
        "is the input log",
    )
    assert _digest(log) == before
    assert sorted(p.name for p in log.parent.iterdir()) == ["demo.mcap"]


def test_existing_output_survives_a_failed_export(log: Path, tmp_path: Path) -> None:
    out = tmp_path / "keep.txt"
    out.write_text("earlier\n")
    _one_line_error(["export", str(log), "--topic", "/rssi", "--format", "mot", "--out", str(out)])
    assert out.read_text() == "earlier\n"


def test_truncated_log_is_read_as_far_as_it_goes(log: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(log.read_bytes()[: log.stat().st_size * 2 // 3])
    out = tmp_path / "imu.csv"
    res = runner.invoke(
        app, ["export", str(cut), "--topic", "/phone/p1/imu", "--format", "csv", "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    assert "warning:" in res.stderr
    rows = out.read_text().splitlines()
    assert 1 < len(rows) <= 401


def test_subprocess(log: Path, tmp_path: Path) -> None:
    out = tmp_path / "odom.csv"
    proc = run_cli(
        "export", str(log), "--topic", "/robot/r1/odom", "--format", "csv", "--out", str(out)
    )
    assert proc.returncode == 0, proc.stderr.decode()
    assert len(out.read_text().splitlines()) == 501
    bad = run_cli("export", str(log), "--topic", "/x", "--format", "csv", "--out", str(out))
    assert bad.returncode == 2 and bad.stderr.decode().count("\n") == 1
