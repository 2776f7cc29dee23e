"""Stage 2 of VM-Tracking, online: the log streamed frame by frame through detection
(:mod:`~trackctl.vmtrack.frames`), association (:mod:`~trackctl.vmtrack.online`, with the injected
:class:`~trackctl.vmtrack.cost.AssociationCost`) and the online binding of phones to tracks.
"""

from __future__ import annotations

import numpy as np

from trackctl.logs import topics
from trackctl.logs.foxglove import detection_annotations
from trackctl.logs.messages import Detections, GroundTruth
from trackctl.logs.reader import LogMessage, LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import Progress
from trackctl.vmtrack.appearance import AppearanceBook
from trackctl.vmtrack.config import Mode, VmTrackConfig
from trackctl.vmtrack.cost import AssociationCost, VisualCost, VisualMotionCost
from trackctl.vmtrack.frames import FrameDetector, detections_topic
from trackctl.vmtrack.inputs import Inputs, ground_points
from trackctl.vmtrack.online import OnlineTracker
from trackctl.vmtrack.overlay import TrackOverlay


def associate_online(
    reader: LogReader,
    writer: LogWriter,
    inputs: Inputs,
    online: OnlineTracker,
    progress: Progress | None,
    overlay: TrackOverlay,
    book: AppearanceBook | None = None,
) -> dict[int, GroundTruth]:
    """Stage 2 (detection, association, identity): stream the log frame by frame through the
    online tracker, each camera's view kept in ``overlay`` for the track boxes and its
    detections' boxes in ``book`` (for the tracks' colours); returns the ground truth seen
    (for the metrics only)."""
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
            points.extend(ground_points(reader, msg.topic, msg.message, inputs.cams))
            _keep(msg.log_time_ns, msg.message.t_ns, msg.message, overlay, book)
            continue
        found = _detect_in_frame(msg, detector, online, writer, search_full, points, covs)
        _keep(msg.log_time_ns, _image_stamp(msg), found, overlay, book)
    if frame_t is not None:
        online.process_frame(frame_t, points, covs)
    online.close()
    return truth


def _keep(
    t_ns: int, stamp_ns: int, found: Detections, overlay: TrackOverlay, book: AppearanceBook | None
) -> None:
    """Keep a camera's detections of the frame at ``t_ns``: in the overlay (for the track
    boxes, at the image's own stamp) and in ``book`` (for the tracks' colours)."""
    overlay.add(t_ns, stamp_ns, found)
    if book is not None:
        book.add(t_ns, found.camera, found)


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


def association_cost(mode: Mode, cfg: VmTrackConfig) -> AssociationCost:
    """Returns the association's cost for ``mode``: position only for ``v-af``, position and
    the phones' velocities for ``vm``."""
    if mode is Mode.V_AF:
        return VisualCost(cfg.association.tracker.gate_p)
    return VisualMotionCost(cfg.association.tracker.gate_p, cfg.association.tracker.pdr_sigma_mps)
