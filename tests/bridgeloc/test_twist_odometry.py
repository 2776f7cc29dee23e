"""BridgeLoc takes odometry as velocities (nav_msgs/Odometry twist) as well as encoder ticks."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from tests.conftest import ROOT
from tests.ingest.ros2_bags import twist_from_ticks
from trackctl.bridgeloc import BridgeLocConfig, BridgeLocProcessor
from trackctl.geometry.odometry import DiffDrive
from trackctl.logs import LogReader, LogWriter
from trackctl.processing import run_processors

SAMPLE = ROOT / "sample_logs" / "bridgeloc.mcap"


def _as_twist(src: Path, dst: Path) -> None:
    """The log with each odometry sample's ticks replaced by the velocities that reproduce the
    next interval's motion."""
    reader = LogReader(src)
    md = reader.metadata()
    drive = DiffDrive(float(md["robot/r1"]["ticks_per_m"]), float(md["robot/r1"]["wheel_base_m"]))
    odos = [m.message for m in reader.messages(["/robot/r1/odom"])]
    vel = twist_from_ticks(odos, drive)
    with LogWriter(dst) as w:
        for name, record in md.items():
            w.add_metadata(name, record)
        for raw in reader.raw():
            if raw.topic != "/robot/r1/odom":
                w.write_raw(raw)
                continue
            o = reader.codec(raw).decode(raw.data)
            v, om = vel.get(o.t_ns, (0.0, 0.0))
            twist = replace(o, left_ticks=None, right_ticks=None, v_mps=v, omega_rps=om)
            w.write("/robot/r1/odom", twist, raw.log_time_ns)


def test_twist_odometry_localizes_like_ticks(tmp_path: Path) -> None:
    twist = tmp_path / "twist.mcap"
    _as_twist(SAMPLE, twist)
    reports = {}
    for name, log in (("ticks", SAMPLE), ("twist", twist)):
        (rep,) = run_processors(log, None, [BridgeLocProcessor(BridgeLocConfig())])
        reports[name] = rep.metrics
    assert reports["twist"]["positions"] == reports["ticks"]["positions"] > 0
    assert reports["twist"]["error_m_mean"] == pytest.approx(
        reports["ticks"]["error_m_mean"], abs=0.005
    )


def test_icam_poses_do_not_need_the_truth(tmp_path: Path) -> None:
    """I-Cam mode writes a pose per infrastructure frame that saw the IR light, with or without
    /ground_truth (which only scores them)."""
    from trackctl.bridgeloc import Mode
    from trackctl.logs.copy import filter_log

    bare = tmp_path / "no-truth.mcap"
    filter_log(SAMPLE, bare, exclude=("/ground_truth",))
    poses = {}
    for name, log in (("with", SAMPLE), ("without", bare)):
        out = tmp_path / f"{name}.mcap"
        run_processors(log, out, [BridgeLocProcessor(BridgeLocConfig(mode=Mode.ICAM))])
        raws = LogReader(out).raw(["/bridgeloc/pose"])
        poses[name] = [(r.log_time_ns, bytes(r.data)) for r in raws]
    # the sample's infrastructure cameras run at 1 Hz for 10 s: one pose per frame with a fix
    # (the robot is within the IR light's range of a camera in 2 of them)
    assert 2 <= len(poses["with"]) <= 11
    assert len({t for t, _ in poses["with"]}) == len(poses["with"])
    assert poses["with"] == poses["without"]
