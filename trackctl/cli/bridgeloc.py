"""``trackctl bridgeloc tags|eval`` and ``trackctl simulate bridgeloc``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

import typer

from trackctl.cli.common import (
    AllowUnmeasuredOption,
    JsonOption,
    OutputsOnlyOption,
    PlotOption,
    QuietOption,
    SeedOption,
    SiteOption,
    VerboseOption,
    fail_if_option,
    load_site_file,
    out_option,
    parse_choice,
    print_json,
    print_written,
    stderr,
)
from trackctl.cli.process import figures_from_output, run_system
from trackctl.logs.output import check_output

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
    family: Annotated[
        str,
        typer.Option(help="plain, or parity (N >= 3: two check cells that catch misreads)."),
    ] = "plain",
    paper: Annotated[
        str,
        typer.Option(
            help="PDF page: a4, a3 or letter (tags larger than a page are tiled with crop "
            "marks and a 1 cm glue overlap), or fit (one custom-size page per tag)."
        ),
    ] = "a4",
    json_out: JsonOption = False,
) -> None:
    """Enumerate unique tag sets (checked against Theorems 5 and 6) and print tag sheets.

    Example: trackctl bridgeloc tags --n 3 --family parity --out tags.pdf
    """
    from trackctl.bridgeloc.sheets import write_sheet
    from trackctl.bridgeloc.tags import (
        MAX_ENUMERATION_N,
        check_family,
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
        check_output(out)
        check_family(family, n)
        sheet = list(iter_sheet_tags(n, practical, family))
        if len(sheet) > 512:
            raise InputError(f"--n {n}: {len(sheet)} tags are too many for one sheet (N <= 3)")
        write_sheet(sheet, n, out, size_cm, border_ratio, paper)
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


@bridgeloc_app.command("eval")
def eval_(
    log: Annotated[Path, typer.Argument(help="MCAP log: camera images + models, wheel odometry.")],
    out: Annotated[Path | None, out_option("input + /bridgeloc/pose + annotations")] = None,
    outputs_only: OutputsOnlyOption = False,
    mode: Annotated[str, typer.Option(help="full (EKF), basic (bridging) or icam.")] = "full",
    pose: Annotated[
        str, typer.Option(help="Robot pose from bridged corners: lstsq (Eq. 4.9) or pnp.")
    ] = "lstsq",
    max_sigma: Annotated[
        float,
        typer.Option(
            help="Full mode: a pose is confident while the EKF position std is below this (m); "
            "a bridged pose must be this good to start the filter or to be a Basic fix."
        ),
    ] = 0.5,
    success_m: Annotated[
        float, typer.Option(help="Scoring: a pose within this distance of the truth is a success.")
    ] = 0.5,
    tag_family: Annotated[
        str | None,
        typer.Option(help="plain or parity; default: the site's or the log's, else plain."),
    ] = None,
    max_range: Annotated[
        float | None,
        typer.Option(
            help="Ignore tags the robot sees farther than this (m); 0 = no limit; "
            "default: the site's max_range_m, else 4.5."
        ),
    ] = None,
    smooth: Annotated[
        bool,
        typer.Option(
            "--smooth/--no-smooth",
            help="Full mode: smooth the EKF over the whole log (RTS, each pose also uses what "
            "came after it); --no-smooth gives the causal filter's poses.",
        ),
    ] = True,
    site: SiteOption = None,
    json_out: JsonOption = False,
    plot: PlotOption = None,
    fail_if: Annotated[str | None, fail_if_option("error_m_mean>0.32")] = None,
    allow_unmeasured: AllowUnmeasuredOption = False,
    verbose: VerboseOption = False,
    quiet: QuietOption = False,
) -> None:
    """BridgeLoc: localize the robot by bridging infrastructure and robot camera views.

    Example: trackctl bridgeloc eval sample_logs/bridgeloc.mcap --out localized.mcap
    """
    from trackctl.bridgeloc import BridgeLocConfig, BridgeLocProcessor, Mode, PoseMethod

    if out is not None:
        check_output(out, [log, site])  # before the site is read
    mode_value = parse_choice(Mode, mode, "--mode")
    pose_value = parse_choice(PoseMethod, pose, "--pose")
    proc = BridgeLocProcessor(
        BridgeLocConfig(
            mode=mode_value,
            pose=pose_value,
            max_sigma_m=max_sigma,
            success_m=success_m,
            max_range_m=None if max_range is None else (max_range if max_range > 0 else math.inf),
            tag_family=tag_family,
            smooth=smooth,
            site=load_site_file(site),
        )
    )
    draw = figures_from_output(out, plot, "bridgeloc")
    run_system(
        "bridgeloc",
        log,
        out,
        proc,
        json_out=json_out,
        fail_if=fail_if,
        quiet=quiet,
        allow_unmeasured=allow_unmeasured,
        verbose=verbose,
        plot=draw,
        outputs_only=outputs_only,
        inputs=[site],
    )


def simulate_bridgeloc(
    out: Annotated[Path, typer.Option(help="MCAP log to write.")],
    field: Annotated[str, typer.Option(help="office (1 camera, 1 tag) or lobby (3, 2-10).")] = (
        "lobby"
    ),
    tags: Annotated[int, typer.Option(help="Tags on the lobby walls.")] = 10,
    path: Annotated[str, typer.Option(help="random, or a CSV of x_m,y_m waypoints.")] = "random",
    duration: Annotated[float, typer.Option(help="Seconds (lobby).")] = 60.0,
    robot_fps: Annotated[float, typer.Option(help="Robot camera frames per second in the log.")] = (
        5.0
    ),
    infra_fps: Annotated[float, typer.Option(help="Infrastructure camera frames per second.")] = (
        5.0
    ),
    seed: SeedOption = 0,
    preset: Annotated[
        str,
        typer.Option(
            help="realistic (posters, lamps, blur, lighting drift, tilt, calibration errors) "
            "or paper (the dissertation's idealised scene)."
        ),
    ] = "realistic",
    n: Annotated[int, typer.Option("--n", help="Code cells per side (N) of the tags.")] = 2,
    family: Annotated[
        str, typer.Option(help="Tag family: plain, or parity (N >= 3, two check cells).")
    ] = "plain",
    patterns: Annotated[
        int,
        typer.Option(
            help="Distinct tag patterns: 0, every tag its own; K, the tags cycle through K "
            "(far apart tags share one, Eq. 4.11)."
        ),
    ] = 0,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """A robot among infrastructure cameras and wall tags, with rendered images (BridgeLoc).

    Example: trackctl simulate bridgeloc --out bridgeloc.mcap --field lobby --tags 6 --duration 10
    """
    from trackctl.sim.bridgeloc import BridgeLocScenario
    from trackctl.sim.bridgeloc import simulate_bridgeloc as simulate

    check_output(out)
    cfg = BridgeLocScenario(
        field=field,
        tags=tags if field == "lobby" else 1,
        path=path,
        seed=seed,
        duration_s=duration,
        robot_fps=robot_fps,
        infra_fps=infra_fps,
        preset=preset,
        n=n,
        family=family,
        patterns=patterns,
    )
    counts = simulate(str(out), cfg)
    print_written(out, counts, json_out=json_out, quiet=quiet)
