"""BridgeLoc end to end on the shipped sample log; errors; the sample log is regenerable."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.conftest import ROOT, run_cli
from tests.logcompare import assert_same_log
from trackctl.bridgeloc import Mode
from trackctl.cli.main import app
from trackctl.logs import topics
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.sim.bridgeloc import BridgeLocScenario, simulate_bridgeloc

SAMPLE = ROOT / "sample_logs" / "bridgeloc.mcap"
KEYS = {
    "system",
    "mode",
    "tags",
    "positions",
    "localized",
    "success_rate",
    "error_m_mean",
    "error_m_median",
}


@pytest.fixture(scope="module")
def reports(tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict]:
    out = {}
    for mode in Mode:
        target = tmp_path_factory.mktemp("bl") / f"{mode.value}.mcap"
        res = CliRunner().invoke(
            app,
            [
                "bridgeloc",
                "eval",
                str(SAMPLE),
                "--out",
                str(target),
                "--mode",
                mode.value,
                "--json",
                "-q",
            ],
        )
        assert res.exit_code == 0, res.output
        out[mode.value] = json.loads(res.stdout) | {"_out": str(target)}
    return out


def test_report_keys_and_values(reports: dict[str, dict]) -> None:
    for mode, rep in reports.items():
        assert KEYS <= rep.keys()
        assert rep["system"] == "bridgeloc" and rep["mode"] == mode and rep["tags"] == 6
        assert rep["positions"] == 50  # 10 s of robot pose samples at 5 Hz
        # success = a pose within 0.5 m of the truth, so never more than the poses given
        assert rep["success_threshold_m"] == 0.5
        assert round(rep["success_rate"] * rep["positions"]) <= rep["localized"]


def test_full_mode_on_sample(reports: dict[str, dict]) -> None:
    full, basic, icam = reports["full"], reports["basic"], reports["icam"]
    assert full["success_rate"] >= basic["success_rate"] >= icam["success_rate"]
    assert full["error_m_mean"] < 0.3
    assert full["tag_observations"] > 0 and full["tags_mapped"] == 6


def test_outputs_poses_and_annotations(reports: dict[str, dict]) -> None:
    tops = LogReader(reports["full"]["_out"]).topics()
    assert tops["/bridgeloc/pose"].schema_name == "foxglove.PoseInFrame"
    assert tops["/bridgeloc/pose"].count == reports["full"]["localized"]
    assert tops["/r1cam/tag_annotations"].schema_name == "foxglove.ImageAnnotations"
    assert "/metrics/bridgeloc" in tops


def test_missing_robot_calibration_is_one_line_error(tmp_path: Path) -> None:
    broken = tmp_path / "nocal.mcap"
    reader = LogReader(SAMPLE)
    with LogWriter(broken) as w:
        for raw in reader.raw():
            if raw.topic != topics.camera_model("r1cam"):
                w.write_raw(raw)
        for name, data in reader.metadata().items():
            w.add_metadata(name, data)
    proc = run_cli("bridgeloc", "eval", str(broken), "--out", str(tmp_path / "o.mcap"))
    assert proc.returncode == 2
    err = proc.stderr.decode().strip()
    assert len(err.splitlines()) == 1 and "/r1cam/camera_model" in err and err.startswith("error")


def test_fail_if(tmp_path: Path) -> None:
    res = CliRunner().invoke(
        app,
        [
            "bridgeloc",
            "eval",
            str(SAMPLE),
            "--out",
            str(tmp_path / "o.mcap"),
            "--mode",
            "icam",
            "--json",
            "-q",
            "--fail-if",
            "success_rate<0.99",
        ],
    )
    assert res.exit_code == 1  # the infrastructure cameras alone miss part of this path
    assert json.loads(res.stdout.splitlines()[0])["mode"] == "icam"


def test_shipped_sample_log_is_regenerable(tmp_path: Path) -> None:
    fresh = tmp_path / "bridgeloc.mcap"
    simulate_bridgeloc(
        fresh, BridgeLocScenario(field="lobby", tags=6, duration_s=10, infra_fps=1, seed=0)
    )
    assert_same_log(fresh, SAMPLE)
    assert SAMPLE.stat().st_size < 5_000_000


def test_simulate_cli_rejects_bad_field(tmp_path: Path) -> None:
    res = CliRunner().invoke(
        app, ["simulate", "bridgeloc", "--out", str(tmp_path / "x.mcap"), "--field", "moon"]
    )
    assert res.exit_code == 2 and "--field" in res.output


def test_csv_path_and_office_field(tmp_path: Path) -> None:
    path = tmp_path / "path.csv"
    path.write_text("x_m,y_m\n2.0,2.0\n2.6,2.0\n")
    log = tmp_path / "csv.mcap"
    counts = simulate_bridgeloc(
        log,
        BridgeLocScenario(
            field="lobby", tags=2, path=str(path), duration_s=1.0, robot_fps=2, infra_fps=1
        ),
    )
    assert counts["/r1cam/image"] >= 2 and counts["/cam0/image"] >= 1
    truth = [m.message.entities[0].position_m for m in LogReader(log).messages(["/ground_truth"])]
    assert truth[0].x == pytest.approx(2.0) and truth[0].y == pytest.approx(2.0)
    bad = tmp_path / "bad.csv"
    bad.write_text("x_m,y_m\n1.0,oops\n")
    with pytest.raises(Exception, match="bad.csv:2"):
        simulate_bridgeloc(tmp_path / "b.mcap", BridgeLocScenario(path=str(bad)))


def test_full_mode_without_ground_truth(tmp_path: Path) -> None:
    """The truth is read only by the metrics: the same poses without /ground_truth, and a report
    that still says how much of the run had a pose and a fix, which tags were mapped and seen,
    and whether the filter's innovations matched its covariance."""
    from trackctl.bridgeloc import BridgeLocConfig, BridgeLocProcessor
    from trackctl.logs.copy import filter_log
    from trackctl.processing import run_processors

    bare = tmp_path / "no-truth.mcap"
    filter_log(SAMPLE, bare, exclude=("/ground_truth",))
    poses, reports = {}, {}
    for name, log in (("with", SAMPLE), ("without", bare)):
        out = tmp_path / f"{name}.mcap"
        reports[name] = run_processors(log, out, [BridgeLocProcessor(BridgeLocConfig())])[0]
        poses[name] = [(r.log_time_ns, bytes(r.data)) for r in LogReader(out).raw([POSE])]
    assert poses["with"] and poses["with"] == poses["without"]
    bare_metrics = reports["without"].metrics
    # what needs the truth is null (not 0) and says why
    assert bare_metrics["positions"] is None and bare_metrics["success_rate"] is None
    assert reports["without"].unmeasured["positions"] == "the log has no /ground_truth"
    assert 0.5 < bare_metrics["pose_share"] <= 1.0 and 0.0 < bare_metrics["fix_share"] <= 1.0
    assert bare_metrics["tags_mapped"] == 6 and bare_metrics["tag0_infra_sightings"] >= 3
    assert bare_metrics["nis_per_dof_mean"] is not None and bare_metrics["nis_within_95"] > 0.5
    assert reports["with"].metrics["pose_share"] == bare_metrics["pose_share"]


POSE = "/bridgeloc/pose"


def test_smoothing_uses_the_future_and_no_smooth_gives_the_filter(tmp_path: Path) -> None:
    """Full mode's poses are smoothed by default: the same frames as the causal filter, the
    same pose at the last frame (nothing follows it), other poses moved by what followed;
    ``--no-smooth`` gives the filter's poses. (That smoothing closes gaps is tested in
    tests/bridgeloc/test_smooth.py.)"""
    out: dict[str, dict] = {}
    poses: dict[str, dict[int, tuple[float, float]]] = {}
    for flag in ("--smooth", "--no-smooth"):
        target = tmp_path / f"{flag}.mcap"
        res = CliRunner().invoke(
            app, ["bridgeloc", "eval", str(SAMPLE), "--out", str(target), flag, "--json", "-q"]
        )
        assert res.exit_code == 0, res.output
        out[flag] = json.loads(res.stdout)
        poses[flag] = {
            m.log_time_ns: (m.message.pose.position.x, m.message.pose.position.y)
            for m in LogReader(target).messages([POSE])
        }
    smooth, causal = poses["--smooth"], poses["--no-smooth"]
    assert sorted(smooth) == sorted(causal) and smooth
    last = max(smooth)
    assert smooth[last] == pytest.approx(causal[last], abs=1e-9)
    moved = [t for t in smooth if abs(smooth[t][0] - causal[t][0]) > 0.01]
    assert len(moved) > len(smooth) // 2
    assert out["--smooth"]["pose_share"] == out["--no-smooth"]["pose_share"]
