"""``trackctl bridgeloc tags|eval`` and ``trackctl simulate bridgeloc``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from trackctl.cli.common import apply_fail_if, print_json, progress, stderr
from trackctl.cli.process import print_reports
from trackctl.metrics.report import jsonable_metrics

bridgeloc_app = typer.Typer(
    help="BridgeLoc (§4.2): rotation-symmetric tags, view bridging, EKF robot localization.",
    no_args_is_help=True,
)


@bridgeloc_app.command("tags")
def tags(
    n: Annotated[int, typer.Option("--n", help="Code cells per side (N).")] = 2,
    practical: Annotated[
        bool, typer.Option("--practical", help="Practically unique set (no roll, 45°, height).")
    ] = False,
    size_cm: Annotated[float, typer.Option(help="Printed side of the black square, cm.")] = 30.0,
    border_ratio: Annotated[float, typer.Option("--b", help="Code width / border width.")] = 5.0,
    count: Annotated[bool, typer.Option("--count", help="Print the set sizes only.")] = False,
    out: Annotated[Path | None, typer.Option(help="Sheet to write: *.png or *.pdf.")] = None,
    json_out: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
) -> None:
    """Enumerate unique tag sets (checked against Theorems 5 and 6) and print tag sheets."""
    from trackctl.bridgeloc.sheets import write_sheet
    from trackctl.bridgeloc.tags import (
        MAX_ENUMERATION_N,
        count_practical,
        count_universal,
        iter_sheet_tags,
        theorem5,
        theorem6,
    )
    from trackctl.errors import InputError

    if not 1 <= n <= MAX_ENUMERATION_N:
        raise InputError(f"--n {n}: enumeration supports 1..{MAX_ENUMERATION_N}")
    if not count and out is None:
        raise InputError("give --count and/or --out SHEET.png|pdf")
    result: dict[str, object] = {"n": n}
    if count:
        result["universal"] = count_universal(n)
        result["practical"] = count_practical(n)
    if out is not None:
        sheet = list(iter_sheet_tags(n, practical))
        if len(sheet) > 512:
            raise InputError(f"--n {n}: {len(sheet)} tags are too many for one sheet (N <= 3)")
        write_sheet(sheet, n, out, size_cm, border_ratio)
        result_out = {"out": str(out), "printed": len(sheet)}
    if json_out:
        print_json(result)  # the documented object: {"n", "universal", "practical"}
        return
    if count:
        typer.echo(
            f"N={n}: universal {result['universal']} (Theorem 5: {theorem5(n)}), "
            f"practical {result['practical']} (Theorem 6: {theorem6(n)})"
        )
    if out is not None:
        stderr.print(f"wrote {result_out['printed']} tags to {out}")
