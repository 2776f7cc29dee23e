"""MOTChallenge text export of tracks or ground truth (what py-motmetrics and TrackEval read).

One line per object per frame: ``frame,id,bb_left,bb_top,bb_width,bb_height,conf,x,y,z``.
``frame`` is the 1-based index of the message on the topic in log-time order, ``id`` a positive
integer per track (or entity) id in order of first appearance (the mapping is written beside the
file as ``FILE.ids.csv``), ``x,y,z`` the world position in metres. The box is a person
``height_m`` tall and 0.41 of that wide standing on the ground point, projected through a
camera's model, 1-based pixels as MOTChallenge counts them; -1 in the four box columns without a
camera (or when the person is behind it).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import IO

import numpy as np

from trackctl.errors import InputError
from trackctl.geometry.boxes import BOX_WIDTH_SHARE, person_boxes
from trackctl.geometry.camera import PinholeCamera
from trackctl.logs import topics
from trackctl.logs.messages import CameraModel, GroundTruth, Tracks, Vec3
from trackctl.logs.reader import LogMessage, LogReader
from trackctl.progress import Progress

__all__ = ["SCHEMAS", "BOX_WIDTH_SHARE", "PersonBoxes", "load_camera", "write_mot"]

SCHEMAS = (Tracks.SCHEMA, GroundTruth.SCHEMA)
"""The schemas a MOT export takes."""

NO_BOX = (-1.0, -1.0, -1.0, -1.0)


@dataclass(frozen=True, slots=True)
class PersonBoxes:
    """Image boxes of people standing on ground points, seen by one camera."""

    camera: PinholeCamera
    height_m: float

    def boxes(self, points: np.ndarray) -> list[tuple[float, float, float, float]]:
        """``(left, top, width, height)`` in 1-based pixels per ground point (N, 3)."""
        out: list[tuple[float, float, float, float]] = []
        for box in person_boxes(self.camera, points, self.height_m):
            # MOTChallenge counts pixels from 1; trackctl's pixel origin is the top-left corner
            out.append(
                NO_BOX if box is None else (box.x_px + 1.0, box.y_px + 1.0, box.w_px, box.h_px)
            )
        return out


def load_camera(reader: LogReader, camera: str) -> PinholeCamera:
    """The camera's model as the log holds it (the first ``/<CAM>/camera_model`` message).

    Raises:
        InputError: the log has no model for that camera, or the model has no world pose.
    """
    topic = topics.camera_model(camera)
    present = reader.topics()
    if topic not in present:
        cams = sorted(
            t.strip("/").rsplit("/", 1)[0] for t in present if t.endswith("/camera_model")
        )
        raise InputError(
            f"{reader.path}: --camera {camera}: no {topic}; cameras with a model: "
            + (", ".join(cams) or "none")
        )
    for msg in reader.messages([topic]):
        if isinstance(msg.message, CameraModel):
            if msg.message.world_from_camera is None:
                raise InputError(
                    f"{reader.path}: {topic} has no world pose (world_from_camera is null): "
                    "boxes cannot be projected"
                )
            return PinholeCamera(msg.message)
    raise InputError(f"{reader.path}: {topic} holds no trackctl.CameraModel message")


def _objects(message: object) -> Iterator[tuple[str, Vec3, float]]:
    """``(id, position, confidence)`` of each object of a Tracks or GroundTruth message."""
    if isinstance(message, Tracks):
        for track in message.tracks:
            conf = 1.0 if track.score is None else float(track.score)
            yield track.track_id, track.position_m, conf
    elif isinstance(message, GroundTruth):
        for entity in message.entities:
            yield entity.entity_id, entity.position_m, 1.0


def _num(value: float) -> str:
    """A number with at most 6 decimals (micrometres, micro-pixels), trailing zeros cut."""
    return f"{value:.6f}".rstrip("0").rstrip(".")


def write_mot(
    messages: Iterable[LogMessage],
    out: IO[str],
    ids_out: IO[str],
    boxes: PersonBoxes | None = None,
    progress: Progress | None = None,
    total: int | None = None,
) -> tuple[int, int]:
    """Write the MOT lines of ``messages`` (one topic, log-time order) to ``out`` and the id
    mapping (``mot_id,track_id``) to ``ids_out``.

    Returns:
        ``(frames, lines)``: messages read and object lines written.
    """
    ids: dict[str, int] = {}
    frame = lines = 0
    ids_out.write("mot_id,track_id\n")
    for msg in messages:
        frame += 1
        objs = list(_objects(msg.message))
        points = np.array([[p.x, p.y, p.z] for _, p, _ in objs], float).reshape(-1, 3)
        rects = boxes.boxes(points) if boxes is not None else [NO_BOX] * len(objs)
        for (obj_id, pos, conf), rect in zip(objs, rects, strict=True):
            mot_id = ids.get(obj_id)
            if mot_id is None:
                mot_id = ids[obj_id] = len(ids) + 1
                ids_out.write(f"{mot_id},{_csv_text(obj_id)}\n")
            cells = [*rect, conf, pos.x, pos.y, pos.z]
            out.write(f"{frame},{mot_id}," + ",".join(_num(float(c)) for c in cells) + "\n")
            lines += 1
        if progress is not None:
            progress(frame, total, "exporting")
    return frame, lines


def _csv_text(text: str) -> str:
    """A CSV cell for ``text`` (quoted when it holds a comma, a quote or a line break)."""
    if any(c in text for c in ',"\n\r'):
        return '"' + text.replace('"', '""') + '"'
    return text
