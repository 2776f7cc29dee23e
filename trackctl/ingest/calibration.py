"""Camera calibration files: OpenCV YAML (``cv2.FileStorage``) and ROS ``camera_info`` YAML.

OpenCV files may carry the extrinsics as ``rvec``/``tvec`` in OpenCV's convention (camera <-
world, as ``cv2.solvePnP`` returns them); trackctl stores the inverse, world <- camera.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from scipy.spatial.transform import Rotation

from trackctl.errors import InputError
from trackctl.logs.messages import CameraModel, Quat, Transform, Vec3

__all__ = ["read_calibration", "to_foxglove_calibration", "camera_matrix"]

_K_KEYS = ("camera_matrix", "cameraMatrix", "K", "intrinsics")
_D_KEYS = ("distortion_coefficients", "dist_coeffs", "distCoeffs", "D", "distortion")


def camera_matrix(model: CameraModel) -> np.ndarray:
    """The 3x3 intrinsic matrix K of a camera model."""
    return np.array([[model.fx_px, 0, model.cx_px], [0, model.fy_px, model.cy_px], [0, 0, 1.0]])


def _numbers(path: Path, name: str, value: Any, sizes: tuple[int, ...]) -> np.ndarray:
    """``value`` as a flat float array of one of ``sizes``; an error naming the field otherwise."""
    expected = " or ".join(str(n) for n in sizes)
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"{path}: field {name}: expected {expected} numbers") from None
    if arr.size not in sizes:
        raise InputError(f"{path}: field {name}: expected {expected} numbers, got {arr.size}")
    if not np.isfinite(arr).all():
        raise InputError(f"{path}: field {name}: holds a NaN or infinite value")
    return arr


def _world_from_camera(path: Path, rvec: Any, tvec: Any) -> Transform:
    r_cw = Rotation.from_rotvec(_numbers(path, "rvec", rvec, (3,)))
    r_wc = r_cw.inv()
    t_wc = -(r_wc.apply(_numbers(path, "tvec", tvec, (3,))))
    return Transform(Vec3(*map(float, t_wc)), Quat(*map(float, r_wc.as_quat())))


_D_SIZES = (0, 4, 5, 8, 12, 14)


def _model(
    path: Path,
    camera: str,
    k: np.ndarray,
    d: np.ndarray,
    width: Any,
    height: Any,
    dist_model: str,
    extr: Transform | None,
) -> CameraModel:
    k = _numbers(path, "camera_matrix", k, (9,))
    d = _numbers(path, "distortion_coefficients", d, _D_SIZES)
    if width is None or height is None:
        raise InputError(f"{path}: image_width and image_height are required")
    for name, value in (("image_width", width), ("image_height", height)):
        if isinstance(value, bool) or not isinstance(value, int | float) or not value >= 1:
            raise InputError(f"{path}: field {name}: expected a positive integer, got {value!r}")
    try:
        return CameraModel(
            t_ns=0,
            camera=camera,
            width_px=int(width),
            height_px=int(height),
            fx_px=float(k[0]),
            fy_px=float(k[4]),
            cx_px=float(k[2]),
            cy_px=float(k[5]),
            distortion_model=dist_model,
            distortion=tuple(float(x) for x in d),
            world_from_camera=extr,
        )
    except ValueError as err:
        raise InputError(f"{path}: {err}") from err


def _read_ros(path: Path, camera: str, doc: dict[str, Any]) -> CameraModel:
    def matrix(key: str) -> np.ndarray:
        entry = doc.get(key)
        if not isinstance(entry, dict) or "data" not in entry:
            raise InputError(f"{path}: ROS camera_info field {key}.data is missing")
        return entry["data"]

    return _model(
        path,
        camera,
        matrix("camera_matrix"),
        matrix("distortion_coefficients"),
        doc.get("image_width"),
        doc.get("image_height"),
        str(doc.get("distortion_model", "plumb_bob")),
        None,
    )


def _read_plain(path: Path, camera: str, doc: dict[str, Any]) -> CameraModel:
    """A plain YAML mapping with list-valued matrices (``camera_matrix: [[fx,0,cx],...]``)."""

    def first(keys: tuple[str, ...]) -> Any:
        return next((doc[k] for k in keys if k in doc), None)

    rvec, tvec = doc.get("rvec"), doc.get("tvec")
    extr = _world_from_camera(path, rvec, tvec) if rvec is not None and tvec is not None else None
    d = first(_D_KEYS)
    return _model(
        path,
        camera,
        first(_K_KEYS),
        np.zeros(5) if d is None else d,
        doc.get("image_width"),
        doc.get("image_height"),
        str(doc.get("distortion_model", "plumb_bob")),
        extr,
    )


def _read_opencv(path: Path, camera: str) -> CameraModel:
    # OpenCV reports a malformed file as cv2.error, or as SystemError from its Python binding
    try:
        return _read_opencv_storage(path, camera)
    except (cv2.error, SystemError) as err:
        reason = " ".join(str(err).split(") ")[-1].split())[:160]
        raise InputError(f"{path}: OpenCV cannot parse this calibration file ({reason})") from None


def _read_opencv_storage(path: Path, camera: str) -> CameraModel:
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        if not fs.isOpened():
            raise InputError(f"{path}: OpenCV cannot parse this calibration file")

        def mat(keys: tuple[str, ...]) -> np.ndarray | None:
            for key in keys:
                node = fs.getNode(key)
                if not node.empty():
                    return node.mat()
            return None

        def num(key: str) -> Any:
            node = fs.getNode(key)
            return None if node.empty() else node.real()

        k = mat(_K_KEYS)
        if k is None:
            raise InputError(f"{path}: no camera matrix (looked for {', '.join(_K_KEYS)})")
        d = mat(_D_KEYS)
        rvec, tvec = mat(("rvec",)), mat(("tvec",))
        extr = None
        if rvec is not None and tvec is not None:
            extr = _world_from_camera(path, rvec, tvec)
        return _model(
            path,
            camera,
            k,
            np.zeros(5) if d is None else d,
            num("image_width"),
            num("image_height"),
            "plumb_bob",
            extr,
        )
    finally:
        fs.release()


def read_calibration(path: str | Path, camera: str) -> CameraModel:
    """A camera model from an OpenCV or ROS calibration YAML file.

    Raises:
        InputError: the file is missing or holds no usable calibration.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such calibration file (camera {camera})")
    try:
        text = path.read_text(errors="replace")
    except OSError as err:
        raise InputError(f"{path}: cannot read ({err.strerror})") from None
    if not text.strip():
        raise InputError(f"{path}: empty calibration file (camera {camera})")
    if path.suffix.lower() == ".xml" and "<opencv_storage>" not in text:
        raise InputError(f"{path}: not an OpenCV XML calibration (no <opencv_storage> element)")
    if text.lstrip().startswith("%YAML") or "!!opencv-matrix" in text or path.suffix == ".xml":
        return _read_opencv(path, camera)
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as err:
        reason = " ".join(str(err).split())[:160]
        raise InputError(f"{path}: not valid YAML ({reason})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{path}: expected a YAML mapping of calibration fields")
    if isinstance(doc.get("camera_matrix"), dict):
        return _read_ros(path, camera, doc)
    if any(isinstance(doc.get(k), list) for k in _K_KEYS):
        return _read_plain(path, camera, doc)
    return _read_opencv(path, camera)


def to_foxglove_calibration(model: CameraModel, t_ns: int | None = None) -> CameraCalibration:
    """The Foxglove CameraCalibration (K, D, R = I, P = [K|0]) of a camera model."""
    k = camera_matrix(model)
    msg = CameraCalibration(
        frame_id=model.camera,
        width=model.width_px,
        height=model.height_px,
        distortion_model=model.distortion_model if model.distortion_model != "none" else "",
        D=list(model.distortion),
        K=list(k.reshape(-1)),
        R=[1, 0, 0, 0, 1, 0, 0, 0, 1],
        P=list(np.hstack([k, np.zeros((3, 1))]).reshape(-1)),
    )
    msg.timestamp.FromNanoseconds(int(model.t_ns if t_ns is None else t_ns))
    return msg
