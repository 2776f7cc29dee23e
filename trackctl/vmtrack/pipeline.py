"""VM-Tracking over a log: detections + phone IMU (+ RSSI check-points) -> identified tracks.

One library function, :func:`run`, is the whole pipeline; ``trackctl vm-track`` and the
``vm-track`` processor call it.
"""

from __future__ import annotations

import math
import time
import warnings
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np
from filterpy.kalman import rts_smoother

from trackctl.errors import MissingTopicError
from trackctl.geometry.camera import PinholeCamera
from trackctl.logs import topics
from trackctl.logs.messages import (
    CameraModel,
    Detections,
    GroundTruth,
    Imu,
    MetricReport,
    RssiScan,
    Track,
    Tracks,
    TrackState,
    Vec3,
)
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.metrics.tracking import InitialIdentity, MotAccumulator
from trackctl.processing.base import Progress
from trackctl.vmtrack.frames import FrameConfig, FrameDetector, detections_topic, image_cameras
from trackctl.vmtrack.motion import MotionConfig, PhoneMotion
from trackctl.vmtrack.scene import scene_update
from trackctl.vmtrack.tracker import GroundTrack, TrackerConfig, associate, merge_detections

__all__ = ["Mode", "Source", "VmTrackConfig", "run", "TRACKS_TOPIC", "SCENE_TOPIC"]

TRACKS_TOPIC = "/vmtrack/tracks"
SCENE_TOPIC = "/vmtrack/scene"


class Mode(StrEnum):
    """``vm``: visual + motion sensors; ``v-af``: the paper's appearance-free visual baseline."""

    VM = "vm"
    V_AF = "v-af"


class Source(StrEnum):
    """Where person detections come from."""

    AUTO = "auto"
    FRAMES = "frames"
    DETECTIONS = "detections"


@dataclass(frozen=True, slots=True)
class VmTrackConfig:
    """Configuration of a VM-Tracking run."""

    mode: Mode = Mode.VM
    smooth: bool = True
    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    merge_m: float = 1.0
    """Detections of one instant from different cameras closer than this are one person."""
    spawn_m: float = 1.0
    """An unmatched detection closer than this to a track does not start a new track."""
    duplicate_m: float = 0.45
    """Two tracks closer than this are one person (the younger, unbound one is dropped)."""
    bind_frames: int = 9
    """Frames of consistent motion before a phone is bound to a visual track (Theorem 1)."""
    reject_mps: float = 0.45
    """A candidate whose mean velocity disagreement exceeds this is filtered away."""
    converge_hits: int = 6
    """Detections a track needs before its velocity is compared with phones."""
    ratio: float = 3.0
    offline_reject_mps: float = 0.6
    """Offline pass: a never-bound phone takes its clear best track if it disagrees less."""
    """Bind early when the best candidate's disagreement is this many times below the next."""
    checkpoint_dbm: float = -40.0
    """RSSI of a phone held within ~1 m of a check-point AP (the paper: "less than 1 meter")."""
    checkpoint_radius_m: float = 1.5
    rssi_at_1m_dbm: float = -40.0
    """Check-point AP path-loss model: RSSI at 1 m, exponent, shadowing std (calibrate per site)."""
    path_loss_exponent: float = 2.5
    shadowing_db: float = 3.0
    rssi_evidence_m: float = 4.0
    """Tracks within this distance of an AP compare their distance with a phone's RSSI there."""
    eval_threshold_m: float = 1.0
    source: Source = Source.AUTO
    """Detections from camera frames or from detections topics (auto: frames when present)."""
    frames: FrameConfig = field(default_factory=FrameConfig)


@dataclass
class _Candidate:
    """Evidence that a phone (MID) is carried by the person of one visual track (VID)."""

    n: int = 0
    d2: float = 0.0
    """Sum of squared velocity disagreements (m/s)^2 over ``n`` frames."""
    rssi_n: int = 0
    rssi_z2: float = 0.0
    """Sum of squared normalised RSSI residuals (observed - path loss at the track's distance)."""

    @property
    def mean(self) -> float:
        """Mean squared velocity disagreement plus the RSSI penalty, in (m/s)^2."""
        return (self.d2 / self.n if self.n else 0.0) + self.rssi_penalty

    @property
    def rssi_penalty(self) -> float:
        # chi-square excess of the RSSI residuals (expected 1 per reading for the right person),
        # in units of the rejection threshold's scale so one incompatible AP pass rejects
        if self.rssi_n < 2:
            return 0.0
        return _RSSI_WEIGHT * max(0.0, self.rssi_z2 / self.rssi_n - 1.0)

    def add_rssi(self, z2: float) -> None:
        self.rssi_n += 1
        self.rssi_z2 += z2


_RSSI_WEIGHT = 0.05


@dataclass
class _FrameOut:
    t_ns: int
    rows: Sequence[tuple[GroundTrack, str | None, TrackState, int]]  # track, MID now, state, k


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


def run(
    reader: LogReader,
    writer: LogWriter,
    config: VmTrackConfig | None = None,
    progress: Progress | None = None,
) -> MetricReport:
    """Track people in ``reader``; write ``/vmtrack/tracks`` to ``writer``; return the report."""
    cfg = config or VmTrackConfig()
    started = time.perf_counter()
    present = reader.topics()
    det_topics = sorted(t for t, i in present.items() if i.schema_name == Detections.SCHEMA)
    det_topics = [t for t in det_topics if not t.startswith("/vmtrack/")]
    has_images = any(i.schema_name == "foxglove.CompressedImage" for i in present.values())
    use_frames = cfg.source is Source.FRAMES or (cfg.source is Source.AUTO and has_images)
    detector: FrameDetector | None = None
    if use_frames:
        frame_cams = image_cameras(reader, present)
        if not frame_cams:
            raise MissingTopicError(
                f"{reader.path}: no foxglove.CompressedImage topic (/<camera>/image); "
                "--source frames needs camera frames"
            )
        detector = FrameDetector(reader, frame_cams, cfg.frames)
        det_topics = [topics.image(c) for c in sorted(frame_cams)]
        cams: dict[str, PinholeCamera] = {}
    else:
        if not det_topics:
            raise MissingTopicError(
                f"{reader.path}: no trackctl.Detections topic (/<camera>/detections) and no "
                f"camera frames; vm-track needs person detections. The log has: "
                f"{', '.join(sorted(present))}"
            )
        cams = _detection_points(reader, det_topics)
    imu_topics = sorted(t for t, i in present.items() if i.schema_name == Imu.SCHEMA)
    mode = cfg.mode
    if mode is Mode.VM and not imu_topics:
        warnings.warn(
            f"{reader.path}: no IMU topic: running as V-AF (visual only)", UserWarning, stacklevel=2
        )
        mode = Mode.V_AF
    tcfg = cfg.tracker

    # pass 1: phone motion (PDR velocity series per MID)
    t_pass1 = time.perf_counter()
    phones: dict[str, PhoneMotion] = {}
    if mode is Mode.VM:
        for msg in reader.messages(imu_topics):
            imu: Imu = msg.message
            mid = imu.frame_id.split("/", 1)[1] if "/" in imu.frame_id else imu.frame_id
            phones.setdefault(mid, PhoneMotion(mid, cfg.motion)).add(imu)
        for p in phones.values():
            p.finish()
    t_motion = time.perf_counter()

    tracks: list[GroundTrack] = []
    bound: dict[str, GroundTrack] = {}
    candidates: dict[str, dict[str, _Candidate]] = defaultdict(dict)
    # whole-log evidence of (never-bound phone, track) agreement, for the offline resolution
    evidence: dict[str, dict[str, _Candidate]] = defaultdict(dict)
    by_vid: dict[str, GroundTrack] = {}
    disagreement: dict[str, list[float]] = defaultdict(list)
    frames: list[_FrameOut] = []
    truth: dict[int, GroundTruth] = {}
    raw_points: dict[int, np.ndarray] = {}
    stats = {"losses": 0, "bindings": 0, "checkpoint_bindings": 0, "frames": 0}
    next_vid = [0]
    pending_rssi: list[RssiScan] = []
    t_assoc = 0.0

    def new_vid() -> str:
        next_vid[0] += 1
        return f"v{next_vid[0]}"

    def velocity(mid: str, t_ns: int) -> np.ndarray | None:
        p = phones.get(mid)
        return None if p is None else p.velocity_at(t_ns)

    def process_frame(t_ns: int, points: list[tuple[str, np.ndarray]]) -> None:
        nonlocal t_assoc
        t0 = time.perf_counter()
        stats["frames"] += 1
        dets = merge_detections(points, cfg.merge_m)
        raw_points[t_ns] = np.array([xy for _, xy in points]).reshape(-1, 2)
        track_mids = [next((m for m, tr in bound.items() if tr is trk), None) for trk in tracks]
        v_m = [velocity(m, t_ns) if m else None for m in track_mids]
        dts = [(t_ns - trk.t_ns) / 1e9 for trk in tracks]
        pairs, lost_idx, new_idx = associate(tracks, dets, dts, v_m, tcfg)
        for i, trk in enumerate(tracks):
            trk.history.append((trk.t_ns, trk.kf.x.copy(), trk.kf.P.copy(), False))
            trk.advance(t_ns, tcfg, v_m[i])
        for i, j, _ in pairs:
            trk = tracks[i]
            trk.correct(dets[j])
            trk.hits += 1
            trk.last_hit_ns = t_ns
            if trk.hits >= tcfg.confirm_hits:
                trk.state = TrackState.TRACKED
        for i in lost_idx:
            if tracks[i].state is not TrackState.TENTATIVE:
                tracks[i].state = TrackState.PREDICTED
        # retire tracks
        keep = []
        for trk in tracks:
            age = (t_ns - trk.last_hit_ns) / 1e9
            mid = next((m for m, tr in bound.items() if tr is trk), None)
            limit = tcfg.lose_bound_after_s if mid else tcfg.drop_unbound_after_s
            if trk.state is TrackState.TENTATIVE and trk.last_hit_ns != t_ns:
                continue
            if age > limit:
                if mid:
                    del bound[mid]
                    stats["losses"] += 1
                continue
            keep.append(trk)
        tracks[:] = keep
        # an unmatched detection next to a live track is a duplicate view of that person
        # (overlapping cameras), not a new person
        for j in new_idx:
            if all(np.linalg.norm(trk.xy - dets[j]) > cfg.spawn_m for trk in tracks):
                tracks.append(GroundTrack.start(new_vid(), dets[j], t_ns, tcfg))
        _prune_duplicates(t_ns)
        if mode is Mode.VM:
            _bind(t_ns)
        out_rows = []
        for trk in tracks:
            if trk.state is TrackState.TENTATIVE:
                continue
            mid = next((m for m, tr in bound.items() if tr is trk), None)
            out_rows.append((trk, mid, trk.state, len(trk.history)))
        frames.append(_FrameOut(t_ns, out_rows))
        t_assoc += time.perf_counter() - t0

    def _prune_duplicates(t_ns: int) -> None:
        """Two tracks on one person: keep the bound one, else the older one."""
        owner = {id(tr): m for m, tr in bound.items()}
        doomed: set[int] = set()
        for a in range(len(tracks)):
            for b in range(a + 1, len(tracks)):
                ta, tb = tracks[a], tracks[b]
                if id(ta) in doomed or id(tb) in doomed:
                    continue
                if np.linalg.norm(ta.xy - tb.xy) >= cfg.duplicate_m:
                    continue
                if id(ta) in owner and id(tb) in owner:
                    continue  # two phones side by side: both stay
                loser = (
                    tb if (id(ta) in owner or (id(tb) not in owner and ta.hits >= tb.hits)) else ta
                )
                doomed.add(id(loser))
        if doomed:
            tracks[:] = [tr for tr in tracks if id(tr) not in doomed]

    def _bind_track(mid: str, trk: GroundTrack, t_ns: int) -> None:
        bound[mid] = trk
        if trk.first_mid is None:
            trk.first_mid, trk.first_bound_ns = mid, t_ns

    def _bind(t_ns: int) -> None:
        free = [
            trk
            for trk in tracks
            if trk.state is TrackState.TRACKED
            and trk.last_hit_ns == t_ns
            and trk not in bound.values()
        ]
        # check-points: a phone heard very strongly by an AP belongs to the person next to it
        for scan in pending_rssi:
            if scan.observer_position_m is None:
                continue
            ap = np.array([scan.observer_position_m.x, scan.observer_position_m.y])
            for reading in scan.readings:
                mid = reading.eid
                if mid in bound or mid not in phones or reading.rssi_dbm < cfg.checkpoint_dbm:
                    continue
                near = [
                    trk for trk in free if np.linalg.norm(trk.xy - ap) < cfg.checkpoint_radius_m
                ]
                if len(near) == 1:
                    _bind_track(mid, near[0], t_ns)
                    free.remove(near[0])
                    candidates.pop(mid, None)
                    stats["bindings"] += 1
                    stats["checkpoint_bindings"] += 1
        # RSSI evidence for the candidate filter: people walking side by side move alike, but
        # the one nearer an AP is heard louder (log-distance path loss with shadowing)
        for scan in pending_rssi:
            if scan.observer_position_m is None:
                continue
            ap = np.array([scan.observer_position_m.x, scan.observer_position_m.y])
            near = [trk for trk in free if np.linalg.norm(trk.xy - ap) < cfg.rssi_evidence_m]
            for reading in scan.readings:
                mid = reading.eid
                if mid in bound or mid not in phones:
                    continue
                for trk in near:
                    d = max(0.3, float(np.linalg.norm(trk.xy - ap)))
                    expect = cfg.rssi_at_1m_dbm - 10 * cfg.path_loss_exponent * math.log10(d)
                    z2 = ((reading.rssi_dbm - expect) / cfg.shadowing_db) ** 2
                    candidates[mid].setdefault(trk.vid, _Candidate()).add_rssi(z2)
                    if trk.first_mid is None:
                        evidence[mid].setdefault(trk.vid, _Candidate()).add_rssi(z2)
                        by_vid[trk.vid] = trk
        pending_rssi.clear()
        # loss detection: a bound track whose motion keeps disagreeing with its phone, or whose
        # phone stopped reporting (its carrier left, or the app was closed)
        for mid, trk in list(bound.items()):
            v = velocity(mid, t_ns)
            if v is None:
                del bound[mid]
                continue
            if trk.last_hit_ns != t_ns:
                continue
            hist = disagreement[mid]
            hist.append(float(np.sum((trk.v - v) ** 2)))
            del hist[: -cfg.bind_frames]
            if len(hist) == cfg.bind_frames and np.mean(hist) > (1.6 * cfg.reject_mps) ** 2:
                del bound[mid]
                hist.clear()
                stats["losses"] += 1
        # candidate filtering for unbound phones (initialization and loss recovery)
        wants: dict[str, tuple[GroundTrack, float]] = {}
        for mid in phones:
            if mid in bound:
                continue
            v = velocity(mid, t_ns)
            if v is None:
                candidates.pop(mid, None)
                continue
            cands = candidates[mid]
            live = {trk.vid for trk in free}
            for vid in list(cands):
                if vid not in live:
                    del cands[vid]
            for trk in free:
                if trk.hits < cfg.converge_hits:
                    continue  # its velocity estimate has not converged yet
                d2 = float(np.sum((trk.v - v) ** 2))
                c = cands.setdefault(trk.vid, _Candidate())
                c.n += 1
                c.d2 += d2
                if trk.first_mid is None:
                    e = evidence[mid].setdefault(trk.vid, _Candidate())
                    e.n += 1
                    e.d2 += d2
                    by_vid[trk.vid] = trk
            alive = sorted(
                (
                    (c.mean, vid, c)
                    for vid, c in cands.items()
                    if not (c.n >= 3 and c.mean > cfg.reject_mps**2)
                ),
                key=lambda a: a[0],
            )
            if not alive or alive[0][2].n < cfg.bind_frames:
                continue
            rivals = [a for a in alive[1:] if a[2].n >= 3]
            if not rivals or rivals[0][0] > cfg.ratio * alive[0][0] + 0.02:
                trk = next(t for t in free if t.vid == alive[0][1])
                wants[mid] = (trk, alive[0][0])
        taken: dict[str, tuple[str, float]] = {}
        for mid, (trk, score) in wants.items():
            if trk.vid not in taken or score < taken[trk.vid][1]:
                taken[trk.vid] = (mid, score)
        for vid, (mid, _) in taken.items():
            trk = next(t for t in free if t.vid == vid)
            _bind_track(mid, trk, t_ns)
            candidates.pop(mid, None)
            disagreement[mid].clear()
            stats["bindings"] += 1

    stream_topics = (
        det_topics
        + ([topics.RSSI] if topics.RSSI in present else [])
        + ([topics.GROUND_TRUTH] if topics.GROUND_TRUTH in present else [])
    )
    frame_t: int | None = None
    points: list[tuple[str, np.ndarray]] = []
    n_msgs = 0
    frame_index = 0
    search_full = True

    def predictions(t_ns: int) -> list[tuple[np.ndarray, float, bool]]:
        """Where each live track can be at ``t_ns`` (ground xy, radius m, undetected in the last
        frame): motion sensors for tracks with a phone, the visual velocity otherwise."""
        fcfg = cfg.frames
        owner = {id(tr): m for m, tr in bound.items()}
        out = []
        for trk in tracks:
            dt = max(0.0, (t_ns - trk.t_ns) / 1e9)
            mid = owner.get(id(trk))
            v = velocity(mid, t_ns) if mid else None
            sigma = tcfg.pdr_sigma_mps if v is not None else fcfg.visual_speed_sigma_mps
            v = trk.v if v is None else v
            var = float(np.trace(trk.kf.P[:2, :2]) / 2) + (sigma * dt) ** 2
            missed = trk.state is not TrackState.TENTATIVE and trk.last_hit_ns != trk.t_ns
            out.append((trk.xy + v * dt, fcfg.region_m + 2.0 * math.sqrt(var), missed))
        return out

    def plan_search() -> bool:
        """Full search to initialize, and periodically for people entering the views; in
        between only predicted regions. A track that went undetected keeps being predicted; its
        region grows with its uncertainty and is searched at more pyramid levels (recovery)."""
        if not cfg.frames.predicted or not tracks:
            return True
        return frame_index % max(1, cfg.frames.full_search_every) == 0

    for msg in reader.messages(stream_topics):
        n_msgs += 1
        if progress is not None and n_msgs % 2000 == 0:
            progress(n_msgs, None)
        if msg.topic == topics.GROUND_TRUTH:
            truth[msg.log_time_ns] = msg.message
            continue
        if msg.topic == topics.RSSI:
            pending_rssi.append(msg.message)
            continue
        if frame_t is not None and msg.log_time_ns != frame_t:
            process_frame(frame_t, points)
            points = []
            frame_index += 1
        if msg.log_time_ns != frame_t:
            search_full = plan_search() if detector is not None else True
        frame_t = msg.log_time_ns
        if detector is not None:
            camera = msg.topic.strip("/").split("/")[0]
            preds = None if search_full else predictions(msg.log_time_ns)
            found, ground = detector.detect(msg.log_time_ns, camera, bytes(msg.message.data), preds)
            writer.write(detections_topic(camera), found, msg.log_time_ns)
            points.extend((camera, g) for g in ground)
            continue
        dets: Detections = msg.message
        for d in dets.detections:
            if d.ground_m is not None:
                points.append((dets.camera, np.array([d.ground_m.x, d.ground_m.y])))
            else:
                cam = cams.get(dets.camera)
                if cam is None:
                    raise MissingTopicError(
                        f"{reader.path}: {topics.camera_model(dets.camera)} is missing or has no "
                        f"world pose; vm-track needs it to place {msg.topic} boxes on the ground"
                    )
                foot = np.array([[d.box.x_px + d.box.w_px / 2, d.box.y_px + d.box.h_px]])
                g = cam.ground_point(foot)[0]
                if not np.isnan(g).any():
                    points.append((dets.camera, g[:2]))
    if frame_t is not None:
        process_frame(frame_t, points)
    for trk in tracks:
        trk.history.append((trk.t_ns, trk.kf.x.copy(), trk.kf.P.copy(), True))
    if mode is Mode.VM:
        stats["offline_bindings"] = _resolve_offline(evidence, by_vid, phones, cfg)
        for trk in by_vid.values():
            _backdate_identity(trk, phones, cfg)
        for m_trk in bound.values():
            _backdate_identity(m_trk, phones, cfg)
    t_track = time.perf_counter()

    positions = _positions(frames, cfg.smooth, tcfg)
    report = _write_and_score(
        writer, frames, positions, truth, raw_points, phones, cfg, mode, stats
    )
    elapsed = time.perf_counter() - started
    report_metrics = dict(report)
    n_frames = max(stats["frames"], 1)
    report_metrics["ms_per_frame"] = round(1000 * elapsed / n_frames, 3)
    report_metrics["ms_per_frame_motion"] = round(1000 * (t_motion - t_pass1) / n_frames, 3)
    report_metrics["ms_per_frame_association"] = round(1000 * t_assoc / n_frames, 3)
    report_metrics["ms_per_frame_smoothing"] = round(
        1000 * (time.perf_counter() - t_track) / n_frames, 3
    )
    report_metrics["imu_bad_samples"] = sum(p.bad_samples for p in phones.values())
    report_metrics["source"] = "frames" if detector is not None else "detections"
    if detector is not None:
        report_metrics["ms_per_frame_decode"] = round(1000 * detector.seconds_decode / n_frames, 3)
        report_metrics["ms_per_frame_detection"] = round(
            1000 * detector.seconds_detect / n_frames, 3
        )
        report_metrics["background_s"] = round(detector.seconds_background, 3)
        report_metrics["full_searches"] = detector.full_searches
        report_metrics["region_searches"] = detector.region_searches
        report_metrics["bad_frames"] = detector.bad_frames
    return MetricReport(
        t_ns=reader.end_ns or 0,
        processor="vm-track",
        metrics=report_metrics,
        params={
            "mode": mode.value,
            "smooth": cfg.smooth,
            "merge_m": cfg.merge_m,
            "bind_frames": cfg.bind_frames,
            "reject_mps": cfg.reject_mps,
            "det_sigma_m": tcfg.det_sigma_m,
            "pdr_sigma_mps": tcfg.pdr_sigma_mps,
        },
    )


def _resolve_offline(
    evidence: dict[str, dict[str, _Candidate]],
    by_vid: dict[str, GroundTrack],
    phones: dict[str, PhoneMotion],
    cfg: VmTrackConfig,
) -> int:
    """Name still-anonymous tracks after phones that were never bound online.

    Online binding waits until one candidate clearly beats the others within a tight gate
    (Theorem 1); in a short visit, or with noisy motion, it may never happen. Offline we know
    every track's whole life: each never-bound phone whose best anonymous track clearly beats the
    runner-up (the online ratio test) and stays within a wider gate takes it, the most consistent
    pairs first; a track goes to at most one phone. The identity then holds back along the track
    as far as its motion agreed with the phone (:func:`_backdate_identity`).
    """
    ever_bound = {trk.first_mid for trk in by_vid.values() if trk.first_mid is not None}
    pairs = []
    for mid, cands in evidence.items():
        if mid not in phones or mid in ever_bound:
            continue
        scored = sorted(
            (c.mean, vid)
            for vid, c in cands.items()
            if by_vid[vid].first_mid is None and c.n >= cfg.bind_frames
        )
        if not scored or scored[0][0] > cfg.offline_reject_mps**2:
            continue
        if len(scored) > 1 and scored[1][0] <= cfg.ratio * scored[0][0] + 0.02:
            continue  # ambiguous (people walking together): leave the phone unbound
        pairs.append((scored[0][0], mid, scored[0][1]))
    made = 0
    for _, mid, vid in sorted(pairs):
        trk = by_vid[vid]
        if trk.first_mid is not None:
            continue
        trk.first_mid = mid
        trk.first_bound_ns = trk.t_ns + 1  # the identity covers the whole track (back-dated)
        made += 1
    return made


def _backdate_identity(
    trk: GroundTrack, phones: dict[str, PhoneMotion], cfg: VmTrackConfig
) -> None:
    """Set how far back before its binding a track carries its phone's identity.

    Walking back from the binding, the track's velocity is compared with the phone's over a
    sliding window of ``bind_frames`` frames; where the mean disagreement exceeds the loss
    threshold the track was following somebody else (visual tracks can swap people before a phone
    anchors them), and the identity stops there.
    """
    if trk.first_mid is None or trk.first_bound_ns is None or not trk.history:
        return
    phone = phones.get(trk.first_mid)
    if phone is None:
        return
    limit = (1.6 * cfg.offline_reject_mps) ** 2  # whole-life evidence: the offline gate
    window: list[float] = []
    start = trk.first_bound_ns
    for t_ns, x, _, _ in reversed(trk.history):
        if t_ns >= trk.first_bound_ns:
            continue
        v = phone.velocity_at(t_ns)
        if v is None:
            break
        window.append(float(np.sum((x[2:, 0] - v) ** 2)))
        del window[: -cfg.bind_frames]
        if len(window) == cfg.bind_frames and float(np.mean(window)) > limit:
            break
        start = t_ns
    trk.identity_from_ns = start


def _positions(
    frames: list[_FrameOut], smooth: bool, cfg: TrackerConfig
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


def _write_and_score(
    writer: LogWriter,
    frames: list[_FrameOut],
    positions: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]],
    truth: dict[int, GroundTruth],
    raw_points: dict[int, np.ndarray],
    phones: dict[str, PhoneMotion],
    cfg: VmTrackConfig,
    mode: Mode,
    stats: dict[str, int],
) -> dict[str, float | int | str | None]:
    users_acc = MotAccumulator(cfg.eval_threshold_m)
    all_acc = MotAccumulator(cfg.eval_threshold_m)
    errors: list[float] = []
    det_err: list[float] = []
    det_hits = det_people = 0
    followed = InitialIdentity(cfg.eval_threshold_m)
    people: set[str] = set()
    users: set[str] = set()
    ok_since: dict[str, bool] = {}
    loss_events = 0
    recovery: list[float] = []
    lost_at: dict[str, int] = {}
    first_loss: dict[str, float] = {}
    t_start = frames[0].t_ns if frames else 0
    for fr in frames:
        tracks = []
        hyp: dict[str, tuple[float, float]] = {}
        for trk, mid_now, state, k in fr.rows:
            out_id = mid_now or trk.vid
            if (
                mid_now is None
                and trk.first_mid is not None
                and trk.identity_from_ns <= fr.t_ns < (trk.first_bound_ns or 0)
            ):
                # offline: the identity found later holds back to where the track's motion
                # stops agreeing with the phone (the track's birth, unless it switched people)
                out_id = trk.first_mid
            # entry k of a track's history is its state at this frame (snapshotted before the
            # next frame's prediction, or when the log ends)
            msg = _track_message(out_id, trk, state, positions.get((id(trk), k)))
            tracks.append(msg)
            hyp[out_id] = (msg.position_m.x, msg.position_m.y)
        writer.write(TRACKS_TOPIC, Tracks(fr.t_ns, tuple(tracks)))
        writer.write(SCENE_TOPIC, scene_update(fr.t_ns, tracks, set(phones)), fr.t_ns)
        gt = truth.get(fr.t_ns)
        if gt is None:
            continue
        gtf = {e.entity_id: (e.position_m.x, e.position_m.y) for e in gt.entities}
        carriers = {e.entity_id: e.electronic_id for e in gt.entities if e.electronic_id}
        people.update(gtf)
        users.update(carriers)
        pts = raw_points.get(fr.t_ns)
        if pts is not None and len(pts) and gtf:
            g = np.array(list(gtf.values()))
            d = np.linalg.norm(pts[:, None, :] - g[None, :, :], axis=2).min(axis=1)
            det_err.extend(float(x) for x in d if x < 2.0)
            # recall: people with a raw detection within the evaluation threshold
            near = np.linalg.norm(g[:, None, :] - pts[None, :, :], axis=2).min(axis=1)
            det_hits += int(np.sum(near < cfg.eval_threshold_m))
        det_people += len(gtf)
        all_acc.update(gtf, hyp)
        nonusers = [p for p in gtf if p not in carriers]
        if mode is Mode.VM:
            # identity is the phone: only tracks carrying a MID claim to be a user; anonymous
            # tracks (non-users, users not yet identified) make no identity claim
            mids = set(phones)
            user_hyp = {h: xy for h, xy in hyp.items() if h in mids}
            users_acc.update({p: gtf[p] for p in carriers}, user_hyp, ignore=nonusers)
            for person, mid in carriers.items():
                xy = hyp.get(mid)
                t_rel = (fr.t_ns - t_start) / 1e9
                good = xy is not None and math.dist(xy, gtf[person]) < cfg.eval_threshold_m
                if xy is not None:
                    errors.append(math.dist(xy, gtf[person]))
                if ok_since.get(person) and not good:
                    loss_events += 1
                    lost_at[person] = fr.t_ns
                    first_loss.setdefault(person, t_rel)
                if good and person in lost_at:
                    recovery.append((fr.t_ns - lost_at.pop(person)) / 1e9)
                ok_since[person] = good
        else:
            # visual-only tracks name nobody: tracks on non-users are don't-care, not false
            # positives (they must be in the truth given, to be matched and ignored)
            users_acc.update(gtf, hyp, ignore=nonusers)
            for person in carriers:
                err = followed.error(person, gtf[person], hyp)
                if err is not None:
                    errors.append(err)
    s_users = users_acc.summary()
    s_all = all_acc.summary()
    return {
        "system": "vm-tracking",
        "mode": mode.value,
        "frames": stats["frames"],
        "people": len(people),
        "users": len(users) if users else len(phones),
        "error_m_mean": round(float(np.mean(errors)), 4) if errors else None,
        "error_m_median": round(float(np.median(errors)), 4) if errors else None,
        "idf1": round(s_users.idf1, 4) if s_users.gt else None,
        "mota": round(s_users.mota, 4) if s_users.gt else None,
        "id_switches": s_users.id_switches,
        "idf1_all": round(s_all.idf1, 4) if s_all.gt else None,
        "mota_all": round(s_all.mota, 4) if s_all.gt else None,
        "loss_events": loss_events if mode is Mode.VM else stats["losses"],
        "recovery_s_mean": round(float(np.mean(recovery)), 3) if recovery else None,
        "first_loss_s_mean": round(float(np.mean(list(first_loss.values()))), 3)
        if first_loss
        else None,
        "bindings": stats["bindings"],
        "checkpoint_bindings": stats["checkpoint_bindings"],
        "offline_bindings": stats.get("offline_bindings", 0),
        "det_error_m_mean": round(float(np.mean(det_err)), 4) if det_err else None,
        "det_recall": round(det_hits / det_people, 4) if det_people else None,
    }
