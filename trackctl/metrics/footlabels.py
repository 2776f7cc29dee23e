"""Detections scored against hand-labelled foot points (real footage without a published truth).

A label file is a CSV ``frame,u_px,v_px,occluded``: the 0-based frame index of the video file and
the pixel on the ground between a person's feet. Labels and detections are compared on the
floor (both through the camera's calibration), so the error is in metres.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trackctl.errors import InputError
from trackctl.geometry.camera import PinholeCamera

__all__ = ["FootLabel", "read_foot_labels", "DetectionScore", "score_detections"]


@dataclass(frozen=True, slots=True)
class FootLabel:
    frame: int
    u_px: float
    v_px: float
    occluded: bool = False


def read_foot_labels(path: str | Path) -> list[FootLabel]:
    """Labels of a ``frame,u_px,v_px,occluded`` CSV (``#`` comments, one header row).

    Raises:
        InputError: a row is not three numbers and a 0/1 flag (named by line).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such label file")
    out: list[FootLabel] = []
    header = False
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip() or line.startswith("#"):
            continue
        cells = [c.strip() for c in line.split(",")]
        try:
            frame, u, v = int(cells[0]), float(cells[1]), float(cells[2])
            occluded = len(cells) > 3 and cells[3] not in ("", "0")
        except (ValueError, IndexError):
            if not header and not out:
                header = True
                continue
            raise InputError(f"{path}:{lineno}: expected frame,u_px,v_px,occluded") from None
        out.append(FootLabel(frame, u, v, occluded))
    return out


@dataclass(frozen=True, slots=True)
class DetectionScore:
    """Detections of the labelled frames against the labels."""

    labels: int
    """Visible (not occluded) labelled people."""
    found: int
    """Of them, with a detection within ``match_m`` on the floor."""
    false_positives: int
    """Detections farther than ``match_m`` from every label of their frame."""
    errors_m: tuple[float, ...]
    """Floor distance of each found person to its nearest detection."""

    @property
    def recall(self) -> float:
        return self.found / self.labels if self.labels else float("nan")

    def summary(self) -> dict[str, float | int | None]:
        err = np.array(self.errors_m)
        return {
            "labelled_people": self.labels,
            "label_recall": round(self.recall, 4) if self.labels else None,
            "label_false_positives": self.false_positives,
            "label_error_m_mean": round(float(err.mean()), 4) if len(err) else None,
            "label_error_m_median": round(float(np.median(err)), 4) if len(err) else None,
            "label_error_m_p90": round(float(np.percentile(err, 90)), 4) if len(err) else None,
        }


def score_detections(
    labels: Iterable[FootLabel],
    detections: Mapping[int, np.ndarray],
    camera: PinholeCamera,
    match_m: float = 1.0,
) -> DetectionScore:
    """Score detected ground points (frame -> (N, 2) metres) against labels (pixels, placed on
    the floor by ``camera``). Only labelled frames count; occluded labels neither count as
    people nor make a nearby detection a false positive."""
    by_frame: dict[int, list[FootLabel]] = {}
    for lab in labels:
        by_frame.setdefault(lab.frame, []).append(lab)
    n = found = fp = 0
    errors: list[float] = []
    for frame, labs in sorted(by_frame.items()):
        px = np.array([[lab.u_px, lab.v_px] for lab in labs])
        ground = camera.ground_point(px)[:, :2]
        visible = np.array([not lab.occluded for lab in labs])
        dets = np.asarray(detections.get(frame, np.empty((0, 2))), float).reshape(-1, 2)
        for g, vis in zip(ground, visible, strict=True):
            if not vis or np.isnan(g).any():
                continue
            n += 1
            if len(dets):
                d = float(np.linalg.norm(dets - g, axis=1).min())
                if d < match_m:
                    found += 1
                    errors.append(d)
        if len(dets):
            dist = np.linalg.norm(dets[:, None, :] - ground[None, :, :], axis=2)
            fp += int(np.sum(np.nan_to_num(dist, nan=np.inf).min(axis=1) >= match_m))
    return DetectionScore(n, found, fp, tuple(errors))
