"""BridgeLoc over a log: camera images + wheel odometry -> robot poses, tag detections, report.

One library function, :func:`run`, is the whole pipeline; ``trackctl bridgeloc eval`` and the
``bridgeloc`` processor call it. Two streaming passes: (1) the infrastructure cameras localize the
static tags (Eq. 4.6) and the robot's IR light (I-Cam); (2) the robot's images and odometry are
replayed in time order: bridging (Eq. 4.9) and the EKF (Eqs. 4.10-4.12).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from trackctl.bridgeloc.bridge import TagMap
from trackctl.bridgeloc.config import (
    POSE_TOPIC,
    BridgeLocConfig,
    Mode,
    PoseMethod,
    annotations_topic,
)
from trackctl.bridgeloc.ekf import chi2_95
from trackctl.bridgeloc.passes import Estimates, RobotPass, Setup, load_setup, map_tags
from trackctl.logs.messages import MetricReport
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import Progress

__all__ = ["POSE_TOPIC", "BridgeLocConfig", "Mode", "PoseMethod", "annotations_topic", "run"]


def run(
    reader: LogReader,
    writer: LogWriter,
    config: BridgeLocConfig | None = None,
    progress: Progress | None = None,
) -> MetricReport:
    """Localize the robot of a BridgeLoc log; write poses and tag annotations; score vs truth.

    The stages: setup, pass 1 (infrastructure cameras: tag map, I-Cam fixes), pass 2 (robot
    camera + odometry: bridging and the EKF), metrics (the only reader of the ground truth).

    Raises:
        MissingTopicError: the robot camera's images or calibration (``/NAME/camera_model``) are
            missing (basic and full modes), or no infrastructure camera has a world pose.
    """
    cfg = config or BridgeLocConfig()
    started = time.perf_counter()
    setup = load_setup(reader, cfg)
    det_times: list[float] = []
    tag_map, icam, n_msgs = map_tags(reader, setup, cfg, writer, progress, det_times)
    robot_pass = RobotPass(reader, setup, cfg, tag_map, icam, writer)
    total = n_msgs + reader.count(robot_pass.topics())
    for msg in reader.messages(robot_pass.topics()):
        n_msgs += 1
        if progress is not None and n_msgs % 10 == 0:
            progress(n_msgs, total, "localizing the robot")
        robot_pass.on_message(msg.topic, msg.log_time_ns, msg.message, det_times)
    robot_pass.finish()
    metrics = _pass_metrics(robot_pass, setup, cfg)
    metrics["detect_ms_median"] = (
        round(1000 * float(np.median(det_times)), 3) if det_times else None
    )
    metrics["ms_per_frame"] = round(
        1000 * (time.perf_counter() - started) / max(1, len(det_times)), 3
    )
    return MetricReport(
        t_ns=reader.end_ns or 0,
        processor="bridgeloc",
        metrics=metrics,
        params={
            "mode": cfg.mode.value,
            "pose": cfg.pose.value,
            "robot": setup.robot,
            "robot_camera": setup.rcam_name,
            "tag_n": setup.tag_n,
            "tag_family": setup.det_cfg.family,
            "tag_size_m": setup.tag_size_m,
            "max_sigma_m": cfg.max_sigma_m,
            "smooth": cfg.smooth,
            "success_m": cfg.success_m,
            "max_range_m": robot_pass.max_range_m
            if math.isfinite(robot_pass.max_range_m)
            else None,
        },
    )


def _pass_metrics(rp: RobotPass, setup: Setup, cfg: BridgeLocConfig) -> dict[str, Any]:
    """The run scored against the ground truth (the only reader of it), as each other mode
    would score it, and the figures that need no truth (coverage, tags, filter consistency)."""
    n_tags = len(rp.tag_map.tags)
    sig = rp.sigmas if cfg.mode is Mode.FULL else None
    metrics: dict[str, Any] = dict(
        _score(rp.est, rp.truth, cfg, n_tags, setup.meta, rp.bridge_only, sig)
    )
    metrics.update(_other_modes(rp, cfg, n_tags))
    metrics.update(_where_basic(rp, cfg))
    metrics.update(asdict(rp.stats))
    metrics.update(_coverage_and_consistency(rp))
    metrics.update(_tag_figures(rp, setup, n_tags))
    return metrics


def _other_modes(rp: RobotPass, cfg: BridgeLocConfig, n_tags: int) -> dict[str, Any]:
    """The same run scored as the other modes would be (same frames, same fixes)."""
    out: dict[str, Any] = {}
    for m, rows in rp.other.items():
        if rows:
            sm = _score(rows, rp.truth, cfg, n_tags, {})
            out[f"success_rate_{m.value}"] = sm["success_rate"]
            out[f"error_m_mean_{m.value}"] = sm["error_m_mean"]
    return out


def _where_basic(rp: RobotPass, cfg: BridgeLocConfig) -> dict[str, Any]:
    """Full mode, like for like: its error where bridging alone gives a pose too."""
    basic = rp.other.get(Mode.BASIC)
    if cfg.mode is not Mode.FULL or not basic:
        return {}
    where = {t for t, p in basic if p is not None}
    errs = [
        math.dist(p[:2], rp.truth[t])
        for t, p in rp.est
        if p is not None and t in where and t in rp.truth
    ]
    return {"error_m_mean_where_basic": round(float(np.mean(errs)), 4) if errs else None}


def _coverage_and_consistency(rp: RobotPass) -> dict[str, Any]:
    """Shares of robot frames with a pose and with a fix; the filter's NIS figures."""
    frames = rp.stats.robot_frames
    nis = [(v, k) for v, k in rp.ekf.nis_values if math.isfinite(v)]
    return {
        "pose_share": round(rp.stats.frames_with_pose / frames, 4) if frames else None,
        "fix_share": round(rp.stats.frames_with_fix / frames, 4) if frames else None,
        "nis_per_dof_mean": round(float(np.mean([v / k for v, k in nis])), 3) if nis else None,
        "nis_within_95": (
            round(float(np.mean([v <= chi2_95(k) for v, k in nis])), 4) if nis else None
        ),
    }


def _tag_figures(rp: RobotPass, setup: Setup, n_tags: int) -> dict[str, Any]:
    """The tag map: each mapped tag and its sightings, and its error against the truth."""
    out: dict[str, Any] = {
        "icam_static_blobs_dropped": rp.icam.static_dropped,
        "tags_mapped": n_tags,
    }
    for k, tag in enumerate(rp.tag_map.tags):
        x, y, z = (round(float(v), 2) for v in tag.center)
        out[f"tag{k}"] = f"{tag.signature} at ({x}, {y}, {z}) m"
        out[f"tag{k}_infra_sightings"] = tag.sightings
        out[f"tag{k}_robot_sightings"] = rp.robot_sightings.get(k, 0)
    out["tag_map_error_m_mean"] = _map_error(rp.tag_map, setup.meta)
    return out


@dataclass(frozen=True, slots=True)
class _Tally:
    """Counts of a scoring pass over the output instants with ground truth."""

    errors: list[float]
    positions: int
    localized: int
    successes: int
    confident: int
    calibrated: int


def _tally(
    est: Estimates,
    truth: dict[int, tuple[float, float]],
    cfg: BridgeLocConfig,
    sigmas: dict[int, float] | None,
) -> _Tally:
    """Errors and counts of the estimates at instants with ground truth."""
    errors = []
    positions = localized = successes = confident = calibrated = 0
    for t_ns, pose in est:
        gt = truth.get(t_ns)
        if gt is None:
            continue
        positions += 1
        if pose is None:
            continue
        localized += 1
        e = math.dist(pose[:2], gt)
        errors.append(e)
        successes += e <= cfg.success_m
        if sigmas is not None and sigmas.get(t_ns, math.inf) <= cfg.max_sigma_m:
            confident += 1
            calibrated += e <= 2 * sigmas[t_ns]
    return _Tally(errors, positions, localized, successes, confident, calibrated)


def _score(
    est: Estimates,
    truth: dict[int, tuple[float, float]],
    cfg: BridgeLocConfig,
    n_tags: int,
    meta: dict[str, str],
    bridge_only: Estimates | None = None,
    sigmas: dict[int, float] | None = None,
) -> dict[str, float | int | str | None]:
    """Positions = output instants with ground truth; success = a pose within ``success_m``
    of the truth; confident (full mode) = the filter's position std <= ``max_sigma_m``."""
    tally = _tally(est, truth, cfg, sigmas)
    errors, positions, confident = tally.errors, tally.positions, tally.confident
    out: dict[str, float | int | str | None] = {
        "system": "bridgeloc",
        "mode": cfg.mode.value,
        "tags": int(len(json.loads(meta["tags_truth"]))) if "tags_truth" in meta else n_tags,
        "positions": positions,
        "localized": tally.localized,
        "success_rate": round(tally.successes / positions, 4) if positions else None,
        "success_threshold_m": cfg.success_m,
        "error_m_mean": round(float(np.mean(errors)), 4) if errors else None,
        "error_m_median": round(float(np.median(errors)), 4) if errors else None,
    }
    if sigmas is not None:
        out["confident_rate"] = round(confident / positions, 4) if positions else None
        out["confident_within_2sigma"] = (
            round(tally.calibrated / confident, 4) if confident else None
        )
    if meta.get("field") == "office" and "tags_truth" in meta and bridge_only is not None:
        out.update(_office_bridging(bridge_only, truth, meta))
    return out


def _office_bridging(
    bridge_only: Estimates, truth: dict[int, tuple[float, float]], meta: dict[str, str]
) -> dict[str, float | None]:
    """Fig. 4.20 is about view bridging itself: the bridging fixes alone, scored per spot."""
    rows = [
        (*truth[t], math.dist(p[:2], truth[t]))
        for t, p in bridge_only
        if p is not None and t in truth
    ]
    return _office_grid(rows, json.loads(meta["tags_truth"])[0])


OFFICE_DISTANCES = (1.0, 2.0, 3.0, 4.0)
OFFICE_ANGLES = (-60.0, -45.0, -30.0, 0.0, 30.0, 45.0, 60.0)


def _office_spot(xy: tuple[float, float], tag: dict) -> tuple[float, float] | None:
    """The test spot (distance, view angle to the tag) the robot stands on, or None."""
    nrm = np.array(tag["normal"])
    v = np.array(xy) - np.array(tag["center_m"][:2])
    d = float(np.linalg.norm(v))
    a = math.degrees(math.atan2(float(v @ np.array([-nrm[1], nrm[0]])), float(v @ nrm)))
    for dd in OFFICE_DISTANCES:
        for aa in OFFICE_ANGLES:
            if abs(d - dd) < 0.03 and abs(a - aa) < 1.0:
                return dd, aa
    return None


def _office_grid(per_frame: list[tuple[float, float, float]], tag: dict) -> dict[str, float | None]:
    """Median error per test spot (distance x view angle to the tag), Fig. 4.20."""
    cells: dict[tuple[float, float], list[float]] = {}
    for x, y, e in per_frame:
        spot = _office_spot((x, y), tag)
        if spot is not None:
            cells.setdefault(spot, []).append(e)
    out: dict[str, float | None] = {}
    near = []
    for (dd, aa), es in sorted(cells.items()):
        med = float(np.median(es))
        out[f"office_median_m_d{dd:g}_a{aa:+g}"] = round(med, 4)
        if dd <= 3.0 and abs(aa) <= 45.0:
            near.append(med)
    out["office_median_m_worst_d_le3_a_le45"] = round(max(near), 4) if near else None
    return out


def _map_error(tag_map: TagMap, meta: dict[str, str]) -> float | None:
    if "tags_truth" not in meta or not tag_map.tags:
        return None
    truth = [np.array(t["center_m"]) for t in json.loads(meta["tags_truth"])]
    errs = [min(float(np.linalg.norm(t.center - g)) for g in truth) for t in tag_map.tags]
    return round(float(np.mean(errs)), 4)
