"""S-Mirror over a log (dissertation §4.1): nodes mirror foreground views on request, the robot
localizes itself from its LEDs in them and dead-reckons in between.

One library function, :func:`run`, is the whole pipeline; ``trackctl smirror`` and the
``smirror`` processor call it. :func:`localize` does the work and returns every per-sample figure
(the benchmark bins them like the paper's figures); :func:`run` writes the channels and the report.
The stages: the site (:mod:`~trackctl.smirror.site`: cameras, robot, coverage), the event-driven
run (:mod:`~trackctl.smirror.localizer`: nodes, link, robot filter), the metrics (here).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from trackctl.logs.messages import MetricReport
from trackctl.logs.reader import LogMessage, LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import Progress
from trackctl.smirror.config import (
    Mode,
    SmirrorConfig,
    SmirrorResult,
    pose_topic,
    sent_topic,
)
from trackctl.smirror.localizer import Localizer
from trackctl.smirror.site import load_site

__all__ = [
    "Mode",
    "SmirrorConfig",
    "SmirrorResult",
    "error_by_range",
    "localize",
    "pose_topic",
    "report_metrics",
    "run",
    "run_detailed",
    "sent_topic",
]


def _stream(
    reader: LogReader, wanted: dict[str, str], images: set[str], res: SmirrorResult
) -> Iterator[LogMessage]:
    """Decoded messages in log order through the reader's one decode path; a message that does
    not decode, or whose topic has another schema than ``wanted`` says, is skipped with a
    warning and counted (a camera glitch must not end a run)."""
    start = reader.decode_errors
    try:
        yield from reader.messages(list(wanted), expect=wanted)
    finally:
        res.decode_failures += reader.decode_errors - start


def localize(
    reader: LogReader,
    cfg: SmirrorConfig,
    writer: LogWriter | None = None,
    progress: Progress | None = None,
) -> SmirrorResult:
    """Run the nodes and the robot over the log; returns the per-sample figures.

    Raises:
        MissingTopicError: no node camera, no robot, or (mirror+odom) no odometry for the robot.
    """
    site = load_site(reader, cfg)
    loc = Localizer(site, cfg, writer)
    images = set(site.image_topics)
    total = reader.count(loc.wanted_topics())
    for count, msg in enumerate(_stream(reader, loc.expected_schemas(), images, loc.res), 1):
        if progress is not None and count % 50 == 0:
            progress(count, total, "localizing")
        loc.on_message(msg)
    return loc.finish()


def _mean(values: Iterable[float]) -> float | None:
    v = [x for x in values if math.isfinite(x)]
    return None if not v else round(float(np.mean(v)), 4)


def _median(values: Sequence[float], digits: int) -> float | None:
    """Rounded median, None without values."""
    return None if not values else round(float(np.median(values)), digits)


def _ratio(num: float, den: float, digits: int) -> float | None:
    """``num / den`` rounded, None when ``den`` is zero."""
    return None if not den else round(num / den, digits)


@dataclass(frozen=True, slots=True)
class _LinkRates:
    """The link's throughput figures, kB/s (all None in centralized mode)."""

    kbps: float | None = None
    unicast: float | None = None
    in_coverage: float | None = None
    out_coverage: float | None = None


def _coverage_rates(
    res: SmirrorResult, cov: np.ndarray, ev: np.ndarray
) -> tuple[float | None, float | None]:
    """The link's bytes split by where the robot was when they were sent: kB/s in, out."""
    if len(res.t_s) <= 1 or not len(ev):
        return None, None
    ts = np.asarray(res.t_s)
    period = float(np.median(np.diff(ts)))
    idx = np.clip(np.searchsorted(ts, ev[:, 0], side="right") - 1, 0, len(ts) - 1)
    ev_cov = cov[idx]
    t_in, t_out = cov.sum() * period, (~cov).sum() * period
    kin = None if t_in == 0 else round(float(ev[ev_cov, 1].sum()) / t_in / 1e3, 3)
    kout = None if t_out == 0 else round(float(ev[~ev_cov, 1].sum()) / t_out / 1e3, 3)
    return kin, kout


def _link_rates(res: SmirrorResult, cov: np.ndarray, ev: np.ndarray, central: bool) -> _LinkRates:
    """Throughput of the nodes' transmissions ``ev`` (none in centralized mode: no link)."""
    if central:
        return _LinkRates()
    dur = max(res.duration_s, 1e-9)
    kin, kout = _coverage_rates(res, cov, ev)
    return _LinkRates(
        kbps=round(float(ev[:, 1].sum()) / dur / 1e3, 3),
        unicast=round(float(ev[:, 2].sum()) / dur / 1e3, 3),
        in_coverage=kin,
        out_coverage=kout,
    )


def _cast_mode(res: SmirrorResult, central: bool) -> str:
    """How the nodes sent: the one mode used, ``mixed``, or ``none``."""
    if central or not res.cast_modes:
        return "none"
    if len(res.cast_modes) == 1:
        return next(iter(res.cast_modes))
    return "mixed"


def _error_figures(
    err: np.ndarray, cov: np.ndarray, rng: np.ndarray
) -> dict[str, float | int | None]:
    """Error spread, error against range in coverage, coverage share, sample count."""
    empty = not len(err)
    return {
        "error_m_p95": None if empty else round(float(np.percentile(err, 95)), 4),
        "error_m_max": None if empty else round(float(err.max()), 4),
        "error_m_in_coverage_le_11m_max_bin": _max_bin(err[cov], rng[cov]),
        "error_m_per_m_range": _slope(err[cov], rng[cov]),
        "coverage_fraction": None if not len(cov) else round(float(cov.mean()), 4),
        "samples": len(err),
    }


def _cost_figures(res: SmirrorResult) -> dict[str, float | int | None]:
    """What the run sent and processed, and how long it took."""
    return {
        "foreground_bytes": res.foreground_bytes,
        "full_frame_bytes": res.full_frame_bytes,
        "full_to_foreground_ratio": _ratio(res.full_frame_bytes, res.foreground_bytes, 2),
        "image_messages": res.image_messages,
        "images_new": res.images_new,
        "images_old": res.images_old,
        "beacons": res.beacons,
        "node_ms_median": _median(res.node_ms, 3),
        "robot_ms_median": _median(res.robot_ms, 3),
        "fix_attempts": res.fix_attempts,
        "fixes": res.fixes,
        "fixes_used": res.fixes_used,
        "broadcast_lost": res.broadcast_lost,
        "decode_failures": res.decode_failures,
        "duration_s": round(res.duration_s, 3),
    }


def _truthless_figures(res: SmirrorResult, central: bool) -> dict[str, float | int | None]:
    """Figures that need no ground truth: localized time, fixes, filter consistency."""
    nis = np.asarray(res.nis)
    return {
        "localized_share": None
        if central or res.odometry_s <= 0
        else round(res.localized_s / res.odometry_s, 4),
        "first_fix_s": None if res.first_fix_s is None else round(res.first_fix_s, 3),
        "fixes_per_min": None
        if res.duration_s <= 0
        else round(res.fixes_used / (res.duration_s / 60), 3),
        "nis_mean": None if not res.nis else round(float(np.mean(res.nis)), 3),
        "nis_within_95": None if not res.nis else round(float(np.mean(nis <= NIS_95_3DOF)), 4),
        "unlocalized_samples": res.unlocalized_samples,
    }


def _queue_figures(res: SmirrorResult, central: bool) -> dict[str, float | int | None]:
    """The links: queueing, answers never sent, our answers that arrived."""
    queued = not central and bool(res.queue_ms)
    return {
        "queue_ms_mean": _mean(res.queue_ms) if queued else None,
        "queue_ms_max": round(float(np.max(res.queue_ms)), 3) if queued else None,
        "answers_dropped": res.answers_dropped,
        "delivered_share": None if central else _ratio(res.fix_attempts, res.ours_requested, 4),
    }


def report_metrics(
    res: SmirrorResult, cfg: SmirrorConfig
) -> dict[str, float | int | str | bool | None]:
    """The report figures of a run (keys of issue 5 first, then the details)."""
    err = np.asarray(res.error_m)
    cov = np.asarray(res.in_coverage, bool)
    delay = np.asarray(res.delay_ms)
    central = cfg.mode is Mode.CENTRALIZED
    ev = np.asarray(res.events, float).reshape(-1, 4)
    link = _link_rates(res, cov, ev, central)
    rng = np.asarray(res.range_m)
    return {
        "system": "smirror",
        "mode": cfg.mode.value,
        "error_m_mean": _mean(err),
        "error_m_mean_in_coverage": _mean(err[cov]),
        "error_m_mean_out_coverage": _mean(err[~cov]),
        "delay_ms_mean": _mean(delay),
        "kbps_mean": link.kbps,
        "kbps_unicast_equivalent": link.unicast,
        "requesters": res.requesters,
        "cast_mode": _cast_mode(res, central),
        "kbps_in_coverage": link.in_coverage,
        "kbps_out_coverage": link.out_coverage,
        "delay_ms_mean_in_coverage": _mean(delay[cov]),
        "delay_ms_mean_out_coverage": _mean(delay[~cov]),
        **_error_figures(err, cov, rng),
        **_cost_figures(res),
        **_truthless_figures(res, central),
        **_queue_figures(res, central),
        "robots": max(1, len(res.per_robot)),
        **_per_robot(res, cfg),
    }


PER_ROBOT_KEYS = (
    "error_m_mean",
    "error_m_mean_out_coverage",
    "localized_share",
    "first_fix_s",
    "fixes_used",
    "delivered_share",
    "delay_ms_mean_in_coverage",
)
"""Figures reported per robot as ``KEY/<ROBOT>`` when a run localizes several robots."""


def _per_robot(res: SmirrorResult, cfg: SmirrorConfig) -> dict[str, float | int | str | None]:
    if len(res.per_robot) < 2:
        return {}
    out: dict[str, float | int | str | None] = {}
    for name, one in res.per_robot.items():
        m = report_metrics(one, cfg)
        for key in PER_ROBOT_KEYS:
            value = m[key]
            assert not isinstance(value, bool)
            out[f"{key}/{name}"] = value
    return out


NIS_95_3DOF = 7.815
"""95% quantile of chi-square with 3 degrees of freedom: a consistent filter has ~95% of its fixes'
NIS below it."""


def _max_bin(err: np.ndarray, rng: np.ndarray) -> float | None:
    """Largest mean error over the 1 m range bins from 2 to 11 m (Fig. 4.6's claim: <= 0.5 m)."""
    out = []
    for lo in range(2, 11):
        sel = (rng >= lo) & (rng < lo + 1)
        if sel.sum() >= 3:
            out.append(float(err[sel].mean()))
    return None if not out else round(max(out), 4)


def _slope(err: np.ndarray, rng: np.ndarray) -> float | None:
    """Least-squares growth of the in-coverage error with range (m of error per m of range)."""
    ok = np.isfinite(rng)
    if ok.sum() < 10 or np.ptp(rng[ok]) < 1.0:
        return None
    return round(float(np.polyfit(rng[ok], err[ok], 1)[0]), 5)


def error_by_range(
    res: SmirrorResult, edges: Iterable[float] = range(2, 13)
) -> list[tuple[float, float | None, int]]:
    """(bin start m, mean error m, samples) of in-coverage samples by distance to the node."""
    err, rng = np.asarray(res.error_m), np.asarray(res.range_m)
    e = list(edges)
    out = []
    for lo, hi in zip(e[:-1], e[1:], strict=True):
        sel = (rng >= lo) & (rng < hi)
        out.append((float(lo), None if not sel.any() else float(err[sel].mean()), int(sel.sum())))
    return out


def run(
    reader: LogReader,
    writer: LogWriter,
    config: SmirrorConfig | None = None,
    progress: Progress | None = None,
) -> MetricReport:
    """S-Mirror over ``reader``: writes robot poses and node transmissions, returns the report."""
    return run_detailed(reader, writer, config, progress)[0]


def run_detailed(
    reader: LogReader,
    writer: LogWriter | None,
    config: SmirrorConfig | None = None,
    progress: Progress | None = None,
) -> tuple[MetricReport, SmirrorResult]:
    """:func:`run` that also returns the per-sample figures (plots and benchmarks bin them)."""
    cfg = config or SmirrorConfig()
    res = localize(reader, cfg, writer, progress)
    report = MetricReport(
        t_ns=reader.end_ns or 0,
        processor="smirror",
        metrics=report_metrics(res, cfg),
        params={
            "mode": cfg.mode.value,
            "broadcast_threshold": cfg.broadcast_threshold,
            "requesters": res.requesters,
            "robot": res.robot,
            "link_kBps": cfg.link.unicast_kBps,
            "broadcast_kBps": cfg.link.broadcast_kBps,
            "dtim_ms": cfg.link.dtim_ms,
            "max_queue_ms": cfg.link.max_queue_ms,
            "beacon_period_s": cfg.beacon_period_s,
            "sensing_ms": cfg.sensing_ms,
        },
    )
    return report, res
