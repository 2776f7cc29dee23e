"""Printable tag sheets: PNG (OpenCV) and PDF at true printed size (matplotlib, ``plot`` extra)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from trackctl.bridgeloc.tags import BORDER_RATIO, Code, Placement, tag_texture
from trackctl.errors import InputError

__all__ = ["write_sheet"]

SheetTag = tuple[str, Code, Placement]


def _diamond(img: np.ndarray) -> np.ndarray:
    """The tag image turned 45° clockwise on a white page (how a diamond tag is hung)."""
    h, w = img.shape
    side = int(math.ceil(math.hypot(h, w)))
    rot = cv2.getRotationMatrix2D((w / 2, h / 2), -45.0, 1.0)
    rot[:, 2] += (side - w) / 2, (side - h) / 2
    return cv2.warpAffine(img, rot, (side, side), flags=cv2.INTER_NEAREST, borderValue=255)


def _texture(code: Code, n: int, side_px: int, placement: Placement, b: float) -> np.ndarray:
    img = tag_texture(code, n, side_px, b, margin=0.1)
    return _diamond(img) if placement is Placement.DIAMOND else img


def sheet_png(
    tags: Sequence[SheetTag],
    n: int,
    path: Path,
    side_px: int = 160,
    border_ratio: float = BORDER_RATIO,
) -> None:
    """A grid of tags with labels under each (for screens and quick prints)."""
    tiles = []
    cell = int(side_px * 1.5) + 24
    for label, code, placement in tags:
        tex = _texture(code, n, side_px, placement, border_ratio)
        tile = np.full((cell, cell), 255, np.uint8)
        th, tw = tex.shape
        s = min(1.0, (cell - 24) / max(th, tw))
        tex = cv2.resize(tex, (int(tw * s), int(th * s)), interpolation=cv2.INTER_NEAREST)
        y0, x0 = (cell - 24 - tex.shape[0]) // 2, (cell - tex.shape[1]) // 2
        tile[y0 : y0 + tex.shape[0], x0 : x0 + tex.shape[1]] = tex
        cv2.putText(tile, label, (4, cell - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.4, 0, 1, cv2.LINE_AA)
        tiles.append(tile)
    cols = max(1, min(8, len(tiles)))
    rows = max(1, math.ceil(len(tiles) / cols))
    sheet = np.full((rows * cell, cols * cell), 255, np.uint8)
    for i, tile in enumerate(tiles):
        r, c = divmod(i, cols)
        sheet[r * cell : (r + 1) * cell, c * cell : (c + 1) * cell] = tile
    if not cv2.imwrite(str(path), sheet):
        raise InputError(f"{path}: cannot write the PNG sheet")


PAPERS: dict[str, tuple[float, float]] = {
    "a4": (8.27, 11.69),
    "a3": (11.69, 16.54),
    "letter": (8.5, 11.0),
}
"""Page sizes (inches, portrait) for ``--paper``; ``fit`` makes one custom-size page per tag."""
MARGIN_IN = 0.4
"""Unprinted border of office printers (~1 cm)."""
OVERLAP_IN = 0.4
"""Overlap of neighbouring tiles of a tag larger than a page (glue strip, ~1 cm)."""
LABEL_IN = 0.35


def _pyplot():  # noqa: ANN202
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.backends.backend_pdf import PdfPages
    except ImportError as err:
        raise InputError("--out *.pdf needs matplotlib: pip install 'trackctl[plot]'") from err
    return plt, PdfPages


def sheet_pdf(
    tags: Sequence[SheetTag],
    n: int,
    path: Path,
    size_cm: float,
    border_ratio: float = BORDER_RATIO,
    paper: str = "a4",
) -> int:
    """Tags at true size (the black square exactly ``size_cm`` wide when printed at 100 %).

    On ``paper`` (a4, a3, letter): tags that fit a page are packed several to a page with their
    labels; a larger tag is tiled over several pages that overlap by 1 cm, each tile with crop
    marks at the page's printable edge, a dashed line where the next tile is glued on, and its
    place in the grid. ``fit``: one custom-size page per tag. Returns the number of pages.
    """
    plt, pdf_pages = _pyplot()
    side_in = size_cm / 2.54
    textures = [(label, _texture(code, n, 400, pl, border_ratio)) for label, code, pl in tags]
    caption = f"black square {size_cm:g} cm, print at 100 % (no scaling)"
    pages = 0
    with pdf_pages(path) as pdf:
        if paper == "fit":
            for label, tex in textures:
                extent = side_in * tex.shape[0] / 400
                pw = extent + 2 * MARGIN_IN
                fig = plt.figure(figsize=(pw, pw + LABEL_IN))
                _place(fig, tex, (MARGIN_IN, LABEL_IN + MARGIN_IN), extent, (0, extent, 0, extent))
                fig.text(0.5, 0.3 * LABEL_IN / (pw + LABEL_IN), f"{label}   {caption}", ha="center")
                pdf.savefig(fig)
                plt.close(fig)
                pages += 1
            return pages
        if paper not in PAPERS:
            raise InputError(f"--paper {paper}: expected one of {', '.join([*PAPERS, 'fit'])}")
        pw, ph = PAPERS[paper]
        aw, ah = pw - 2 * MARGIN_IN, ph - 2 * MARGIN_IN - LABEL_IN
        small = [(lb, t) for lb, t in textures if side_in * t.shape[0] / 400 <= min(aw, ah)]
        large = [(lb, t) for lb, t in textures if side_in * t.shape[0] / 400 > min(aw, ah)]
        pages += _packed(plt, pdf, small, side_in, (pw, ph), caption)
        for label, tex in large:
            pages += _tiled(plt, pdf, label, tex, side_in, (pw, ph), caption)
    return pages


def _place(fig, tex: np.ndarray, at_in: tuple[float, float], extent: float, window) -> None:  # noqa: ANN001
    """Draw the part ``window`` = (x0, x1, y0, y1) (inches, y down) of a tag ``extent`` inches
    wide, with its lower-left corner at ``at_in`` on the page."""
    x0, x1, y0, y1 = window
    pw, ph = fig.get_size_inches()
    ax = fig.add_axes((at_in[0] / pw, at_in[1] / ph, (x1 - x0) / pw, (y1 - y0) / ph))
    ax.imshow(
        tex, cmap="gray", vmin=0, vmax=255, interpolation="nearest", extent=(0, extent, extent, 0)
    )
    ax.set_xlim(x0, x1)
    ax.set_ylim(y1, y0)
    ax.set_axis_off()


def _packed(plt, pdf, textures, side_in: float, page: tuple[float, float], caption: str) -> int:  # noqa: ANN001
    """Tags smaller than the page, as many per page as fit, each with its label."""
    pw, ph = page
    pages, i = 0, 0
    while i < len(textures):
        fig = plt.figure(figsize=(pw, ph))
        x, y_top, row_h = MARGIN_IN, ph - MARGIN_IN, 0.0
        while i < len(textures):
            label, tex = textures[i]
            extent = side_in * tex.shape[0] / 400
            if x + extent > pw - MARGIN_IN + 1e-9:
                x, y_top, row_h = MARGIN_IN, y_top - row_h - 0.2, 0.0
            if y_top - extent - LABEL_IN < MARGIN_IN - 1e-9:
                break
            _place(fig, tex, (x, y_top - extent), extent, (0, extent, 0, extent))
            fig.text(x / pw, (y_top - extent - 0.22) / ph, label, fontsize=8)
            x += extent + 0.2
            row_h = max(row_h, extent + LABEL_IN)
            i += 1
        fig.text(0.5, 0.15 / ph, caption, ha="center", fontsize=8)
        pdf.savefig(fig)
        plt.close(fig)
        pages += 1
    return pages


def _tiled(plt, pdf, label: str, tex: np.ndarray, side_in: float, page, caption: str) -> int:  # noqa: ANN001
    """A tag larger than the page on rows x cols pages overlapping by OVERLAP_IN."""
    pw, ph = page
    aw, ah = pw - 2 * MARGIN_IN, ph - 2 * MARGIN_IN - LABEL_IN
    extent = side_in * tex.shape[0] / 400
    step_x, step_y = aw - OVERLAP_IN, ah - OVERLAP_IN
    cols = max(1, math.ceil((extent - OVERLAP_IN) / step_x))
    rows = max(1, math.ceil((extent - OVERLAP_IN) / step_y))
    for r in range(rows):
        for c in range(cols):
            x0, y0 = c * step_x, r * step_y
            x1, y1 = min(x0 + aw, extent), min(y0 + ah, extent)
            fig = plt.figure(figsize=(pw, ph))
            left, bottom = MARGIN_IN, ph - MARGIN_IN - (y1 - y0)
            _place(fig, tex, (left, bottom), extent, (x0, x1, y0, y1))
            line = {"color": "0.3", "linewidth": 0.6}
            # crop marks at the corners of the printed area
            for cx, cy in (
                (left, bottom),
                (left + x1 - x0, bottom),
                (left, ph - MARGIN_IN),
                (left + x1 - x0, ph - MARGIN_IN),
            ):
                fig.add_artist(
                    plt.Line2D([(cx - 0.15) / pw, (cx + 0.15) / pw], [cy / ph, cy / ph], **line)
                )
                fig.add_artist(
                    plt.Line2D([cx / pw, cx / pw], [(cy - 0.15) / ph, (cy + 0.15) / ph], **line)
                )
            # where the next tile (right, below) is glued on
            if c + 1 < cols:
                gx = (left + step_x) / pw
                fig.add_artist(
                    plt.Line2D(
                        [gx, gx], [bottom / ph, (ph - MARGIN_IN) / ph], linestyle="--", **line
                    )
                )
            if r + 1 < rows:
                gy = (ph - MARGIN_IN - step_y) / ph
                fig.add_artist(
                    plt.Line2D([left / pw, (left + x1 - x0) / pw], [gy, gy], linestyle="--", **line)
                )
            fig.text(
                0.5,
                0.15 / ph,
                f"{label}: tile row {r + 1}/{rows}, column {c + 1}/{cols}; lay the next tile's "
                f"edge on the dashed line (1 cm overlap); {caption}",
                ha="center",
                fontsize=7,
            )
            pdf.savefig(fig)
            plt.close(fig)
    return rows * cols


def write_sheet(
    tags: Sequence[SheetTag],
    n: int,
    path: Path,
    size_cm: float = 30.0,
    border_ratio: float = BORDER_RATIO,
    paper: str = "a4",
) -> None:
    """Write a sheet; the format follows the suffix (``.png`` or ``.pdf`` on ``paper``)."""
    if not tags:
        raise InputError(f"no tags to print for N={n}")
    suffix = path.suffix.lower()
    if suffix == ".png":
        sheet_png(tags, n, path, border_ratio=border_ratio)
    elif suffix == ".pdf":
        sheet_pdf(tags, n, path, size_cm, border_ratio, paper)
    else:
        raise InputError(f"--out {path}: expected a .png or .pdf file")
