"""Camera frames from video files or image folders, as ``foxglove.CompressedImage``."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import cv2
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

from trackctl.errors import InputError

__all__ = ["read_frames", "IMAGE_SUFFIXES", "make_compressed_image"]

IMAGE_SUFFIXES = {".jpg": "jpeg", ".jpeg": "jpeg", ".png": "png", ".webp": "webp"}


def make_compressed_image(t_ns: int, frame_id: str, data: bytes, fmt: str) -> CompressedImage:
    """A Foxglove CompressedImage stamped at ``t_ns``."""
    msg = CompressedImage(frame_id=frame_id, data=data, format=fmt)
    msg.timestamp.FromNanoseconds(int(t_ns))
    return msg


def read_frames(
    path: str | Path,
    camera: str,
    *,
    fps: float | None = None,
    start_ns: int = 0,
    jpeg_quality: int = 90,
) -> Iterator[tuple[int, CompressedImage]]:
    """Frames of a video file or an image folder, as ``(t_ns, CompressedImage)``.

    Frame ``i`` is stamped ``start_ns + i / fps``. A video's own frame rate is used unless ``fps``
    overrides it; an image folder (files in name order) needs ``fps``. Image files are stored as
    they are; video frames are encoded as JPEG.

    Raises:
        InputError: missing path, unreadable video, empty folder, or no frame rate.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such video file or image folder (camera {camera})")
    if fps is not None and fps <= 0:
        raise InputError(f"--fps must be positive, got {fps}")
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise InputError(
                f"{path}: image folder holds no .jpg/.png/.webp files (camera {camera})"
            )
        if fps is None:
            raise InputError(f"{path}: an image folder needs --fps to stamp its frames")
        for i, f in enumerate(files):
            t_ns = start_ns + int(round(i * 1e9 / fps))
            yield (
                t_ns,
                make_compressed_image(
                    t_ns, camera, f.read_bytes(), IMAGE_SUFFIXES[f.suffix.lower()]
                ),
            )
        return
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise InputError(f"{path}: OpenCV cannot open this video (camera {camera})")
        rate = fps or cap.get(cv2.CAP_PROP_FPS)
        if not rate or rate <= 0:
            raise InputError(f"{path}: the video has no frame rate; pass --fps")
        params = [int(cv2.IMWRITE_JPEG_QUALITY), int(jpeg_quality)]
        i = 0
        while True:
            ok, frame = cap.read()
            if not ok:
                break
            ok, buf = cv2.imencode(".jpg", frame, params)
            if not ok:
                raise InputError(f"{path}: frame {i} cannot be encoded as JPEG")
            t_ns = start_ns + int(round(i * 1e9 / rate))
            yield t_ns, make_compressed_image(t_ns, camera, buf.tobytes(), "jpeg")
            i += 1
        if i == 0:
            raise InputError(f"{path}: the video holds no decodable frame (camera {camera})")
    finally:
        cap.release()
