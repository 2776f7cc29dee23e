"""BridgeLoc visual tags (dissertation §4.2.3 B): codec, enumeration of unique tag sets, textures.

A tag is an N x N grid of black/white code cells inside a black border; the ratio of the code
area's width to the border width is ``b`` (5 by default). A code is a tuple of N*N bits in
row-major order as printed (row 0 at the top), ``1`` = black.

Two notions of uniqueness:

* **universal** — the tag may be seen under any 90° rotation (constraints 1 and 2 of §4.2.3):
  a code must differ from its own rotations, and the set holds one code per rotation class.
* **practical** — the robot cannot roll and a wall tag cannot be mirrored, so every code is read
  in its printed orientation; all-white and all-black codes are dropped (false positives); a tag
  mounted above or below the robot camera's height, and mounted square or rotated by 45°, is a
  different symbol.

Counts come from enumeration (:func:`enumerate_universal`, :func:`enumerate_practical`) and are
compared with the closed forms of Theorem 5 and Theorem 6 (:func:`theorem5`, :func:`theorem6`).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

__all__ = [
    "BORDER_RATIO",
    "FAMILIES",
    "check_family",
    "in_family",
    "parity_ok",
    "MAX_ENUMERATION_N",
    "Mount",
    "Placement",
    "PracticalTag",
    "code_from_int",
    "count_practical",
    "count_universal",
    "code_to_int",
    "canonical",
    "enumerate_practical",
    "enumerate_universal",
    "rotate",
    "rotations",
    "tag_geometry",
    "tag_texture",
    "theorem5",
    "theorem6",
]

BORDER_RATIO = 5.0
"""b: width of the code area / width of the black border (the paper's default)."""

MAX_ENUMERATION_N = 4
"""Enumeration is exhaustive over 2^(N^2) codes; N = 5 would be 33 M codes (use the theorems)."""

Code = tuple[int, ...]


def _check_code(code: Sequence[int], n: int) -> None:
    if n < 1:
        raise ValueError(f"tag size N must be >= 1, got {n}")
    if len(code) != n * n:
        raise ValueError(f"a {n}x{n} tag code needs {n * n} bits, got {len(code)}")
    if any(b not in (0, 1) for b in code):
        raise ValueError(f"tag code bits must be 0 or 1, got {tuple(code)}")


def code_to_int(code: Sequence[int]) -> int:
    """The code as an integer, first cell = most significant bit."""
    v = 0
    for b in code:
        v = (v << 1) | int(b)
    return v


def code_from_int(value: int, n: int) -> Code:
    """Inverse of :func:`code_to_int` for an N x N code."""
    if not 0 <= value < 1 << (n * n):
        raise ValueError(f"code value {value} out of range for N={n}")
    return tuple((value >> (n * n - 1 - i)) & 1 for i in range(n * n))


def rotate(code: Sequence[int], n: int, quarter_turns: int = 1) -> Code:
    """The code as it appears after rotating the printed tag clockwise by 90° x quarter_turns."""
    _check_code(code, n)
    grid = np.asarray(code, dtype=np.uint8).reshape(n, n)
    # np.rot90 turns counter-clockwise for positive k
    return tuple(int(b) for b in np.rot90(grid, -quarter_turns).ravel())


def rotations(code: Sequence[int], n: int) -> list[Code]:
    """The four views of a code under 0°, 90°, 180°, 270° clockwise rotations."""
    return [rotate(code, n, k) for k in range(4)]


def canonical(code: Sequence[int], n: int) -> Code:
    """The rotation-class representative: the rotation with the smallest integer value."""
    return min(rotations(code, n), key=code_to_int)


def _all_codes(n: int) -> np.ndarray:
    if n > MAX_ENUMERATION_N:
        raise ValueError(
            f"enumeration is exhaustive over 2^(N^2) codes and limited to N <= "
            f"{MAX_ENUMERATION_N}; got N={n} (use theorem5/theorem6 for the closed forms)"
        )
    values = np.arange(1 << (n * n), dtype=np.int64)
    shifts = np.arange(n * n - 1, -1, -1, dtype=np.int64)
    return ((values[:, None] >> shifts[None, :]) & 1).astype(np.uint8).reshape(-1, n, n)


def _to_int(grids: np.ndarray) -> np.ndarray:
    n2 = grids.shape[1] * grids.shape[2]
    weights = (1 << np.arange(n2 - 1, -1, -1, dtype=np.int64)).astype(np.int64)
    return grids.reshape(len(grids), n2).astype(np.int64) @ weights


def enumerate_universal(n: int) -> list[Code]:
    """Universally unique codes: one representative per rotation class with 4 distinct views.

    Enumerates all 2^(N^2) codes (vectorised), drops those equal to one of their own rotations
    (constraint 1) and keeps the canonical member of each rotation class (constraint 2).
    """
    grids = _all_codes(n)
    views = np.stack([_to_int(np.rot90(grids, -k, axes=(1, 2))) for k in range(4)], axis=1)
    distinct = (
        (views[:, 0] != views[:, 1]) & (views[:, 0] != views[:, 2]) & (views[:, 0] != views[:, 3])
    )
    is_canon = views[:, 0] == views.min(axis=1)
    return [code_from_int(int(v), n) for v in views[distinct & is_canon, 0]]


class Placement(StrEnum):
    """How a tag is mounted: square (edges vertical/horizontal) or rotated by 45° (a diamond)."""

    SQUARE = "square"
    DIAMOND = "diamond"


class Mount(StrEnum):
    """Tag centre above or below the robot camera's height."""

    ABOVE = "above"
    BELOW = "below"


@dataclass(frozen=True, slots=True)
class PracticalTag:
    """A practically unique symbol: a code read upright + how and where it is mounted."""

    n: int
    code: Code
    placement: Placement = Placement.SQUARE
    mount: Mount = Mount.ABOVE

    def __post_init__(self) -> None:
        _check_code(self.code, self.n)

    @property
    def label(self) -> str:
        """Short printable name, e.g. ``2:0110/D/above``."""
        bits = "".join(map(str, self.code))
        return f"{self.n}:{bits}/{'D' if self.placement is Placement.DIAMOND else 'S'}/{self.mount}"

    @property
    def pattern_id(self) -> str:
        """What a camera reads from the image alone (code + placement), without the height."""
        return f"{self.n}:{''.join(map(str, self.code))}/{self.placement.value}"


def observed_signatures(code: Sequence[int], n: int, placement: Placement) -> set[Code]:
    """Codes an upright (roll-free) camera can read from this tag under the practical rules.

    No roll and no mirror: a square tag is read exactly as printed; a diamond is read by turning it
    back by 45°, which is unambiguous because the camera knows which way is up.
    """
    _check_code(code, n)
    return {tuple(code)}


def enumerate_practical(n: int) -> list[PracticalTag]:
    """Practically unique tags: every non-uniform code x {square, diamond} x {above, below}.

    A tag is kept only if its observable signature (code read upright, placement, mount) differs
    from every other kept tag's; uniform codes (all white, all black) are dropped.
    """
    grids = _all_codes(n)
    values = _to_int(grids)
    full = (1 << (n * n)) - 1
    out: list[PracticalTag] = []
    seen: set[tuple[Code, Placement, Mount]] = set()
    for v in values:
        if v in (0, full):
            continue
        code = code_from_int(int(v), n)
        for placement in Placement:
            for mount in Mount:
                sigs = observed_signatures(code, n, placement)
                keys = {(s, placement, mount) for s in sigs}
                if keys & seen:
                    continue
                seen |= keys
                out.append(PracticalTag(n, code, placement, mount))
    return out


def count_practical(n: int) -> int:
    """Size of :func:`enumerate_practical` without building the tag objects (vectorised).

    Keys (code read upright, placement, mount) of every non-uniform code are deduplicated with
    ``np.unique``; this is the same rule as :func:`enumerate_practical`, fast enough for N = 4.
    """
    values = _to_int(_all_codes(n))
    full = (1 << (n * n)) - 1
    values = values[(values != 0) & (values != full)]
    keys = [
        values * 4 + 2 * p + m for p in range(len(Placement)) for m in range(len(Mount))
    ]  # the upright reading of a code is the code itself (see observed_signatures)
    return int(len(np.unique(np.concatenate(keys)))) if len(values) else 0


def count_universal(n: int) -> int:
    """Size of :func:`enumerate_universal`."""
    return len(enumerate_universal(n))


def theorem5(n: int) -> int:
    """Theorem 5: 2^(N^2 - 2) - 2^(floor((N^2 + 1) / 2) - 2) universally unique tags."""
    return (2 ** (n * n) - 2 ** ((n * n + 1) // 2)) // 4


def theorem6(n: int) -> int:
    """Theorem 6: 2^(N^2 + 2) - 8 practically unique tags."""
    return 2 ** (n * n + 2) - 8


@dataclass(frozen=True, slots=True)
class TagGeometry:
    """Sizes of a tag's parts as fractions of its outer (black border) side."""

    n: int
    border_ratio: float

    @property
    def border(self) -> float:
        """Border width / outer side."""
        return 1.0 / (self.border_ratio + 2.0)

    @property
    def cell(self) -> float:
        """Code cell side / outer side."""
        return self.border_ratio / (self.border_ratio + 2.0) / self.n


def tag_geometry(n: int, border_ratio: float = BORDER_RATIO) -> TagGeometry:
    """Geometry of an N x N tag with ratio b (code area width = b x border width)."""
    if border_ratio <= 0:
        raise ValueError(f"border ratio b must be positive, got {border_ratio}")
    return TagGeometry(n, border_ratio)


def tag_texture(
    code: Sequence[int],
    n: int,
    side_px: int,
    border_ratio: float = BORDER_RATIO,
    margin: float = 0.25,
    white: int = 255,
    black: int = 0,
) -> np.ndarray:
    """Grayscale image of a tag: the black-bordered square (``side_px``) inside a white margin.

    ``margin`` is the quiet zone on each side as a fraction of the outer side (the paper the tag is
    printed on). The returned image has side ``side_px * (1 + 2 * margin)`` (rounded).
    """
    _check_code(code, n)
    geo = tag_geometry(n, border_ratio)
    pad = int(round(side_px * margin))
    img = np.full((side_px + 2 * pad, side_px + 2 * pad), white, np.uint8)
    img[pad : pad + side_px, pad : pad + side_px] = black
    grid = np.asarray(code).reshape(n, n)
    b = geo.border * side_px
    c = geo.cell * side_px
    for r in range(n):
        for q in range(n):
            if grid[r, q] == 0:
                y0, x0 = pad + b + r * c, pad + b + q * c
                img[int(round(y0)) : int(round(y0 + c)), int(round(x0)) : int(round(x0 + c))] = (
                    white
                )
    return img


FAMILIES = ("plain", "parity")
"""``plain``: every code (no error detection); ``parity``: N >= 3 codes whose last two cells
are check bits (:func:`parity_ok`)."""


def parity_ok(code: Sequence[int], n: int) -> bool:
    """The ``parity`` family's check: with d the first N^2 - 2 cells (row-major, as printed), the
    second-to-last cell is the XOR of d's even positions and the last the XOR of its odd ones.
    Any single misread cell, and any two misread neighbours in reading order, break it."""
    bits = [int(b) for b in code]
    if n < 3 or len(bits) != n * n:
        return False
    data = bits[:-2]
    return bits[-2] == sum(data[0::2]) % 2 and bits[-1] == sum(data[1::2]) % 2


def check_family(family: str, n: int) -> None:
    """Raise InputError for an unknown family or a parity family with N < 3."""
    from trackctl.errors import InputError

    if family not in FAMILIES:
        raise InputError(f"tag family {family!r}: expected one of {', '.join(FAMILIES)}")
    if family == "parity" and n < 3:
        raise InputError(f"tag family parity needs N >= 3 (two check cells), got N={n}")


def in_family(code: Sequence[int], n: int, family: str) -> bool:
    return family == "plain" or parity_ok(code, n)


def iter_sheet_tags(
    n: int, practical: bool, family: str = "plain"
) -> Iterator[tuple[str, Code, Placement]]:
    """(label, code, placement) of every tag of a printable sheet (mount is how it is hung)."""
    if practical:
        for tag in enumerate_practical(n):
            if tag.mount is Mount.ABOVE and in_family(tag.code, n, family):
                yield tag.pattern_id, tag.code, tag.placement  # one print serves both heights
    else:
        for code in enumerate_universal(n):
            if in_family(code, n, family):
                yield f"{n}:{''.join(map(str, code))}", code, Placement.SQUARE
