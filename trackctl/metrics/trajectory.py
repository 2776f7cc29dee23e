"""Trajectory errors (APE, RPE) of a planar estimate against a reference, computed by evo.

`evo <https://github.com/MichaelGrupp/evo>`_ is the field's tool for these figures; it is an
optional dependency (``pip install 'trackctl[eval]'``): without it the figures are unmeasured
(null, with the reason). Both trajectories are planar (x, y, yaw; z = 0): dead reckoning is, and a
3-D reference (a visual odometry in UTM) is compared in its ground plane.

evo associates poses by nearest stamp within a tolerance; sensors at different rates (odometry at
10 Hz, a GPS at 1 Hz) rarely share stamps, so the reference is interpolated at the estimate's
stamps here first (linearly, never across a gap of more than ``max_gap_s``), and evo gets two
trajectories of equal stamps.
"""

from __future__ import annotations

import math
from array import array
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "ALIGNMENTS",
    "PlanarTrack",
    "TrajectoryErrors",
    "evo_missing",
    "trajectory_errors",
]

ALIGNMENTS = ("origin", "se3")
"""How the estimate is aligned to the reference before APE: ``origin`` (its first pose on the
reference's, evo's ``--align_origin``), ``se3`` (Umeyama least squares, evo's ``--align``)."""


@dataclass
class PlanarTrack:
    """A growing planar trajectory (compact arrays: 32 bytes per pose)."""

    t_ns: array[int] = field(default_factory=lambda: array("q"))
    x_m: array[float] = field(default_factory=lambda: array("d"))
    y_m: array[float] = field(default_factory=lambda: array("d"))
    yaw_rad: array[float] = field(default_factory=lambda: array("d"))

    def add(self, t_ns: int, x: float, y: float, yaw: float) -> None:
        """Append one pose (NaN yaw: unknown heading)."""
        self.t_ns.append(int(t_ns))
        self.x_m.append(x)
        self.y_m.append(y)
        self.yaw_rad.append(yaw)

    def __len__(self) -> int:
        return len(self.t_ns)


@dataclass(frozen=True, slots=True)
class TrajectoryErrors:
    """APE and RPE of one estimate (translation part, metres).

    Attributes:
        pairs: Estimate poses with a reference pose (the APE's sample count).
        ape_m_rmse: Root mean square absolute position error after alignment.
        ape_m_mean: Mean absolute position error.
        ape_m_max: Largest absolute position error.
        rpe_m_rmse: RMS relative position error per ``rpe_delta_m`` of path (None: too short).
    """

    pairs: int
    ape_m_rmse: float | None
    ape_m_mean: float | None
    ape_m_max: float | None
    rpe_m_rmse: float | None


def evo_missing() -> str | None:
    """Why APE/RPE cannot be computed here (evo not installed), or None."""
    try:
        import evo.core.metrics  # type: ignore[import-untyped] # noqa: F401
    except ImportError:
        return "evo is not installed (pip install 'trackctl[eval]')"
    return None


def _sorted(track: PlanarTrack) -> tuple[np.ndarray, ...]:
    t = np.frombuffer(track.t_ns, dtype=np.int64)
    order = np.argsort(t, kind="stable")
    cols = (np.frombuffer(a, dtype=np.float64)[order] for a in (track.x_m, track.y_m))
    yaw = np.unwrap(np.nan_to_num(np.frombuffer(track.yaw_rad, dtype=np.float64)[order]))
    known = ~np.isnan(np.frombuffer(track.yaw_rad, dtype=np.float64)[order])
    return (t[order], *cols, yaw, known)


def _at(est: PlanarTrack, ref: PlanarTrack, max_gap_s: float) -> tuple[np.ndarray, ...] | None:
    """Estimate and reference poses at the estimate's stamps inside the reference's span:
    (t s, est xyz, est yaw, ref xyz, ref yaw); None when fewer than 2 pairs."""
    te, ex, ey, eyaw, _ = _sorted(est)
    tr, rx, ry, ryaw, rknown = _sorted(ref)
    if len(tr) < 2 or len(te) < 2:
        return None
    i = np.clip(np.searchsorted(tr, te), 1, len(tr) - 1)
    inside = (te >= tr[0]) & (te <= tr[-1]) & ((tr[i] - tr[i - 1]) <= max_gap_s * 1e9)
    if inside.sum() < 2:
        return None
    te, ex, ey, eyaw, i = te[inside], ex[inside], ey[inside], eyaw[inside], i[inside]
    a = (te - tr[i - 1]) / np.maximum(tr[i] - tr[i - 1], 1)
    px, py = rx[i - 1] + a * (rx[i] - rx[i - 1]), ry[i - 1] + a * (ry[i] - ry[i - 1])
    pyaw = ryaw[i - 1] + a * (ryaw[i] - ryaw[i - 1])
    # a reference without heading (a GPS, a truth without yaw) borrows the estimate's, so the
    # alignment is a translation there
    pyaw = np.where(rknown[i - 1] & rknown[i], pyaw, eyaw)
    zeros = np.zeros_like(ex)
    return (
        te / 1e9,
        np.column_stack([ex, ey, zeros]),
        eyaw,
        np.column_stack([px, py, zeros]),
        pyaw,
    )


def _quats_wxyz(yaw: np.ndarray) -> np.ndarray:
    return np.column_stack(
        [np.cos(yaw / 2), np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2)]
    )


def _round(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else round(float(v), 4)


def trajectory_errors(
    est: PlanarTrack,
    ref: PlanarTrack,
    align: str = "origin",
    rpe_delta_m: float = 1.0,
    max_gap_s: float = 1.0,
) -> TrajectoryErrors | None:
    """APE and RPE (translation, metres) of ``est`` against ``ref`` after ``align`` (one of
    :data:`ALIGNMENTS`); None when they overlap in fewer than 2 poses or evo is missing.

    Raises:
        ValueError: an unknown ``align``.
    """
    if align not in ALIGNMENTS:
        raise ValueError(f"align {align!r}: expected one of {', '.join(ALIGNMENTS)}")
    if evo_missing() is not None:
        return None
    pairs = _at(est, ref, max_gap_s)
    if pairs is None:
        return None
    from evo.core import metrics
    from evo.core.trajectory import PoseTrajectory3D  # type: ignore[import-untyped]

    t, exyz, eyaw, rxyz, ryaw = pairs
    e = PoseTrajectory3D(positions_xyz=exyz, orientations_quat_wxyz=_quats_wxyz(eyaw), timestamps=t)
    r = PoseTrajectory3D(positions_xyz=rxyz, orientations_quat_wxyz=_quats_wxyz(ryaw), timestamps=t)
    try:
        if align == "origin":
            e.align_origin(r)
        else:
            e.align(r, correct_scale=False)
        ape = metrics.APE(metrics.PoseRelation.translation_part)
        ape.process_data((r, e))
        stats = ape.get_all_statistics()
    except Exception:  # noqa: BLE001 - evo's GeometryException on degenerate (collinear) data
        return TrajectoryErrors(len(t), None, None, None, None)
    return TrajectoryErrors(
        pairs=len(t),
        ape_m_rmse=_round(stats["rmse"]),
        ape_m_mean=_round(stats["mean"]),
        ape_m_max=_round(stats["max"]),
        rpe_m_rmse=_rpe(r, e, rpe_delta_m),
    )


def _rpe(ref: object, est: object, delta_m: float) -> float | None:
    """RMS relative translation error per ``delta_m`` metres of the reference's path."""
    from evo.core import metrics
    from evo.core.units import Unit  # type: ignore[import-untyped]

    try:
        rpe = metrics.RPE(
            metrics.PoseRelation.translation_part,
            delta=delta_m,
            delta_unit=Unit.meters,
            all_pairs=False,
        )
        rpe.process_data((ref, est))
        return _round(rpe.get_statistic(metrics.StatisticsType.rmse))
    except Exception:  # noqa: BLE001 - evo's MetricsException: a path shorter than delta_m
        return None
