"""VM-Tracking over a log: detections + phone IMU (+ RSSI check-points) -> identified tracks.

One library function, :func:`run`, is the whole pipeline; ``trackctl vm-track`` and the
``vm-track`` processor call it. It is a sequence of stages, each in its own module:

1. inputs (:func:`_plan_inputs`): frames or detections, cameras, phones;
2. motion (:mod:`~trackctl.vmtrack.motion`): every phone's walking velocity series;
3. detection (:mod:`~trackctl.vmtrack.frames`), association (:mod:`~trackctl.vmtrack.online`) and
   identity (:mod:`~trackctl.vmtrack.identity`), online, frame by frame;
4. the offline identity passes (:meth:`IdentityBinder.finish`);
5. smoothing (:func:`_positions`, RTS);
6. writing and metrics (:func:`_write_and_score`; the only reader of the ground truth).
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Container, Iterable
from dataclasses import dataclass, field

import numpy as np
from filterpy.kalman import rts_smoother

from trackctl.errors import MissingTopicError
from trackctl.geometry.camera import PinholeCamera
from trackctl.logs import topics
from trackctl.logs.foxglove import detection_annotations
from trackctl.logs.messages import (
    CameraModel,
    Detections,
    GroundTruth,
    Imu,
    MetricReport,
    Track,
    Tracks,
    TrackState,
    Vec3,
)
from trackctl.logs.reader import LogMessage, LogReader, TopicInfo
from trackctl.logs.writer import LogWriter
from trackctl.metrics.tracking import InitialIdentity, MotAccumulator
from trackctl.processing.base import Progress
from trackctl.vmtrack.align import Alignment
from trackctl.vmtrack.config import Identity, Mode, Source, VmTrackConfig
from trackctl.vmtrack.cost import AssociationCost, VisualCost, VisualMotionCost
from trackctl.vmtrack.frames import FrameDetector, detections_topic, image_cameras
from trackctl.vmtrack.identify import Identities, identify
from trackctl.vmtrack.identity import BindingStats, IdentityBinder
from trackctl.vmtrack.interfaces import FrameOut
from trackctl.vmtrack.motion import PhoneMotion
from trackctl.vmtrack.online import OnlineTracker
from trackctl.vmtrack.overlay import TrackOverlay
from trackctl.vmtrack.radio import RadioEvidence
from trackctl.vmtrack.retrack import PhoneTrack, Retracked, VisitReading, retrack
from trackctl.vmtrack.scene import scene_update
from trackctl.vmtrack.stitch import Publication, plan_publication
from trackctl.vmtrack.tracker import GroundTrack, TrackerConfig

__all__ = ["Mode", "Source", "VmTrackConfig", "run", "TRACKS_TOPIC", "SCENE_TOPIC"]

TRACKS_TOPIC = "/vmtrack/tracks"
SCENE_TOPIC = "/vmtrack/scene"


def _detection_points(reader: LogReader, det_topics: list[str]) -> dict[str, PinholeCamera]:
    """Cameras needed to place box-only detections on the ground (checked up front).

    Raises:
        MissingTopicError: a detections topic holds boxes without ground points and its camera
            has no calibrated world pose (``/<camera>/camera_model``).
    """
    cams: dict[str, PinholeCamera] = {}
    present = reader.topics()
    for topic in det_topics:
        cam = topic.split("/")[1]
        model_topic = topics.camera_model(cam)
        if model_topic in present:
            for m in reader.messages([model_topic]):
                model: CameraModel = m.message
                if model.world_from_camera is not None:
                    cams[cam] = PinholeCamera(model)
                break
        if cam in cams:
            continue
        # Fail before any work when the first frame with boxes already needs the calibration.
        for m in reader.messages([topic]):
            dets: Detections = m.message
            if not dets.detections:
                continue
            if any(d.ground_m is None for d in dets.detections):
                raise MissingTopicError(
                    f"{reader.path}: {model_topic} is missing or has no world pose; vm-track "
                    f"needs it to place {topic} boxes on the ground"
                )
            break
    return cams


@dataclass
class _Inputs:
    """What a run reads: where detections come from, and which phones."""

    mode: Mode
    det_topics: list[str]
    imu_topics: list[str]
    detector: FrameDetector | None = None
    cams: dict[str, PinholeCamera] = field(default_factory=dict)

    def stream_topics(self, present: Container[str]) -> list[str]:
        """Detection (or image) topics, then RSSI and ground truth when the log has them."""
        extra = [t for t in (topics.RSSI, topics.GROUND_TRUTH) if t in present]
        return self.det_topics + extra


def _plan_inputs(reader: LogReader, cfg: VmTrackConfig) -> _Inputs:
    """Stage 0: frames or detections, cameras, phones; errors before any work.

    Raises:
        MissingTopicError: no detections and no frames (or ``--source frames`` without frames).
    """
    present = reader.topics()
    det_topics = sorted(t for t, i in present.items() if i.schema_name == Detections.SCHEMA)
    det_topics = [t for t in det_topics if not t.startswith("/vmtrack/")]
    has_images = any(i.schema_name == "foxglove.CompressedImage" for i in present.values())
    imu_topics = sorted(t for t, i in present.items() if i.schema_name == Imu.SCHEMA)
    if cfg.source is Source.FRAMES or (cfg.source is Source.AUTO and has_images):
        inputs = _frame_inputs(reader, present, cfg, imu_topics)
    elif not det_topics:
        raise MissingTopicError(
            f"{reader.path}: no trackctl.Detections topic (/<camera>/detections) and no "
            f"camera frames; vm-track needs person detections. The log has: "
            f"{', '.join(sorted(present))}"
        )
    else:
        cams = _detection_points(reader, det_topics)
        inputs = _Inputs(cfg.mode, det_topics, imu_topics, cams=cams)
    if inputs.mode is Mode.VM and not imu_topics:
        warnings.warn(
            f"{reader.path}: no IMU topic: running as V-AF (visual only)", UserWarning, stacklevel=3
        )
        inputs.mode = Mode.V_AF
    return inputs


def _frame_inputs(
    reader: LogReader, present: dict[str, TopicInfo], cfg: VmTrackConfig, imu_topics: list[str]
) -> _Inputs:
    """Stage 0 for a log with camera frames: the detector over its image topics."""
    frame_cams = image_cameras(reader, present)
    if not frame_cams:
        raise MissingTopicError(
            f"{reader.path}: no foxglove.CompressedImage topic (/<camera>/image); "
            "--source frames needs camera frames"
        )
    detector = FrameDetector(reader, frame_cams, cfg.frames)
    image_topics = [topics.image(c) for c in sorted(frame_cams)]
    return _Inputs(cfg.mode, image_topics, imu_topics, detector=detector)


def _phone_motions(
    reader: LogReader, inputs: _Inputs, cfg: VmTrackConfig
) -> dict[str, PhoneMotion]:
    """Stage 1: every phone's walking velocity series (PDR), by MID."""
    phones: dict[str, PhoneMotion] = {}
    if inputs.mode is not Mode.VM:
        return phones
    for msg in reader.messages(inputs.imu_topics):
        imu: Imu = msg.message
        mid = imu.frame_id.split("/", 1)[1] if "/" in imu.frame_id else imu.frame_id
        phones.setdefault(mid, PhoneMotion(mid, cfg.motion)).add(imu)
    for p in phones.values():
        p.finish()
    return phones


def _ground_points(
    reader: LogReader, topic: str, dets: Detections, cams: dict[str, PinholeCamera]
) -> list[tuple[str, np.ndarray]]:
    """Ground points (camera, xy) of a detections message: given, or the box's foot point
    projected through the calibrated camera."""
    out = []
    for d in dets.detections:
        if d.ground_m is not None:
            out.append((dets.camera, np.array([d.ground_m.x, d.ground_m.y])))
            continue
        cam = cams.get(dets.camera)
        if cam is None:
            raise MissingTopicError(
                f"{reader.path}: {topics.camera_model(dets.camera)} is missing or has no "
                f"world pose; vm-track needs it to place {topic} boxes on the ground"
            )
        foot = np.array([[d.box.x_px + d.box.w_px / 2, d.box.y_px + d.box.h_px]])
        g = cam.ground_point(foot)[0]
        if not np.isnan(g).any():
            out.append((dets.camera, g[:2]))
    return out


def _track_log(
    reader: LogReader,
    writer: LogWriter,
    inputs: _Inputs,
    online: OnlineTracker,
    progress: Progress | None,
    overlay: TrackOverlay,
) -> dict[int, GroundTruth]:
    """Stage 2 (detection, association, identity): stream the log frame by frame through the
    online tracker; returns the ground truth seen (for the metrics only)."""
    detector = inputs.detector
    truth: dict[int, GroundTruth] = {}
    frame_t: int | None = None
    points: list[tuple[str, np.ndarray]] = []
    covs: list[np.ndarray] | None = None if detector is None else []
    search_full = True
    stream = inputs.stream_topics(reader.topics())
    total = reader.count(stream)
    for n_msgs, msg in enumerate(reader.messages(stream), 1):
        if progress is not None and n_msgs % 50 == 0:
            progress(n_msgs, total, "tracking")
        if msg.topic == topics.GROUND_TRUTH:
            truth[msg.log_time_ns] = msg.message
            continue
        if msg.topic == topics.RSSI:
            online.identity.pending_rssi.append(msg.message)
            online.rssi_log.append(msg.message)
            continue
        if frame_t is not None and msg.log_time_ns != frame_t:
            online.process_frame(frame_t, points, covs)
            points = []
            covs = None if detector is None else []
            online.frame_index += 1
        if msg.log_time_ns != frame_t:
            search_full = online.plan_search() if detector is not None else True
        frame_t = msg.log_time_ns
        if detector is None:
            points.extend(_ground_points(reader, msg.topic, msg.message, inputs.cams))
            overlay.add(msg.log_time_ns, msg.message.t_ns, msg.message)
            continue
        found = _detect_in_frame(msg, detector, online, writer, search_full, points, covs)
        overlay.add(msg.log_time_ns, _image_stamp(msg), found)
    if frame_t is not None:
        online.process_frame(frame_t, points, covs)
    online.close()
    return truth


def _detect_in_frame(
    msg: LogMessage,
    detector: FrameDetector,
    online: OnlineTracker,
    writer: LogWriter,
    search_full: bool,
    points: list[tuple[str, np.ndarray]],
    covs: list[np.ndarray] | None,
) -> Detections:
    """One camera image of stage 2: people detected (in the tracks' predicted regions unless
    ``search_full``), their detections written (with their image overlay), their ground points
    (and covariances) appended to the frame's; returns the detections."""
    camera = msg.topic.strip("/").split("/")[0]
    people = online.predictions(msg.log_time_ns, moved_only=True)
    preds = None if search_full else online.predictions(msg.log_time_ns)
    found, ground, ground_covs = detector.detect(
        msg.log_time_ns, camera, bytes(msg.message.data), preds, people
    )
    writer.write(detections_topic(camera), found, msg.log_time_ns)
    writer.write(
        topics.overlay(detections_topic(camera)),
        detection_annotations(found, _image_stamp(msg)),
        msg.log_time_ns,
    )
    points.extend((camera, g) for g in ground)
    if covs is not None:
        covs.extend(ground_covs)
    return found


def _image_stamp(msg: LogMessage) -> int:
    """The image's own timestamp (what Foxglove matches overlays on), else its log time."""
    image = msg.message
    if image.HasField("timestamp"):
        return int(image.timestamp.ToNanoseconds())
    return msg.log_time_ns


def _association_cost(mode: Mode, cfg: VmTrackConfig) -> AssociationCost:
    """Returns the association's cost for ``mode``: position only for ``v-af``, position and
    the phones' velocities for ``vm``."""
    if mode is Mode.V_AF:
        return VisualCost(cfg.tracker.gate_p)
    return VisualMotionCost(cfg.tracker.gate_p, cfg.tracker.pdr_sigma_mps)


def run(
    reader: LogReader,
    writer: LogWriter,
    config: VmTrackConfig | None = None,
    progress: Progress | None = None,
) -> MetricReport:
    """Track people in ``reader``; write ``/vmtrack/tracks`` to ``writer``; return the report.

    The stages: inputs, phone motion, detection + association + identity (online, frame by
    frame), offline identity passes, smoothing, writing and metrics.
    """
    cfg = config or VmTrackConfig()
    clock = _Clock()
    inputs = _plan_inputs(reader, cfg)
    phones = _phone_motions(reader, inputs, cfg)
    clock.lap("motion")
    identity = IdentityBinder(phones, cfg)
    online = OnlineTracker(cfg, identity, inputs.mode, _association_cost(inputs.mode, cfg))
    cams = inputs.detector.cams if inputs.detector is not None else inputs.cams
    overlay = TrackOverlay(cams, cfg.frames.detector.person_height_m)
    truth = _track_log(reader, writer, inputs, online, progress, overlay)
    if inputs.mode is Mode.VM:
        identity.finish()
    clock.lap("tracking")
    progress = progress or _silent
    progress(0, None, "smoothing")
    positions = _positions(online.frames, cfg.smooth, cfg.tracker)
    report = _write_and_score(
        writer, online, positions, truth, phones, cfg, inputs.mode, progress, overlay
    )
    clock.lap("smoothing")
    metrics = dict(report)
    metrics.update(_timing_metrics(clock, online, inputs.detector))
    metrics["imu_bad_samples"] = sum(p.bad_samples for p in phones.values())
    metrics["source"] = "frames" if inputs.detector is not None else "detections"
    if inputs.detector is not None:
        metrics.update(_detector_metrics(inputs.detector, online.frame_count))
    return MetricReport(
        t_ns=reader.end_ns or 0,
        processor="vm-track",
        metrics=metrics,
        unmeasured=_unmeasured(metrics, cfg, inputs.mode),
        params={
            "mode": inputs.mode.value,
            "smooth": cfg.smooth,
            "retrack": cfg.retrack.enabled,
            "rssi": cfg.retrack.radio.enabled,
            "merge_m": cfg.merge_m,
            "bind_frames": cfg.bind_frames,
            "reject_mps": cfg.reject_mps,
            "det_sigma_m": cfg.tracker.det_sigma_m,
            "pdr_sigma_mps": cfg.tracker.pdr_sigma_mps,
        },
    )


def _silent(done: int, total: int | None, stage: str | None = None) -> None:
    """No progress to report to."""


_RETRACK_ONLY = (
    "withheld_s/",
    "ambiguous_s/",
    "grouped_s/",
    "searched/",
    "visits",
    "edge_turnover",
    "occupancy_steadiness",
)
_BINDINGS = ("bindings", "checkpoint_bindings", "offline_bindings")


def _unmeasured(
    metrics: dict[str, float | int | str | None], cfg: VmTrackConfig, mode: Mode
) -> dict[str, str]:
    """Why figures the configuration leaves out are null (the log's own gaps, such as no
    ground truth, are found by the runner from metrics/catalog.py). V-AF binds no phone: its
    binding counts are set to null here."""
    why: dict[str, str] = {}
    if mode is Mode.V_AF:
        for key in _BINDINGS:
            if key in metrics:
                metrics[key] = None
                why[key] = "v-af binds no phone (visual only)"
    if mode is Mode.V_AF or not cfg.retrack.enabled:
        reason = (
            "re-tracking is off (--no-retrack)" if mode is Mode.VM else "v-af re-tracks nothing"
        )
        why.update(
            {k: reason for k, v in metrics.items() if k.startswith(_RETRACK_ONLY) and v is None}
        )
    return why


class _Clock:
    """Wall time of each stage (reported per frame)."""

    def __init__(self) -> None:
        self.started = self._last = time.perf_counter()
        self.laps: dict[str, float] = {}

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.laps[name] = now - self._last
        self._last = now


def _timing_metrics(
    clock: _Clock, online: OnlineTracker, detector: FrameDetector | None
) -> dict[str, float]:
    n = max(online.frame_count, 1)
    return {
        "ms_per_frame": round(1000 * (time.perf_counter() - clock.started) / n, 3),
        "ms_per_frame_motion": round(1000 * clock.laps["motion"] / n, 3),
        "ms_per_frame_association": round(1000 * online.seconds / n, 3),
        "ms_per_frame_smoothing": round(1000 * clock.laps["smoothing"] / n, 3),
    }


def _detector_metrics(detector: FrameDetector, frames: int) -> dict[str, float | int]:
    n = max(frames, 1)
    return {
        "ms_per_frame_decode": round(1000 * detector.seconds_decode / n, 3),
        "ms_per_frame_detection": round(1000 * detector.seconds_detect / n, 3),
        "background_s": round(detector.seconds_background, 3),
        "full_searches": detector.full_searches,
        "region_searches": detector.region_searches,
        "bad_frames": detector.bad_frames,
    }


def _positions(
    frames: list[FrameOut], smooth: bool, cfg: TrackerConfig
) -> dict[tuple[int, int], tuple[np.ndarray, np.ndarray]]:
    """State (x, y, vx, vy) and covariance of every (track, history index): RTS-smoothed when
    asked (filterpy; the offline advantage the paper's real-time system did not have)."""
    out: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
    seen: dict[int, GroundTrack] = {}
    for fr in frames:
        for trk, _, _, _ in fr.rows:
            seen[id(trk)] = trk
    for key, trk in seen.items():
        hist = trk.history
        if not hist:
            continue
        xs = np.array([h[1] for h in hist])
        ps = np.array([h[2] for h in hist])
        if smooth and len(hist) > 2:
            fs, qs = [], []
            for k in range(len(hist)):
                dt = (hist[k + 1][0] - hist[k][0]) / 1e9 if k + 1 < len(hist) else 0.0
                f, q = trk.transition(dt, cfg)
                fs.append(f)
                qs.append(q)
            xs, ps, _, _ = rts_smoother(xs, ps, np.array(fs), np.array(qs))
        for k in range(len(hist)):
            out[(key, k)] = (xs[k][:, 0], ps[k])
    return out


def _track_message(
    out_id: str, trk: GroundTrack, state: TrackState, est: tuple[np.ndarray, np.ndarray] | None
) -> Track:
    """A trackctl.Track from an estimated state (x, y, vx, vy) and its covariance."""
    if est is None:
        x, p = trk.kf.x[:, 0], trk.kf.P
    else:
        x, p = est
    cov = np.zeros((3, 3))
    cov[:2, :2] = p[:2, :2]
    return Track(
        out_id,
        Vec3(float(x[0]), float(x[1]), 0.0),
        Vec3(float(x[2]), float(x[3]), 0.0),
        tuple(float(c) for c in cov.ravel()),
        state=state,
        visual_id=trk.vid,
    )


def _frame_tracks(
    fr: FrameOut,
    plan: Publication,
    positions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    ids: Identities | None = None,
    carriers: tuple[dict[str, PhoneTrack], int, float] | None = None,
) -> list[Track]:
    """The tracks published at one frame: the online rows the clean-up keeps, under their
    published ids (the offline identity's MID, else the online binding's, else the visual
    id), plus interpolated positions across stitched gaps. ``carriers``: the re-tracked
    carriers, this frame's index and the gate (m); a re-tracked phone's MID is published only
    where its re-tracking put it, on the nearest track within the gate (or on its own)."""
    retracked = carriers[0] if carriers is not None else {}
    tracks: list[Track] = []
    names: set[str] = set()
    _add_rows(tracks, names, fr, plan, positions, ids, retracked)
    _add_fills(tracks, names, fr.t_ns, plan, ids, retracked)
    if carriers is not None:
        _place_carriers(tracks, names, *carriers)
    if ids is not None:
        _add_unseen(tracks, names, ids.unseen.get(fr.t_ns, ()), retracked)
    return tracks


def _add_rows(
    tracks: list[Track],
    names: set[str],
    fr: FrameOut,
    plan: Publication,
    positions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    ids: Identities | None,
    retracked: dict[str, PhoneTrack],
) -> None:
    """Append (in place) the frame's online rows the clean-up keeps, each under an id no other
    track of the frame has taken."""
    # tracks bound now name first: one phone (MID) is never on two tracks in one frame, so a
    # back-dated identity gives way to the binding of the moment
    rows = sorted(fr.rows, key=lambda r: r[1] is None)
    for trk, mid_now, state, k in rows:
        if (id(trk), fr.t_ns) in plan.hidden:
            continue
        out_id = _row_id(trk, mid_now, fr.t_ns, plan, ids, retracked)
        out_id = _unclaimed_id(out_id, trk, plan, names)
        # entry k of a track's history is its state at this frame (snapshotted before the
        # next frame's prediction, or when the log ends)
        tracks.append(_track_message(out_id, trk, state, positions.get((id(trk), k))))
        names.add(out_id)


def _row_id(
    trk: GroundTrack,
    mid_now: str | None,
    t_ns: int,
    plan: Publication,
    ids: Identities | None,
    retracked: dict[str, PhoneTrack],
) -> str:
    """The id an online row would be published under at ``t_ns``: the offline identity's MID,
    else the online binding's (or its back-dated identity), else the track's published name."""
    name = plan.name.get(id(trk), trk.vid)
    if ids is not None:
        return _chain_mid(ids, plan.head.get(id(trk), id(trk)), t_ns, retracked, name)
    if mid_now is not None:
        return mid_now
    if trk.first_mid is not None and trk.identity_from_ns <= t_ns < (trk.first_bound_ns or 0):
        # online identity, offline back-dated: the identity found later holds back to
        # where the track's motion stops agreeing with the phone
        return trk.first_mid
    return name


def _unclaimed_id(out_id: str, trk: GroundTrack, plan: Publication, names: set[str]) -> str:
    """``out_id`` unless another track of the frame has it; then the track's published name,
    or its visual id if that is taken too."""
    if out_id not in names:
        return out_id
    out_id = plan.name.get(id(trk), trk.vid)
    return trk.vid if out_id in names else out_id


def _add_fills(
    tracks: list[Track],
    names: set[str],
    t_ns: int,
    plan: Publication,
    ids: Identities | None,
    retracked: dict[str, PhoneTrack],
) -> None:
    """Append (in place) the positions interpolated across stitched gaps at ``t_ns`` (under
    their chain's MID when the offline identity gives one), where the id is still free."""
    for name, xy, v in plan.fills.get(t_ns, ()):
        out_id = name
        if ids is not None:
            out_id = _chain_mid(ids, plan.head_of_name.get(name, -1), t_ns, retracked, name)
        if out_id not in names:
            names.add(out_id)
            tracks.append(_coasting_track(out_id, xy, v))


def _add_unseen(
    tracks: list[Track],
    names: set[str],
    unseen: Iterable[tuple[str, tuple[float, float], tuple[float, float]]],
    retracked: dict[str, PhoneTrack],
) -> None:
    """Append (in place) the carriers no camera showed, walked on their phone between two
    stretches of their chains (not a MID already published, nor a re-tracked one)."""
    for mid, xy, v in unseen:
        if mid not in names and mid not in retracked:
            names.add(mid)
            tracks.append(_coasting_track(mid, xy, v))


def _coasting_track(
    out_id: str, xy: np.ndarray | tuple[float, float], v: np.ndarray | tuple[float, float]
) -> Track:
    """A ``predicted`` trackctl.Track at ground position ``xy`` with velocity ``v`` (no
    covariance)."""
    return Track(
        out_id,
        Vec3(float(xy[0]), float(xy[1]), 0.0),
        Vec3(float(v[0]), float(v[1]), 0.0),
        state=TrackState.PREDICTED,
    )


def _chain_mid(
    ids: Identities, head: int, t_ns: int, retracked: dict[str, PhoneTrack], default: str
) -> str:
    """The MID the offline identity gives chain ``head`` at ``t_ns`` (``default`` if none, or
    if that phone was re-tracked: then its re-tracking alone places it)."""
    mid = ids.mid_at.get((head, t_ns))
    return default if mid is None or mid in retracked else mid


def _place_carriers(
    tracks: list[Track], names: set[str], retracked: dict[str, PhoneTrack], k: int, gate: float
) -> None:
    """Name the re-tracked carriers at frame ``k`` (in place): each MID takes the nearest
    anonymous track within ``gate`` of where its phone put the carrier, at that position; a
    carrier no track is near is published on its own (``predicted`` where no detection was on
    its path)."""
    for mid in sorted(retracked):
        pt = retracked[mid]
        xy = pt.xy.get(k)
        if xy is None or mid in names:
            continue
        v = pt.velocity[k]
        vel = Vec3(0.0, 0.0, 0.0) if np.isnan(v).any() else Vec3(float(v[0]), float(v[1]), 0.0)
        state = TrackState.TRACKED if k in pt.seen else TrackState.PREDICTED
        best, best_d = -1, gate
        for i, trk in enumerate(tracks):
            if trk.track_id in retracked:
                continue
            d = math.hypot(trk.position_m.x - xy[0], trk.position_m.y - xy[1])
            if d < best_d:
                best, best_d = i, d
        pos = Vec3(float(xy[0]), float(xy[1]), 0.0)
        if best >= 0:
            old = tracks[best]
            names.discard(old.track_id)
            tracks[best] = Track(
                mid, pos, vel, old.covariance_m2, state=old.state, visual_id=old.visual_id
            )
        else:
            tracks.append(Track(mid, pos, vel, state=state))
        names.add(mid)


def _write_and_score(
    writer: LogWriter,
    online: OnlineTracker,
    positions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    truth: dict[int, GroundTruth],
    phones: dict[str, PhoneMotion],
    cfg: VmTrackConfig,
    mode: Mode,
    progress: Progress,
    overlay: TrackOverlay,
) -> dict[str, float | int | str | None]:
    """Stages 4-5: write tracks, the 3-D scene and the cameras' track overlays per frame; score
    them against the ground truth when the log has it (metrics only: nothing above reads the
    truth)."""
    offline = _offline_stages(online, positions, phones, cfg, mode, progress)
    score = _TruthScore(truth, online, cfg.eval_threshold_m, mode, set(phones))
    tally = _write_frames(
        writer,
        online.frames,
        positions,
        offline,
        phones,
        cfg.retrack.gate_m,
        progress,
        score,
        overlay,
    )
    return _report(online, phones, mode, offline, score, tally)


@dataclass(frozen=True)
class _Offline:
    """What the offline stages give the writing: the publication plan (stitching, clean-up),
    the offline identity (None unless asked) and the re-tracked carriers (empty unless run)."""

    plan: Publication
    ids: Identities | None
    retracked: Retracked


def _offline_stages(
    online: OnlineTracker,
    positions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    phones: dict[str, PhoneMotion],
    cfg: VmTrackConfig,
    mode: Mode,
    progress: Progress,
) -> _Offline:
    """The offline stages: the publication plan, then (VM with the offline identity) the
    identities, then (when enabled) the re-tracking."""
    frames = online.frames
    offline = mode is Mode.VM and cfg.identity is Identity.OFFLINE
    deaths = np.array(online.static_death_log, float).reshape(-1, 2)
    progress(0, None, "stitching and identifying")
    plan = plan_publication(frames, positions, cfg.stitch, all_tracks=offline, static_deaths=deaths)
    ids = (
        identify(frames, plan, phones, cfg.align, cfg.identify, cfg.phones_aligned)
        if offline
        else None
    )
    if ids is None or not cfg.retrack.enabled:
        return _Offline(plan, ids, Retracked())
    return _Offline(plan, ids, _retrack(online, ids, phones, cfg, progress))


def _retrack(
    online: OnlineTracker,
    ids: Identities,
    phones: dict[str, PhoneMotion],
    cfg: VmTrackConfig,
    progress: Progress,
) -> Retracked:
    """The identified phones' carriers re-tracked over the raw detections (and RSSI); their
    alignments replace the identity's in ``ids`` (for the report)."""
    frame_t = np.array([fr.t_ns for fr in online.frames], np.int64)
    points = [online.raw_points.get(int(t), np.empty((0, 2))) for t in frame_t]
    model = (cfg.rssi_at_1m_dbm, cfg.path_loss_exponent)
    radio = RadioEvidence(frame_t, online.rssi_log, model, cfg.retrack.radio)
    retracked = retrack(
        frame_t,
        points,
        phones,
        ids.known,
        cfg.align,
        cfg.retrack,
        cfg.phones_aligned,
        radio,
        progress,
        _trusted(ids, cfg.retrack.trust_clear_share),
    )
    _take_retrack_alignments(ids.alignments, retracked)
    return retracked


@dataclass
class _Tally:
    """The tracks written: frames published per id, track-frames coasting, track-frames."""

    published: dict[str, int] = field(default_factory=dict)
    coasting: int = 0
    shown: int = 0

    def add(self, tracks: list[Track]) -> None:
        """Count one frame's published tracks."""
        for msg in tracks:
            self.published[msg.track_id] = self.published.get(msg.track_id, 0) + 1
            self.coasting += msg.state is TrackState.PREDICTED
        self.shown += len(tracks)


def _write_frames(
    writer: LogWriter,
    frames: list[FrameOut],
    positions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    offline: _Offline,
    phones: dict[str, PhoneMotion],
    gate_m: float,
    progress: Progress,
    score: _TruthScore,
    overlay: TrackOverlay,
) -> _Tally:
    """Each frame's published tracks and 3-D scene written, counted and scored; returns the
    count."""
    tally = _Tally()
    for k_fr, fr in enumerate(frames):
        progress(k_fr, len(frames), "writing tracks")
        placed = (offline.retracked, k_fr, gate_m) if offline.retracked else None
        tracks = _frame_tracks(fr, offline.plan, positions, offline.ids, placed)
        tally.add(tracks)
        writer.write(TRACKS_TOPIC, Tracks(fr.t_ns, tuple(tracks)))
        writer.write(SCENE_TOPIC, scene_update(fr.t_ns, tracks, set(phones)), fr.t_ns)
        overlay.write(writer, fr.t_ns, tracks)
        score.add_frame(fr.t_ns, tracks)
    return tally


class _TruthScore:
    """The published tracks scored against the ground truth, frame by frame (the only reader
    of the truth): MOT over everybody and over the phone users, each carrier's position error,
    its losses and recoveries of identity (VM), and the raw detections' error and recall."""

    def __init__(
        self,
        truth: dict[int, GroundTruth],
        online: OnlineTracker,
        threshold_m: float,
        mode: Mode,
        mids: set[str],
    ) -> None:
        self.truth = truth
        self.raw_points = online.raw_points
        self.threshold = threshold_m
        self.mode = mode
        self.mids = mids
        frames = online.frames
        self.t_start = frames[0].t_ns if frames else 0
        self.frame_s = (
            (frames[-1].t_ns - frames[0].t_ns) / 1e9 / max(len(frames) - 1, 1) if frames else 0.0
        )
        self.users_acc = MotAccumulator(threshold_m)
        self.all_acc = MotAccumulator(threshold_m)
        self.followed = InitialIdentity(threshold_m)
        self.people: set[str] = set()
        self.users: set[str] = set()
        self.errors: list[float] = []
        self.det_err: list[float] = []
        self.det_hits = self.det_people = 0
        self.ok_since: dict[str, bool] = {}
        self.lost_at: dict[str, int] = {}
        self.first_loss: dict[str, float] = {}
        self.recovery: list[float] = []
        self.loss_events = 0
        self.wrong_s = 0.0

    def add_frame(self, t_ns: int, tracks: list[Track]) -> None:
        """Score the tracks published at ``t_ns`` (nothing when the truth has no such frame)."""
        gt = self.truth.get(t_ns)
        if gt is None:
            return
        hyp = {m.track_id: (m.position_m.x, m.position_m.y) for m in tracks}
        gtf = {e.entity_id: (e.position_m.x, e.position_m.y) for e in gt.entities}
        carriers = {e.entity_id: e.electronic_id for e in gt.entities if e.electronic_id}
        self.people.update(gtf)
        self.users.update(carriers)
        self._score_detections(self.raw_points.get(t_ns), gtf)
        self.all_acc.update(gtf, hyp)
        nonusers = [p for p in gtf if p not in carriers]
        if self.mode is Mode.VM:
            self._score_phones(t_ns, gtf, carriers, hyp, nonusers)
        else:
            self._score_visual(gtf, carriers, hyp, nonusers)

    def _score_detections(
        self, pts: np.ndarray | None, gtf: dict[str, tuple[float, float]]
    ) -> None:
        """The raw detections' distance to the nearest person (within 2 m) and the people with
        a detection within the evaluation threshold."""
        if pts is not None and len(pts) and gtf:
            g = np.array(list(gtf.values()))
            d = np.linalg.norm(pts[:, None, :] - g[None, :, :], axis=2).min(axis=1)
            self.det_err.extend(float(x) for x in d if x < 2.0)
            # recall: people with a raw detection within the evaluation threshold
            near = np.linalg.norm(g[:, None, :] - pts[None, :, :], axis=2).min(axis=1)
            self.det_hits += int(np.sum(near < self.threshold))
        self.det_people += len(gtf)

    def _score_phones(
        self,
        t_ns: int,
        gtf: dict[str, tuple[float, float]],
        carriers: dict[str, str],
        hyp: dict[str, tuple[float, float]],
        nonusers: list[str],
    ) -> None:
        """VM: the users' MOT over the tracks naming a phone, and each carrier followed by its
        phone's MID."""
        # identity is the phone: only tracks carrying a MID claim to be a user; anonymous
        # tracks (non-users, users not yet identified) make no identity claim
        user_hyp = {h: xy for h, xy in hyp.items() if h in self.mids}
        self.users_acc.update({p: gtf[p] for p in carriers}, user_hyp, ignore=nonusers)
        for person, mid in carriers.items():
            self._follow(t_ns, person, hyp.get(mid), gtf)

    def _follow(
        self,
        t_ns: int,
        person: str,
        xy: tuple[float, float] | None,
        gtf: dict[str, tuple[float, float]],
    ) -> None:
        """One carrier at one frame, its MID's track at ``xy`` (None: not published): the
        error, time bound to somebody else, a loss (its track no longer on it) or recovery."""
        good = xy is not None and math.dist(xy, gtf[person]) < self.threshold
        if xy is not None:
            self.errors.append(math.dist(xy, gtf[person]))
            if not good and self._near_another(xy, person, gtf):
                self.wrong_s += self.frame_s
        if self.ok_since.get(person) and not good:
            self.loss_events += 1
            self.lost_at[person] = t_ns
            self.first_loss.setdefault(person, (t_ns - self.t_start) / 1e9)
        if good and person in self.lost_at:
            self.recovery.append((t_ns - self.lost_at.pop(person)) / 1e9)
        self.ok_since[person] = good

    def _near_another(
        self, xy: tuple[float, float], person: str, gtf: dict[str, tuple[float, float]]
    ) -> bool:
        """Whether a person other than ``person`` is within the threshold of ``xy`` (the MID's
        track is bound to somebody else)."""
        return any(
            math.dist(xy, pos) < self.threshold for other, pos in gtf.items() if other != person
        )

    def _score_visual(
        self,
        gtf: dict[str, tuple[float, float]],
        carriers: dict[str, str],
        hyp: dict[str, tuple[float, float]],
        nonusers: list[str],
    ) -> None:
        """V-AF: the users' MOT over every track, and each carrier's error on the track first
        matched to it."""
        # visual-only tracks name nobody: tracks on non-users are don't-care, not false
        # positives (they must be in the truth given, to be matched and ignored)
        self.users_acc.update(gtf, hyp, ignore=nonusers)
        for person in carriers:
            err = self.followed.error(person, gtf[person], hyp)
            if err is not None:
                self.errors.append(err)

    def people_metrics(self, n_phones: int) -> dict[str, float | int | None]:
        """People and users seen, and the users' position error (m)."""
        return {
            "people": len(self.people),
            "users": len(self.users) if self.users else n_phones,
            "error_m_mean": _rounded_mean(self.errors, 4),
            "error_m_median": round(float(np.median(self.errors)), 4) if self.errors else None,
        }

    def mot_metrics(self) -> dict[str, float | int | None]:
        """IDF1 and MOTA over the users (and their identity switches), then over everybody."""
        s_users = self.users_acc.summary()
        s_all = self.all_acc.summary()
        return {
            "idf1": round(s_users.idf1, 4) if s_users.gt else None,
            "mota": round(s_users.mota, 4) if s_users.gt else None,
            "id_switches": s_users.id_switches,
            "idf1_all": round(s_all.idf1, 4) if s_all.gt else None,
            "mota_all": round(s_all.mota, 4) if s_all.gt else None,
        }

    def recovery_metrics(self) -> dict[str, float | None]:
        """Mean time to recover a lost identity, and mean time to a carrier's first loss (s)."""
        return {
            "recovery_s_mean": _rounded_mean(self.recovery, 3),
            "first_loss_s_mean": _rounded_mean(list(self.first_loss.values()), 3),
        }

    def detection_metrics(self) -> dict[str, float | None]:
        """The raw detections' mean error (m) and recall, and (VM) the time a MID's track was
        on somebody else (s)."""
        return {
            "det_error_m_mean": _rounded_mean(self.det_err, 4),
            "det_recall": round(self.det_hits / self.det_people, 4) if self.det_people else None,
            "wrong_binding_s": round(self.wrong_s, 3)
            if self.mode is Mode.VM and self.people
            else None,
        }


def _rounded_mean(values: list[float], digits: int) -> float | None:
    """The mean of ``values`` rounded to ``digits`` (None without values)."""
    return round(float(np.mean(values)), digits) if values else None


def _report(
    online: OnlineTracker,
    phones: dict[str, PhoneMotion],
    mode: Mode,
    offline: _Offline,
    score: _TruthScore,
    tally: _Tally,
) -> dict[str, float | int | str | None]:
    """The run's figures: against the ground truth, then those a log without it can give."""
    stats = online.identity.stats
    return {
        "system": "vm-tracking",
        "mode": mode.value,
        "frames": online.frame_count,
        **score.people_metrics(len(phones)),
        **score.mot_metrics(),
        "loss_events": score.loss_events if mode is Mode.VM else stats.losses,
        **score.recovery_metrics(),
        "bindings": stats.bindings,
        "checkpoint_bindings": stats.checkpoint_bindings,
        "offline_bindings": stats.offline_bindings,
        **score.detection_metrics(),
        **_no_truth_metrics(online, tally.published, tally.coasting, tally.shown, offline.plan),
        **_identity_metrics(offline.ids, stats, phones, offline.retracked),
        **_radio_metrics(offline.retracked),
        **_visit_metrics(offline.retracked.visits),
    }


def _visit_metrics(reading: VisitReading | None) -> dict[str, float | int | str | None]:
    """The visit model the re-tracking read from the log and what it read it from (null: not
    read; an edge turnover is null too where no walk begins or ends inside, unbounded)."""
    if reading is None:
        return dict.fromkeys(("visits", "edge_turnover", "occupancy_steadiness"))
    turnover = reading.edge_turnover
    finite = turnover is not None and math.isfinite(turnover)
    steady = reading.steadiness
    return {
        "visits": "one" if reading.one_visit else "throughout",
        "edge_turnover": round(turnover, 1) if finite and turnover is not None else None,
        "occupancy_steadiness": round(steady, 2) if steady is not None else None,
    }


def _trusted(ids: Identities, share: float | None) -> set[str]:
    """The phones whose offline identity is clear in at least ``share`` of the frames it puts
    them on a chain, with an alignment fitted (:attr:`RetrackConfig.trust_clear_share`)."""
    if share is None:
        return set()
    return {
        mid
        for mid, (on, clear) in ids.clear.items()
        if on and clear >= share * on and mid in ids.known
    }


def _radio_metrics(retracked: Retracked) -> dict[str, float | int | None]:
    """Each AP's path loss as the re-tracking fitted it (a site's calibration, from the log)."""
    out: dict[str, float | int | None] = {}
    for ap, model in sorted(retracked.calibration.items()):
        out[f"rssi_at_1m_dbm/{ap}"] = round(model.at1_dbm, 1)
        out[f"path_loss_exponent/{ap}"] = round(model.exponent, 2)
        out[f"rssi_sigma_db/{ap}"] = round(model.sigma_db, 1)
        out[f"rssi_readings/{ap}"] = model.readings
    if retracked.calibration:
        out["searched_again"] = len(retracked.searched_again)
    return out


def _take_retrack_alignments(
    alignments: dict[str, Alignment], retracked: dict[str, PhoneTrack]
) -> None:
    """Each re-tracked phone's alignment into ``alignments`` (for the report): its clock
    offset, and the circular mean of its yaw and the median of its scale over the frames it was
    seen. A phone seen nowhere (its carrier never in view, or every frame withheld) has none:
    the search's guess there has nothing behind it, and the report says so rather than give
    it."""
    for mid, pt in retracked.items():
        seen = np.array(sorted(pt.seen), int)
        a = pt.a[seen]
        a = a[~np.isnan(a)]
        if not len(a):
            alignments.pop(mid, None)
            continue
        yaw = np.angle(np.mean(a / np.abs(a)))
        scale = float(np.median(np.abs(a)))
        alignments[mid] = Alignment(complex(scale * np.exp(1j * yaw)), pt.lag_s, -1)


def _identity_metrics(
    ids: Identities | None,
    stats: BindingStats,
    phones: dict[str, PhoneMotion],
    retracked: Retracked | None = None,
) -> dict[str, float | int | None]:
    """Identity figures a log without ground truth can give: ambiguity, each phone's
    estimated alignment (clock offset, device-to-walk yaw, step scale), the share of its
    identity that is clear and whether the re-tracking searched its alignment (1) or started
    from its identity's (0)."""
    if not phones:
        return {}
    out: dict[str, float | int | None] = {
        "ambiguous_frames": ids.ambiguous_frames if ids else stats.ambiguous_frames,
        "unanchored_frames": ids.unanchored_frames if ids else None,
    }
    for mid in sorted(phones):
        out.update(_phone_figures(mid, ids, retracked))
    return out


def _phone_figures(
    mid: str, ids: Identities | None, retracked: Retracked | None
) -> dict[str, float | int | None]:
    """One phone's figures of :func:`_identity_metrics` (null where the stage that gives them
    did not run)."""
    al = ids.alignments.get(mid) if ids else None
    pt = retracked.get(mid) if retracked else None
    on, clear = ids.clear.get(mid, (0, 0)) if ids else (0, 0)
    searched = int(mid in retracked.searched) if pt and retracked else None
    if al is None:
        aligned: dict[str, float | int | None] = dict.fromkeys(
            (f"clock_offset_s/{mid}", f"yaw_offset_deg/{mid}", f"step_scale/{mid}")
        )
    else:
        aligned = {
            f"clock_offset_s/{mid}": round(al.lag_s, 3),
            f"yaw_offset_deg/{mid}": round(al.yaw_deg, 1),
            f"step_scale/{mid}": round(al.scale, 3),
        }
    return {
        **aligned,
        f"withheld_s/{mid}": round(pt.withheld_s, 1) if pt else None,
        f"ambiguous_s/{mid}": round(pt.ambiguous_s, 1) if pt else None,
        f"grouped_s/{mid}": round(pt.grouped_s, 1) if pt else None,
        f"clear_share/{mid}": round(clear / on, 3) if on else None,
        f"searched/{mid}": searched,
    }


def _no_truth_metrics(
    online: OnlineTracker, published: dict[str, int], coasting: int, shown: int, plan: Publication
) -> dict[str, float | int | None]:
    """What a log without ground truth can say: detections, tracks and their lengths."""
    counts = np.array([len(p) for p in online.raw_points.values()] or [0])
    lengths = np.array(sorted(published.values()) or [0])
    return {
        "detections_per_frame_mean": round(float(counts.mean()), 3),
        "detections_per_frame_max": int(counts.max()),
        "tracks_started": online.tracks_started,
        "tracks_published": len(published),
        "tracks_stitched": plan.links,
        "tracks_dropped_short": plan.dropped,
        "track_frames_median": float(np.median(lengths)),
        "track_frames_p10": float(np.percentile(lengths, 10)),
        "track_frames_p90": float(np.percentile(lengths, 90)),
        "coasting_share": round(coasting / shown, 4) if shown else None,
    }
