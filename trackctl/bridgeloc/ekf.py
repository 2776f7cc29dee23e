"""Continuous localization (dissertation §4.2.3 C, Eqs. 4.10-4.12): an EKF over the robot pose
with wheel odometry as control and the bridged tag observations as measurements.

The paper's EKF turns each tag seen into a range-bearing reading of the tag's centre (Eq. 4.12)
and keeps the tag's corners only to start the filter. Here every bridged observation (Eq. 4.9 on
one tag's four corners) enters as a full pose (x, y, θ) with the covariance propagated from the
corners' pixel noise, so the heading the corners carry is never thrown away; Basic mode is that
same measurement without the motion model. The state carries the heading bias per metre that
wheel scale errors cause (:mod:`trackctl.geometry.odometry_ekf`, shared with S-Mirror); the
filter's consistency is checked by the normalized innovation squared (NIS) of every update.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache

import numpy as np
from scipy.stats import chi2

from trackctl.bridgeloc.smooth import RtsSmoother, position_sigma
from trackctl.geometry.odometry_ekf import DiffDriveEkf, OdometryNoise, nis, wrap

__all__ = ["EkfConfig", "RobotEkf", "corner_covariance", "pose_cov", "wrap", "chi2_95", "gate"]


@cache
def chi2_95(dof: int) -> float:
    """95 % quantile of chi-square: a consistent filter's NIS falls below it 95 % of the time."""
    return float(chi2.ppf(0.95, dof))


@cache
def gate(dof: int) -> float:
    """99.9 % quantile: a measurement beyond it is an outlier (wrong tag, reflection)."""
    return float(chi2.ppf(0.999, dof))


def corner_covariance(
    n_corners: int,
    corner_px: float,
    common_px: float,
    map_jacobian: np.ndarray | None = None,
    map_cov: np.ndarray | None = None,
) -> np.ndarray:
    """Covariance of a tag's ``n_corners`` pixels stacked (u0, v0, u1, v1, ...).

    Each corner's own noise ``corner_px``; ``common_px`` that moves every corner of the tag
    together (the camera's pitch, roll and mount error); and the map's error of the tag's pose
    seen through ``map_jacobian`` (pixels per unit of the map's error, (2 n, k)) with
    covariance ``map_cov`` (k, k). The map's position error moves the corners together and
    scales them (range); its yaw error turns the tag's shape, which says where around the tag
    the robot stands. As independent noise per corner it would drown that shape instead, and
    a tag 3 m away would say little more than its bearing; as exact corners, a mapped tag's
    few degrees of yaw would move the robot by tens of centimetres, wrongly sure of it."""
    r = np.eye(2 * n_corners) * corner_px**2
    r[0::2, 0::2] += common_px**2
    r[1::2, 1::2] += common_px**2
    if map_jacobian is not None and map_cov is not None:
        r += map_jacobian @ map_cov @ map_jacobian.T
    return r


@dataclass(frozen=True, slots=True)
class EkfConfig:
    """Noise model of the EKF (documented sources in docs/bridgeloc.md)."""

    odometry: OdometryNoise = field(default_factory=OdometryNoise)
    corner_sigma_px: float = 1.0
    """Std of a detected tag corner (px): sub-pixel corners on JPEG'd, blurred images are good to
    ~0.3 px (OpenCV cornerSubPix), widened for lens calibration residuals."""
    bridge_floor_m: float = 0.03
    """Position std added to every bridged pose: camera mount and tag map errors."""
    bridge_floor_rad: float = 0.02
    """Heading std added to every bridged pose: camera mount yaw, robot pitch and roll."""
    camera_tilt_rad: float = 0.01
    """Std of the robot camera's rotation away from its calibrated mount at any instant
    (pitch and roll of a small robot on a real floor, mount calibration): a common shift of all
    corners of a frame, f x this in pixels."""
    calib_rad: float = 0.004
    """Residual rotation error of an infrastructure camera's calibrated pose (a floor-point PnP
    calibration good to a few pixels): ground errors growing with range, for I-Cam fixes and
    for the tag map."""
    map_yaw_rad: float = 0.07
    """Std of a mapped tag's yaw (the direction its plane faces): an infrastructure camera
    metres away sees it only through the foreshortening of a tag tens of pixels wide. Measured
    on our own lobby logs (the tags mapped from 8-9 m against their true walls): 1-9.5 deg,
    rms 4 deg."""
    map_scale_frac: float = 0.01
    """Systematic range error of a tag localized by an infrastructure camera, as a fraction of
    its distance (sub-pixel corner bias on a tag tens of pixels wide)."""
    icam_sigma_px: float = 1.5
    """Std of the IR light's centroid in an infrastructure image (px)."""
    icam_floor_m: float = 0.05
    """Position std added to every I-Cam fix: light not over the base centre, camera pose."""
    ambiguity_nis: float = 9.0
    """A tag whose pattern several mapped tags share is used only if the best candidate's NIS
    beats the next by this much (a likelihood ratio of e^4.5, ~90:1)."""
    max_rejects: int = 3
    """After this many robot frames in a row whose tags were all gated out, a pose bridged
    from uniquely identified tags restarts the filter (wheel slip or a wrong start: the state,
    not the cameras, is wrong)."""


class RobotEkf:
    """Odometry prediction, pose and position updates with NIS gating."""

    def __init__(
        self, config: EkfConfig | None = None, smoother: RtsSmoother | None = None
    ) -> None:
        self.cfg = config or EkfConfig()
        self.kf = DiffDriveEkf()
        self.initialized = False
        self.nis_values: list[tuple[float, int]] = []
        """(NIS, dof) of every update tested against the state."""
        self.smoother = smoother
        """Records the filter's nodes for offline smoothing (None: filtering only)."""
        self.t_ns = 0
        """Time of the updates that follow (set by the caller)."""

    def _node(self) -> None:
        """An update is about to change the state at ``t_ns``: the smoother keeps the prior."""
        if self.smoother is not None and self.initialized:
            self.smoother.open(self.t_ns, self.kf.x, self.kf.P)

    def output(self, t_ns: int) -> None:
        """A pose is wanted at ``t_ns`` (the smoother emits it once it knows what followed)."""
        if self.smoother is not None and self.initialized:
            self.smoother.output(t_ns, self.kf.x, self.kf.P)

    def finish(self) -> None:
        """The log is over: the smoother emits what it holds."""
        if self.smoother is not None and self.initialized:
            self.smoother.finish(self.kf.x, self.kf.P)

    def init(self, pose: tuple[float, float, float], cov: np.ndarray) -> None:
        if self.smoother is not None:
            if self.initialized:
                self.smoother.close(self.kf.x, self.kf.P)
            self.smoother.restart()
        self.kf.x = np.array([[pose[0]], [pose[1]], [wrap(pose[2])], [0.0]])
        p = np.zeros((4, 4))
        p[:3, :3] = cov
        p[3, 3] = self.cfg.odometry.heading_bias_sigma**2
        self.kf.P = p
        self.initialized = True

    @property
    def pose(self) -> tuple[float, float, float]:
        x = self.kf.x
        return float(x[0, 0]), float(x[1, 0]), float(x[2, 0])

    @property
    def sigma_m(self) -> float:
        """Largest position standard deviation (m)."""
        return position_sigma(self.kf.P)

    @property
    def sigma_yaw(self) -> float:
        return float(math.sqrt(max(float(self.kf.P[2, 2]), 0.0)))

    def predict(self, ds: float, dyaw: float) -> None:
        """Control c_t from the wheel encoders (Eq. 4.10's g, with the heading bias)."""
        if self.initialized:
            if self.smoother is not None:
                self.smoother.close(self.kf.x, self.kf.P)
            self.kf.predict_odometry(ds, dyaw, self.cfg.odometry)
            if self.smoother is not None:
                self.smoother.predicted(self.kf.F)

    def pose_nis(self, pose: tuple[float, float, float], cov: np.ndarray) -> float:
        """NIS a pose measurement would have (for choosing among tags sharing a pattern)."""
        y = np.array(pose) - np.array(self.pose)
        y[2] = wrap(float(y[2]))
        return nis(y, self.kf.P[:3, :3] + cov)

    def position_nis(self, xy: np.ndarray, cov: np.ndarray) -> float:
        y = np.asarray(xy, float)[:2] - np.array(self.pose[:2])
        return nis(y, self.kf.P[:2, :2] + cov)

    def update_pose(self, pose: tuple[float, float, float], cov: np.ndarray) -> bool:
        """A bridged pose (x, y, θ) with its 3x3 covariance; False when gated out."""
        if not self.initialized:
            self.init(pose, cov)
            return True
        if not self._gate(self.pose_nis(pose, cov), 3):
            return False
        self._node()
        self.kf.update(
            np.array(pose, float)[:, None],
            lambda _x: np.eye(3, 4),
            lambda s: s[:3],
            R=cov,
            residual=_res_yaw,
        )
        self.kf.x[2, 0] = wrap(float(self.kf.x[2, 0]))
        return True

    def measurement_nis(
        self, z: np.ndarray, hx: Callable[[np.ndarray], np.ndarray], jac: np.ndarray, r: np.ndarray
    ) -> float:
        """NIS of a measurement ``z`` with model ``hx`` (of the pose) and Jacobian ``jac``
        (len z, 3) at the current state."""
        h = np.hstack([jac, np.zeros((len(z), 1))])
        return nis(np.asarray(z, float) - hx(np.array(self.pose)), h @ self.kf.P @ h.T + r)

    def update_measurement(
        self,
        z: np.ndarray,
        hx: Callable[[np.ndarray], np.ndarray],
        jac: np.ndarray,
        r: np.ndarray,
    ) -> bool:
        """A non-linear measurement of the pose (a tag's corner pixels), gated by NIS."""
        if not self._gate(self.measurement_nis(z, hx, jac, r), len(z)):
            return False
        h = np.hstack([jac, np.zeros((len(z), 1))])
        self._node()
        self.kf.update(
            np.asarray(z, float)[:, None],
            lambda _x: h,
            lambda s: hx(s[:3, 0])[:, None],
            R=r,
        )
        self.kf.x[2, 0] = wrap(float(self.kf.x[2, 0]))
        return True

    def floor_position(self, sigma_m: float) -> None:
        """Keep the position std at least ``sigma_m``: a measurement relative to a mapped tag
        cannot make the robot surer of its position than the map is of the tag (the map's
        systematic error does not average out over repeated sightings)."""
        p = self.kf.P[:2, :2]
        low = float(np.linalg.eigvalsh(p).min())
        if low < sigma_m**2:
            self._node()
            if self.smoother is not None:
                self.smoother.unfloored(self.kf.P)
            self.kf.P[:2, :2] = p + np.eye(2) * (sigma_m**2 - low)

    def update_position(self, xy: np.ndarray, cov: np.ndarray) -> bool:
        """An I-Cam position fix with its 2x2 covariance; False when gated out."""
        if not self.initialized:
            # position known, heading not: a wide prior until a tag gives it
            self.init((float(xy[0]), float(xy[1]), 0.0), pose_cov(cov, math.pi**2))
            return True
        if not self._gate(self.position_nis(xy, cov), 2):
            return False
        h = np.eye(2, 4)
        self._node()
        self.kf.update(np.asarray(xy, float)[:2, None], lambda _x: h, lambda s: h @ s, R=cov)
        self.kf.x[2, 0] = wrap(float(self.kf.x[2, 0]))
        return True

    def _gate(self, d2: float, dof: int) -> bool:
        """True unless the NIS is beyond the 99.9 % gate (an outlier); every NIS is kept."""
        self.nis_values.append((d2, dof))
        return d2 <= gate(dof)


def pose_cov(cov2: np.ndarray, var_yaw: float) -> np.ndarray:
    """A 3x3 pose covariance from a 2x2 position covariance and a heading variance."""
    out = np.zeros((3, 3))
    out[:2, :2] = cov2
    out[2, 2] = var_yaw
    return out


def _res_yaw(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    y = a - b
    y[2, 0] = wrap(float(y[2, 0]))
    return y
