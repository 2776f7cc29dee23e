"""The real ROS 1 bag (``../shared/data/robots/mustang_ros1.bag``): ``record --ros`` then
``process --with dead-reckoning``, checked against the bag itself read with ``rosbags``.

The bag's /wheel_odometry twist does not agree with its own pose (speed from the pose ~3.7 m/s,
twist ~0.3 m/s forward plus a lateral 3.5 m/s): dead reckoning must follow the pose, end where the
bag's own odometry ends, and warn once."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.conftest import shared_file
from trackctl.cli.main import app
from trackctl.logs import LogReader

runner = CliRunner()
ROBOT = "mustang"
WHEELS = f"/robot/{ROBOT}/wheel_odometry"
STEREO = f"/robot/{ROBOT}/stereo_odometer"


@pytest.fixture(scope="module")
def bag() -> Path:
    return shared_file("robots", "mustang_ros1.bag")


@pytest.fixture(scope="module")
def recorded(bag: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("ros1") / "bag.mcap"
    res = runner.invoke(app, ["record", str(out), "--ros", str(bag), "--json"])
    assert res.exit_code == 0, res.output
    topics = json.loads(res.stdout)["topics"]
    assert topics[f"{WHEELS}/odom"] == 1294 and topics[f"{STEREO}/odom"] == 1313
    return out


def _bag_pose_displacement(bag: Path, topic: str) -> tuple[float, float]:
    """Where the bag's own odometry pose ends, in its first pose's frame (forward, left), m."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    poses = []
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        for conn, _, raw in reader.messages(connections=conns):
            p = reader.deserialize(raw, conn.msgtype).pose.pose
            q = p.orientation
            yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y**2 + q.z**2))
            poses.append((p.position.x, p.position.y, yaw))
    (x0, y0, yaw0), (x1, y1, _) = poses[0], poses[-1]
    c, s = math.cos(yaw0), math.sin(yaw0)
    return c * (x1 - x0) + s * (y1 - y0), -s * (x1 - x0) + c * (y1 - y0)


def _process(log: Path, out: Path, *extra: str) -> tuple[dict, list[str]]:
    res = runner.invoke(
        app, ["process", str(log), "--with", "dead-reckoning", "--out", str(out), "--json", *extra]
    )
    assert res.exit_code == 0, res.output
    (report,) = json.loads(res.stdout)["reports"]
    return report["metrics"], [ln for ln in res.stderr.splitlines() if "warning" in ln]


def test_wheel_odometry_follows_its_pose_warns_once_and_scores_the_stereo_odometry(
    bag: Path, recorded: Path, tmp_path: Path
) -> None:
    out = tmp_path / "dr.mcap"
    metrics, warned = _process(recorded, out)
    assert metrics["robots"] == 1 and metrics["sources"] == 2
    # exactly one warning, about /wheel_odometry's twist against its own pose
    assert len(warned) == 1, warned
    assert f"{WHEELS}/odom: its twist disagrees with its pose" in warned[0]
    assert "dead reckoning follows the pose" in warned[0]
    assert metrics[f"method/{ROBOT}/wheel_odometry"] == "pose"
    # the end: within 0.5 m of where the bag's own odometry pose ends (the bug: 233 m vs 35 m)
    *_, last = LogReader(out).messages([f"{WHEELS}/dead_reckoning"])
    fwd, left = _bag_pose_displacement(bag, "/wheel_odometry")
    end = last.message.pose.position
    assert math.hypot(end.x - fwd, end.y - left) < 0.5
    assert 30 < math.hypot(fwd, left) < 40  # the bag's pose ends ~35 m from its start
    # the stereo odometry scored against the wheel odometry's pose (the robot's other reference)
    assert (
        metrics[f"reference/{ROBOT}/stereo_odometer"] == f"/robot/{ROBOT}/reference/wheel_odometry"
    )
    ape = metrics[f"ape_m_rmse/{ROBOT}/stereo_odometer"]
    assert ape is not None and 0 < ape < 50
    assert metrics[f"rpe_m_rmse/{ROBOT}/stereo_odometer"] is not None


def test_named_reference_and_source(recorded: Path, tmp_path: Path) -> None:
    metrics, warned = _process(
        recorded,
        tmp_path / "dr.mcap",
        "--source",
        "/wheel_odometry",
        "--reference",
        "/stereo_odometer/odometry",
    )
    assert metrics["robots"] == 1 and metrics["sources"] == 1 and len(warned) == 1
    assert metrics["reference"] == f"/robot/{ROBOT}/reference/stereo_odometer"
    assert metrics[f"ape_m_rmse/{ROBOT}/wheel_odometry"] == metrics["ape_m_rmse"] > 0
