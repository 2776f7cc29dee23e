"""Compiled inner loops of the re-tracking's Viterbi passes over (layer, position) grids.

The re-tracking (:mod:`~trackctl.vmtrack.retrack`) follows each phone's carrier through the
detections by a Viterbi recursion over a site-sized grid, frame after frame, for many
alignments at once (layers). Written with numpy, one frame is some twenty whole-array passes
(shift each layer by the phone's walk, the 3 x 3 min-plus relaxation, the ring of yaws, the
doors, the frame's emissions): each pass reads and writes every cell, and the re-tracking
spent ~90 % of its time there. No library does this recursion (a min-plus convolution whose
input moves by a per-layer shift every step, over ~10^4 cells and tens of layers: scipy's
``grey_erosion`` with a non-flat structure was 3x slower than the numpy passes), so it is
written out here once, fused cell by cell, and compiled with numba.

Each kernel computes bit for bit what the numpy formulation in :mod:`~trackctl.vmtrack.
retrack` computed (the tests compare them): float32 throughout, the same additions in the same
order, minima (exact) in any order, ties broken as ``np.argmin`` breaks them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["BIG", "OFFSETS", "advance", "come_in", "layer_frame", "predecessors", "return_costs"]

BIG = np.float32(1e9)
"""Unreachable: the cost of cells off the grid."""

OFFSETS = np.array([(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1)], np.int64)
"""The random walk's nine steps (dy, dx), in the order of the step costs."""


@njit(cache=True, nogil=True)
def advance(
    acc: np.ndarray,
    out: np.ndarray,
    whole: np.ndarray,
    restart: np.ndarray,
    steps: np.ndarray,
) -> None:
    """``out`` (layers, rows, columns) = each layer of ``acc`` moved by its whole cells
    (``whole``: (layers, 2) as (x, y) cells; a ``restart`` layer is its own minimum
    everywhere), then relaxed: each cell's cheapest 3 x 3 neighbour plus that step's cost
    (``steps``, float32, in :data:`OFFSETS` order), cells off the grid at :data:`BIG`."""
    n_l, h, w = acc.shape
    pad = np.empty((h + 2, w + 2), np.float32)
    for r in range(n_l):
        a = acc[r]
        pad[:, :] = BIG
        if restart[r]:
            m0 = a[0, 0]
            for y in range(h):
                for x in range(w):
                    if a[y, x] < m0:
                        m0 = a[y, x]
            pad[1 : h + 1, 1 : w + 1] = m0
        else:
            sx = whole[r, 0]
            sy = whole[r, 1]
            y0, y1 = max(sy, 0), min(h + sy, h)
            x0, x1 = max(sx, 0), min(w + sx, w)
            if y0 < y1 and x0 < x1:
                pad[1 + y0 : 1 + y1, 1 + x0 : 1 + x1] = a[y0 - sy : y1 - sy, x0 - sx : x1 - sx]
        _relax_into(pad, steps, out[r])


@njit(cache=True, nogil=True, inline="always")
def _relax_into(pad: np.ndarray, steps: np.ndarray, out: np.ndarray) -> None:
    """``out`` (rows, columns): each cell's minimum over the 3 x 3 neighbourhood of ``pad``
    (rows + 2, columns + 2: a border of :data:`BIG`) plus the step's cost."""
    h, w = out.shape
    c0, c1, c2, c3, c4, c5, c6, c7, c8 = (
        steps[0],
        steps[1],
        steps[2],
        steps[3],
        steps[4],
        steps[5],
        steps[6],
        steps[7],
        steps[8],
    )
    for y in range(h):
        up = pad[y]
        mid = pad[y + 1]
        down = pad[y + 2]
        row = out[y]
        for x in range(w):
            best = mid[x + 1] + c4
            v = up[x] + c0
            best = v if v < best else best
            v = up[x + 1] + c1
            best = v if v < best else best
            v = up[x + 2] + c2
            best = v if v < best else best
            v = mid[x] + c3
            best = v if v < best else best
            v = mid[x + 2] + c5
            best = v if v < best else best
            v = down[x] + c6
            best = v if v < best else best
            v = down[x + 1] + c7
            best = v if v < best else best
            v = down[x + 2] + c8
            best = v if v < best else best
            row[x] = best


@njit(cache=True, nogil=True)
def layer_frame(
    src: np.ndarray,
    dst: np.ndarray,
    turn_cost: np.float32,
    jump: np.float32,
    has_turn: bool,
    before: np.ndarray,
    doors: np.ndarray,
    has_visit: bool,
    emission: np.ndarray,
    mins: np.ndarray,
) -> None:
    """One frame's update of the relaxed ``src`` (layers, rows, columns) into ``dst``, after
    :func:`advance`: with ``has_turn`` the layers are a ring of yaws (a neighbour at
    ``turn_cost``, then any at the cheapest plus ``jump``); with ``has_visit`` a path may come
    into view (``before`` per layer plus the ``doors`` cost of the cell); then the frame's
    ``emission`` (rows, columns; (1, 1): one cost for every cell) is added and each layer's
    minimum written to ``mins``."""
    n_l, h, w = src.shape
    em = emission if emission.shape[0] == h and emission.shape[1] == w else None
    e0 = emission[0, 0]
    low = np.empty(w, np.float32)
    for r in range(n_l):
        mins[r] = BIG
    for y in range(h):
        if has_turn:
            _ring_row(src, dst, y, turn_cost, jump, low)
        for r in range(n_l):
            own = dst[r, y] if has_turn else src[r, y]
            mins[r] = _finish_row(
                own, dst[r, y], low, has_turn, before[r], doors[y], has_visit, em, e0, y, mins[r]
            )


@njit(cache=True, nogil=True)
def _finish_row(
    own: np.ndarray,
    out: np.ndarray,
    low: np.ndarray,
    has_turn: bool,
    b: np.float32,
    drow: np.ndarray,
    has_visit: bool,
    em: np.ndarray | None,
    e0: np.float32,
    y: int,
    m: np.float32,
) -> np.float32:
    """One layer's row of :func:`layer_frame` after the ring: the jump (``low``), coming into
    view (``b`` plus the row's door costs), the emission; returns the layer's minimum so far
    (``m`` before the row)."""
    w = out.shape[0]
    if has_turn:
        for x in range(w):
            out[x] = own[x] if own[x] < low[x] else low[x]
    elif not has_visit:
        out[:] = own
    if has_visit:
        for x in range(w):
            c = b + drow[x]
            out[x] = own[x] if own[x] < c else c
    if em is None:
        for x in range(w):
            v = out[x] + e0
            out[x] = v
            m = v if v < m else m
    else:
        erow = em[y]
        for x in range(w):
            v = out[x] + erow[x]
            out[x] = v
            m = v if v < m else m
    return m


@njit(cache=True, nogil=True)
def _ring_row(
    src: np.ndarray,
    dst: np.ndarray,
    y: int,
    turn_cost: np.float32,
    jump: np.float32,
    low: np.ndarray,
) -> None:
    """Row ``y`` of the ring of yaws: ``dst`` = each layer or its neighbours' plus
    ``turn_cost``, whichever is cheaper; ``low`` = the cheapest layer of ``dst`` plus
    ``jump``."""
    n_l, _, w = src.shape
    for r in range(n_l):
        left = src[r - 1, y] if r > 0 else src[n_l - 1, y]
        right = src[r + 1, y] if r < n_l - 1 else src[0, y]
        own = src[r, y]
        out = dst[r, y]
        for x in range(w):
            t = left[x] if left[x] < right[x] else right[x]
            t = t + turn_cost
            out[x] = t if t < own[x] else own[x]
    low[:] = dst[0, y]
    for r in range(1, n_l):
        out = dst[r, y]
        for x in range(w):
            low[x] = out[x] if out[x] < low[x] else low[x]
    for x in range(w):
        low[x] = low[x] + jump


@njit(cache=True, nogil=True)
def predecessors(
    acc: np.ndarray, sy: int, sx: int, steps: np.ndarray, back: np.ndarray, out: np.ndarray
) -> None:
    """For one layer: ``acc`` (rows, columns) moved by (``sy``, ``sx``) whole cells, then each
    cell's cheapest predecessor's cost plus the step's into ``out``, and which step it is into
    ``back`` (index into :data:`OFFSETS`; the first of equals, as ``np.argmin``). The
    predecessor of a cell by step (dy, dx) is the cell (dy, dx) behind it."""
    h, w = acc.shape
    pad = np.full((h + 2, w + 2), BIG, np.float32)
    y0, y1 = max(sy, 0), min(h + sy, h)
    x0, x1 = max(sx, 0), min(w + sx, w)
    if y0 < y1 and x0 < x1:
        pad[1 + y0 : 1 + y1, 1 + x0 : 1 + x1] = acc[y0 - sy : y1 - sy, x0 - sx : x1 - sx]
    for y in range(h):
        row = out[y]
        arg = back[y]
        for x in range(w):
            row[x] = pad[y + 2, x + 2] + steps[0]
            arg[x] = 0
        for i in range(1, 9):
            src = pad[y + 1 - OFFSETS[i, 0]]
            c = steps[i]
            off = 1 - OFFSETS[i, 1]
            for x in range(w):
                v = src[x + off] + c
                if v < row[x]:
                    row[x] = v
                    arg[x] = i


@njit(cache=True, nogil=True)
def come_in(
    acc: np.ndarray,
    back: np.ndarray,
    before: np.float32,
    doors: np.ndarray,
    back_in: np.ndarray,
    returns: bool,
) -> None:
    """For one path's frame (rows, columns), in place: where coming into view (``before`` +
    ``doors``, float32) is cheaper than ``acc``, ``acc`` takes it and ``back`` is -2; then,
    with ``returns``, where coming back into view (``back_in``) is cheaper still, ``acc``
    takes that and ``back`` is -3."""
    h, w = acc.shape
    for y in range(h):
        for x in range(w):
            c = before + doors[y, x]
            if c < acc[y, x]:
                acc[y, x] = c
                back[y, x] = -2
            if returns and back_in[y, x] < acc[y, x]:
                acc[y, x] = back_in[y, x]
                back[y, x] = -3


@njit(cache=True, nogil=True)
def return_costs(
    base: np.float32,
    doors: np.ndarray,
    row_y: np.ndarray,
    col_x: np.ndarray,
    wx: float,
    wy: float,
    two_var: float,
    out: np.ndarray,
) -> None:
    """Each cell's cost of coming back into view, float32 into ``out``: ``base`` + the door's
    cost (float32), plus the squared distance from the cell's centre (``row_y``, ``col_x``)
    to (``wx``, ``wy``) over ``two_var`` (float64), as numpy adds a float32 grid to a float64
    one."""
    h, w = out.shape
    for y in range(h):
        dy = row_y[y] - wy
        dy2 = dy * dy
        for x in range(w):
            dx = col_x[x] - wx
            d2 = dy2 + dx * dx
            out[y, x] = np.float32(np.float64(base + doors[y, x]) + d2 / two_var)
