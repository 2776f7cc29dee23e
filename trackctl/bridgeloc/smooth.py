"""Offline smoothing of the EKF (Rauch-Tung-Striebel), in blocks so memory stays flat.

The filter's pose at time t knows only the past: when the robot leaves every camera's view its
dead reckoning drifts, and the fix that ends the gap corrects only the poses after it. A log is
processed after the fact, so every pose can also use what came later. The RTS recursion runs
backward over the filter's nodes (one per robot frame or update instant):

    C_k   = P_k|k F_k+1^T P_k+1|k^-1
    x_k|N = x_k|k + C_k (x_k+1|N - x_k+1|k)
    P_k|N = P_k|k + C_k (P_k+1|N - P_k+1|k) C_k^T

with F_k+1 the product of the motion Jacobians between the two nodes and x_k+1|k the non-linear
prediction the filter made (filterpy's ``rts_smoother`` recomputes the prediction as F x, exact
only for a linear motion model, hence this short loop). A restart of the filter (a new start
from a fix) ends a segment: nothing is smoothed across it.

Fixed lag in blocks: once the buffered nodes span ``2 x lag_s``, the backward pass runs from the
newest node and the nodes older than ``lag_s`` are emitted (each with at least ``lag_s`` of the
future behind it); the rest stays for the next block. At the end everything is emitted.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from trackctl.geometry.odometry_ekf import wrap

__all__ = ["Node", "RtsSmoother", "position_sigma"]


@dataclass(slots=True)
class Node:
    """One instant of the filter: its prior (before the updates there), its posterior, the
    Jacobian of the motion from the previous node, and what to emit there."""

    t_ns: int
    x_prior: np.ndarray
    p_prior: np.ndarray
    f: np.ndarray | None
    """Motion Jacobian from the previous node; None = the first node of a segment."""
    x_post: np.ndarray | None = None
    p_post: np.ndarray | None = None
    output: bool = False
    p_unfloored: np.ndarray | None = None


Emit = Callable[[int, np.ndarray, np.ndarray], None]
"""Called with (time, smoothed state (4, 1), smoothed covariance) of every output node."""


class RtsSmoother:
    """Collects the filter's nodes and emits smoothed output nodes in time order."""

    def __init__(self, emit: Emit, lag_s: float = 60.0) -> None:
        self.emit = emit
        self.lag_ns = int(lag_s * 1e9)
        self.nodes: list[Node] = []
        self._open: Node | None = None
        self._f = np.eye(4)
        self._new_segment = True

    def open(self, t_ns: int, x: np.ndarray, p: np.ndarray) -> None:
        """The filter is about to update or output at ``t_ns`` (state before any update)."""
        if self._open is not None:
            return
        f = None if self._new_segment else self._f
        self._open = Node(t_ns, x.copy(), p.copy(), f)
        self._f = np.eye(4)
        self._new_segment = False

    def output(self, t_ns: int, x: np.ndarray, p: np.ndarray) -> None:
        """A pose is wanted at ``t_ns``."""
        self.open(t_ns, x, p)
        assert self._open is not None
        self._open.output = True

    def unfloored(self, p: np.ndarray) -> None:
        """The filter is about to raise its position variance to the map's floor (a
        systematic error, the same at every node): the smoother links the nodes with the
        covariance the measurements left, or a floored node would pass the newest node's
        offset back over the whole run."""
        if self._open is not None and self._open.p_unfloored is None:
            self._open.p_unfloored = p.copy()

    def close(self, x: np.ndarray, p: np.ndarray) -> None:
        """The node's updates are over (the filter is about to predict or restart)."""
        node = self._open
        if node is None:
            return
        node.x_post = x.copy()
        node.p_post = p.copy() if node.p_unfloored is None else node.p_unfloored
        self.nodes.append(node)
        self._open = None
        if self.nodes[-1].t_ns - self.nodes[0].t_ns >= 2 * self.lag_ns:
            self._flush(self.nodes[-1].t_ns - self.lag_ns)

    def predicted(self, f: np.ndarray) -> None:
        """One motion step with Jacobian ``f`` happened since the last node."""
        self._f = f @ self._f

    def restart(self) -> None:
        """The filter starts anew: the next node begins a segment."""
        self._new_segment = True
        self._f = np.eye(4)

    def finish(self, x: np.ndarray, p: np.ndarray) -> None:
        self.close(x, p)
        self._flush(None)

    def _flush(self, before_ns: int | None) -> None:
        """Smooth the buffer backward from its newest node; emit the output nodes older than
        ``before_ns`` (all when None) and drop them."""
        nodes = self.nodes
        if not nodes:
            return
        xs: list[np.ndarray] = [np.empty(0)] * len(nodes)
        ps: list[np.ndarray] = [np.empty(0)] * len(nodes)
        last = nodes[-1]
        assert last.x_post is not None and last.p_post is not None
        xs[-1], ps[-1] = last.x_post, last.p_post
        for k in range(len(nodes) - 2, -1, -1):
            cur, nxt = nodes[k], nodes[k + 1]
            assert cur.x_post is not None and cur.p_post is not None
            if nxt.f is None:  # a restart follows: this segment's newest node is its own
                xs[k], ps[k] = cur.x_post, cur.p_post
                continue
            c = _gain(cur.p_post, nxt.f, nxt.p_prior)
            dx = xs[k + 1] - nxt.x_prior
            dx[2, 0] = wrap(float(dx[2, 0]))
            x = cur.x_post + c @ dx
            x[2, 0] = wrap(float(x[2, 0]))
            p = cur.p_post + c @ (ps[k + 1] - nxt.p_prior) @ c.T
            xs[k], ps[k] = x, 0.5 * (p + p.T)
        keep = (
            len(nodes)
            if before_ns is None
            else bisect.bisect_left([n.t_ns for n in nodes], before_ns)
        )
        for k in range(keep):
            if nodes[k].output:
                self.emit(nodes[k].t_ns, xs[k], ps[k])
        del nodes[:keep]


def _gain(p_post: np.ndarray, f: np.ndarray, p_prior: np.ndarray) -> np.ndarray:
    """P_k|k F^T P_k+1|k^-1 (solved, not inverted)."""
    try:
        return np.linalg.solve(p_prior.T, (p_post @ f.T).T).T
    except np.linalg.LinAlgError:
        return np.zeros_like(p_post)


def position_sigma(p: np.ndarray) -> float:
    """Largest position standard deviation of a state covariance (m)."""
    return float(math.sqrt(max(float(np.linalg.eigvalsh(p[:2, :2]).max()), 0.0)))
