"""S-Mirror over a rendered log: accuracy, the centralized baseline, data rates and cast modes."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame

from trackctl.errors import InputError, MissingTopicError
from trackctl.logs import LogReader, LogWriter, topics
from trackctl.logs.copy import filter_log
from trackctl.logs.messages import MirrorTransmission
from trackctl.processing import run_processors
from trackctl.smirror import (
    SmirrorConfig,
    SmirrorProcessor,
    error_by_range,
    localize,
    pose_topic,
    run_detailed,
    sent_topic,
)

KEYS = {
    "system",
    "mode",
    "error_m_mean",
    "error_m_mean_in_coverage",
    "error_m_mean_out_coverage",
    "delay_ms_mean",
    "kbps_mean",
    "kbps_unicast_equivalent",
    "requesters",
    "cast_mode",
}


def test_report_has_the_issue_keys(mirror_run) -> None:  # type: ignore[no-untyped-def]
    metrics, _ = mirror_run
    assert KEYS <= set(metrics)
    assert metrics["system"] == "smirror" and metrics["mode"] == "mirror+odom"
    assert metrics["requesters"] == 1 and metrics["cast_mode"] == "unicast"


def test_mirror_odom_is_accurate_in_and_out_of_coverage(mirror_run) -> None:  # type: ignore[no-untyped-def]
    metrics, res = mirror_run
    assert 0.1 < metrics["coverage_fraction"] < 0.95  # the log has both kinds of segment
    assert metrics["error_m_mean_in_coverage"] < 0.2
    assert metrics["error_m_mean_out_coverage"] < 0.33
    assert metrics["fixes"] > 0.5 * metrics["fix_attempts"]
    bins = [b for b in error_by_range(res) if b[2] >= 5]
    assert bins and max(b[1] for b in bins) <= 0.5  # type: ignore[type-var]


def test_centralized_fails_out_of_coverage(mirror_run, centralized_run) -> None:  # type: ignore[no-untyped-def]
    mirror, _ = mirror_run
    central, _ = centralized_run
    assert central["mode"] == "centralized" and central["kbps_mean"] is None
    assert central["error_m_mean_out_coverage"] > 2 * mirror["error_m_mean_out_coverage"]
    assert central["error_m_mean"] > mirror["error_m_mean"]


def test_delay_is_higher_with_images_than_with_odometry(mirror_run) -> None:  # type: ignore[no-untyped-def]
    metrics, _ = mirror_run
    assert metrics["delay_ms_mean_in_coverage"] > metrics["delay_ms_mean_out_coverage"]
    assert metrics["delay_ms_mean_out_coverage"] >= 40.0  # the sensing delay


def test_foreground_only_is_cheaper_than_full_frames(mirror_run) -> None:  # type: ignore[no-untyped-def]
    metrics, _ = mirror_run
    assert metrics["kbps_in_coverage"] <= 174
    assert metrics["kbps_out_coverage"] < metrics["kbps_in_coverage"]
    assert metrics["full_to_foreground_ratio"] >= 4


def test_twenty_requesters_switch_to_broadcast(smirror_log: Path) -> None:
    cfg = SmirrorConfig(requesters=20)
    res = localize(LogReader(smirror_log), cfg)
    from trackctl.smirror import report_metrics

    m = report_metrics(res, cfg)
    assert m["cast_mode"] == "broadcast" and m["requesters"] == 20
    assert m["kbps_mean"] <= 0.1 * m["kbps_unicast_equivalent"]
    below = report_metrics(localize(LogReader(smirror_log), SmirrorConfig(requesters=10)), cfg)
    assert below["cast_mode"] == "unicast"
    assert below["kbps_mean"] > m["kbps_mean"]


def test_outputs_poses_and_transmissions(smirror_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "out.mcap"
    (report,) = run_processors(smirror_log, out, [SmirrorProcessor()])
    reader = LogReader(out)
    present = reader.topics()
    assert present[pose_topic("r1")].schema_name == "foxglove.PoseInFrame"
    assert present[sent_topic("node1")].schema_name == MirrorTransmission.SCHEMA
    poses = [m for m in reader.messages([pose_topic("r1")])]
    assert isinstance(poses[0].message, PoseInFrame)
    # a pose for every odometry sample from the first fix on, none before (start unknown)
    odom = [m.log_time_ns for m in reader.messages(["/robot/r1/odom"])]
    assert 0 < len(poses) < len(odom)
    assert [m.log_time_ns for m in poses] == odom[-len(poses) :]
    first_fix_ns = reader.start_ns + report.metrics["first_fix_s"] * 1e9
    assert poses[0].log_time_ns == pytest.approx(first_fix_ns, abs=1e6)
    sent = [
        m.message for m in reader.messages([sent_topic(n) for n in ("node0", "node1", "node2")])
    ]
    kinds = {s.kind for s in sent}
    assert kinds == {"image", "beacon"}
    images = [s for s in sent if s.kind == "image"]
    assert all(s.bytes_sent == s.payload_bytes * s.requesters for s in images)
    total = sum(s.bytes_sent for s in sent)
    assert total / report.metrics["duration_s"] / 1e3 == pytest.approx(
        report.metrics["kbps_mean"], rel=1e-3
    )


def _copy_without(
    src: Path, dst: Path, drop: str | None = None, corrupt: str | None = None
) -> None:
    """Copy a log, dropping a topic, or damaging two frames of a topic: one's JPEG bytes and
    one's whole protobuf message."""
    reader = LogReader(src)
    with LogWriter(dst) as w:
        for name, data in reader.metadata().items():
            w.add_metadata(name, data)
        damaged = 0
        for raw in reader.raw():
            if raw.topic == drop:
                continue
            if raw.topic == corrupt and raw.log_time_ns > 5e9 and damaged < 2:
                if damaged == 0:
                    msg = reader.codec(raw).decode(raw.data)
                    msg.data = b"\xff\xd8 not a jpeg"
                    w.write(raw.topic, msg, raw.log_time_ns)
                else:
                    w.write_raw(replace(raw, data=b"\x0a\xff\xff not protobuf"))
                damaged += 1
                continue
            w.write_raw(raw)


def test_undecodable_frames_are_skipped_and_counted(smirror_log: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad.mcap"
    _copy_without(smirror_log, bad, corrupt="/node1/image")
    res = localize(LogReader(bad), SmirrorConfig())
    assert res.decode_failures == 2
    assert np.mean(res.error_m) < 0.3


def test_missing_odometry_names_the_topic(smirror_log: Path, tmp_path: Path) -> None:
    no_odom = tmp_path / "no_odom.mcap"
    _copy_without(smirror_log, no_odom, drop="/robot/r1/odom")
    with pytest.raises(MissingTopicError, match=r"/robot/r1/odom is missing.*'r1'"):
        localize(LogReader(no_odom), SmirrorConfig())


def test_poses_do_not_depend_on_the_ground_truth(smirror_log: Path, tmp_path: Path) -> None:
    """The robot finds itself through the nodes: the same poses with and without the truth."""
    without = tmp_path / "no-truth.mcap"
    filter_log(smirror_log, without, exclude=(topics.GROUND_TRUTH,))
    runs = {}
    for name, log in (("with", smirror_log), ("without", without)):
        out = tmp_path / f"{name}.mcap"
        (report,) = run_processors(log, out, [SmirrorProcessor()], outputs_only=True)
        poses = [(r.log_time_ns, bytes(r.data)) for r in LogReader(out).raw([pose_topic("r1")])]
        runs[name] = (report.metrics, poses)
    (m_with, p_with), (m_without, p_without) = runs["with"], runs["without"]
    assert p_with and p_with == p_without
    # scored against the truth only when it is there; the truth-free figures are the same
    assert m_with["error_m_mean"] is not None and m_without["error_m_mean"] is None
    # the truth-scored counts are null without it (a 0 would let a gate pass on nothing)
    assert m_with["unlocalized_samples"] > 0 and m_with["samples"] > 0
    assert m_without["samples"] is None and m_without["unlocalized_samples"] is None
    for key in ("localized_share", "first_fix_s", "fixes_per_min", "nis_mean", "fixes_used"):
        assert m_with[key] == m_without[key] and m_with[key] is not None
    assert 0.5 < m_without["localized_share"] < 1.0


def test_finding_itself_costs_little_against_a_known_start(smirror_log: Path) -> None:
    """A known start (a dock, ``--start``) localizes from the first odometry sample; a robot that
    finds itself through the nodes is as accurate once it has its first fix."""
    reader = LogReader(smirror_log)
    truth = next(iter(reader.messages([topics.GROUND_TRUTH]))).message
    start = next(e for e in truth.entities if e.entity_id == "r1")
    pose = (start.position_m.x, start.position_m.y, float(start.yaw_rad or 0.0))
    known, res_known = run_detailed(LogReader(smirror_log), None, SmirrorConfig(start=pose))
    found, res_found = run_detailed(LogReader(smirror_log), None, SmirrorConfig())
    assert known.metrics["localized_share"] == 1.0
    assert known.metrics["unlocalized_samples"] == 0
    assert found.metrics["first_fix_s"] < 5.0
    # the same samples (from the first fix on): within 3 cm of the run that knew its start
    tail = np.isin(res_known.t_s, res_found.t_s)
    assert tail.sum() == len(res_found.t_s) > 0.8 * len(res_known.t_s)
    err_known = float(np.mean(np.asarray(res_known.error_m)[tail]))
    assert float(np.mean(res_found.error_m)) <= err_known + 0.03


def test_led_coloured_clothes_are_not_taken_for_the_robot(tmp_path: Path) -> None:
    """People in green and magenta shirts (the LEDs' colours) in every room: blobs too large for
    an LED, and pairs that do not lie the LEDs' distance apart, are never a fix."""
    from trackctl.sim.smirror import SmirrorScenario, simulate_smirror

    log = tmp_path / "clutter.mcap"
    scene = SmirrorScenario(
        paths=1, people=6, led_clothes=0.5, width_px=480, height_px=360, fps=2.5, duration_s=34.0
    )
    simulate_smirror(str(log), scene)
    metrics, _ = run_detailed(LogReader(log), None, SmirrorConfig())
    assert metrics.metrics["fixes_used"] > 20
    assert metrics.metrics["error_m_mean"] < 0.2


def test_every_robot_of_a_fleet_is_localized(tmp_path: Path) -> None:
    """Three robots with their own LED colours patrol the same rooms; each asks the nodes for
    images, finds its own LEDs and is localized, and the report says so per robot."""
    from trackctl.sim.smirror import SmirrorScenario, simulate_smirror

    log = tmp_path / "fleet.mcap"
    scene = SmirrorScenario(
        paths=1, people=3, robots=3, width_px=480, height_px=360, fps=2.5, duration_s=45.0, seed=4
    )
    simulate_smirror(str(log), scene)
    out = tmp_path / "out.mcap"
    with LogWriter(out) as writer:
        report, res = run_detailed(LogReader(log), writer, SmirrorConfig())
    m = report.metrics
    assert m["robots"] == 3 and m["requesters"] == 3
    for name in ("r1", "r2", "r3"):
        one = res.per_robot[name]
        assert one.robot == name and len(one.error_m) > 20, name
        assert m[f"error_m_mean/{name}"] is not None and m[f"error_m_mean/{name}"] < 0.25, name
        assert m[f"fixes_used/{name}"] > 10, name
    # the run's samples are all robots' samples
    assert len(res.error_m) == sum(len(r.error_m) for r in res.per_robot.values())
    poses = LogReader(out).topics()
    assert {"/smirror/r1/pose", "/smirror/r2/pose", "/smirror/r3/pose"} <= set(poses)
    # one robot chosen: the others are not localized (nor counted as ours)
    only, res_only = run_detailed(LogReader(log), None, SmirrorConfig(robot="r2"))
    assert only.metrics["robots"] == 1 and list(res_only.per_robot) == ["r2"]
    # the log's other two robots still load the links as requesters (traffic)
    assert only.metrics["requesters"] == 3 and only.metrics["error_m_mean"] < 0.25
    with pytest.raises(InputError, match="choose one with --robot"):
        run_detailed(LogReader(log), None, SmirrorConfig(start=(13.5, 4.0, 0.0)))
