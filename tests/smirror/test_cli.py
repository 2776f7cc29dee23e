"""``trackctl smirror`` and ``trackctl simulate smirror``: in-process and as a real subprocess."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from tests.conftest import ROOT, run_cli
from trackctl.cli.main import app

SAMPLE = ROOT / "sample_logs" / "smirror.mcap"


def test_cli_json_in_process(smirror_log: Path, tmp_path: Path) -> None:
    result = CliRunner().invoke(
        app, ["smirror", str(smirror_log), "--out", str(tmp_path / "o.mcap"), "--json", "-q"]
    )
    assert result.exit_code == 0, result.output
    metrics = json.loads(result.stdout)
    assert metrics["system"] == "smirror" and metrics["error_m_mean"] < 0.3


def test_cli_fail_if_and_bad_mode(smirror_log: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    out = str(tmp_path / "o.mcap")
    result = runner.invoke(
        app, ["smirror", str(smirror_log), "--out", out, "-q", "--fail-if", "error_m_mean>0.001"]
    )
    assert result.exit_code == 1
    result = runner.invoke(app, ["smirror", str(smirror_log), "--out", out, "--mode", "bogus"])
    assert result.exit_code == 2
    assert "--mode 'bogus': expected mirror+odom or centralized" in result.output


def test_cli_on_the_sample_log_subprocess(tmp_path: Path) -> None:
    proc = run_cli(
        "smirror", str(SAMPLE), "--out", str(tmp_path / "o.mcap"), "--json", "--plot", str(tmp_path / "fig"),
        check=True,
    )
    metrics = json.loads(proc.stdout)
    assert metrics["cast_mode"] == "unicast" and metrics["error_m_mean_out_coverage"] < 0.33
    assert (tmp_path / "fig" / "smirror_distance.png").stat().st_size > 1000
    assert (tmp_path / "fig" / "smirror_path.png").stat().st_size > 1000


def test_cli_missing_odometry_is_one_line_exit_2(tmp_path: Path) -> None:
    from trackctl.logs import LogReader, LogWriter

    reader = LogReader(SAMPLE)
    src = tmp_path / "no_odom.mcap"
    with LogWriter(src) as w:
        for name, data in reader.metadata().items():
            w.add_metadata(name, data)
        for m in reader.messages():
            if m.topic != "/robot/r1/odom":
                w.write(m.topic, m.message, m.log_time_ns)
    proc = run_cli("smirror", str(src), "--out", str(tmp_path / "o.mcap"))
    assert proc.returncode == 2
    err = proc.stderr.decode().strip()
    assert err.startswith("error: ") and "/robot/r1/odom" in err and "\n" not in err


def test_simulate_smirror_subprocess(tmp_path: Path) -> None:
    out = tmp_path / "s.mcap"
    proc = run_cli(
        "simulate", "smirror", "--out", str(out), "--paths", "1", "--people", "1", "--size", "160x120",
        "--fps", "2", "--duration", "3", "--json", check=True,
    )
    counts = json.loads(proc.stdout)["topics"]
    assert counts["/robot/r1/odom"] == 75 and counts["/node0/image"] == 6
    bad = run_cli("simulate", "smirror", "--out", str(out), "--paths", "9")
    assert bad.returncode == 2 and "paths must be 1..4" in bad.stderr.decode()
