"""TUM export: read back by evo."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from evo.tools import file_interface

from tests.export.conftest import SAMPLES
from trackctl.errors import InputError, SchemaError
from trackctl.export import ExportConfig, ExportFormat, export
from trackctl.export.tum import tum_time
from trackctl.logs.reader import LogReader

TOPIC = "/robot/r1/dead_reckoning"


def test_dead_reckoning_reads_back_in_evo(demo_reckoned: Path, tmp_path: Path) -> None:
    out = tmp_path / "dr.txt"
    result = export(demo_reckoned, out, ExportConfig(TOPIC, ExportFormat.TUM))
    traj = file_interface.read_tum_trajectory_file(str(out))
    msgs = list(LogReader(demo_reckoned).messages([TOPIC]))
    assert traj.num_poses == len(msgs) == result.rows > 100
    np.testing.assert_allclose(traj.timestamps, [m.log_time_ns / 1e9 for m in msgs], atol=1e-9)
    last = msgs[-1].message.pose
    np.testing.assert_allclose(
        traj.positions_xyz[-1], [last.position.x, last.position.y, last.position.z], atol=1e-6
    )
    q = last.orientation  # evo holds quaternions w first
    np.testing.assert_allclose(traj.orientations_quat_wxyz[-1], [q.w, q.x, q.y, q.z], atol=1e-8)
    assert out.read_text().splitlines()[1].split()[0] == tum_time(msgs[1].log_time_ns)


def test_ground_truth_robot_is_chosen_by_name(tmp_path: Path) -> None:
    log = SAMPLES / "bridgeloc.mcap"
    out = tmp_path / "gt.txt"
    export(log, out, ExportConfig("/ground_truth", ExportFormat.TUM))  # one robot: no --robot
    traj = file_interface.read_tum_trajectory_file(str(out))
    assert traj.num_poses == 50
    first = next(LogReader(log).messages(["/ground_truth"])).message.entities[0]
    yaw = 2 * math.atan2(traj.orientations_quat_wxyz[0][3], traj.orientations_quat_wxyz[0][0])
    assert yaw == pytest.approx(first.yaw_rad, abs=1e-8)


def test_several_robots_need_robot(tmp_path: Path) -> None:
    log = SAMPLES / "vm-office.mcap"
    out = tmp_path / "gt.txt"
    with pytest.raises(
        InputError, match=r"3 entities: choose one with --robot NAME \(n0, u0, u1\)"
    ):
        export(log, out, ExportConfig("/ground_truth", ExportFormat.TUM))
    with pytest.raises(InputError, match=r"no pose of --robot r7; it has: n0, u0, u1"):
        export(log, out, ExportConfig("/ground_truth", ExportFormat.TUM, robot="r7"))
    assert list(tmp_path.iterdir()) == []
    export(log, out, ExportConfig("/ground_truth", ExportFormat.TUM, robot="u1"))
    assert file_interface.read_tum_trajectory_file(str(out)).num_poses == 90


def test_non_pose_topic_is_refused(tmp_path: Path) -> None:
    with pytest.raises(SchemaError, match=r"/rssi holds trackctl.RssiScan; tum export takes"):
        export(SAMPLES / "demo.mcap", tmp_path / "x.txt", ExportConfig("/rssi", ExportFormat.TUM))


def test_tum_time_is_exact() -> None:
    assert tum_time(0) == "0.000000000"
    assert tum_time(1_700_000_000_123_456_789) == "1700000000.123456789"
