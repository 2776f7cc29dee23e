"""Locate far, tiny tags by fitting a blurred model of the printed tag to the pixels.

A tag a few pixels wide defeats the quad detector: its one-pixel black border blurs into the white
cells, so neither the dark blob nor the hole of the white quiet zone outlines it, and a quad off
by half a pixel reads the neighbours' light in every cell. Here the image of a tag is modelled
instead. At that size perspective is affine within the tag, so the tag's image is an affine map of
the printed pattern (quiet zone, black square, N x N cells) blurred by lens, pixel and compression:
for a Gaussian blur each printed rectangle becomes a product of two normal CDFs, an analytic
function of the geometry and linear in the grey levels.

The geometry (centre, the two side vectors, the quiet zone's width) is fitted by
Levenberg-Marquardt (``scipy.optimize.least_squares``) with the grey levels (background, quiet
zone, black square, one free level per cell) solved in closed form at every step (variable
projection). The fit only says *where* the tag is; the detector reads the cells from the fitted
corners with the same rule as every other quad, so a far tag is not read more leniently than a
near one.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.special import ndtr

from trackctl.bridgeloc.tags import tag_geometry

__all__ = ["TinyFit", "TinyFitConfig", "fit_tiny_tag"]


@dataclass(frozen=True, slots=True)
class TinyFitConfig:
    """Model and acceptance thresholds of the tiny-tag fit."""

    blur_px: float = 0.8
    """Gaussian blur of lens + pixel + compression (px); the fit is insensitive to +-0.2."""
    reach: float = 0.4
    """Pixels up to this fraction of the side outside the tag are fitted (quiet zone + a rim)."""
    max_pixels: int = 320
    """Larger patches are subsampled to about this many pixels (the fit's cost is linear in it)."""
    min_contrast: float = 25.0
    """Quiet-zone white minus printed black, grey levels."""
    max_rms_frac: float = 0.12
    """The fit's RMS residual must be below this fraction of the contrast."""
    min_dark: float = 40.0
    """A start is fitted only if its darkest pixel lies this far below its surround's median (a
    cheap screen: most holes of a textured background are no darker than their rim)."""


@dataclass(frozen=True, slots=True)
class TinyFit:
    """Where the fit put the tag: corners in the start's order, contrast and RMS residual."""

    corners: np.ndarray
    """(4, 2) px, in the order of the start quad's corners."""
    contrast: float
    rms: float


_M_LO, _M_HI = 0.1, 0.6
"""Bounds of the fitted quiet-zone width (fraction of the side). Unbounded, a blurred quiet zone
of a pixel trades its width against its brightness and the black square's darkness runs away."""
_Z0 = float(np.log((0.2 - _M_LO) / (_M_HI - 0.2)))  # z of a 0.2 quiet zone


@functools.lru_cache(maxsize=16)
def _edges(n: int, border_ratio: float) -> np.ndarray:
    geo = tag_geometry(n, border_ratio)
    return np.array([0.0] + [geo.border + k * geo.cell for k in range(n + 1)] + [1.0])


def _design(
    thetas: np.ndarray, px: np.ndarray, py: np.ndarray, n: int, edges: np.ndarray, blur: float
) -> np.ndarray:
    """Columns [1, quiet zone, black square, cell_00 .. cell_(n-1)(n-1)] for a batch of geometries.

    ``thetas`` (B, 7): centre x, y; side vector u (x, y); side vector v (x, y); quiet-zone width
    (fraction of the side) as the logit ``z`` between its bounds. Returns (B, P, 3 + n*n).
    """
    tx, ty, ux, uy, vx, vy, z = thetas.T
    m = _M_LO + (_M_HI - _M_LO) / (1.0 + np.exp(-z))
    det = ux * vy - uy * vx
    det = np.where(np.abs(det) < 1e-6, 1e-6, det)
    i00, i01, i10, i11 = vy / det, -vx / det, -uy / det, ux / det
    dx = px[None, :] - tx[:, None]
    dy = py[None, :] - ty[:, None]
    u = i00[:, None] * dx + i01[:, None] * dy + 0.5
    v = i10[:, None] * dx + i11[:, None] * dy + 0.5
    # the blur in tag units along each axis: a pixel-space Gaussian seen through the inverse map
    su = (blur * np.hypot(i00, i01))[:, None, None]
    sv = (blur * np.hypot(i10, i11))[:, None, None]
    b = len(m)
    e = np.concatenate(
        [-m[:, None], np.broadcast_to(edges, (b, len(edges))), 1.0 + m[:, None]], axis=1
    )[:, None, :]
    fu = ndtr((u[:, :, None] - e) / su)  # (B, P, E) = P(blurred point is right of each edge)
    fv = ndtr((v[:, :, None] - e) / sv)
    quiet = (fu[..., 0] - fu[..., -1]) * (fv[..., 0] - fv[..., -1])
    square = (fu[..., 1] - fu[..., -2]) * (fv[..., 1] - fv[..., -2])
    cu = fu[..., 2 : n + 2] - fu[..., 3 : n + 3]
    cv = fv[..., 2 : n + 2] - fv[..., 3 : n + 3]
    cells = (cv[..., :, None] * cu[..., None, :]).reshape(b, len(px), n * n)
    ones = np.ones((b, len(px), 1))
    return np.concatenate([ones, quiet[..., None], square[..., None], cells], axis=2)


def _darkness(gray: np.ndarray, centre: np.ndarray, side: float) -> float:
    """Median of the ring 0.6-0.8 sides around ``centre`` minus the darkest pixel within half
    a side of it."""
    r = 0.8 * side
    x0, y0 = max(int(np.floor(centre[0] - r)), 0), max(int(np.floor(centre[1] - r)), 0)
    x1, y1 = int(np.ceil(centre[0] + r)), int(np.ceil(centre[1] + r))
    patch = gray[y0 : y1 + 1, x0 : x1 + 1].astype(np.float64)
    ys, xs = np.mgrid[y0 : y0 + patch.shape[0], x0 : x0 + patch.shape[1]]
    cheb = np.maximum(np.abs(xs - centre[0]), np.abs(ys - centre[1]))
    # the core spans the whole start square: a start a pixel off still holds the black border
    core, ring = patch[cheb <= 0.5 * side], patch[cheb >= 0.6 * side]
    if core.size == 0 or ring.size == 0:
        return 0.0
    return float(np.median(ring) - core.min())


def _solve(x: np.ndarray, vals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched linear least squares: residuals (B, P) and coefficients (B, K)."""
    xt = x.transpose(0, 2, 1)
    a = xt @ x
    a += 1e-6 * np.eye(x.shape[2])
    beta = np.linalg.solve(a, xt @ vals[:, None])
    return vals[None, :] - (x @ beta)[..., 0], beta[..., 0]


_Start = tuple[np.ndarray, np.ndarray, np.ndarray, float]
"""A start quad as centre, side vectors u and v (px) and side length (px)."""


def _start(corners: np.ndarray) -> _Start | None:
    """Centre, mean side vectors and side of the start quad; None for a degenerate quad."""
    q = np.asarray(corners, np.float64).reshape(4, 2)
    t = q.mean(axis=0)
    u0 = ((q[1] - q[0]) + (q[2] - q[3])) / 2
    v0 = ((q[3] - q[0]) + (q[2] - q[1])) / 2
    side = float(np.sqrt(abs(u0[0] * v0[1] - u0[1] * v0[0])))
    if side < 2.0 or np.linalg.norm(u0) < 1e-6 or np.linalg.norm(v0) < 1e-6:
        return None
    return t, u0, v0, side


@dataclass(frozen=True, slots=True)
class _Patch:
    """The pixels the model is fitted to: coordinates and grey levels (flat)."""

    px: np.ndarray
    py: np.ndarray
    vals: np.ndarray


def _patch(
    gray: np.ndarray, t: np.ndarray, u0: np.ndarray, v0: np.ndarray, cfg: TinyFitConfig
) -> _Patch | None:
    """The pixels around the start (subsampled when many); None when they leave the image."""
    r = (0.5 + cfg.reach) * (np.abs(u0) + np.abs(v0))
    x0, x1 = int(np.floor(t[0] - r[0])), int(np.ceil(t[0] + r[0]))
    y0, y1 = int(np.floor(t[1] - r[1])), int(np.ceil(t[1] + r[1]))
    h, w = gray.shape
    if x0 < 0 or y0 < 0 or x1 >= w or y1 >= h:
        return None
    ys, xs = np.mgrid[y0 : y1 + 1, x0 : x1 + 1]
    px, py = xs.ravel().astype(np.float64), ys.ravel().astype(np.float64)
    vals = gray[y0 : y1 + 1, x0 : x1 + 1].ravel().astype(np.float64)
    if len(vals) > cfg.max_pixels:
        # a larger tag has pixels to spare: fit a checkerboard half (or less) of them
        keep = ((xs + ys).ravel() % int(np.ceil(len(vals) / cfg.max_pixels))) == 0
        px, py, vals = px[keep], py[keep], vals[keep]
    return _Patch(px, py, vals)


_Residuals = Callable[[np.ndarray], np.ndarray]
"""Residuals (B, P) of a batch of geometries (B, 7)."""


def _coarse_start(
    resid: _Residuals, t: np.ndarray, u0: np.ndarray, v0: np.ndarray, side: float
) -> np.ndarray:
    """The best of a grid of starts: the hole's centre may be off by a pixel and its size by
    15 %; a pixel matters below 8 px only (and the grid costs most on large patches)."""
    shifts = (-0.75, 0.0, 0.75) if side < 8.0 else (0.0,)
    starts = np.array(
        [
            [t[0] + ox, t[1] + oy, *(k * u0), *(k * v0), _Z0]
            for k in (0.85, 1.0, 1.15)
            for ox in shifts
            for oy in shifts
        ]
    )
    return starts[int(np.argmin((resid(starts) ** 2).sum(axis=1)))]


def _refine(resid: _Residuals, theta0: np.ndarray) -> np.ndarray:
    """Levenberg-Marquardt from ``theta0``; the fitted geometry."""

    def jac(theta: np.ndarray) -> np.ndarray:
        # forward differences evaluated as one batch (one vectorised call instead of eight)
        step = 1e-3 * np.maximum(1.0, np.abs(theta))
        r_all = resid(np.vstack([theta, theta + np.diag(step)]))
        return ((r_all[1:] - r_all[:1]) / step[:, None]).T

    sol = least_squares(
        lambda th: resid(th[None, :])[0], theta0, jac=jac, method="lm", xtol=1e-3, ftol=1e-3
    )
    return np.asarray(sol.x)


def _stayed(theta: np.ndarray, t: np.ndarray, side: float) -> bool:
    """False when the fit ran off to another blob (size or centre far from the start's)."""
    tx, ty, ux, uy, vx, vy, _ = theta
    su, sv = float(np.hypot(ux, uy)), float(np.hypot(vx, vy))
    if not (0.7 * side <= su <= 1.4 * side and 0.7 * side <= sv <= 1.4 * side):
        return False
    return not np.hypot(tx - t[0], ty - t[1]) > 0.5 * side


def _fitted_corners(theta: np.ndarray) -> np.ndarray:
    """The (4, 2) corners of a geometry, in the start quad's order."""
    tx, ty, ux, uy, vx, vy, _ = theta
    ctr = np.array([tx, ty])
    uu, vv = np.array([ux, uy]), np.array([vx, vy])
    return np.stack(
        [ctr - uu / 2 - vv / 2, ctr + uu / 2 - vv / 2, ctr + uu / 2 + vv / 2, ctr - uu / 2 + vv / 2]
    )


def fit_tiny_tag(
    gray: np.ndarray,
    corners: np.ndarray,
    n: int,
    border_ratio: float,
    cfg: TinyFitConfig | None = None,
) -> TinyFit | None:
    """Fit the tag model around a start quad (corners in printed order TL, TR, BR, BL).

    Returns ``None`` when nothing tag-like is there: too little contrast, a poor fit, or a fit that
    ran off to another blob.
    """
    cfg = cfg or TinyFitConfig()
    start = _start(corners)
    if start is None:
        return None
    t, u0, v0, side = start
    if _darkness(gray, t, side) < cfg.min_dark:
        return None  # cheap screen first: a tag's black is far below its margin even blurred
    u0 = u0 / np.linalg.norm(u0) * side  # the hole of a far tag is lopsided: start square
    v0 = v0 / np.linalg.norm(v0) * side
    patch = _patch(gray, t, u0, v0, cfg)
    if patch is None:
        return None
    px, py, vals = patch.px, patch.py, patch.vals
    edges = _edges(n, border_ratio)
    k_lin = 3 + n * n
    if len(vals) <= k_lin + 7 + 4:
        return None

    def resid(thetas: np.ndarray) -> np.ndarray:
        return _solve(_design(thetas, px, py, n, edges, cfg.blur_px), vals)[0]

    theta = _refine(resid, _coarse_start(resid, t, u0, v0, side))
    if not _stayed(theta, t, side):
        return None  # ran off to another blob
    res, beta = _solve(_design(theta[None, :], px, py, n, edges, cfg.blur_px), vals)
    contrast = float(-beta[0, 2])
    rms = float(np.sqrt(np.mean(res[0] ** 2)))
    if contrast < cfg.min_contrast or rms > cfg.max_rms_frac * contrast:
        return None  # not a dark square in a white margin
    return TinyFit(_fitted_corners(theta), contrast, rms)
