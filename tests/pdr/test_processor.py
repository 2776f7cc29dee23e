"""The ``pdr`` processor through the library, Typer's runner and a real subprocess."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.conftest import run_cli
from tests.pdr.test_steps import _walk
from trackctl.logs.messages import Imu, Quat, Vec3
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.pdr import PdrProcessor, steps_topic
from trackctl.processing import run_processors


def _log(path: Path, orientation: bool, heading_rad: float = 0.5) -> int:
    t, acc, true = _walk(50.0, 1.8, 40.0, 5.0)
    quat = Rotation.from_euler("z", heading_rad).as_quat()  # device yaw = walking direction
    with LogWriter(path) as w:
        for ti, a in zip(t, acc, strict=True):
            t_ns = 1_000_000_000 + int(ti * 1e9)
            imu = Imu(
                t_ns,
                "phone/p1",
                Vec3(*map(float, a)),
                orientation=Quat(*map(float, quat)) if orientation else None,
            )
            w.write("/phone/p1/imu", imu, t_ns)
    return true


def test_steps_poses_and_path_follow_the_walk(tmp_path: Path) -> None:
    log, out = tmp_path / "walk.mcap", tmp_path / "out.mcap"
    true = _log(log, orientation=True, heading_rad=0.5)
    (rep,) = run_processors(log, out, [PdrProcessor()])
    m = rep.metrics
    assert abs(m["steps_total"] - true) <= 0.03 * true + 1
    assert m["steps/p1"] == m["steps_total"]
    assert m["imu_rate_hz/p1"] == pytest.approx(50.0, abs=0.5)
    assert m["cadence_hz/p1"] == pytest.approx(1.8, abs=0.05)
    steps = [msg.message for msg in LogReader(out).messages([steps_topic("p1")])]
    assert len(steps) == m["steps_total"]
    assert [s.index for s in steps] == list(range(1, len(steps) + 1))
    last = steps[-1]
    # 0.7 m steps along the phone's yaw
    assert math.atan2(last.position_m.y, last.position_m.x) == pytest.approx(0.5, abs=0.01)
    assert math.hypot(last.position_m.x, last.position_m.y) == pytest.approx(0.7 * len(steps))
    assert last.heading_rad == pytest.approx(0.5, abs=0.01)
    topics = LogReader(out).topics()
    assert topics["/pdr/p1/pose"].schema_name == "foxglove.PoseInFrame"
    assert topics["/pdr/p1/path"].count == 1


def test_accelerometer_only_phone_counts_steps_and_says_heading_is_unknown(tmp_path: Path) -> None:
    log = tmp_path / "acc.mcap"
    true = _log(log, orientation=False)
    with pytest.warns(UserWarning, match="accelerometer only"):
        (rep,) = run_processors(log, tmp_path / "o.mcap", [PdrProcessor()])
    assert abs(rep.metrics["steps_total"] - true) <= 0.03 * true + 1
    steps = [m.message for m in LogReader(tmp_path / "o.mcap").messages([steps_topic("p1")])]
    assert steps[0].heading_rad is None


def test_process_with_pdr_from_the_command_line(tmp_path: Path) -> None:
    log, out = tmp_path / "walk.mcap", tmp_path / "out.mcap"
    true = _log(log, orientation=True)
    proc = run_cli("process", str(log), "--with", "pdr", "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr.decode()
    (rep,) = json.loads(proc.stdout)["reports"]
    assert rep["processor"] == "pdr"
    assert abs(rep["metrics"]["steps_total"] - true) <= 0.03 * true + 1
    assert rep["metrics"]["duration_s"] == pytest.approx(50.0, abs=0.1)
    # in-process, through Typer's runner: the same report
    from typer.testing import CliRunner

    from trackctl.cli.main import app

    res = CliRunner().invoke(app, ["process", str(log), "--with", "pdr", "--json"])
    assert res.exit_code == 0
    again = json.loads(res.stdout)["reports"][0]["metrics"]
    # the same figures, processing time aside
    assert {k: v for k, v in again.items() if k != "wall_s"} == {
        k: v for k, v in rep["metrics"].items() if k != "wall_s"
    }
    # a log without phones is a one-line error naming what is missing
    empty = tmp_path / "empty.mcap"
    with LogWriter(empty) as w:
        w.write("/other", Imu(1, "robot/r", Vec3(0, 0, 9.8)), 1)
    proc = run_cli("process", str(empty), "--with", "pdr")
    err = proc.stderr.decode().strip()
    assert proc.returncode == 2 and "/phone/<NAME>/imu" in err and len(err.splitlines()) == 1


def test_shipped_phone_trace_through_record_and_process(tmp_path: Path) -> None:
    from tests.conftest import SHARED_DATA, shared_file

    shared_file("phones", "README.md")
    (src,) = sorted((SHARED_DATA / "phones").glob("user1_hand_*.csv"))
    raw = np.loadtxt(src, delimiter=",")
    csv = tmp_path / "hand.csv"
    np.savetxt(csv, raw[:, :4], delimiter=",", header="t_s,ax,ay,az", comments="", fmt="%.9g")
    log = tmp_path / "hand.mcap"
    rec = run_cli("record", str(log), "--imu", f"hand={csv}", "--time-unit", "ns", "--quiet")
    assert rec.returncode == 0, rec.stderr.decode()
    proc = run_cli("process", str(log), "--with", "pdr", "--json")
    m = json.loads(proc.stdout)["reports"][0]["metrics"]
    true = raw[-1, 5] - raw[0, 5]
    assert abs(m["steps/hand"] - true) <= 0.03 * true
