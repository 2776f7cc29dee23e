"""Built-in processors: check and dead-reckoning."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from tests.conftest import run_cli
from trackctl.geometry.odometry import DiffDrive, integrate_step
from trackctl.logs import (
    GroundTruth,
    GroundTruthEntity,
    Imu,
    LogReader,
    LogWriter,
    Vec3,
    WheelOdometry,
)
from trackctl.logs.copy import filter_log
from trackctl.processing import get_processor, processors, run_processors
from trackctl.processing.builtin import DeadReckoningProcessor


def test_registry_lists_builtins() -> None:
    names = [p.name for p in processors()]
    assert {"check", "dead-reckoning"} <= set(names)
    assert get_processor("check").factory().name == "check"


def test_diff_drive_circle_closes() -> None:
    drive = DiffDrive(ticks_per_m=1000, wheel_base_m=0.5)
    assert drive.motion_from_ticks(100, 300) == pytest.approx((0.2, 0.4))
    x = y = yaw = 0.0
    # a 1 m radius circle: left wheel radius 0.75 m, right 1.25 m, in 1000 steps
    for _ in range(1000):
        dl = 2 * math.pi * 0.75 / 1000
        dr = 2 * math.pi * 1.25 / 1000
        ds, dyaw = (dl + dr) / 2, (dr - dl) / 0.5
        x, y, yaw = integrate_step(x, y, yaw, ds, dyaw)
    assert (x, y) == pytest.approx((0.0, 0.0), abs=1e-6)
    assert yaw == pytest.approx(2 * math.pi)


def test_diff_drive_rejects_bad_geometry() -> None:
    with pytest.raises(ValueError, match="positive ticks_per_m and wheel_base_m"):
        DiffDrive(ticks_per_m=0)


def _straight_log(path: Path, with_metadata: bool) -> None:
    with LogWriter(path) as w:
        if with_metadata:
            w.add_metadata("robot/r1", {"ticks_per_m": 500, "wheel_base_m": 0.4})
        for k in range(11):
            t = k * 100_000_000
            # 0.1 m per step at 500 ticks/m = 50 ticks per wheel
            w.write("/robot/r1/odom", WheelOdometry(t, "robot/r1", 50 * k, 50 * k))
            w.write(
                "/ground_truth",
                GroundTruth(
                    t, (GroundTruthEntity("r1", Vec3(1.0 + 0.1 * k, 2.0, 0.0), yaw_rad=0.0),)
                ),
            )


def test_dead_reckoning_uses_log_geometry_and_reads_truth_only_to_score(tmp_path: Path) -> None:
    src, out = tmp_path / "in.mcap", tmp_path / "out.mcap"
    _straight_log(src, with_metadata=True)
    (report,) = run_processors(src, out, [DeadReckoningProcessor()])
    assert report.metrics["path_m"] == pytest.approx(1.0)
    # scored after aligning the start with the truth's first pose (1, 2)
    assert report.metrics["error_m_max"] == pytest.approx(0.0, abs=1e-9)
    poses = [m.message for m in LogReader(out).messages(["/robot/r1/dead_reckoning"])]
    assert len(poses) == 11
    # the poses are in the robot's odometry frame: the truth does not move them
    assert (poses[-1].pose.position.x, poses[-1].pose.position.y) == pytest.approx((1.0, 0.0))
    assert poses[-1].frame_id == "r1/odom"
    without = tmp_path / "no-truth.mcap"
    filter_log(src, without, exclude=("/ground_truth",))
    (bare,) = run_processors(without, tmp_path / "bare.mcap", [DeadReckoningProcessor()])
    assert bare.metrics["error_m_mean"] is None
    again = [
        m.message for m in LogReader(tmp_path / "bare.mcap").messages(["/robot/r1/dead_reckoning"])
    ]
    assert again == poses


def test_dead_reckoning_alignment_turns_with_the_true_heading(tmp_path: Path) -> None:
    """A robot driving +y in the world drives +x in its odometry frame: no error once aligned."""
    src = tmp_path / "in.mcap"
    with LogWriter(src) as w:
        for k in range(11):
            t = k * 100_000_000
            w.write("/robot/r1/odom", WheelOdometry(t, "robot/r1", 200 * k, 200 * k))
            truth = GroundTruthEntity("r1", Vec3(5.0, 0.1 * k, 0.0), yaw_rad=math.pi / 2)
            w.write("/ground_truth", GroundTruth(t, (truth,)))
    (report,) = run_processors(src, tmp_path / "o.mcap", [DeadReckoningProcessor()])
    assert report.metrics["error_m_max"] == pytest.approx(0.0, abs=1e-9)


def test_dead_reckoning_default_geometry_differs(tmp_path: Path) -> None:
    src, out = tmp_path / "in.mcap", tmp_path / "out.mcap"
    _straight_log(src, with_metadata=False)
    (report,) = run_processors(src, out, [DeadReckoningProcessor()])
    # default 2000 ticks/m: the robot believes it moved a quarter of the true distance
    assert report.metrics["path_m"] == pytest.approx(0.25)
    assert report.metrics["error_m_final"] == pytest.approx(0.75)


def test_dead_reckoning_on_sample_log_drifts(sample_log: Path, tmp_path: Path) -> None:
    proc = run_cli(
        "process",
        str(sample_log),
        "--with",
        "dead-reckoning",
        "--out",
        str(tmp_path / "o.mcap"),
        "--json",
        check=True,
    )
    m = json.loads(proc.stdout)["reports"][0]["metrics"]
    assert m["robots"] == 1 and m["path_m"] > 3.0
    # 1% opposite wheel-scale errors: drift is visible but bounded over ~4 m
    assert 0.01 < m["error_m_final"] < 1.0


def test_dead_reckoning_without_odometry_names_the_missing_topic(tmp_path: Path) -> None:
    src = tmp_path / "imu_only.mcap"
    with LogWriter(src) as w:
        w.write("/phone/p1/imu", Imu(0, "phone/p1", Vec3(0, 0, 9.8), Vec3(0, 0, 0)))
    proc = run_cli(
        "process", str(src), "--with", "dead-reckoning", "--out", str(tmp_path / "o.mcap")
    )
    assert proc.returncode == 2
    lines = proc.stderr.decode().strip().splitlines()
    assert len(lines) == 1
    assert "topic /robot/<NAME>/odom is missing; dead-reckoning needs it" in lines[0]
    assert not (tmp_path / "o.mcap").exists()
