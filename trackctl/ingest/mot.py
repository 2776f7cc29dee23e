"""MOTChallenge public detections (``det.txt``) as a camera's detections (``record --detections``).

One line per box: ``frame,id,bb_left,bb_top,bb_width,bb_height,conf[,x,y,z]`` (MOTChallenge
2D format: ``frame`` 1-based, ``id`` -1, the box in pixels with ``bb_left``/``bb_top`` 1-based,
``conf`` a detector score on any scale, ``x,y,z`` -1). Commas separate the fields (a file
without commas is split on white space). Frame k becomes one ``trackctl.Detections`` message on
``/<CAM>/detections`` at ``start_ns + (k - 1) / fps`` seconds, the boxes 0-based (``bb_left - 1``,
``bb_top - 1``) and box-only: vm-track places each on the ground through the camera's
``/<CAM>/camera_model`` (the foot point, bottom centre of the box), so the calibration must be
recorded with it (``--calib CAM=...``).

Hostile input never stops the recording: a line that does not parse (fewer than 7 or more than
10 fields, a field that is not a number, NaN or infinity, a box of zero or negative size, a
coordinate beyond :data:`MAX_PX`, a frame that is not an integer from 1 to :data:`MAX_FRAME`)
is skipped and counted, and the file gets one warning naming the first such line and its
column. A file with no usable line is an
error. The file is read whole and its boxes sorted by frame (det.txt files are a few MB and
sorted by frame in practice; unsorted ones come out in frame order too). Frames between the
first and last with no box get an empty message (the camera saw nobody), except in gaps longer
than :data:`MAX_FILL_S` (a camera that was off). Scores are kept as they are when every kept
``conf`` is in [0, 1], else rescaled ``(conf - min) / (max - min)`` over the file's kept boxes
(``trackctl.Detection.score`` is in [0, 1]); ``min_score`` applies to the raw ``conf``.
"""

from __future__ import annotations

import math
import warnings
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from trackctl.errors import InputError
from trackctl.logs.messages import BBox, Detection, Detections

__all__ = ["MotDetections", "MotLineError", "parse_mot_line", "read_mot_detections", "COLUMNS"]

COLUMNS = ("frame", "id", "bb_left", "bb_top", "bb_width", "bb_height", "conf", "x", "y", "z")
MIN_FIELDS = 7
MAX_FRAME = 10_000_000
"""Frames above this (3.8 days at 30 fps) are refused as junk."""
MAX_PX = 1e6
"""Box coordinates beyond +-this many pixels are refused as junk."""
MAX_FILL_S = 10.0
"""Gaps between frames with boxes up to this long get empty messages."""


class MotLineError(ValueError):
    """Why one det.txt line is unusable, and in which column (1-based; 0: the whole line)."""

    def __init__(self, column: int, reason: str) -> None:
        super().__init__(reason)
        self.column = column
        self.reason = reason

    def where(self) -> str:
        """``column 3 (bb_left)``, or ``the line`` for a whole-line problem."""
        if self.column == 0:
            return "the line"
        return f"column {self.column} ({COLUMNS[self.column - 1]})"


@dataclass(frozen=True, slots=True)
class MotBox:
    """One parsed det.txt line: 1-based frame, 0-based box, raw conf."""

    frame: int
    box: BBox
    conf: float


def _fields(line: str) -> list[str]:
    if "," in line:
        return [f.strip() for f in line.split(",")]
    return line.split()


def _number(text: str, column: int) -> float:
    try:
        value = float(text)
    except ValueError:
        raise MotLineError(column, f"{text[:20]!r} is not a number") from None
    if not math.isfinite(value):
        raise MotLineError(column, f"{text[:20]!r} is not finite")
    return value


def parse_mot_line(line: str) -> MotBox:
    """One det.txt line.

    Raises:
        MotLineError: the line is unusable (see the module docstring); never anything else.
    """
    fields = _fields(line.strip().lstrip("\ufeff"))
    if not MIN_FIELDS <= len(fields) <= len(COLUMNS):
        raise MotLineError(0, f"{len(fields)} fields, expected 7 to 10")
    values = [_number(text, k) for k, text in enumerate(fields, 1)]
    frame, _, left, top, width, height, conf = values[:MIN_FIELDS]
    for k in range(2, 6):
        if abs(values[k]) > MAX_PX:
            raise MotLineError(k + 1, f"{fields[k][:20]} is beyond {MAX_PX:.0e} px")
    if not frame.is_integer() or not 1 <= frame <= MAX_FRAME:
        raise MotLineError(1, f"{fields[0][:20]!r} is not a frame number from 1 to {MAX_FRAME}")
    if width <= 0:
        raise MotLineError(5, f"box width {fields[4][:20]} is not positive")
    if height <= 0:
        raise MotLineError(6, f"box height {fields[5][:20]} is not positive")
    return MotBox(int(frame), BBox(left - 1.0, top - 1.0, width, height), conf)


def _lines(path: Path) -> Iterator[tuple[int, str]]:
    try:
        with path.open("rb") as f:
            for lineno, raw in enumerate(f, 1):
                yield lineno, raw.decode("utf-8", errors="replace")
    except OSError as err:
        raise InputError(f"{path}: cannot read ({err.strerror or err})") from err


@dataclass(frozen=True, slots=True)
class MotDetections:
    """What :func:`read_mot_detections` made of one file."""

    messages: tuple[Detections, ...]
    """One per frame, in frame order."""
    boxes: int
    """Boxes kept."""
    skipped: int
    """Unusable lines skipped."""
    below_score: int
    """Boxes dropped by ``min_score``."""
    first_problem: str | None
    """``FILE:LINE: column C (NAME): reason`` of the first skipped line."""


def _score_map(confs: list[float]) -> tuple[float, float]:
    """(offset, scale) turning raw conf into [0, 1]."""
    lo, hi = min(confs), max(confs)
    if lo >= 0.0 and hi <= 1.0:
        return 0.0, 1.0
    return lo, (hi - lo) or 1.0


def _frame_messages(
    by_frame: dict[int, list[MotBox]], camera: str, fps: float, start_ns: int
) -> Iterator[Detections]:
    """One message per frame with boxes, and an empty one per frame in short gaps."""
    confs = [b.conf for boxes in by_frame.values() for b in boxes]
    offset, scale = _score_map(confs)
    fill = max(1, round(MAX_FILL_S * fps))
    last: int | None = None
    for frame in sorted(by_frame):
        if last is not None and frame - last - 1 <= fill:
            for empty in range(last + 1, frame):
                yield Detections(_stamp(empty, fps, start_ns), camera, ())
        dets = tuple(
            Detection(b.box, min(1.0, max(0.0, (b.conf - offset) / scale))) for b in by_frame[frame]
        )
        yield Detections(_stamp(frame, fps, start_ns), camera, dets)
        last = frame


def _stamp(frame: int, fps: float, start_ns: int) -> int:
    return start_ns + round((frame - 1) * 1e9 / fps)


def _collect(
    path: Path, min_score: float | None
) -> tuple[dict[int, list[MotBox]], int, int, str | None]:
    """Boxes by frame, lines skipped, boxes below ``min_score``, the first problem."""
    by_frame: dict[int, list[MotBox]] = defaultdict(list)
    skipped = below = 0
    first: str | None = None
    for lineno, line in _lines(path):
        if not line.strip():
            continue
        try:
            box = parse_mot_line(line)
        except MotLineError as err:
            skipped += 1
            first = first or f"{path}:{lineno}: {err.where()}: {err.reason}"
            continue
        if min_score is not None and box.conf < min_score:
            below += 1
            continue
        by_frame[box.frame].append(box)
    return by_frame, skipped, below, first


def read_mot_detections(
    path: str | Path,
    camera: str,
    fps: float,
    start_ns: int = 0,
    min_score: float | None = None,
) -> MotDetections:
    """Read a MOTChallenge det.txt into one Detections message per frame (module docstring).

    Warns once (``UserWarning``) when lines were skipped.

    Raises:
        InputError: no such file, a bad ``fps``, or no usable line (or none at ``min_score``).
    """
    path = Path(path)
    from trackctl.ingest.video import check_fps

    if not (math.isfinite(fps) and fps > 0):
        raise InputError(f"--fps {fps}: the detections' frame rate must be positive")
    check_fps(fps)
    if not path.is_file():
        raise InputError(f"{path}: no such file (--detections {camera})")
    by_frame, skipped, below, first = _collect(path, min_score)
    if not by_frame:
        why = f"none at --min-score {min_score} or above" if below else "no usable line"
        hint = f"; first problem: {first}" if first else ""
        raise InputError(
            f"{path}: {why} (MOTChallenge det.txt: frame,id,bb_left,bb_top,bb_width,"
            f"bb_height,conf,x,y,z; camera {camera}){hint}"
        )
    if skipped:
        warnings.warn(
            f"{path}: skipped {skipped} unusable line(s); first {first}", UserWarning, stacklevel=2
        )
    messages = tuple(_frame_messages(by_frame, camera, fps, start_ns))
    kept = sum(len(v) for v in by_frame.values())
    return MotDetections(messages, kept, skipped, below, first)
