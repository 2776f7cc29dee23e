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


def sheet_pdf(
    tags: Sequence[SheetTag], n: int, path: Path, size_cm: float, border_ratio: float = BORDER_RATIO
) -> None:
    """One tag per page, the black square exactly ``size_cm`` wide when printed at 100%."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.backends.backend_pdf import PdfPages
    except ImportError as err:
        raise InputError("--out *.pdf needs matplotlib: pip install 'trackctl[plot]'") from err
    side_in = size_cm / 2.54
    with PdfPages(path) as pdf:
        for label, code, placement in tags:
            tex = _texture(code, n, 400, placement, border_ratio)
            extent_in = side_in * tex.shape[0] / 400
            page = extent_in + 1.0
            fig = plt.figure(figsize=(page, page + 0.4))
            ax = fig.add_axes(
                (0.5 / page, 0.9 / (page + 0.4), extent_in / page, extent_in / (page + 0.4))
            )
            ax.imshow(tex, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
            ax.set_axis_off()
            fig.text(
                0.5,
                0.3 / (page + 0.4),
                f"{label}   black square {size_cm:g} cm",
                ha="center",
                fontsize=10,
            )
            pdf.savefig(fig)
            plt.close(fig)


def write_sheet(
    tags: Sequence[SheetTag],
    n: int,
    path: Path,
    size_cm: float = 30.0,
    border_ratio: float = BORDER_RATIO,
) -> None:
    """Write a sheet; the format follows the suffix (``.png`` or ``.pdf``)."""
    if not tags:
        raise InputError(f"no tags to print for N={n}")
    suffix = path.suffix.lower()
    if suffix == ".png":
        sheet_png(tags, n, path, border_ratio=border_ratio)
    elif suffix == ".pdf":
        sheet_pdf(tags, n, path, size_cm, border_ratio)
    else:
        raise InputError(f"--out {path}: expected a .png or .pdf file")
