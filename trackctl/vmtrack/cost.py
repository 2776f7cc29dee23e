"""The association's cost, an injected part (norfair's ``distance_function`` is the model): how
likely each predicted track is to have made each of a frame's detections, and the gate below
which a pair is not made. Below the stages that use it (:mod:`~trackctl.vmtrack.tracker`'s
``associate``, :mod:`~trackctl.vmtrack.online`'s ``OnlineTracker``); the pipeline chooses
:class:`VisualCost` for ``v-af`` and :class:`VisualMotionCost` for ``vm``."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

__all__ = [
    "AssociationCost",
    "CostTrack",
    "VisualCost",
    "VisualMotionCost",
    "fused_probability",
]


class CostTrack(Protocol):
    """What a cost may read of a track (:class:`~trackctl.vmtrack.tracker.GroundTrack` is
    one): its motion-sensor prediction."""

    def motion_predicted(
        self, dt: float, v_m: np.ndarray, pdr_sigma_mps: float
    ) -> tuple[np.ndarray, float]:
        """Last position + phone velocity x ``dt``, and its per-axis variance."""
        ...


class AssociationCost(Protocol):
    """The association's cost: the probabilities of every (track, detection) pair of one
    camera's frame, and the gate below which a pair is not made.

    To plug a new cost in, write a class (a small frozen dataclass holding its parameters, as
    :class:`VisualCost`) with a ``gate_p`` and a ``probabilities`` of this signature, returning
    an (n tracks, m detections) array of probabilities in [0, 1]; pass it to ``OnlineTracker``
    (or to ``tracker.associate``) and, for a run, choose it in
    :func:`trackctl.vmtrack.association.association_cost` (which picks one by mode). The
    association takes the one-to-one assignment of least total ``-log p`` (scipy's Hungarian
    solver) among the pairs with ``p >= gate_p``;
    a probability below the gate forbids the pair, and a detection no track takes becomes a
    candidate for a new track.

    The arguments: ``tracks`` (n), ``dets`` (m, 2) ground points and ``covs`` (m, 2, 2) their
    covariances, ``predicted`` the tracks' visual-only predicted positions (n, 2) and per-axis
    variances (n,), ``dt`` each track's step to the frame (s), ``v_m`` each track's phone
    velocity in the site frame (None: no phone bound)."""

    @property
    def gate_p(self) -> float:
        """Pairs with a probability below this are not made."""
        ...

    def probabilities(
        self,
        tracks: Sequence[CostTrack],
        dets: np.ndarray,
        covs: np.ndarray,
        predicted: tuple[np.ndarray, np.ndarray],
        dt: Sequence[float],
        v_m: Sequence[np.ndarray | None],
    ) -> np.ndarray:
        """Returns the (n, m) association probabilities."""
        ...


def fused_probability(
    q: np.ndarray, r: np.ndarray, sv2: float | np.ndarray, sm2: float | np.ndarray
) -> np.ndarray:
    """The paper's fusion of visual (q) and motion (r) association probabilities."""
    a = sv2 / (sv2 + sm2)
    return np.power(q, a) * np.power(r, 1.0 - a)


def _mahalanobis2(diff: np.ndarray, var: np.ndarray, covs: np.ndarray) -> np.ndarray:
    """Squared Mahalanobis distances of ``diff`` (n, m, 2) under ``var[i]`` I + ``covs[j]``
    ((n,), (m, 2, 2)); the 2x2 inverse in closed form, for all pairs at once."""
    a = covs[None, :, 0, 0] + var[:, None]
    b = covs[None, :, 0, 1]
    c = covs[None, :, 1, 1] + var[:, None]
    det = a * c - b * b
    dx, dy = diff[..., 0], diff[..., 1]
    return np.asarray((c * dx * dx - 2 * b * dx * dy + a * dy * dy) / det)


def _visual_likelihood(
    dets: np.ndarray, covs: np.ndarray, predicted: tuple[np.ndarray, np.ndarray]
) -> np.ndarray:
    """Returns q_ij: the likelihood of detection j under track i's visual-only prediction."""
    pv, sv2 = predicted
    return np.exp(-0.5 * _mahalanobis2(dets[None, :, :] - pv[:, None, :], sv2, covs))


@dataclass(frozen=True, slots=True)
class VisualCost:
    """V-AF (the paper's appearance-free baseline): position only, q_ij."""

    gate_p: float = 1e-3

    def probabilities(
        self,
        tracks: Sequence[CostTrack],
        dets: np.ndarray,
        covs: np.ndarray,
        predicted: tuple[np.ndarray, np.ndarray],
        dt: Sequence[float],
        v_m: Sequence[np.ndarray | None],
    ) -> np.ndarray:
        """Returns q: the phones' velocities are not read."""
        return _visual_likelihood(dets, covs, predicted)


@dataclass(frozen=True, slots=True)
class VisualMotionCost:
    """VM (VM-Tracking §3.1.2): the rows of tracks with a phone velocity take the paper's fused
    probability ``q_ij ** (sv2 / (sv2 + sm2)) * r_ij ** (sm2 / (sv2 + sm2))``, r_ij the
    likelihood under the motion-sensor prediction (PDR velocity std ``pdr_sigma_mps`` per
    axis); the other rows (non-users) q_ij alone."""

    gate_p: float = 1e-3
    pdr_sigma_mps: float = 0.25

    def probabilities(
        self,
        tracks: Sequence[CostTrack],
        dets: np.ndarray,
        covs: np.ndarray,
        predicted: tuple[np.ndarray, np.ndarray],
        dt: Sequence[float],
        v_m: Sequence[np.ndarray | None],
    ) -> np.ndarray:
        """Returns q, fused with the motion-sensor likelihood in the rows of tracks with a
        phone velocity."""
        q = _visual_likelihood(dets, covs, predicted)
        moving = [i for i, v in enumerate(v_m) if v is not None]
        if not moving:
            return q
        sv2 = predicted[1]
        r2 = np.trace(covs, axis1=1, axis2=2) / 2  # per-axis variance, for the fusion weights
        mp = [
            tracks[i].motion_predicted(dt[i], v_m[i], self.pdr_sigma_mps)  # type: ignore[arg-type]
            for i in moving
        ]
        pm = np.array([p for p, _ in mp])
        sm2 = np.array([v for _, v in mp])
        r = np.exp(-0.5 * _mahalanobis2(dets[None, :, :] - pm[:, None, :], sm2, covs))
        sv = sv2[moving][:, None] + r2[None, :]
        sm = sm2[:, None] + r2[None, :]
        prob = q.copy()
        prob[moving] = fused_probability(q[moving], r, sv, sm)
        return prob
