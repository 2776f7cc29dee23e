"""``trackctl smirror`` and ``trackctl simulate smirror``: in-process and as a real subprocess."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from tests.conftest import ROOT, run_cli
from trackctl.cli.main import app

SAMPLE = ROOT / "sample_logs" / "smirror.mcap"


def test_cli_json_and_fail_if_in_process(smirror_log: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    out = str(tmp_path / "o.mcap")
    result = runner.invoke(
        app,
        [
            "smirror",
            str(smirror_log),
            "--out",
            out,
            "--json",
            "-q",
            "--fail-if",
            "error_m_mean>0.001",
        ],
    )
    assert result.exit_code == 1, result.output
    metrics = json.loads(result.stdout.splitlines()[0])
    assert metrics["system"] == "smirror" and metrics["error_m_mean"] < 0.3
    result = runner.invoke(app, ["smirror", str(smirror_log), "--out", out, "--mode", "bogus"])
    assert result.exit_code == 2
    assert "--mode 'bogus': expected mirror+odom or centralized" in result.output


def test_cli_on_the_sample_log_subprocess(tmp_path: Path) -> None:
    proc = run_cli(
        "smirror",
        str(SAMPLE),
        "--out",
        str(tmp_path / "o.mcap"),
        "--json",
        "--plot",
        str(tmp_path / "fig"),
        check=True,
    )
    metrics = json.loads(proc.stdout)
    assert metrics["cast_mode"] == "unicast" and metrics["error_m_mean_out_coverage"] < 0.33
    assert (tmp_path / "fig" / "smirror_distance.png").stat().st_size > 1000
    assert (tmp_path / "fig" / "smirror_path.png").stat().st_size > 1000


def test_cli_missing_odometry_is_one_line_exit_2(tmp_path: Path) -> None:
    from trackctl.ingest.video import make_compressed_image
    from trackctl.logs import LogWriter
    from trackctl.sim.smirror import SmirrorScenario, node_models

    src = tmp_path / "no_odom.mcap"
    model = node_models(SmirrorScenario(width_px=64, height_px=48))[0]
    with LogWriter(src) as w:
        w.add_metadata("robot/r1", {"ticks_per_m": 2000})
        w.write("/node0/camera_model", model, 0)
        w.write("/node0/image", make_compressed_image(0, "node0", b"", "jpeg"), 0)
    proc = run_cli("smirror", str(src), "--out", str(tmp_path / "o.mcap"))
    assert proc.returncode == 2
    err = proc.stderr.decode().strip()
    assert err.startswith("error: ") and "/robot/r1/odom" in err and "\n" not in err


def test_simulate_smirror_subprocess(tmp_path: Path) -> None:
    out = tmp_path / "s.mcap"
    proc = run_cli(
        "simulate",
        "smirror",
        "--out",
        str(out),
        "--paths",
        "1",
        "--people",
        "1",
        "--size",
        "160x120",
        "--fps",
        "2",
        "--duration",
        "3",
        "--json",
        check=True,
    )
    counts = json.loads(proc.stdout)["topics"]
    assert counts["/robot/r1/odom"] == 75 and counts["/node0/image"] == 6
    bad = CliRunner().invoke(app, ["simulate", "smirror", "--out", str(out), "--paths", "9"])
    assert bad.exit_code == 2 and "paths must be 1..4" in bad.output


def test_cli_start_pose(smirror_log: Path) -> None:
    runner = CliRunner()
    known = runner.invoke(app, ["smirror", str(smirror_log), "--json", "-q", "--start", "1,2,0"])
    assert known.exit_code == 0, known.output
    assert json.loads(known.stdout.splitlines()[0])["localized_share"] == 1.0
    found = runner.invoke(app, ["smirror", str(smirror_log), "--json", "-q"])
    assert json.loads(found.stdout.splitlines()[0])["localized_share"] < 1.0
    bad = runner.invoke(app, ["smirror", str(smirror_log), "--start", "1,2"])
    assert bad.exit_code == 2
    assert "--start '1,2': expected X,Y,YAW" in bad.output
