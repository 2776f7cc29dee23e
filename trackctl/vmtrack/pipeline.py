"""VM-Tracking over a log: detections + phone IMU (+ RSSI check-points) -> identified tracks.

:func:`run_stages` is the whole pipeline, and reads as it: each stage is a module with one job,
and each hands the next a typed record (keyed by the tracks' serial keys, never by ``id()``):

0. inputs (:mod:`~trackctl.vmtrack.inputs`): frames or detections, cameras, phones -> ``Inputs``;
1. motion (:mod:`~trackctl.vmtrack.inputs`, :mod:`~trackctl.vmtrack.motion`): every phone's
   walking velocity series (PDR) -> ``PhoneMotion`` by MID;
2. online association (:mod:`~trackctl.vmtrack.association`): detection, association under an
   injected :class:`~trackctl.vmtrack.cost.AssociationCost` and the online binding of phones,
   frame by frame -> ``FrameOut`` per frame (and each frame's detection boxes, kept for 3b);
3. smoothing (:mod:`~trackctl.vmtrack.smooth`, RTS) -> state per (track key, history index);
   3b. appearance (:mod:`~trackctl.vmtrack.appearance`): each track's colour signature from the
   frames in the log (one more pass, decoding only the frames sampled) -> signature by key;
4. offline (:mod:`~trackctl.vmtrack.offline`): publication plan (stitching, and re-identification
   by the signatures across gaps the motion gate cannot bridge), offline identity, identity
   refinement (an injected :class:`~trackctl.vmtrack.offline.Refinement`; by default the
   re-tracking) -> ``Offline``;
5. naming (:mod:`~trackctl.vmtrack.naming`, whose docstring states the rule) and writing
   (:mod:`~trackctl.vmtrack.write`), each frame scored by :mod:`~trackctl.vmtrack.score` (the
   only reader of the ground truth);
6. report (:mod:`~trackctl.vmtrack.report`) -> :class:`~trackctl.vmtrack.interfaces.VmResult`.

``trackctl vm-track`` and the ``vm-track`` processor call :func:`run` (the report only).
"""

from __future__ import annotations

from collections.abc import Sequence

from trackctl.logs.messages import MetricReport
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import Progress
from trackctl.vmtrack.appearance import AppearanceBook, track_appearance
from trackctl.vmtrack.association import associate_online, association_cost
from trackctl.vmtrack.binder import IdentityBinder
from trackctl.vmtrack.config import Identity, Mode, Source, VmTrackConfig
from trackctl.vmtrack.cost import AssociationCost
from trackctl.vmtrack.inputs import phone_motions, plan_inputs
from trackctl.vmtrack.interfaces import FrameOut, VmResult
from trackctl.vmtrack.offline import Refinement, offline_stages
from trackctl.vmtrack.online import OnlineTracker
from trackctl.vmtrack.overlay import TrackOverlay
from trackctl.vmtrack.report import (
    StageClock,
    detector_metrics,
    report_metrics,
    timing_metrics,
    unmeasured,
)
from trackctl.vmtrack.score import TruthScore
from trackctl.vmtrack.smooth import smoothed_positions
from trackctl.vmtrack.tracker import GroundTrack
from trackctl.vmtrack.write import SCENE_TOPIC, TRACKS_TOPIC, write_frames

__all__ = ["Mode", "Source", "VmResult", "VmTrackConfig", "run", "run_stages"]
__all__ += ["SCENE_TOPIC", "TRACKS_TOPIC"]


def run(
    reader: LogReader,
    writer: LogWriter,
    config: VmTrackConfig | None = None,
    progress: Progress | None = None,
) -> MetricReport:
    """Track people in ``reader``; write ``/vmtrack/tracks`` to ``writer``; return the report
    (the processor interface; :func:`run_stages` gives the tracks too)."""
    return run_stages(reader, writer, config, progress).report


def run_stages(
    reader: LogReader,
    writer: LogWriter,
    config: VmTrackConfig | None = None,
    progress: Progress | None = None,
    *,
    cost: AssociationCost | None = None,
    refinement: Refinement | None = None,
) -> VmResult:
    """Track people in ``reader``; write ``/vmtrack/tracks`` (and the scene) to ``writer``;
    return the published tracks and the report.

    The injected parts default to what ``config`` asks for: ``cost``, the association's
    (:func:`~trackctl.vmtrack.association.association_cost`: visual + motion for ``vm``,
    visual only for ``v-af``); ``refinement``, the offline identity refinement
    (:func:`~trackctl.vmtrack.offline.default_refinement`; ``no_refinement`` skips it)."""
    cfg = config or VmTrackConfig()
    progress = progress or _silent
    clock = StageClock()
    inputs = plan_inputs(reader, cfg)
    phones = phone_motions(reader, inputs, cfg)
    clock.lap("motion")
    identity = IdentityBinder(
        phones,
        cfg.binding,
        cfg.align,
        phones_aligned=cfg.phones_aligned,
        keep_evidence=cfg.identity is Identity.ONLINE,
    )
    online = OnlineTracker(cfg, identity, inputs.mode, cost or association_cost(inputs.mode, cfg))
    cams = inputs.detector.cams if inputs.detector is not None else inputs.cams
    overlay = TrackOverlay(cams, cfg.frames.detector.person_height_m)
    # colours come from the frames the detector reads (box-only detections carry none)
    book = AppearanceBook() if cfg.appearance.enabled and inputs.detector is not None else None
    truth = associate_online(reader, writer, inputs, online, progress, overlay, book)
    if inputs.mode is Mode.VM:
        identity.finish()
    clock.lap("tracking")
    progress(0, None, "smoothing")
    positions = smoothed_positions(online.frames, cfg.smooth, cfg.association.tracker)
    looks = (
        track_appearance(reader, book, _all_tracks(online.frames), cfg.appearance)
        if book is not None
        else {}
    )
    offline = offline_stages(
        online, positions, phones, cfg, inputs.mode, progress, refinement, looks
    )
    score = TruthScore(truth, online, cfg.report.eval_threshold_m, inputs.mode, set(phones))
    gate_m = cfg.refinement.gate_m
    tally = write_frames(
        writer, online.frames, positions, offline, phones, gate_m, progress, score, overlay
    )
    metrics = report_metrics(online, phones, inputs.mode, offline, score, tally)
    clock.lap("smoothing")
    metrics.update(timing_metrics(clock, online, inputs.detector))
    metrics["imu_bad_samples"] = sum(p.bad_samples for p in phones.values())
    metrics["source"] = "frames" if inputs.detector is not None else "detections"
    if inputs.detector is not None:
        metrics.update(detector_metrics(inputs.detector, online.frame_count))
    report = MetricReport(
        t_ns=reader.end_ns or 0,
        processor="vm-track",
        metrics=metrics,
        unmeasured=unmeasured(metrics, cfg, inputs.mode),
        params={
            "mode": inputs.mode.value,
            "smooth": cfg.smooth,
            "retrack": cfg.refinement.enabled,
            "rssi": cfg.refinement.radio.enabled,
            "merge_m": cfg.association.merge_m,
            "bind_frames": cfg.binding.bind_frames,
            "reject_mps": cfg.binding.reject_mps,
            "det_sigma_m": cfg.association.tracker.det_sigma_m,
            "pdr_sigma_mps": cfg.association.tracker.pdr_sigma_mps,
        },
    )
    return VmResult(tuple(tally.written), report)


def _all_tracks(frames: Sequence[FrameOut]) -> list[GroundTrack]:
    """Every track of the frames' rows, once each, in order of first appearance."""
    seen: dict[int, GroundTrack] = {}
    for fr in frames:
        for trk, _, _, _ in fr.rows:
            seen.setdefault(trk.key, trk)
    return list(seen.values())


def _silent(done: int, total: int | None, stage: str | None = None) -> None:
    """No progress to report to."""
