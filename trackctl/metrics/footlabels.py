"""Detections and tracks scored against hand-labelled foot points (real footage without a
published truth).

A label file is a CSV ``frame,u_px,v_px,occluded``: the 0-based frame index of the video file and
the pixel on the ground between a person's feet. Labels and detections are compared on the
floor (both through the camera's calibration), so the error is in metres.

An identity label file adds a ``person`` column (``frame,person,u_px,v_px,occluded``): the same
person keeps the same name over the frames, which scores tracks (CLEAR MOT, IDF1, ID switches,
and how many track ids cover each person) on the labelled frames.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from trackctl.errors import InputError
from trackctl.geometry.camera import PinholeCamera
from trackctl.metrics.tracking import MotAccumulator, MotSummary

__all__ = [
    "FootLabel",
    "read_foot_labels",
    "DetectionScore",
    "score_detections",
    "PersonLabel",
    "read_person_labels",
    "TrackScore",
    "score_tracks",
]


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
    detections: int = 0
    """Detections on the labelled frames."""

    @property
    def recall(self) -> float:
        return self.found / self.labels if self.labels else float("nan")

    @property
    def precision(self) -> float:
        """Share of the labelled frames' detections within ``match_m`` of a label (occluded
        labels included)."""
        return 1.0 - self.false_positives / self.detections if self.detections else float("nan")

    def summary(self) -> dict[str, float | int | None]:
        err = np.array(self.errors_m)
        return {
            "labelled_people": self.labels,
            "label_recall": round(self.recall, 4) if self.labels else None,
            "label_precision": round(self.precision, 4) if self.detections else None,
            "label_detections": self.detections,
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
    n = found = fp = n_dets = 0
    errors: list[float] = []
    for frame, labs in sorted(by_frame.items()):
        px = np.array([[lab.u_px, lab.v_px] for lab in labs])
        ground = camera.ground_point(px)[:, :2]
        visible = np.array([not lab.occluded for lab in labs])
        dets = np.asarray(detections.get(frame, np.empty((0, 2))), float).reshape(-1, 2)
        n_dets += len(dets)
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
    return DetectionScore(n, found, fp, tuple(errors), n_dets)


@dataclass(frozen=True, slots=True)
class PersonLabel:
    frame: int
    person: str
    u_px: float
    v_px: float
    occluded: bool = False


def _person_row(path: Path, lineno: int, cells: list[str]) -> PersonLabel:
    try:
        frame, person, u, v = int(cells[0]), cells[1], float(cells[2]), float(cells[3])
        flag = cells[4] if len(cells) > 4 else "0"
        if flag not in ("", "0", "1") or not person or frame < 0:
            raise ValueError
    except (ValueError, IndexError):
        raise InputError(
            f"{path}:{lineno}: expected frame,person,u_px,v_px,occluded "
            "(a frame >= 0, a name, two numbers and a 0/1 flag)"
        ) from None
    return PersonLabel(frame, person, u, v, flag == "1")


def read_person_labels(path: str | Path) -> list[PersonLabel]:
    """Identity labels of a ``frame,person,u_px,v_px,occluded`` CSV (``#`` comments, one header
    row).

    Raises:
        InputError: a row is not a frame, a name, two numbers and a 0/1 flag, or a person is
            labelled twice in one frame (named by line).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such label file")
    out: list[PersonLabel] = []
    seen: set[tuple[int, str]] = set()
    header = False
    for lineno, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip() or line.startswith("#"):
            continue
        cells = [c.strip() for c in line.split(",")]
        if not header and not out and not cells[0].lstrip("-").isdigit():
            header = True
            continue
        lab = _person_row(path, lineno, cells)
        if (lab.frame, lab.person) in seen:
            raise InputError(
                f"{path}:{lineno}: person {lab.person!r} labelled twice in frame {lab.frame}"
            )
        seen.add((lab.frame, lab.person))
        out.append(lab)
    return out


@dataclass(frozen=True, slots=True)
class TrackScore:
    """Tracks of the labelled frames against identity labels."""

    mot: MotSummary
    """CLEAR MOT and IDF1 over the labelled frames (occluded labels are don't-care)."""
    person_tracks: Mapping[str, frozenset[str]]
    """Per person labelled visible at least once, the track ids matched to them (maybe none)."""

    @property
    def ids_per_person(self) -> dict[str, int]:
        """Per labelled person, how many distinct track ids were matched to them."""
        return {p: len(t) for p, t in self.person_tracks.items()}

    @property
    def track_ids(self) -> int:
        """Distinct track ids matched to any labelled person (a track matched to two people
        counts once)."""
        return len(frozenset().union(*self.person_tracks.values()))

    def summary(self) -> dict[str, float | int | None]:
        per = np.array(list(self.ids_per_person.values()), float)
        m = self.mot
        return {
            "track_labelled_frames": m.frames,
            "track_labelled_people": len(per),
            "track_people_untracked": int(np.sum(per == 0)),
            "track_mota": round(m.mota, 4),
            "track_idf1": round(m.idf1, 4),
            "track_id_switches": m.id_switches,
            "track_misses": m.misses,
            "track_false_positives": m.false_positives,
            "track_ids_per_person_mean": round(float(per.mean()), 3) if len(per) else None,
            "track_ids_per_person_max": int(per.max()) if len(per) else None,
            "track_ids_matched": self.track_ids,
        }


def score_tracks(
    labels: Iterable[PersonLabel],
    tracks: Mapping[int, Mapping[str, tuple[float, float]]],
    camera: PinholeCamera,
    match_m: float = 1.0,
) -> TrackScore:
    """Score ground-plane tracks (frame -> track id -> (x, y) metres) against identity labels
    (pixels, placed on the floor by ``camera``) on the labelled frames only, in frame order.

    A label's person and a track match when closer than ``match_m`` (CLEAR MOT's procedure,
    :class:`~trackctl.metrics.tracking.MotAccumulator`). Occluded labels are don't-care: a track
    on them is neither a hit nor a false positive. Labels off the floor (above the horizon) are
    left out. A labelled frame without tracks counts its people as misses.
    """
    by_frame: dict[int, list[PersonLabel]] = {}
    for lab in labels:
        by_frame.setdefault(lab.frame, []).append(lab)
    acc = MotAccumulator(match_m)
    matched: dict[str, set[str]] = {}
    visible: set[str] = set()
    for frame, labs in sorted(by_frame.items()):
        ground = camera.ground_point(np.array([[lab.u_px, lab.v_px] for lab in labs]))[:, :2]
        gt: dict[str, tuple[float, float]] = {}
        ignore: list[str] = []
        for lab, g in zip(labs, ground, strict=True):
            if np.isnan(g).any():
                continue
            gt[lab.person] = (float(g[0]), float(g[1]))
            if lab.occluded:
                ignore.append(lab.person)
            else:
                visible.add(lab.person)
        hyp = {str(k): (float(x), float(y)) for k, (x, y) in tracks.get(frame, {}).items()}
        for person, track in acc.update(gt, hyp, ignore).items():
            matched.setdefault(person, set()).add(track)
    tracks_of = {p: frozenset(matched.get(p, ())) for p in sorted(visible)}
    return TrackScore(acc.summary(), tracks_of)
