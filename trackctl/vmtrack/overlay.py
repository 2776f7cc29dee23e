"""Published tracks drawn on each camera's images: ``/vmtrack/<CAM>/tracks/annotations``.

Stage 2 records what each camera saw in each frame (:meth:`TrackOverlay.add`: its detection
boxes, their ground points and the image's timestamp); stage 5 draws the frame's published
tracks on it (:meth:`TrackOverlay.write`): a track takes the box of the camera's detection it is
matched to (one-to-one, least total ground distance, within :data:`MATCH_M`), drawn thick;
a track no detection of that camera matches gets the box of a person ``height_m`` tall standing
on its position, projected through the camera's calibration (the MOT export's projection,
:mod:`trackctl.geometry.boxes`), drawn thin and clipped to the image. Every box is labelled with
the track's id (a phone's MID once identified), under the box (the detections' overlay writes
its labels above). The overlay carries the image's own timestamp
so Foxglove's Image panel draws it on that image. Nothing here changes the tracks.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from trackctl.geometry.boxes import clip_box, person_boxes
from trackctl.geometry.camera import PinholeCamera
from trackctl.logs import topics
from trackctl.logs.foxglove import ImageBox, image_annotations, label_color
from trackctl.logs.messages import BBox, Detections, Track
from trackctl.logs.writer import LogWriter

__all__ = ["MATCH_M", "CameraView", "TrackOverlay", "tracks_annotations_topic"]

MATCH_M = 1.0
"""A track takes a detection's box when their ground points are at most this far apart."""

MATCHED_PX = 3.0
PROJECTED_PX = 1.0


def tracks_annotations_topic(camera: str) -> str:
    """Where vm-track draws its published tracks on a camera's images."""
    return topics.overlay(f"/vmtrack/{camera}/tracks")


@dataclass(frozen=True, slots=True)
class CameraView:
    """What one camera saw in one frame: its image's timestamp, the detection boxes and their
    ground points (N, 2; NaN rows where a box has none)."""

    camera: str
    stamp_ns: int
    boxes: tuple[BBox, ...]
    ground: np.ndarray


class TrackOverlay:
    """Every frame's camera views (kept until the frame's tracks are drawn), then the tracks
    drawn on them."""

    def __init__(self, cams: Mapping[str, PinholeCamera], height_m: float) -> None:
        self.cams = cams
        self.height_m = height_m
        self.views: dict[int, list[CameraView]] = {}

    def add(self, t_ns: int, stamp_ns: int, dets: Detections) -> None:
        """Record a camera's detections at frame time ``t_ns`` (its image stamped ``stamp_ns``);
        box-only detections are placed on the ground through the camera's calibration."""
        boxes = tuple(d.box for d in dets.detections)
        ground = np.full((len(boxes), 2), np.nan)
        cam = self.cams.get(dets.camera)
        for k, d in enumerate(dets.detections):
            if d.ground_m is not None:
                ground[k] = (d.ground_m.x, d.ground_m.y)
            elif cam is not None:
                foot = np.array([[d.box.x_px + d.box.w_px / 2, d.box.y_px + d.box.h_px]])
                ground[k] = cam.ground_point(foot)[0, :2]
        self.views.setdefault(t_ns, []).append(CameraView(dets.camera, stamp_ns, boxes, ground))

    def write(self, writer: LogWriter, t_ns: int, tracks: Sequence[Track]) -> None:
        """Draw a frame's published tracks on each camera that saw the frame (one
        foxglove.ImageAnnotations per camera, an empty one when no track is in view)."""
        for view in self.views.pop(t_ns, []):
            boxes = self._boxes(view, tracks)
            writer.write(
                tracks_annotations_topic(view.camera),
                image_annotations(view.stamp_ns, boxes),
                t_ns,
            )

    def _boxes(self, view: CameraView, tracks: Sequence[Track]) -> list[ImageBox]:
        """Each track's box on one camera: its matched detection's, else its projection."""
        xy = np.array([[t.position_m.x, t.position_m.y] for t in tracks], float).reshape(-1, 2)
        matched = _match(xy, view.ground)
        cam = self.cams.get(view.camera)
        projected = person_boxes(cam, xy, self.height_m) if cam is not None else [None] * len(xy)
        out = []
        for k, trk in enumerate(tracks):
            color = label_color(trk.track_id)
            if k in matched:
                box: BBox | None = view.boxes[matched[k]]
                thickness = MATCHED_PX
            else:
                box = projected[k]
                thickness = PROJECTED_PX
            if box is not None and cam is not None:
                box = clip_box(box, cam.model.width_px, cam.model.height_px)
            if box is not None:
                out.append(ImageBox(*box, trk.track_id, color, thickness, label_below=True))
        return out


def _match(tracks_xy: np.ndarray, ground: np.ndarray) -> dict[int, int]:
    """Track index -> detection index, one-to-one, least total distance within MATCH_M."""
    if len(tracks_xy) == 0 or len(ground) == 0:
        return {}
    d = np.linalg.norm(tracks_xy[:, None, :] - ground[None, :, :], axis=2)
    d = np.where(np.isfinite(d) & (d <= MATCH_M), d, 1e6)
    rows, cols = linear_sum_assignment(d)
    return {int(r): int(c) for r, c in zip(rows, cols, strict=True) if d[r, c] <= MATCH_M}
