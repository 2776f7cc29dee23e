"""Camera frames from video files or image folders, as ``foxglove.CompressedImage``.

Timestamps are true: a video's frame ``i`` is at ``start + i / rate`` (the file's own rate, or
``fps`` when the file has none or a wrong one); subsampling (``every``, ``rate_hz``) and the
``start_s``/``end_s`` window keep each kept frame's time. Image folders are stamped from a CSV
(``file,t``), from numeric file names when asked (``1506422223341.jpg``, in ``time_unit``;
``frame_times="names"``) or by ``fps``.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

from trackctl.errors import IncompleteInputWarning, InputError

__all__ = [
    "read_frames",
    "check_fps",
    "check_log_seconds",
    "MAX_LOG_SECONDS",
    "MIN_FPS",
    "MAX_FPS",
    "IMAGE_SUFFIXES",
    "make_compressed_image",
    "frame_size",
    "FrameSelection",
]

IMAGE_SUFFIXES = {".jpg": "jpeg", ".jpeg": "jpeg", ".png": "png", ".webp": "webp"}
_NS_PER_UNIT = {"s": 1e9, "ms": 1e6, "us": 1e3, "ns": 1.0}
MAX_LOG_SECONDS = 9.2e9
"""Latest log time a frame may get, seconds (log times are int64 nanoseconds: 2^63 ns is 9.22e9 s,
the year 2262)."""
MIN_FPS = 1e-6
"""Slowest frame rate accepted (one frame in 11.6 days)."""
MAX_FPS = 1e6
"""Fastest frame rate accepted (frames 1 us apart; nanosecond stamps stay distinct)."""


def check_fps(fps: float, option: str = "--fps") -> float:
    """``fps`` if it is a frame rate trackctl can stamp with: finite, in [1e-6, 1e6] Hz.

    Raises:
        InputError: naming ``option``, the value and the accepted range.
    """
    if not (math.isfinite(fps) and MIN_FPS <= fps <= MAX_FPS):
        raise InputError(
            f"{option} {fps:g}: expected a frame rate in [{MIN_FPS:g}, {MAX_FPS:g}] Hz"
            + (" (must be positive)" if fps <= 0 else "")
        )
    return fps


def check_log_seconds(t_s: float, option: str) -> float:
    """``t_s`` if it is a log time in seconds that fits int64 nanoseconds ([0, 9.2e9] s).

    Raises:
        InputError: naming ``option``, the value and the accepted range.
    """
    if not (math.isfinite(t_s) and 0 <= t_s <= MAX_LOG_SECONDS):
        raise InputError(
            f"{option} {t_s:g}: expected seconds in [0, {MAX_LOG_SECONDS:g}] (log times are int64 "
            "nanoseconds)"
        )
    return t_s


def _stamp(start_ns: int, t_s: float, where: str) -> int:
    """``start_ns + t_s`` in integer nanoseconds, refused when it does not fit int64."""
    t_ns = start_ns + t_s * 1e9
    if not (math.isfinite(t_ns) and 0 <= t_ns <= MAX_LOG_SECONDS * 1e9):
        raise InputError(
            f"{where}: frame time {t_ns / 1e9:g} s is outside [0, {MAX_LOG_SECONDS:g}] s (log "
            "times are int64 nanoseconds); check --fps, --frame-times and --video-start"
        )
    return start_ns + int(round(t_s * 1e9))


def make_compressed_image(t_ns: int, frame_id: str, data: bytes, fmt: str) -> CompressedImage:
    """A Foxglove CompressedImage stamped at ``t_ns``."""
    msg = CompressedImage(frame_id=frame_id, data=data, format=fmt)
    msg.timestamp.FromNanoseconds(int(t_ns))
    return msg


@dataclass(frozen=True, slots=True)
class FrameSelection:
    """Which frames to keep (times in seconds of the source: video time, or the folder's
    timestamps relative to its first frame)."""

    every: int = 1
    """Keep one frame in ``every``."""
    rate_hz: float | None = None
    """Keep frames at most this often (the first frame at or after each 1/rate step)."""
    start_s: float | None = None
    end_s: float | None = None

    def check(self) -> None:
        for option, value in (
            ("--rate", self.rate_hz),
            ("--start", self.start_s),
            ("--end", self.end_s),
        ):
            if value is not None and not math.isfinite(value):
                raise InputError(f"{option} {value}: expected a finite number")
        if self.every < 1:
            raise InputError(f"--every must be >= 1, got {self.every}")
        if self.rate_hz is not None and not self.rate_hz > 0:
            raise InputError(f"--rate must be positive, got {self.rate_hz}")
        if self.start_s is not None and self.end_s is not None and self.end_s <= self.start_s:
            raise InputError(f"--end {self.end_s} must be after --start {self.start_s}")


class _Picker:
    def __init__(self, sel: FrameSelection) -> None:
        self.sel = sel
        self.t0: float | None = None
        self.last_slot = -1
        self.i = -1

    def keep(self, t_s: float) -> bool:
        """Whether the next source frame, at ``t_s``, is kept."""
        sel = self.sel
        if sel.start_s is not None and t_s < sel.start_s - 1e-9:
            return False
        if sel.end_s is not None and t_s > sel.end_s + 1e-9:
            return False
        self.i += 1  # frames inside the window
        if self.i % sel.every:
            return False
        if sel.rate_hz is not None:
            # a grid of 1/rate steps anchored at the first kept frame: keep the first frame at
            # or after each grid point
            if self.t0 is None:
                self.t0 = t_s
            step = 1.0 / sel.rate_hz
            slot = int(np.floor((t_s - self.t0) / step + 1e-6))
            if slot <= self.last_slot:
                return False
            self.last_slot = slot
        return True

    def past_end(self, t_s: float) -> bool:
        return self.sel.end_s is not None and t_s > self.sel.end_s + 1e-9


def frame_size(path: str | Path, camera: str) -> tuple[int, int]:
    """(width, height) of a video's or an image folder's frames.

    Raises:
        InputError: missing path, or nothing decodes.
    """
    path = Path(path)
    if path.is_dir():
        files = _image_files(path, camera)
        image = cv2.imread(str(files[0]), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise InputError(f"{files[0]}: not a decodable image (camera {camera})")
        return int(image.shape[1]), int(image.shape[0])
    if not path.exists():
        raise InputError(f"{path}: no such video file or image folder (camera {camera})")
    cap = cv2.VideoCapture(str(path))
    try:
        ok, frame = cap.read()
        if not ok:
            raise InputError(f"{path}: OpenCV cannot read a frame of this video (camera {camera})")
        return int(frame.shape[1]), int(frame.shape[0])
    finally:
        cap.release()


def _image_files(path: Path, camera: str) -> list[Path]:
    files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise InputError(f"{path}: image folder holds no .jpg/.png/.webp files (camera {camera})")
    return files


def _csv_times(
    path: Path, files: list[Path], times: Path, time_unit: str, scale: float
) -> np.ndarray:
    """Seconds of every image file from the frame-times CSV ``times`` (``file,t``, t in
    ``time_unit``, which is ``scale`` seconds)."""
    if not times.is_file():
        raise InputError(f"{times}: no such frame-times CSV")
    table: dict[str, float] = {}
    for lineno, line in enumerate(times.read_text(errors="replace").splitlines(), 1):
        if not line.strip() or line.startswith("#"):
            continue
        name, _, value = line.partition(",")
        try:
            t = float(value) * scale
        except ValueError:
            if lineno == 1:
                continue  # header
            raise InputError(f"{times}:{lineno}: expected file,t (t in {time_unit})") from None
        if not (math.isfinite(t) and abs(t) <= MAX_LOG_SECONDS):
            raise InputError(
                f"{times}:{lineno}: t={value.strip()[:40]} is not a time; expected a finite number "
                f"of {time_unit} within {MAX_LOG_SECONDS:g} s"
            )
        table[Path(name.strip()).name] = t
    missing = [f.name for f in files if f.name not in table]
    if missing:
        raise InputError(f"{times}: no time for image {missing[0]} of {path}")
    return np.array([table[f.name] for f in files])


def _name_times(path: Path, files: list[Path], scale: float) -> np.ndarray:
    """Seconds of every image file from its numeric name (in units of ``scale`` seconds)."""
    try:
        out = np.array([float(f.stem) for f in files]) * scale
        far = ~(np.isfinite(out) & (np.abs(out) <= MAX_LOG_SECONDS))
        if far.any():
            raise InputError(
                f"{path}: image name {files[int(np.argmax(far))].name} is not a time within "
                f"{MAX_LOG_SECONDS:g} s"
            )
        return out
    except ValueError:
        bad = next(f.name for f in files if not f.stem.replace(".", "", 1).isdigit())
        raise InputError(
            f"{path}: image name {bad} is not a timestamp; pass --fps or --frame-times CSV"
        ) from None


def _folder_times(
    path: Path, files: list[Path], fps: float | None, times: Path | str | None, time_unit: str
) -> np.ndarray:
    """Seconds of every image file: from the CSV ``times``, numeric names (``times="names"``;
    a frame number is not a time, so this is never guessed), or ``fps``."""
    scale = _NS_PER_UNIT[time_unit] / 1e9
    if isinstance(times, Path):
        out = _csv_times(path, files, times, time_unit, scale)
    elif times == "names":
        out = _name_times(path, files, scale)
    elif fps is not None:
        return np.arange(len(files)) / fps
    else:
        raise InputError(
            f"{path}: an image folder needs --fps, --frame-times CSV or --frame-times names "
            "to stamp its frames"
        )
    order = np.argsort(out, kind="stable")
    if (order != np.arange(len(out))).any() or (np.diff(out) <= 0).any():
        raise InputError(f"{path}: image timestamps are not strictly increasing in name order")
    return out - out[0]


def read_frames(
    path: str | Path,
    camera: str,
    *,
    fps: float | None = None,
    start_ns: int = 0,
    jpeg_quality: int = 90,
    select: FrameSelection | None = None,
    frame_times: Path | str | None = None,
    time_unit: str = "s",
) -> Iterator[tuple[int, CompressedImage]]:
    """Frames of a video file or an image folder, as ``(t_ns, CompressedImage)``.

    A kept frame at source time ``t`` (seconds from the first frame) is stamped ``start_ns + t``.
    A video's own frame rate is used unless ``fps`` overrides it (a file with a wrong rate); an
    image folder is stamped by ``frame_times``, numeric names or ``fps``. Image files are stored
    as they are; video frames are encoded as JPEG.

    Raises:
        InputError: missing path, unreadable video, empty folder, or no timestamps.
    """
    path = Path(path)
    sel = select or FrameSelection()
    sel.check()
    if not path.exists():
        raise InputError(f"{path}: no such video file or image folder (camera {camera})")
    if fps is not None:
        check_fps(fps)
    picker = _Picker(sel)
    if path.is_dir():
        files = _image_files(path, camera)
        times = _folder_times(path, files, fps, frame_times, time_unit)
        kept = 0
        for f, t_s in zip(files, times, strict=True):
            if picker.past_end(t_s):
                break
            if not picker.keep(t_s):
                continue
            t_ns = _stamp(start_ns, float(t_s), f"{f} (camera {camera})")
            fmt = IMAGE_SUFFIXES[f.suffix.lower()]
            kept += 1
            yield t_ns, make_compressed_image(t_ns, camera, f.read_bytes(), fmt)
        if kept == 0:
            raise InputError(f"{path}: no image in the --start/--end window (camera {camera})")
        return
    yield from _video_frames(path, camera, fps, start_ns, jpeg_quality, picker)


def _video_rate(
    path: Path, cap: cv2.VideoCapture, camera: str, fps: float | None, every: int
) -> float:
    """The frame rate that stamps an opened video (``fps`` overrides the file's own rate, with a
    warning when that restamps every frame)."""
    if not cap.isOpened():
        raise InputError(f"{path}: OpenCV cannot open this video (camera {camera})")
    own = cap.get(cv2.CAP_PROP_FPS)
    if not (math.isfinite(own) and MIN_FPS <= own <= MAX_FPS):
        own = 0.0  # none, or junk: treated as none
    rate = fps or own
    if not rate:
        raise InputError(f"{path}: the video has no usable frame rate; pass --fps")
    if fps is not None and own and own > 0 and abs(fps - own) > 1e-3 and every == 1:
        warnings.warn(
            f"{path}: --fps {fps:g} restamps the video's {own:g} fps frames (every frame "
            f"kept, time scaled by {own / fps:.3g}); to keep fewer frames use --rate/--every",
            IncompleteInputWarning,
            stacklevel=3,  # the caller of _video_frames
        )
    return rate


def _picked_frames(
    cap: cv2.VideoCapture, rate: float, picker: _Picker
) -> Iterator[tuple[int, float, np.ndarray]]:
    """``(frame number, source time in s, image)`` of the kept frames, until the window or the
    video ends (skipped frames are not decoded)."""
    i = 0
    while True:
        t_s = i / rate
        if picker.past_end(t_s):
            return
        if not picker.keep(t_s):
            if not cap.grab():
                return
            i += 1
            continue
        ok, frame = cap.read()
        if not ok:
            return
        yield i, t_s, frame
        i += 1


def _video_frames(
    path: Path, camera: str, fps: float | None, start_ns: int, quality: int, picker: _Picker
) -> Iterator[tuple[int, CompressedImage]]:
    cap = cv2.VideoCapture(str(path))
    try:
        rate = _video_rate(path, cap, camera, fps, picker.sel.every)
        params = [int(cv2.IMWRITE_JPEG_QUALITY), int(quality)]
        kept = 0
        for i, t_s, frame in _picked_frames(cap, rate, picker):
            ok, buf = cv2.imencode(".jpg", frame, params)
            if not ok:
                raise InputError(f"{path}: frame {i} cannot be encoded as JPEG")
            t_ns = _stamp(start_ns, t_s, f"{path}: frame {i} (camera {camera})")
            kept += 1
            yield t_ns, make_compressed_image(t_ns, camera, buf.tobytes(), "jpeg")
        if kept == 0:
            raise InputError(
                f"{path}: the video holds no decodable frame in the window (camera {camera})"
            )
    finally:
        cap.release()
