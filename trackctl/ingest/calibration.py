"""Camera calibration files: OpenCV YAML/XML (``cv2.FileStorage``), ROS ``camera_info`` YAML and
Tsai camera XML (the PETS datasets' format).

OpenCV files may carry the extrinsics as ``rvec``/``tvec`` in OpenCV's convention (camera <-
world, as ``cv2.solvePnP`` returns them), in metres unless ``metres_per_unit`` says otherwise;
trackctl stores the inverse, world <- camera. Frames and units: docs/cameras.md.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any
from xml.etree.ElementTree import Element

import cv2
import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from scipy.spatial.transform import Rotation

from trackctl.errors import InputError, OutputError
from trackctl.geometry.calib import (
    GroundFit,
    TsaiCamera,
    ground_pose,
    pose_vectors,
    scale_translation,
    tsai_model,
)
from trackctl.ingest.limits import (
    bounded_number,
    check_text_nesting,
    load_yaml,
    parse_xml,
    read_bounded,
    short_repr,
)
from trackctl.logs.messages import CameraModel, Quat, Transform, Vec3
from trackctl.logs.output import check_output_path

__all__ = [
    "read_calibration",
    "read_tsai_xml",
    "write_calibration",
    "checked_model",
    "read_point_pairs",
    "calibrate_ground",
    "to_foxglove_calibration",
    "camera_matrix",
]

MAX_CALIBRATION_BYTES = 1 << 20
"""Largest calibration file read (1 MiB; real ones are a few kB): refused before reading."""
MAX_IMAGE_SIDE_PX = 100_000
"""Largest image width or height a calibration may give."""

MAX_POINTS_BYTES = 16 << 20
"""Largest floor point CSV read (16 MiB)."""

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
        bounded_number(value, f"{path}: field {name}", 1, MAX_IMAGE_SIDE_PX)
    try:
        model = CameraModel(
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
    return checked_model(path, model)


_RANGES = (
    ("fx_px", 1e-6, 1e7),
    ("fy_px", 1e-6, 1e7),
    ("cx_px", -1e6, 1e6),
    ("cy_px", -1e6, 1e6),
)
MAX_DISTORTION = 1e6
"""Largest distortion coefficient accepted (real ones are below 10^3 even for fisheyes)."""
MAX_TRANSLATION = 1e7
"""Largest camera translation accepted, in the file's unit (millimetres included)."""


def checked_model(path: Path, model: CameraModel) -> CameraModel:
    """``model`` after checking that every value is finite and in a range a camera can have
    (what later geometry divides by or raises to powers).

    Raises:
        InputError: naming the file, the value and the range expected.
    """
    for name, lo, hi in _RANGES:
        bounded_number(getattr(model, name), f"{path}: {name}", lo, hi)
    for i, d in enumerate(model.distortion):
        bounded_number(d, f"{path}: distortion[{i}]", -MAX_DISTORTION, MAX_DISTORTION)
    pose = model.world_from_camera
    if pose is not None:
        q = pose.rotation
        if not np.isfinite([q.x, q.y, q.z, q.w]).all():
            raise InputError(f"{path}: the camera rotation is not finite (check rvec)")
        for axis in ("x", "y", "z"):
            bounded_number(
                getattr(pose.translation, axis),
                f"{path}: camera position {axis}",
                -MAX_TRANSLATION,
                MAX_TRANSLATION,
            )
    return model


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


def _read_opencv(path: Path, data: bytes, camera: str) -> CameraModel:
    # OpenCV's parsers recurse per nesting level and segfault on deep nesting: bound it first
    check_text_nesting(data, str(path))
    # OpenCV reports a malformed file as cv2.error, or as SystemError from its Python binding
    try:
        return _read_opencv_storage(path, data.decode("utf-8", errors="replace"), camera)
    except (cv2.error, SystemError) as err:
        reason = " ".join(str(err).split(") ")[-1].split())[:160]
        raise InputError(f"{path}: OpenCV cannot parse this calibration file ({reason})") from None


def _read_opencv_storage(path: Path, text: str, camera: str) -> CameraModel:
    # from memory: OpenCV parses exactly the bytes checked above (the path may have changed)
    fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
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


def _tsai_attr(path: Path, node: Element | None, element: str, name: str) -> float:
    if node is None:
        raise InputError(f"{path}: Tsai camera XML without a <{element}> element")
    value = node.get(name)
    if value is None:
        raise InputError(f"{path}: <{element}> has no attribute {name}")
    try:
        number = float(value)
    except ValueError:
        raise InputError(
            f"{path}: <{element}> attribute {name}: not a number ({short_repr(value)})"
        ) from None
    if not np.isfinite(number):
        raise InputError(f"{path}: <{element}> attribute {name}: not finite ({short_repr(value)})")
    return number


def read_tsai_xml(path: str | Path) -> TsaiCamera:
    """A Tsai camera (PETS ``<Camera><Geometry/><Intrinsic/><Extrinsic/></Camera>``, mm).

    Raises:
        InputError: not such a file, or an attribute is missing or not a number.
    """
    path = Path(path)
    return _parse_tsai(path, read_bounded(path, str(path), MAX_CALIBRATION_BYTES))


_TSAI_RANGES = (
    ("width", 1, MAX_IMAGE_SIDE_PX),
    ("height", 1, MAX_IMAGE_SIDE_PX),
    ("dpx", 1e-9, 1e3),
    ("dpy", 1e-9, 1e3),
    ("focal", 1e-6, 1e6),
    ("sx", 1e-3, 1e3),
    ("cx", -1e6, 1e6),
    ("cy", -1e6, 1e6),
)
"""Tsai values (mm, or pixels for width/height) a real camera has; outside them the model's
conversion overflows or divides by zero."""


def _parse_tsai(path: Path, data: bytes) -> TsaiCamera:
    root = parse_xml(data, str(path))
    geo, intr, extr = (root.find(e) for e in ("Geometry", "Intrinsic", "Extrinsic"))

    def g(e: str, n: str) -> float:
        node = {"Geometry": geo, "Intrinsic": intr, "Extrinsic": extr}[e]
        return _tsai_attr(path, node, e, n)

    dpx = g("Geometry", "dpx") if geo is not None and geo.get("dpx") else None
    if dpx is None:  # Tsai: dpx = dx * ncx / nfx
        dpx = g("Geometry", "dx") * g("Geometry", "ncx") / g("Geometry", "nfx")
    tsai = TsaiCamera(
        width=int(g("Geometry", "width")),
        height=int(g("Geometry", "height")),
        dpx=dpx,
        dpy=g("Geometry", "dpy"),
        focal=g("Intrinsic", "focal"),
        kappa1=g("Intrinsic", "kappa1"),
        cx=g("Intrinsic", "cx"),
        cy=g("Intrinsic", "cy"),
        sx=g("Intrinsic", "sx"),
        t=(g("Extrinsic", "tx"), g("Extrinsic", "ty"), g("Extrinsic", "tz")),
        r=(g("Extrinsic", "rx"), g("Extrinsic", "ry"), g("Extrinsic", "rz")),
    )
    for name, lo, hi in _TSAI_RANGES:
        bounded_number(getattr(tsai, name), f"{path}: Tsai {name}", lo, hi)
    return tsai


def _is_tsai(text: str) -> bool:
    return "<Camera" in text and "<Intrinsic" in text and "<opencv_storage>" not in text


def read_calibration(
    path: str | Path, camera: str, metres_per_unit: float | None = None
) -> CameraModel:
    """A camera model from an OpenCV or ROS calibration YAML file or a Tsai camera XML.

    ``metres_per_unit`` converts the file's translation to metres (``1e-3``: millimetres); None
    takes metres for OpenCV/ROS files and millimetres for Tsai XML (Tsai's own unit).

    Raises:
        InputError: the file is missing or holds no usable calibration.
    """
    path = Path(path)
    if not os.path.lexists(path):
        raise InputError(f"{path}: no such calibration file (camera {camera})")
    data = read_bounded(path, str(path), MAX_CALIBRATION_BYTES)
    text = data.decode("utf-8", errors="replace")
    if not text.strip():
        raise InputError(f"{path}: empty calibration file (camera {camera})")
    if _is_tsai(text):
        try:
            model = tsai_model(_parse_tsai(path, data), camera, metres_per_unit or 1e-3)
        except ValueError as err:
            raise InputError(f"{path}: {err}") from None
        return checked_model(path, model)
    model = _read_calibration_text(path, data, text, camera)
    return scale_translation(model, metres_per_unit or 1.0)


def _read_calibration_text(path: Path, data: bytes, text: str, camera: str) -> CameraModel:
    if path.suffix.lower() == ".xml" and "<opencv_storage>" not in text:
        raise InputError(
            f"{path}: not an OpenCV XML calibration (no <opencv_storage> element) nor a Tsai "
            "camera XML (<Camera> with <Geometry>, <Intrinsic>, <Extrinsic>)"
        )
    if text.lstrip().startswith("%YAML") or "!!opencv-matrix" in text or path.suffix == ".xml":
        return _read_opencv(path, data, camera)
    doc = load_yaml(data, str(path))
    if not isinstance(doc, dict):
        raise InputError(f"{path}: expected a YAML mapping of calibration fields")
    if isinstance(doc.get("camera_matrix"), dict):
        return _read_ros(path, camera, doc)
    if any(isinstance(doc.get(k), list) for k in _K_KEYS):
        return _read_plain(path, camera, doc)
    return _read_opencv(path, data, camera)


def read_point_pairs(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Floor point pairs from a CSV ``u_px,v_px,x_m,y_m[,z_m]`` (a header row is optional):
    pixels (N, 2) and world points (N, 3, metres; z = 0 when not given).

    Raises:
        InputError: missing file, a row that is not 4 or 5 numbers (named by line).
    """
    path = Path(path)
    if not os.path.lexists(path):
        raise InputError(f"{path}: no such point file")
    text = read_bounded(path, str(path), MAX_POINTS_BYTES).decode("utf-8", errors="replace")
    rows: list[list[float]] = []
    header = False
    for lineno, line in enumerate(text.splitlines(), 1):
        cells = [c.strip() for c in line.replace(";", ",").split(",")]
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            values = [float(c) for c in cells]
        except ValueError:
            if not rows and not header:
                header = True
                continue
            raise InputError(f"{path}:{lineno}: expected numbers u_px,v_px,x_m,y_m[,z_m]") from None
        if len(values) not in (4, 5) or not np.isfinite(values).all():
            raise InputError(
                f"{path}:{lineno}: expected 4 or 5 finite numbers u_px,v_px,x_m,y_m[,z_m], "
                f"got {line.strip()!r}"
            )
        rows.append(values + [0.0] * (5 - len(values)))
    if not rows:
        raise InputError(f"{path}: no point pairs")
    arr = np.array(rows)
    return arr[:, :2], arr[:, 2:5]


def calibrate_ground(
    intrinsics: str | Path,
    camera: str,
    image_px: np.ndarray,
    world_m: np.ndarray,
    points_name: str = "points",
) -> GroundFit:
    """Place a camera on the floor: intrinsics from a calibration file (any format
    :func:`read_calibration` reads; its pose, if any, is ignored) and floor point pairs.

    Raises:
        InputError: unreadable intrinsics, or point pairs that fix no pose (named).
    """
    model = read_calibration(intrinsics, camera)
    try:
        return ground_pose(model, image_px, world_m)
    except ValueError as err:
        raise InputError(f"{points_name}: {err}") from None


def write_calibration(model: CameraModel, path: str | Path) -> None:
    """Write ``model`` as the OpenCV YAML that :func:`read_calibration` reads (atomically: the
    file appears whole or not at all; an existing device, FIFO or folder is refused, never
    replaced).

    Raises:
        OutputError: the path is not a regular file or new path, or cannot be written.
    """
    path = check_output_path(path)
    d = np.asarray(model.distortion or (0.0,) * 5, float).reshape(1, -1)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".yaml", dir=path.parent or ".")
    os.close(fd)
    try:
        fs = cv2.FileStorage(tmp, cv2.FILE_STORAGE_WRITE)
        fs.writeComment(
            f"trackctl camera {model.camera}: world metres, z up, floor z = 0; rvec/tvec are "
            "camera <- world (OpenCV solvePnP)"
        )
        fs.write("image_width", int(model.width_px))
        fs.write("image_height", int(model.height_px))
        fs.write("camera_matrix", camera_matrix(model))
        fs.write("distortion_coefficients", d)
        if model.world_from_camera is not None:
            rvec, tvec = pose_vectors(model)
            fs.write("rvec", rvec.reshape(3, 1))
            fs.write("tvec", tvec.reshape(3, 1))
        fs.release()
        os.replace(tmp, path)
    except (OSError, cv2.error) as err:
        Path(tmp).unlink(missing_ok=True)
        raise OutputError(f"{path}: cannot write the calibration ({err})") from None


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
