"""The re-tracking's position grid over the site: each frame's detection-distance emissions
and where a path may come into view or leave it (:mod:`~trackctl.vmtrack.retrack`; the RSSI
terms of :mod:`~trackctl.vmtrack.radio` are laid on the same grid)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

__all__ = ["DoorModel", "SiteGrid", "Visit", "occupancy_steadiness"]


class DoorModel(Protocol):
    """Where paths come into view and leave it (the fields of
    :class:`~trackctl.vmtrack.retrack.RetrackConfig` of the same names)."""

    @property
    def away_cost(self) -> float | None: ...
    @property
    def door_cost(self) -> float: ...
    @property
    def wall_cost(self) -> float: ...
    @property
    def edge_m(self) -> float: ...
    @property
    def door_ratio(self) -> float | None: ...
    @property
    def door_link_m(self) -> float: ...
    @property
    def door_frames(self) -> int: ...
    @property
    def door_smooth_m(self) -> float: ...
    @property
    def return_cost(self) -> float | None: ...


MAX_CELLS = 50_000_000
"""Cells a position grid may hold (a 700 m square site at 0.1 m)."""

Visit = tuple[np.ndarray, "float | np.ndarray"]
"""Door costs per cell, and the cost of a frame out of view (one for all, or per frame)."""


class SiteGrid:
    """A site-sized position grid with the frames' detection-distance emissions."""

    def __init__(self, points: Sequence[np.ndarray], cell_m: float) -> None:
        pts = [p for p in points if len(p)]
        allp = np.vstack(pts) if pts else np.zeros((1, 2))
        self.lo = allp.min(axis=0) - 2.0
        hi = allp.max(axis=0) + 2.0
        self.cell = cell_m
        size = ((hi - self.lo) / cell_m).astype(int) + 1
        if not np.isfinite(hi - self.lo).all() or float(np.prod(size.astype(float))) > MAX_CELLS:
            from trackctl.errors import ProcessorError

            raise ProcessorError(
                f"the detections span {hi - self.lo} m: a position grid of {cell_m:g} m cells "
                f"would exceed {MAX_CELLS:,} cells"
            )
        self.shape = (int(size[1]), int(size[0]))
        self.visit: Visit | None = None
        """Door costs per cell and the cost per frame out of view (None: always in view)."""
        self.return_cost: float | None = None
        """Cost of coming back into view after leaving it (None: one visit); with
        :attr:`visit` only."""
        self.covered: np.ndarray | None = None
        """The area the cameras cover (every cell a detection fell in, closed over 1 m gaps and
        filled); with :attr:`visit` only."""

    def with_visits(self, points: Sequence[np.ndarray], cfg: DoorModel) -> SiteGrid:
        """This grid, with the path's one visit to the view set up (``cfg.away_cost``; None:
        the path is in view throughout)."""
        if cfg.away_cost is not None:
            self.visit = (self.doors(points, cfg), cfg.away_cost)
            self.return_cost = cfg.return_cost
            if cfg.return_cost is not None:  # only coming back reads it
                self.covered = self._areas(self._counts(points), cfg.edge_m)[0]
        return self

    def emission(self, pts: np.ndarray, sigma: float, cap: float) -> np.ndarray | float:
        """Cost of each cell at one frame: min(d^2 / 2 sigma^2, cap), d the distance to the
        nearest detection (a distance transform; detections snapped to cells)."""
        if not len(pts):
            return cap
        mask = np.ones(self.shape, bool)
        mask[self.cells_of(pts)[0]] = False
        if mask.all():
            return cap
        dist = ndimage.distance_transform_edt(mask, sampling=self.cell)
        return np.minimum(dist * dist / (2 * sigma * sigma), cap).astype(np.float32)

    def cells_of(self, pts: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
        """The (rows, cols) index of the cells ``pts`` (n, 2) snap to, for those on the grid,
        and which those are (n,)."""
        ij = np.round((pts - self.lo) / self.cell).astype(int)
        ok = (ij >= 0).all(axis=1) & (ij[:, 0] < self.shape[1]) & (ij[:, 1] < self.shape[0])
        return (ij[ok, 1], ij[ok, 0]), ok

    def xy(self, cells: np.ndarray) -> np.ndarray:
        """Positions of (row, col) cells; NaN where the path is out of view (row -1)."""
        out = (self.lo + cells[:, ::-1] * self.cell).astype(float)
        out[cells[:, 0] < 0] = np.nan
        return out

    def doors(self, points: Sequence[np.ndarray], cfg: DoorModel) -> np.ndarray:
        """Cost of coming into view or leaving it at each cell: ``door_cost`` at the doors and
        outside the covered area (every cell a detection fell in over the log, closed over 1 m
        gaps and filled), ``wall_cost`` inside it. The doors are its edge, or where the edge
        sees people come and go (:attr:`~trackctl.vmtrack.retrack.RetrackConfig.door_ratio`)."""
        seen = self._counts(points)
        covered, edge, inner = self._areas(seen, cfg.edge_m)
        if cfg.door_ratio is None or seen[inner].sum() == 0:
            return np.where(inner, cfg.wall_cost, cfg.door_cost).astype(np.float32)
        ends = self._counts(points, cfg)
        sigma = cfg.door_smooth_m / self.cell
        s_ends = ndimage.gaussian_filter(np.where(edge, ends, 0.0), sigma)
        s_seen = ndimage.gaussian_filter(np.where(edge, seen, 0.0), sigma)
        rate = s_ends / np.maximum(s_seen, 1e-9)
        door = (
            edge & (s_seen > 0) & (rate >= cfg.door_ratio * ends[inner].sum() / seen[inner].sum())
        )
        # outside the covered area: a door within reach of one (people walk in through it)
        reach = max(int(round((cfg.edge_m + 2.0) / self.cell)), 1)
        door |= ~covered & ndimage.binary_dilation(door, iterations=reach)
        return np.where(door, cfg.door_cost, cfg.wall_cost).astype(np.float32)

    def edge_turnover(self, points: Sequence[np.ndarray], cfg: DoorModel) -> float | None:
        """How many times as often a detection begins or ends a walk (nobody within
        ``door_link_m`` in the ``door_frames`` frames before, or after) at the edge of the area
        the cameras cover as inside it: high where people cross the view (they come and go at
        its edge), low where they stay in it and the edge is only where the cameras' fields end.
        Infinite when nothing begins or ends inside; None without detections on both."""
        seen = self._counts(points)
        _, edge, inner = self._areas(seen, cfg.edge_m)
        if seen[edge].sum() == 0 or seen[inner].sum() == 0:
            return None
        ends = self._counts(points, cfg)
        at_edge = ends[edge].sum() / seen[edge].sum()
        inside = ends[inner].sum() / seen[inner].sum()
        return float(at_edge / inside) if inside > 0 else float("inf")

    def _areas(self, seen: np.ndarray, edge_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The covered area (every cell a detection fell in, closed over 1 m gaps and filled),
        its edge (within ``edge_m`` of its border) and its inside."""
        r = max(int(round(1.0 / self.cell)), 1)
        covered = ndimage.binary_closing(seen > 0, structure=np.ones((2 * r + 1, 2 * r + 1)))
        covered = ndimage.binary_fill_holes(covered)
        depth = ndimage.distance_transform_edt(np.pad(covered, 1), sampling=self.cell)[1:-1, 1:-1]
        edge = covered & (depth <= edge_m)
        return covered, edge, covered & ~edge

    def _counts(self, points: Sequence[np.ndarray], ends: DoorModel | None = None) -> np.ndarray:
        """Detections per cell over the log; with ``ends``, how many of them begin or end
        (half a count each: nobody within ``door_link_m`` in the ``door_frames`` frames before,
        or after; the log's first and last frames count neither)."""
        out = np.zeros(self.shape)
        trees = [cKDTree(p) if len(p) else None for p in points] if ends else []
        for k, p in enumerate(points):
            if not len(p):
                continue
            at, ok = self.cells_of(p)
            if ends is None:
                np.add.at(out, at, 1.0)
                continue
            m = ends.door_frames
            for side in (-1, 1):
                if not 0 <= k + side * m < len(points):
                    continue
                near = np.zeros(int(ok.sum()), bool)
                for j in range(k + side, k + side * (m + 1), side):
                    tree = trees[j]
                    if tree is not None:
                        near |= tree.query(p[ok])[0] < ends.door_link_m
                np.add.at(out, at, (~near).astype(float) / 2)
        return out


def occupancy_steadiness(
    frame_t: np.ndarray, points: Sequence[np.ndarray], window_s: float
) -> float | None:
    """How steady the number of people in view is: the 5th over the 95th percentile of the
    detections per frame, averaged over ``window_s`` (misses and occlusions average out). Near 1
    where the same people are in view all log (a closed room), low where they come and go.
    None for a log shorter than four windows (too few to tell) or without detections."""
    if len(frame_t) < 2:
        return None
    dt = float(np.median(np.diff(frame_t))) / 1e9
    k = max(int(round(window_s / dt)), 1) if dt > 0 else len(points) + 1
    counts = np.array([len(p) for p in points], float)
    if len(counts) < 4 * k or not counts.any():
        return None
    mean = np.convolve(counts, np.ones(k) / k, mode="valid")
    return float(np.percentile(mean, 5) / np.percentile(mean, 95))
