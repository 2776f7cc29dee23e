"""Detect and decode BridgeLoc tags in a grayscale image (OpenCV quads + our own N x N decoder).

OpenCV finds the candidates (adaptive threshold, contours, ``approxPolyDP`` quads, sub-pixel
corners); the cells are read by our decoder because cv2.aruco can only hold codes with four
distinct rotations, not the practical 2x2 family (see ``shared/ECOSYSTEM.md``).

Orientation rules (§4.2.3 B, practical uniqueness): the cameras never roll, so "up" in the image
is up on the wall. A quad with a near-vertical edge is a square-mounted tag, read with its top
edge up; a quad without one is a diamond (mounted 45° turned), read with its top corner as the
printed top-left corner.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from trackctl.bridgeloc.tags import BORDER_RATIO, Code, Placement, parity_ok, tag_geometry
from trackctl.bridgeloc.tinyfit import TinyFitConfig, fit_tiny_tag

__all__ = ["DetectorConfig", "TagDetection", "read_oriented", "detect_tags", "order_corners"]


@dataclass(frozen=True, slots=True)
class DetectorConfig:
    """Thresholds of the tag detector."""

    n: int = 2
    border_ratio: float = BORDER_RATIO
    family: str = "plain"
    """``plain`` or ``parity`` (codes must pass :func:`~trackctl.bridgeloc.tags.parity_ok`)."""
    min_side_px: float = 6.0
    """Quads with a shorter side are ignored (too few pixels per cell)."""
    min_contrast: float = 25.0
    """Grey-level difference required between the white quiet zone and the black border."""
    cell_margin: float = 0.25
    """A cell must differ from the black/white midpoint by this fraction of the contrast."""
    border_dark_share: float = 0.7
    """Share of samples along each side's border that must be darker than the midpoint."""
    quiet_light_share: float = 0.7
    """Share of samples outside each side that must be lighter than the midpoint."""
    tiny_parallel_tol: float = 0.2
    """Tags under ~16 px: opposite sides may differ by this fraction of their mean."""
    side_contrast: float = 0.3
    """Each side's quiet zone must be this fraction of the tag's contrast lighter than its
    border."""

    edge_margin_px: float = 2.0
    """Quads with a corner this close to the image edge are cut by it: rejected."""
    vertical_tol_deg: float = 20.0
    """An edge within this angle of vertical marks a square-mounted tag."""
    block_size: int = 9
    threshold_c: float = 7.0
    large_block_size: int = 25
    tiny_side_px: float = 12.0
    """Tags up to this size are also sought as holes of their white quiet zone (far tags)."""
    fit_min_side_px: float = 4.0
    fit_max_side_px: float = 16.0
    """Quiet-zone holes of this size range that no quad reads are located by the model fit, then
    read by the same cell rule (above 12 px the quads take over, with a margin)."""
    fit: TinyFitConfig | None = TinyFitConfig()
    """The tiny-tag model fit (:mod:`trackctl.bridgeloc.tinyfit`); ``None`` turns it off."""


@dataclass(frozen=True, slots=True)
class TagDetection:
    """One decoded tag: its code read upright, how it is mounted, corners TL, TR, BR, BL (px)."""

    code: Code
    placement: Placement
    corners: np.ndarray
    contrast: float

    @property
    def pattern_id(self) -> str:
        """Code + placement, as :attr:`PracticalTag.pattern_id`."""
        n = int(round(math.sqrt(len(self.code))))
        return f"{n}:{''.join(map(str, self.code))}/{self.placement.value}"

    @property
    def center(self) -> np.ndarray:
        return self.corners.mean(axis=0)


def order_corners(quad: np.ndarray, vertical_tol_deg: float = 20.0) -> tuple[np.ndarray, Placement]:
    """Corners in printed order TL, TR, BR, BL and the placement, for an upright camera."""
    q = np.asarray(quad, np.float64).reshape(4, 2)
    c = q.mean(axis=0)
    ang = np.arctan2(q[:, 1] - c[1], q[:, 0] - c[0])  # y down: increasing = clockwise on screen
    q = q[np.argsort(ang)]
    edges = np.roll(q, -1, axis=0) - q
    from_vertical = np.degrees(np.arctan2(np.abs(edges[:, 0]), np.abs(edges[:, 1])))
    if from_vertical.min() <= vertical_tol_deg:
        # square: the top edge joins the two highest corners
        k = max(
            range(4),
            key=lambda i: q[(i + 2) % 4, 1] + q[(i + 3) % 4, 1] - q[i, 1] - q[(i + 1) % 4, 1],
        )
        placement = Placement.SQUARE
    else:
        k = int(np.argmin(q[:, 1]))  # diamond: the top corner is the printed top-left
        placement = Placement.DIAMOND
    return np.roll(q, -k, axis=0), placement


@functools.lru_cache(maxsize=16)
def _rings(n: int, border_ratio: float) -> tuple[int, int, float, np.ndarray, np.ndarray]:
    """Canonical warp size and the masks of the black border's middle and the white quiet zone."""
    geo = tag_geometry(n, border_ratio)
    side = 28 * n
    m = int(round(side * 0.14))
    size = side + 2 * m
    b = geo.border * side
    ring_in = np.zeros((size, size), bool)
    lo, hi = int(m + 0.3 * b), int(round(m + side - 0.3 * b))
    ring_in[lo:hi, lo:hi] = True
    lo2, hi2 = int(round(m + 0.7 * b)), int(m + side - 0.7 * b)
    ring_in[lo2:hi2, lo2:hi2] = False
    ring_out = np.zeros((size, size), bool)
    o1, o2 = int(m * 0.25), size - int(m * 0.25)
    ring_out[o1:o2, o1:o2] = True
    i1, i2 = int(round(m * 0.75)), size - int(round(m * 0.75))
    ring_out[i1:i2, i1:i2] = False
    return side, m, b, ring_in, ring_out


def _decode(
    gray: np.ndarray, corners: np.ndarray, cfg: DetectorConfig, check_sides: bool = True
) -> tuple[Code, float] | None:
    geo = tag_geometry(cfg.n, cfg.border_ratio)
    side, m, b, ring_in, ring_out = _rings(cfg.n, cfg.border_ratio)
    dst = np.array([[m, m], [m + side, m], [m + side, m + side], [m, m + side]], np.float32)
    hmat = cv2.getPerspectiveTransform(corners.astype(np.float32), dst)
    size = side + 2 * m
    canon = cv2.warpPerspective(
        gray, hmat, (size, size), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
    )
    # black reference: the middle line of the border; white: a ring in the quiet zone
    inner = canon[ring_in]
    outer = canon[ring_out]
    black = float(np.median(inner))
    white = float(np.median(outer))
    contrast = white - black
    if contrast < cfg.min_contrast:
        return None
    mid = (white + black) / 2
    # a tag's border is dark and its quiet zone light on every side: text, frames and signage
    # are dark on some sides only (a "[" has no right side, a framed sign no quiet zone)
    if np.mean(inner < mid) < 0.6 or np.mean(outer < mid) > 0.25:
        return None  # not a black border inside a white margin
    if check_sides and not _sides_ok(gray, corners, mid, contrast, cfg):
        return None
    cell = geo.cell * side
    bits = []
    for r in range(cfg.n):
        for q in range(cfg.n):
            y0 = m + b + (r + 0.25) * cell
            x0 = m + b + (q + 0.25) * cell
            patch = canon[int(y0) : int(y0 + cell / 2), int(x0) : int(x0 + cell / 2)]
            v = float(patch.mean())
            if abs(v - mid) < cfg.cell_margin * contrast:
                return None  # a grey cell: too small or blurred to read safely
            bits.append(1 if v < mid else 0)
    if all(bits) or not any(bits):
        return None  # uniform codes are not tags (practical rule: too many false positives)
    if cfg.family == "parity" and not parity_ok(bits, cfg.n):
        return None  # a misread cell (or not a tag at all)
    return tuple(bits), contrast


def read_oriented(
    gray: np.ndarray,
    det: TagDetection,
    corners_3d: np.ndarray,
    up: np.ndarray,
    cfg: DetectorConfig,
) -> TagDetection | None:
    """The detection re-read with its placement from 3-D geometry instead of image edges.

    ``corners_3d`` are the detection's corners in the camera frame (in ``det.corners``' order),
    ``up`` the world's up direction in that frame. A square-mounted tag has two edges along
    ``up`` (within 12°), a diamond none (all >= 33° off): unlike the image test (an edge within
    20° of vertical) this holds at any view angle, where foreshortening makes a diamond's edges
    look steep. A tag seen nearly edge-on (> 75°) or between the two keeps the image's
    reading. Corners are then
    reordered (square: TL starts the top edge; diamond: TL is the top corner, keeping the
    image's clockwise order) and the code read again; None when that reading fails.
    """
    p = np.asarray(corners_3d, np.float64)
    u = np.asarray(up, np.float64) / float(np.linalg.norm(up))
    edges = np.roll(p, -1, axis=0) - p
    along_up = np.abs(edges @ u) / np.maximum(np.linalg.norm(edges, axis=1), 1e-12)
    height = p @ u
    normal = np.cross(p[1] - p[0], p[3] - p[0])
    view = p.mean(axis=0)
    incidence = abs(float(normal @ view)) / max(
        float(np.linalg.norm(normal) * np.linalg.norm(view)), 1e-12
    )
    if incidence < math.cos(math.radians(75.0)):
        return det  # seen edge-on: its 3-D pose says less than its image
    if along_up.max() >= math.cos(math.radians(12.0)):
        placement = Placement.SQUARE
        k = int(np.argmax(height + np.roll(height, -1)))  # the top edge: corners k, k+1
    elif along_up.max() <= math.cos(math.radians(33.0)):
        placement = Placement.DIAMOND
        k = int(np.argmax(height))
    else:
        return det  # neither clearly: keep the image's reading
    if placement is det.placement and k == 0:
        return det
    corners = np.roll(np.asarray(det.corners, np.float64), -k, axis=0)
    dec = _decode(gray, corners, cfg, check_sides=False)  # the quad itself passed already
    if dec is None:
        return None
    return TagDetection(dec[0], placement, corners, dec[1])


def _parallel_enough(corners: np.ndarray, cfg: DetectorConfig) -> bool:
    """A tag under ``tiny_side_px`` is far enough for no visible perspective: its opposite
    sides are equally long (within ``tiny_parallel_tol``). Larger quads are not tested."""
    sides = np.linalg.norm(corners - np.roll(corners, 1, axis=0), axis=1)
    if sides.max() > cfg.tiny_side_px * 1.35:
        return True
    d02 = abs(sides[0] - sides[2]) / (sides[0] + sides[2])
    d13 = abs(sides[1] - sides[3]) / (sides[1] + sides[3])
    return max(d02, d13) <= cfg.tiny_parallel_tol / 2


def _sides_ok(
    gray: np.ndarray, corners: np.ndarray, mid: float, contrast: float, cfg: DetectorConfig
) -> bool:
    """Every side of the quad is a dark border with a light quiet zone outside it.

    Sampled in image pixels along each side (its middle 60 %): in the middle of the border and
    at least 1.2 px outside the edge, so tiny tags are judged on pixels the blur has not mixed
    (the canonical warp's rings lie within a pixel of the edge for a 10 px tag)."""
    q = np.asarray(corners, np.float64).reshape(4, 2)
    side_px = float(np.mean(np.linalg.norm(q - np.roll(q, 1, axis=0), axis=1)))
    border_px = side_px / (cfg.border_ratio + 2)
    d_in = 0.5 * border_px
    d_out = max(1.2, 0.5 * border_px)
    ctr = q.mean(axis=0)
    ts = np.linspace(0.2, 0.8, 7)
    for i in range(4):
        a, b = q[i], q[(i + 1) % 4]
        d = (b - a) / max(float(np.linalg.norm(b - a)), 1e-9)
        nrm = np.array([-d[1], d[0]])
        if nrm @ (a - ctr) < 0:
            nrm = -nrm
        base = a[None, :] + ts[:, None] * (b - a)[None, :]
        pts = np.concatenate([base - d_in * nrm, base + d_out * nrm]).astype(np.float32)
        vals = (
            cv2.remap(
                gray,
                pts[None, :, 0],
                pts[None, :, 1],
                cv2.INTER_LINEAR,
                borderMode=cv2.BORDER_REPLICATE,
            )
            .reshape(-1)
            .astype(np.float64)
        )
        inside, outside = vals[: len(ts)], vals[len(ts) :]
        if np.mean(inside < mid) < cfg.border_dark_share:
            return False  # this side has no dark border ("[" has no right side)
        if np.mean(outside > mid) < cfg.quiet_light_share:
            return False  # no light quiet zone here (a frame, a line of text next to it)
        if float(outside.mean() - inside.mean()) < cfg.side_contrast * contrast:
            return False
    return True


def _quiet_zone_quads(
    gray: np.ndarray, cfg: DetectorConfig
) -> tuple[list[tuple[float, np.ndarray]], list[np.ndarray]]:
    """Quads of far, tiny tags found from their white quiet zone, and starts for the model fit.

    A few pixels wide, a tag's thin black border blurs into its white cells and the dark blob no
    longer outlines the tag; the white quiet zone around it still does: the hole of that bright
    ring is the tag. At that size perspective distortion is below a pixel, so the hole's
    minimum-area rectangle is the quad. A white cell on the tag's edge joins the quiet zone, so the
    hole is lopsided: the model fit starts from a square of the hole's area instead.
    """
    bright = cv2.adaptiveThreshold(
        gray, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY, cfg.large_block_size, -7.0
    )
    contours, hierarchy = cv2.findContours(bright, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    out: list[tuple[float, np.ndarray]] = []
    starts: list[tuple[float, np.ndarray]] = []
    if hierarchy is None:
        return out, []
    for cnt, (_, _, _, parent) in zip(contours, hierarchy[0], strict=True):
        if parent < 0:
            continue  # an outer boundary; tags are the holes
        _, _, bw, bh = cv2.boundingRect(cnt)
        if not (cfg.fit_min_side_px <= max(bw, bh) <= cfg.fit_max_side_px):
            continue
        if min(bw, bh) < 0.6 * max(bw, bh):
            continue
        (cx, cy), (rw, rh), ang = cv2.minAreaRect(cnt)
        side = max(float(np.sqrt(max(rw, 1.0) * max(rh, 1.0))), cfg.fit_min_side_px)
        starts.append((side, cv2.boxPoints(((cx, cy), (side, side), ang)).astype(np.float32)))
        if not cfg.min_side_px - 1 <= max(bw, bh) <= cfg.tiny_side_px:
            continue
        # the blurred inner edge of the quiet zone may fall inside or outside the bright mask:
        # try the hole as found and one pixel tighter on every side
        for shrink in (0.0, 2.0):
            if min(rw, rh) - shrink < cfg.min_side_px - 1:
                continue
            box = cv2.boxPoints(((cx, cy), (rw - shrink, rh - shrink), ang)).astype(np.float32)
            out.append((float(cv2.contourArea(box)), box.reshape(4, 1, 2)))
    starts.sort(key=lambda sq: -sq[0])
    return out, [box for _, box in starts]


def refine_edges(gray: np.ndarray, quad: np.ndarray, border_px: float) -> np.ndarray:
    """Corners as the intersections of the four border edges, each edge fitted to the points
    where the grey level crosses halfway between the black border and the white quiet zone.

    cornerSubPix alone leaves the corners of a blurred, JPEG'd small square ~0.35 px inside it
    (measured on rendered 26 px tags): 2 % of the side, i.e. 2 % of the distance. Edges are
    symmetric under blur, so their halfway crossings are not biased (AprilTag refines its quads
    the same way). Falls back to ``quad`` where an edge cannot be measured."""
    q = np.asarray(quad, np.float64).reshape(4, 2)
    reach = float(np.clip(0.8 * border_px, 1.5, 4.0))
    offsets = np.linspace(-reach, reach, 2 * int(np.ceil(reach * 2)) + 1)
    ts = np.linspace(0.2, 0.8, 9)
    ctr = q.mean(axis=0)
    lines = []
    for i in range(4):
        a, b = q[i], q[(i + 1) % 4]
        d = b - a
        length = float(np.linalg.norm(d))
        if length < 4:
            return q
        d /= length
        nrm = np.array([-d[1], d[0]])
        if nrm @ (a - ctr) < 0:
            nrm = -nrm  # outward
        base = a[None, :] + ts[:, None] * (b - a)[None, :]
        pts = base[:, None, :] + offsets[None, :, None] * nrm[None, None, :]
        prof = cv2.remap(
            gray.astype(np.float32),
            pts[..., 0].astype(np.float32),
            pts[..., 1].astype(np.float32),
            cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REPLICATE,
        )
        found = []
        for k in range(len(ts)):
            row = prof[k]
            lo, hi = float(row[: len(row) // 3].mean()), float(row[-(len(row) // 3) :].mean())
            if hi - lo < 20:
                continue  # no clear dark-to-light edge here
            mid = (lo + hi) / 2
            j = np.nonzero((row[:-1] < mid) & (row[1:] >= mid))[0]
            if len(j) != 1:
                continue
            j0 = int(j[0])
            f = (mid - row[j0]) / (row[j0 + 1] - row[j0])
            off = offsets[j0] + f * (offsets[j0 + 1] - offsets[j0])
            found.append(base[k] + off * nrm)
        if len(found) < 4:
            return q
        pts_e = np.array(found)
        m = pts_e.mean(axis=0)
        _, _, vt = np.linalg.svd(pts_e - m)
        lines.append((m, vt[0]))
    out = np.empty_like(q)
    for i in range(4):
        (p1, d1), (p2, d2) = lines[i - 1], lines[i]  # corner i joins edges i-1 and i
        a_mat = np.column_stack([d1, -d2])
        if abs(np.linalg.det(a_mat)) < 1e-6:
            return q
        s_, _ = np.linalg.solve(a_mat, p2 - p1)
        out[i] = p1 + s_ * d1
    if np.abs(out - q).max() > 1.5:
        return q  # the edges disagree with the quad: keep the corner detector's answer
    return out


def _cut_by_edge(q: np.ndarray, w: int, h: int, margin: float) -> bool:
    return bool(
        (q[:, 0] < margin).any()
        or (q[:, 1] < margin).any()
        or (q[:, 0] > w - 1 - margin).any()
        or (q[:, 1] > h - 1 - margin).any()
    )


def _fit_tiny(gray: np.ndarray, box: np.ndarray, cfg: DetectorConfig) -> TagDetection | None:
    """Locate a tiny tag by the model fit from a quiet-zone hole no quad read, then read it."""
    assert cfg.fit is not None
    start, _ = order_corners(box, cfg.vertical_tol_deg)
    got = fit_tiny_tag(gray, start, cfg.n, cfg.border_ratio, cfg.fit)
    if got is None:
        return None
    corners, placement = order_corners(got.corners, cfg.vertical_tol_deg)
    sides = np.linalg.norm(corners - np.roll(corners, 1, axis=0), axis=1)
    if (
        max(
            abs(sides[0] - sides[2]) / (sides[0] + sides[2]),
            abs(sides[1] - sides[3]) / (sides[1] + sides[3]),
        )
        > cfg.tiny_parallel_tol / 2
    ):
        return None  # a tag this small is seen without perspective: opposite sides are equal
    # the fit itself matched the quiet zone, the border and the cells (residual-gated)
    dec = _decode(gray, corners, cfg, check_sides=False)
    if dec is None:
        return None
    return TagDetection(dec[0], placement, corners, dec[1])


def detect_tags(gray: np.ndarray, cfg: DetectorConfig | None = None) -> list[TagDetection]:
    """All decodable tags of a grayscale image (corners in the image's own, distorted pixels)."""
    cfg = cfg or DetectorConfig()
    if gray.ndim != 2:
        gray = cv2.cvtColor(gray, cv2.COLOR_BGR2GRAY)
    quads = _border_quads(gray, cfg)
    hole_quads, fit_starts = _quiet_zone_quads(gray, cfg)
    quads.extend((area, quad, False) for area, quad in hole_quads)
    quads.sort(key=lambda aq: -aq[0])  # outer borders first: a tag's inner outline is a dup
    out: list[TagDetection] = []
    for _, quad, refine in quads:
        det = _read_quad(gray, quad, refine, out, cfg)
        if det is not None:
            out.append(det)
    if cfg.fit is not None:
        out.extend(_fit_far_tags(gray, fit_starts, out, cfg))
    return out


def _border_quads(gray: np.ndarray, cfg: DetectorConfig) -> list[tuple[float, np.ndarray, bool]]:
    """Convex quadrilateral contours of the thresholded image: candidate tag borders (area,
    quad, refine corners)."""
    min_area = cfg.min_side_px**2
    quads: list[tuple[float, np.ndarray, bool]] = []
    # two window sizes, as ArUco does: a small one separates tiny far tags from the background,
    # a large one keeps the thick border of near tags in one piece
    for block, c in ((cfg.block_size, cfg.threshold_c), (cfg.large_block_size, 7.0)):
        binary = cv2.adaptiveThreshold(
            gray, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY_INV, block, c
        )
        contours, _ = cv2.findContours(binary, cv2.RETR_LIST, cv2.CHAIN_APPROX_SIMPLE)
        for cnt in contours:
            if len(cnt) < 4:
                continue
            _, _, bw, bh = cv2.boundingRect(cnt)
            if bw < cfg.min_side_px or bh < cfg.min_side_px:
                continue
            area = cv2.contourArea(cnt)
            if area < min_area:
                continue
            peri = cv2.arcLength(cnt, True)
            quad = cv2.approxPolyDP(cnt, 0.06 * peri, True)
            if len(quad) == 4 and cv2.isContourConvex(quad):
                quads.append((area, quad, True))
    return quads


def _read_quad(
    gray: np.ndarray,
    quad: np.ndarray,
    refine: bool,
    found: list[TagDetection],
    cfg: DetectorConfig,
) -> TagDetection | None:
    """A tag read from one candidate quad (sub-pixel corners unless it is a tiny hole), or None:
    too small, cut by the border, a duplicate of one ``found``, or not decodable."""
    h, w = gray.shape
    q = quad.reshape(4, 2).astype(np.float32)
    sides = np.linalg.norm(q - np.roll(q, 1, axis=0), axis=1)
    if sides.min() < cfg.min_side_px:
        return None
    if _cut_by_edge(q, w, h, cfg.edge_margin_px):
        return None  # cut by the image border: corners would be wrong
    # keep the window inside the black border: the code cells' edges would pull the corner
    border_px = sides.min() / (cfg.border_ratio + 2)
    win = int(np.clip(border_px * 0.6, 2, 5))
    ctr0 = q.mean(axis=0)
    if any(np.linalg.norm(d.center - ctr0) < max(3.0, sides.min() / 2) for d in found):
        return None  # the same tag found again (inner outline, or the other threshold)
    refined: np.ndarray
    if not refine:
        refined = q  # a quiet-zone hole of a few pixels: no corner for sub-pixel refinement
    else:
        refined = cv2.cornerSubPix(
            gray,
            q.reshape(-1, 1, 2).copy(),
            (win, win),
            (-1, -1),
            (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 20, 0.01),
        )
    corners, placement = order_corners(refined.reshape(4, 2), cfg.vertical_tol_deg)
    if not _parallel_enough(corners, cfg):
        return None
    dec = _decode(gray, corners, cfg)
    if dec is None:
        return None
    code, contrast = dec
    if refine and border_px >= 3.0:
        # only quads that read as tags (most candidates are not), with a border wide enough to
        # hold an edge profile (below 3 px the code cells and the blur reach the crossing and
        # the edges are worse than cornerSubPix: measured on rendered tags at 3-4 m)
        corners = refine_edges(gray, corners, border_px)
    return TagDetection(code, placement, corners, contrast)


def _fit_far_tags(
    gray: np.ndarray, fit_starts: list[np.ndarray], found: list[TagDetection], cfg: DetectorConfig
) -> list[TagDetection]:
    """Far, tiny tags located by the blurred-model fit from quiet-zone holes no quad read."""
    h, w = gray.shape
    out: list[TagDetection] = []
    tried: list[np.ndarray] = []
    for box in fit_starts:
        ctr0 = box.mean(axis=0)
        side = float(np.linalg.norm(box[1] - box[0]))
        if any(np.linalg.norm(d.center - ctr0) < max(3.0, side) for d in [*found, *out]):
            continue  # inside a tag already read (a white cell's hole) or the tag itself
        if any(np.linalg.norm(c - ctr0) < 1.5 for c in tried):
            continue  # the same hole at another size: the fit already failed there
        tried.append(ctr0)
        if _cut_by_edge(box, w, h, cfg.edge_margin_px):
            continue
        det = _fit_tiny(gray, box, cfg)
        if det is not None:
            out.append(det)
    return out
