"""Tag codec and enumeration of unique tag sets (§4.2.3 B, Theorems 5 and 6)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st
from typer.testing import CliRunner

from tests.conftest import run_cli
from trackctl.bridgeloc.tags import (
    canonical,
    code_from_int,
    code_to_int,
    count_practical,
    count_universal,
    enumerate_practical,
    enumerate_universal,
    rotate,
    rotations,
    tag_geometry,
    tag_texture,
    theorem5,
    theorem6,
)
from trackctl.cli.main import app

codes = st.integers(2, 4).flatmap(
    lambda n: st.tuples(st.just(n), st.lists(st.integers(0, 1), min_size=n * n, max_size=n * n))
)


@given(codes)
def test_four_rotations_are_identity(nc: tuple[int, list[int]]) -> None:
    n, code = nc
    assert rotate(code, n, 4) == tuple(code)
    assert rotate(rotate(code, n, 1), n, 3) == tuple(code)


@given(codes)
def test_int_roundtrip_and_canonical_is_class_invariant(nc: tuple[int, list[int]]) -> None:
    n, code = nc
    assert code_from_int(code_to_int(code), n) == tuple(code)
    assert all(canonical(r, n) == canonical(code, n) for r in rotations(code, n))


def test_rotate_is_clockwise() -> None:
    # top-left black -> after a clockwise quarter turn it is top-right
    assert rotate((1, 0, 0, 0), 2) == (0, 1, 0, 0)


@pytest.mark.parametrize(("n", "universal", "practical"), [(1, 0, 0), (2, 3, 56), (3, 120, 2040)])
def test_counts_match_paper_and_theorems(n: int, universal: int, practical: int) -> None:
    assert count_universal(n) == universal == theorem5(n)
    assert len(enumerate_practical(n)) == count_practical(n) == practical == theorem6(n)


def test_n4_enumeration() -> None:
    assert count_universal(4) == 16320 == theorem5(4)
    assert count_practical(4) == 262136 == theorem6(4)


@pytest.mark.parametrize("n", [2, 3])
def test_universal_set_satisfies_both_constraints(n: int) -> None:
    tags = enumerate_universal(n)
    views = [set(rotations(c, n)) for c in tags]
    assert all(len(v) == 4 for v in views)  # constraint 1: no self-symmetry
    for i in range(len(views)):  # constraint 2: no tag is a rotation of another
        for j in range(i + 1, len(views)):
            assert not views[i] & views[j]


def test_practical_set_has_no_uniform_codes_and_distinct_symbols() -> None:
    tags = enumerate_practical(2)
    assert all(0 < sum(t.code) < 4 for t in tags)
    assert len({t.label for t in tags}) == len(tags)


def test_enumeration_refuses_huge_n() -> None:
    with pytest.raises(ValueError, match="N <= 4"):
        enumerate_universal(5)


def test_texture_layout_b5() -> None:
    geo = tag_geometry(2, 5.0)
    assert geo.border == pytest.approx(1 / 7)
    assert geo.cell * 2 == pytest.approx(5 * geo.border)
    img = tag_texture((1, 0, 0, 1), 2, 140, margin=0.0)
    assert img.shape == (140, 140)
    assert img[5, 70] == 0  # border
    assert img[40, 40] == 0 and img[40, 100] == 255  # row 0: black, white
    assert img[100, 40] == 255 and img[100, 100] == 0


def test_cli_count_json_in_process_and_subprocess() -> None:
    res = CliRunner().invoke(app, ["bridgeloc", "tags", "--n", "2", "--count", "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout) == {"n": 2, "universal": 3, "practical": 56}
    proc = run_cli("bridgeloc", "tags", "--n", "3", "--count", "--json", check=True)
    assert json.loads(proc.stdout) == {"n": 3, "universal": 120, "practical": 2040}


def test_cli_sheets(tmp_path) -> None:
    png = tmp_path / "s.png"
    res = CliRunner().invoke(
        app, ["bridgeloc", "tags", "--n", "2", "--practical", "--out", str(png)]
    )
    assert res.exit_code == 0, res.output
    assert png.stat().st_size > 1000
    pdf = tmp_path / "s.pdf"
    res = CliRunner().invoke(app, ["bridgeloc", "tags", "--n", "2", "--out", str(pdf)])
    assert res.exit_code == 0, res.output
    assert pdf.read_bytes()[:4] == b"%PDF"
    bad = CliRunner().invoke(
        app, ["bridgeloc", "tags", "--n", "2", "--out", str(tmp_path / "s.txt")]
    )
    assert bad.exit_code == 2 and "error:" in bad.output


def _pdf_pages(path: Path) -> tuple[int, set[bytes]]:
    import re

    data = path.read_bytes()
    return len(re.findall(rb"/Type /Page\b", data)), set(re.findall(rb"/MediaBox \[[^\]]*\]", data))


@pytest.mark.parametrize(
    ("paper", "size_cm", "pages", "box"),
    [
        ("a4", 30, 12, b"/MediaBox [ 0 0 595.44 841.68 ]"),  # 3 tags x 2 x 2 tiles
        ("a3", 30, 6, b"/MediaBox [ 0 0 841.68 1190.88 ]"),  # 36 cm tags: 2 x 1 tiles
        ("a4", 8, 2, b"/MediaBox [ 0 0 595.44 841.68 ]"),  # small tags packed, 2 a page
    ],
)
def test_pdf_tiles_onto_office_paper(
    tmp_path: Path, paper: str, size_cm: int, pages: int, box: bytes
) -> None:
    """Tags larger than the page are tiled over A4/A3 pages; small ones share pages."""
    pytest.importorskip("matplotlib")
    pdf = tmp_path / "s.pdf"
    args = ["bridgeloc", "tags", "--n", "2", "--out", str(pdf), "--size-cm", str(size_cm)]
    res = CliRunner().invoke(app, [*args, "--paper", paper])
    assert res.exit_code == 0, res.output
    assert _pdf_pages(pdf) == (pages, {box})


@given(st.integers(0, 2**7 - 1), st.integers(0, 8))
def test_parity_family_catches_every_single_misread_cell(data: int, flip: int) -> None:
    from trackctl.bridgeloc.tags import parity_ok

    d = [(data >> i) & 1 for i in range(7)]
    code = (*d, sum(d[0::2]) % 2, sum(d[1::2]) % 2)
    assert parity_ok(code, 3)
    misread = list(code)
    misread[flip] ^= 1
    assert not parity_ok(misread, 3)


def test_parity_family_needs_three_cells_a_side() -> None:
    from trackctl.bridgeloc.tags import check_family, iter_sheet_tags
    from trackctl.errors import InputError

    with pytest.raises(InputError, match="N >= 3"):
        check_family("parity", 2)
    sheet = list(iter_sheet_tags(3, practical=False, family="parity"))
    assert sheet and len(sheet) < len(list(iter_sheet_tags(3, practical=False)))


def test_parity_tags_read_no_ghosts_in_signage() -> None:
    """The plain N=3 family reads one ghost in the 40 signage images; with check cells, none."""
    from trackctl.bridgeloc.detect import DetectorConfig, detect_tags
    from trackctl.sim.clutter import signage_image

    plain = DetectorConfig(n=3)
    parity = DetectorConfig(n=3, family="parity")
    images = [signage_image(seed) for seed in range(40)]
    assert sum(len(detect_tags(img, parity)) for img in images) == 0
    assert sum(len(detect_tags(img, plain)) for img in images) >= 1
