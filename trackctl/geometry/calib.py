"""Camera calibration on the floor: Tsai import, floor pose from point pairs, sanity checks.

Frames and units (docs/cameras.md): the world is metres with z up and the floor at z = 0; a
camera's pose is stored world <- camera optical frame (x right, y down, z forward). Calibration
files carry OpenCV's ``rvec``/``tvec`` (camera <- world, what ``cv2.solvePnP`` returns).

* :func:`tsai_model` converts a Tsai (1987) camera (the PETS datasets' XML: millimetres, one
  radial coefficient kappa1 acting on *distorted* sensor coordinates, Euler angles) into an
  OpenCV pinhole model; OpenCV's polynomial acts on *undistorted* coordinates, so k1, k2, k3 are
  fitted to Tsai's inverse by linear least squares over the image's radius range.
* :func:`ground_pose` places a camera with known intrinsics on the floor from >= 4 pairs of image
  pixels and floor points (``cv2.solvePnP``: IPPE for a planar start, then Levenberg-Marquardt).
* :func:`camera_problems` names what is implausible in a calibration (millimetres taken for
  metres, a camera below the floor or looking at the sky, a calibration for another image size).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from trackctl.logs.messages import CameraModel, Quat, Transform, Vec3

__all__ = [
    "TsaiCamera",
    "tsai_model",
    "tsai_project",
    "with_pose",
    "pose_vectors",
    "scale_translation",
    "GroundFit",
    "ground_pose",
    "CameraGeometry",
    "camera_geometry",
    "camera_problems",
    "MAX_CAMERA_HEIGHT_M",
    "UNITS",
    "metres_per_unit",
    "geometry_summary",
]

UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
"""Length units a calibration's translation may be given in, as metres per unit."""


def metres_per_unit(unit: str | None, option: str = "--units") -> float | None:
    """Metres per ``unit`` (None stays None: the file format's own unit).

    Raises:
        InputError: an unknown unit, named with the option that gave it.
    """
    from trackctl.errors import InputError

    if unit is None:
        return None
    if unit not in UNITS:
        raise InputError(f"{option} {unit!r}: expected one of {', '.join(UNITS)}")
    return UNITS[unit]


MAX_CAMERA_HEIGHT_M = 100.0
"""Above this a floor camera's height is taken as a unit error (millimetres read as metres)."""


@dataclass(frozen=True, slots=True)
class TsaiCamera:
    """A camera in Tsai's model, as the PETS XML files give it (lengths in millimetres).

    Pixel (Xf, Yf) of a world point: Xc = R Xw + T (R = Rz(rz) Ry(ry) Rx(rx)); undistorted sensor
    Xu = f Xc / Zc; distorted Xd with Xu = Xd (1 + kappa1 (Xd^2 + Yd^2)); Xf = sx Xd / dpx + cx,
    Yf = Yd / dpy + cy.
    """

    width: int
    height: int
    dpx: float
    dpy: float
    focal: float
    kappa1: float
    cx: float
    cy: float
    sx: float
    t: tuple[float, float, float]
    r: tuple[float, float, float]
    """Euler angles rx, ry, rz, radians."""

    def rotation(self) -> np.ndarray:
        """Rotation camera <- world."""
        rx, ry, rz = self.r
        return np.asarray(Rotation.from_euler("ZYX", [rz, ry, rx]).as_matrix())


def pose_vectors(model: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV ``rvec``, ``tvec`` (camera <- world) of a model with a world pose."""
    if model.world_from_camera is None:
        raise ValueError(f"camera {model.camera!r} has no world pose")
    tr = model.world_from_camera
    r_wc = Rotation.from_quat([tr.rotation.x, tr.rotation.y, tr.rotation.z, tr.rotation.w])
    r_cw = r_wc.inv()
    t = np.array([tr.translation.x, tr.translation.y, tr.translation.z])
    return r_cw.as_rotvec(), -r_cw.apply(t)


def with_pose(model: CameraModel, rvec: np.ndarray, tvec: np.ndarray) -> CameraModel:
    """``model`` placed by OpenCV's ``rvec``/``tvec`` (camera <- world)."""
    r_wc = Rotation.from_rotvec(np.asarray(rvec, float).reshape(3)).inv()
    t_wc = -r_wc.apply(np.asarray(tvec, float).reshape(3))
    pose = Transform(Vec3(*map(float, t_wc)), Quat(*map(float, r_wc.as_quat())))
    return replace(model, world_from_camera=pose)


def scale_translation(model: CameraModel, metres_per_unit: float) -> CameraModel:
    """The model with its translation converted to metres (``1e-3`` for millimetres)."""
    if model.world_from_camera is None or metres_per_unit == 1.0:
        return model
    rvec, tvec = pose_vectors(model)
    return with_pose(model, rvec, tvec * metres_per_unit)


def tsai_model(tsai: TsaiCamera, camera: str, metres_per_unit: float = 1e-3) -> CameraModel:
    """The OpenCV pinhole model (plumb_bob k1 k2 0 0 k3) of a Tsai camera.

    Raises:
        ValueError: no OpenCV distortion fits the camera's kappa1 (a degenerate camera).
    """
    fx = tsai.focal * tsai.sx / tsai.dpx
    fy = tsai.focal / tsai.dpy
    # Tsai: undistorted = distorted * (1 + c rho_d^2) in normalised coordinates, c = kappa1 f^2;
    # OpenCV: distorted = undistorted * (1 + k1 rho_u^2 + k2 rho_u^4 + k3 rho_u^6). Fit OpenCV's
    # factor over the normalised radii the image reaches (its corners, plus a margin).
    corners = np.array([[0, 0], [tsai.width, 0], [0, tsai.height], [tsai.width, tsai.height]])
    xn = (corners[:, 0] - tsai.cx) / fx
    yn = (corners[:, 1] - tsai.cy) / fy
    rho_max = 1.05 * float(np.hypot(xn, yn).max())
    k = _tsai_distortion(tsai.kappa1 * tsai.focal**2, rho_max)
    model = CameraModel(
        t_ns=0,
        camera=camera,
        width_px=int(tsai.width),
        height_px=int(tsai.height),
        fx_px=float(fx),
        fy_px=float(fy),
        cx_px=float(tsai.cx),
        cy_px=float(tsai.cy),
        distortion_model="plumb_bob",
        distortion=(float(k[0]), float(k[1]), 0.0, 0.0, float(k[2])),
    )
    rvec = Rotation.from_matrix(tsai.rotation()).as_rotvec()
    return with_pose(model, rvec, np.asarray(tsai.t, float) * metres_per_unit)


def _tsai_distortion(c: float, rho_max: float) -> np.ndarray:
    """OpenCV's k1, k2, k3 fitted to Tsai's inverse distortion ``c`` (normalised) up to radius
    ``rho_max``.

    Raises:
        ValueError: the fit is impossible (radii or factors overflow, or the least squares
            does not converge): kappa1 or the focal length is far outside a real camera's.
    """
    problem = (
        f"Tsai kappa1 * focal^2 = {c:.3g} over normalised radii up to {rho_max:.3g} admits no "
        "OpenCV distortion fit (check kappa1, focal, dpx, cx, cy)"
    )
    with np.errstate(all="ignore"):
        rho_d = np.linspace(0.0, rho_max, 400)
        rho_u = rho_d * (1 + c * rho_d**2)
        factor = 1.0 / (1 + c * rho_d**2)
        a = np.column_stack([rho_u**2, rho_u**4, rho_u**6])
    if not (np.isfinite(a).all() and np.isfinite(factor).all()):
        raise ValueError(problem)
    try:
        k, *_ = np.linalg.lstsq(a, factor - 1.0, rcond=None)
    except np.linalg.LinAlgError:
        raise ValueError(problem) from None
    if not np.isfinite(k).all():
        raise ValueError(problem)
    return np.asarray(k)


def tsai_project(tsai: TsaiCamera, world: np.ndarray, metres_per_unit: float = 1e-3) -> np.ndarray:
    """Pixels (N, 2) of world points (N, 3, metres) by Tsai's own model (the reference the
    conversion is checked against). Undistorted -> distorted is solved by Newton iteration."""
    pts = np.asarray(world, float).reshape(-1, 3) / metres_per_unit
    cam = pts @ tsai.rotation().T + np.asarray(tsai.t, float)
    xu = tsai.focal * cam[:, 0] / cam[:, 2]
    yu = tsai.focal * cam[:, 1] / cam[:, 2]
    ru = np.hypot(xu, yu)
    rd = ru.copy()
    for _ in range(30):  # solve rd (1 + kappa1 rd^2) = ru
        f = rd * (1 + tsai.kappa1 * rd**2) - ru
        rd -= f / (1 + 3 * tsai.kappa1 * rd**2)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(ru > 0, rd / ru, 1.0)
    return np.column_stack([tsai.sx * xu * s / tsai.dpx + tsai.cx, yu * s / tsai.dpy + tsai.cy])


@dataclass(frozen=True, slots=True)
class GroundFit:
    """A camera placed on the floor by :func:`ground_pose`, and how well its points fit."""

    model: CameraModel
    residuals_px: tuple[float, ...]
    """Reprojection error of every point pair, pixels."""

    @property
    def rms_px(self) -> float:
        return float(np.sqrt(np.mean(np.square(self.residuals_px))))

    @property
    def max_px(self) -> float:
        return float(np.max(self.residuals_px))


def _point_pairs(image_px: np.ndarray, world_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (N, 2) and world points (N, 3; floor points get z = 0), checked for
    :func:`ground_pose`.

    Raises:
        ValueError: the counts differ, fewer than 4 pairs, or a NaN or infinite value.
    """
    img = np.ascontiguousarray(np.asarray(image_px, float).reshape(-1, 2))
    world = np.asarray(world_m, float)
    if world.ndim == 2 and world.shape[1] == 2:
        world = np.column_stack([world, np.zeros(len(world))])
    world = np.ascontiguousarray(world.reshape(-1, 3))
    if len(img) != len(world):
        raise ValueError(f"{len(img)} image points but {len(world)} world points")
    if len(img) < 4:
        raise ValueError(f"need at least 4 point pairs, got {len(img)}")
    if not (np.isfinite(img).all() and np.isfinite(world).all()):
        raise ValueError("a point holds a NaN or infinite value")
    return img, world


def _pnp_flag(world: np.ndarray, sv: np.ndarray) -> int:
    """The solvePnP method for these world points (``sv``: their centred singular values)."""
    planar = sv[2] < 1e-6 * sv[0]
    # OpenCV's IPPE needs the plane z = 0 in object coordinates; the floor is, when planar
    flag = cv2.SOLVEPNP_IPPE if planar and np.allclose(world[:, 2], 0) else cv2.SOLVEPNP_EPNP
    if flag == cv2.SOLVEPNP_EPNP and len(world) < 6 and not planar:
        flag = cv2.SOLVEPNP_SQPNP
    return int(flag)


def _solve_pnp(
    world: np.ndarray, img: np.ndarray, k: np.ndarray, dist: np.ndarray, flag: int
) -> tuple[np.ndarray, np.ndarray]:
    """solvePnP then Levenberg-Marquardt refinement: (rvec, tvec).

    Raises:
        ValueError: OpenCV found no pose or failed.
    """
    try:
        ok, rvec, tvec = cv2.solvePnP(world, img, k, dist, flags=flag)
        if not ok:
            raise ValueError("OpenCV's solvePnP found no pose for these points")
        rvec, tvec = cv2.solvePnPRefineLM(world, img, k, dist, rvec, tvec)
    except cv2.error as err:
        raise ValueError(
            f"OpenCV's solvePnP failed ({str(err).strip().splitlines()[-1]})"
        ) from None
    return rvec, tvec


def ground_pose(intrinsics: CameraModel, image_px: np.ndarray, world_m: np.ndarray) -> GroundFit:
    """Pose of a camera from floor point pairs: pixels (N, 2) and world points (N, 2 on the floor
    or N, 3), N >= 4, not all on one line.

    Raises:
        ValueError: too few or degenerate points, or no pose puts the points in front of the
            camera.
    """
    img, world = _point_pairs(image_px, world_m)
    centred = world - world.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    if sv[1] < 1e-3 * max(sv[0], 1e-9):
        raise ValueError("the world points lie on one line; spread them over the floor")
    k = np.array(
        [
            [intrinsics.fx_px, 0, intrinsics.cx_px],
            [0, intrinsics.fy_px, intrinsics.cy_px],
            [0, 0, 1.0],
        ]
    )
    dist = np.asarray(intrinsics.distortion or (0.0,) * 5, float)
    rvec, tvec = _solve_pnp(world, img, k, dist, _pnp_flag(world, sv))
    depth = (cv2.Rodrigues(rvec)[0] @ world.T + tvec).T[:, 2]
    if (depth <= 0).any():
        raise ValueError("the best pose puts points behind the camera; check the pairs' order")
    proj, _ = cv2.projectPoints(world, rvec, tvec, k, dist)
    res = np.linalg.norm(proj.reshape(-1, 2) - img, axis=1)
    return GroundFit(with_pose(intrinsics, rvec, tvec), tuple(float(r) for r in res))


@dataclass(frozen=True, slots=True)
class CameraGeometry:
    """Where a calibrated camera is and where it looks (world frame, z up)."""

    position_m: tuple[float, float, float]
    height_m: float
    tilt_deg: float
    """Angle of the optical axis below the horizontal (90: straight down; < 0: looking up)."""
    floor_share: float
    """Share of the image (a 16 x 12 grid of pixels) that sees the floor."""
    hfov_deg: float


def camera_geometry(model: CameraModel) -> CameraGeometry:
    """Height, tilt, field of view and floor coverage of a model with a world pose."""
    from trackctl.geometry.camera import PinholeCamera  # camera imports nothing from here

    cam = PinholeCamera(model)
    axis = cam.world_R_cam[:, 2]
    tilt = math.degrees(math.asin(max(-1.0, min(1.0, -float(axis[2])))))
    u, v = np.meshgrid(
        np.linspace(0.5, model.width_px - 0.5, 16), np.linspace(0.5, model.height_px - 0.5, 12)
    )
    ground = cam.ground_point(np.column_stack([u.ravel(), v.ravel()]))
    share = float(np.mean(~np.isnan(ground).any(axis=1)))
    hfov = math.degrees(2 * math.atan(model.width_px / (2 * model.fx_px)))
    pos = cam.position
    return CameraGeometry(
        (float(pos[0]), float(pos[1]), float(pos[2])), float(pos[2]), tilt, share, hfov
    )


def camera_problems(
    model: CameraModel, image_size: tuple[int, int] | None = None
) -> tuple[list[str], list[str]]:
    """What is wrong (errors) or doubtful (warnings) in a floor camera's calibration.

    ``image_size`` (width, height) is the size of the frames the calibration will be used on.
    """
    errors: list[str] = []
    warns: list[str] = []
    if image_size is not None and (model.width_px, model.height_px) != tuple(image_size):
        errors.append(
            f"the calibration is for {model.width_px}x{model.height_px} images but the frames "
            f"are {image_size[0]}x{image_size[1]}; calibrate at the recorded size"
        )
    if model.world_from_camera is None:
        return errors, warns
    geo = camera_geometry(model)
    dist = math.dist(geo.position_m, (0.0, 0.0, 0.0))
    if geo.height_m > MAX_CAMERA_HEIGHT_M or dist > 50 * MAX_CAMERA_HEIGHT_M:
        errors.append(
            f"the camera is {geo.height_m:.0f} units above the floor and {dist:.0f} from the "
            "origin: is the translation in millimetres? (metres expected; --units mm)"
        )
    elif geo.height_m <= 0:
        errors.append(
            f"the camera is {-geo.height_m:.2f} m below the floor (world z up): rvec/tvec must be "
            "camera <- world (OpenCV's solvePnP convention), in a z-up world"
        )
    else:
        if geo.floor_share == 0:
            errors.append(
                f"no pixel sees the floor (optical axis {geo.tilt_deg:.0f} deg below the "
                "horizon): a floor camera must look down; check rvec"
            )
        elif geo.tilt_deg < 0:
            warns.append(f"the camera looks {-geo.tilt_deg:.0f} deg above the horizon")
        if geo.height_m < 0.3:
            warns.append(f"the camera is only {geo.height_m:.2f} m above the floor")
    return errors, warns


def geometry_summary(model: CameraModel) -> dict[str, float | int | str | None]:
    """A flat summary of a calibration (for tables and ``--json``)."""
    out: dict[str, float | int | str | None] = {
        "camera": model.camera,
        "image": f"{model.width_px}x{model.height_px}",
        "fx_px": round(model.fx_px, 3),
        "fy_px": round(model.fy_px, 3),
        "cx_px": round(model.cx_px, 3),
        "cy_px": round(model.cy_px, 3),
        "hfov_deg": round(math.degrees(2 * math.atan(model.width_px / (2 * model.fx_px))), 2),
    }
    if model.world_from_camera is not None:
        geo = camera_geometry(model)
        out.update(
            {
                "x_m": round(geo.position_m[0], 3),
                "y_m": round(geo.position_m[1], 3),
                "height_m": round(geo.height_m, 3),
                "tilt_deg": round(geo.tilt_deg, 2),
                "floor_share": round(geo.floor_share, 3),
            }
        )
    return out
