"""``trackctl process`` and ``trackctl report``."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.table import Table

from trackctl.cli.common import (
    AllowUnmeasuredOption,
    JsonOption,
    QuietOption,
    VerboseOption,
    apply_fail_if,
    check_fail_if,
    console,
    print_json,
    progress,
    report_dict,
    split_csv,
)
from trackctl.errors import InputError
from trackctl.logs.messages import MetricReport
from trackctl.logs.output import check_output, write_text_atomic
from trackctl.logs.reader import LogReader
from trackctl.metrics.catalog import catalog
from trackctl.metrics.report import jsonable_metrics, read_reports
from trackctl.processing import Processor, get_processor, processors, run_processors


def _cell(value: object) -> str:
    if value is None:
        return "-"
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def print_reports(
    reports: Sequence[MetricReport], *, verbose: bool = False, out: Path | None = None
) -> None:
    """Reports on stdout for a person: per report its headline figures (every figure with
    ``verbose``), which figures were not measured and why, and the file written."""
    screen = console()
    for rep in reports:
        cat = catalog(rep.processor)
        keys = list(rep.metrics)
        if cat is not None and cat.headline and not verbose:
            keys = [k for k in cat.headline if k in rep.metrics]
        table = Table(title=f"{rep.processor}", show_edge=False, title_justify="left")
        table.add_column("metric")
        table.add_column("value", justify="right")
        for key in keys:
            table.add_row(escape(key), escape(_cell(rep.metrics[key])))
        screen.print(table)
        by_reason: dict[str, list[str]] = {}
        for key, why in rep.unmeasured.items():
            if verbose or key in keys:
                by_reason.setdefault(why, []).append(key)
        for why, names in by_reason.items():
            screen.print(f"not measured ({escape(why)}): {escape(', '.join(names))}")
        hidden = len(rep.metrics) - len(keys)
        if hidden:
            screen.print(f"{hidden} more figures: --verbose (or --json)")
    if out is not None:
        screen.print(f"wrote {escape(str(out))}")


def _dead_reckoning(
    source: list[str] | None, reference: str | None, align: bool, origin: bool, twist: bool
) -> Processor | None:
    """The dead-reckoning processor its options configure (None: no option given)."""
    if not (source or reference or align or origin or twist):
        return None
    if align and origin:
        raise InputError("--align and --align-origin exclude each other: give one")
    from trackctl.processing.dead_reckoning import DeadReckoningConfig, DeadReckoningProcessor

    config = DeadReckoningConfig(
        sources=tuple(split_csv(source) or ()),
        reference=reference,
        align="se3" if align else "origin",
        use_pose=not twist,
    )
    return DeadReckoningProcessor(config)


def _chain(names: list[str], reckoning: Processor | None) -> list[Processor]:
    """The processors ``names`` name, with dead reckoning as its options configure it."""
    if reckoning is not None and "dead-reckoning" not in names:
        raise InputError(
            "--source/--reference/--align/--align-origin/--twist are dead-reckoning options: "
            "add --with dead-reckoning"
        )
    return [
        reckoning if name == "dead-reckoning" and reckoning else get_processor(name).factory()
        for name in names
    ]


def process(
    log: Annotated[Path | None, typer.Argument(help="Input MCAP log.")] = None,
    with_: Annotated[
        list[str] | None,
        typer.Option("--with", help="Processor(s) to run in order (repeat or comma-separate)."),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(help="Output MCAP: input + derived channels (omit: report only)."),
    ] = None,
    outputs_only: Annotated[
        bool,
        typer.Option("--outputs-only", help="Write only the derived channels, not the input."),
    ] = False,
    list_: Annotated[bool, typer.Option("--list", help="List registered processors.")] = False,
    json_out: JsonOption = False,
    fail_if: Annotated[
        str | None,
        typer.Option(help='Exit 1 when a metric crosses a threshold, e.g. "nonfinite_values>0".'),
    ] = None,
    allow_unmeasured: AllowUnmeasuredOption = False,
    verbose: VerboseOption = False,
    quiet: QuietOption = False,
    source: Annotated[
        list[str] | None,
        typer.Option(
            metavar="TOPIC",
            help="dead-reckoning: the odometry source(s) to integrate (trackctl or ROS topic, "
            "or SOURCE); default: all.",
        ),
    ] = None,
    reference: Annotated[
        str | None,
        typer.Option(
            metavar="TOPIC",
            help="dead-reckoning: the reference for APE/RPE (a /robot/NAME/reference/* topic, "
            "its last segment, its ROS topic, or ground_truth); default: the ground truth, "
            "else the robot's other references.",
        ),
    ] = None,
    align: Annotated[
        bool,
        typer.Option(
            "--align", help="dead-reckoning: align to the reference by SE(3) Umeyama (evo -a)."
        ),
    ] = False,
    align_origin: Annotated[
        bool,
        typer.Option(
            "--align-origin",
            help="dead-reckoning: align the first poses (evo --align_origin; the default).",
        ),
    ] = False,
    twist: Annotated[
        bool,
        typer.Option(
            "--twist", help="dead-reckoning: integrate the twist even where a pose is given."
        ),
    ] = False,
) -> None:
    """Run registered processors over a log; the output holds the input plus their results.

    Example: trackctl process run.mcap --with check,dead-reckoning --out checked.mcap
    """
    if list_:
        entries = processors()
        if json_out:
            print_json(
                {"processors": [{"name": p.name, "description": p.description} for p in entries]}
            )
        else:
            for p in entries:
                typer.echo(f"{p.name:14s} {p.description}")
        return
    names = split_csv(with_)
    if log is None or not names:
        raise InputError("process needs LOG and --with NAME (or --list to see processors)")
    chain = _chain(names, _dead_reckoning(source, reference, align, align_origin, twist))
    check_fail_if(fail_if, [p.name for p in chain])  # a typo fails before the run, not after
    if out is not None:
        check_output(out, [log])
    with progress("processing", quiet) as bar:
        reports = run_processors(log, out, chain, bar, outputs_only=outputs_only)
    if json_out:
        print_json(
            {"out": None if out is None else str(out), "reports": [report_dict(r) for r in reports]}
        )
    else:
        print_reports(reports, verbose=verbose, out=out)
    apply_fail_if(fail_if, reports, allow_unmeasured)


def report(
    log: Annotated[Path, typer.Argument(help="MCAP log written by a processor.")],
    json_out: JsonOption = False,
    csv: Annotated[Path | None, typer.Option(help="Also write the reports as CSV.")] = None,
    fail_if: Annotated[
        str | None,
        typer.Option(help='Exit 1 when a metric crosses a threshold, e.g. "error_m_mean>0.5".'),
    ] = None,
    allow_unmeasured: AllowUnmeasuredOption = False,
    verbose: VerboseOption = False,
) -> None:
    """Print the metric reports stored in a log.

    Example: trackctl report tracked.mcap --fail-if "idf1<0.9" --csv report.csv
    """
    if csv is not None:
        check_output(csv, [log])
    reports = read_reports(LogReader(log))
    if not reports:
        raise InputError(
            f"{log}: holds no metric report (no /metrics/* topic or metadata); "
            "run a processor on it first"
        )
    if csv is not None:
        import pandas as pd  # only for --csv

        rows = [{"processor": r.processor, "t_ns": r.t_ns, **dict(r.metrics)} for r in reports]
        # object columns: an integer stays 1242, not 1242.0 beside a report without it
        write_text_atomic(csv, pd.DataFrame(rows, dtype=object).to_csv(index=False), [log])
    if json_out:
        print_json({"reports": [report_dict(r) for r in reports]})
    else:
        print_reports(reports, verbose=verbose)
    apply_fail_if(fail_if, reports, allow_unmeasured)


def figures_from_output(
    out: Path | None, folder: Path | None, module: str
) -> Callable[[], object] | None:
    """The ``--plot FOLDER`` callback of a system whose figures are drawn from its output log
    (``trackctl.plots.<module>.plot_run(out, folder)``); matplotlib is checked before the run.

    Raises:
        InputError: ``--plot`` without ``--out``, or matplotlib is missing.
    """
    if folder is None:
        return None
    if out is None:
        raise InputError("--plot draws from the output log: give --out too")
    import importlib

    from trackctl.plots import pyplot

    pyplot()  # fail before the run when matplotlib is missing
    plot_run = importlib.import_module(f"trackctl.plots.{module}").plot_run
    return lambda: plot_run(out, folder)


def run_system(
    name: str,
    log: Path,
    out: Path | None,
    processor: Processor,
    *,
    json_out: bool,
    fail_if: str | None,
    quiet: bool,
    plot: Callable[[], object] | None = None,
    outputs_only: bool = False,
    allow_unmeasured: bool = False,
    verbose: bool = False,
    inputs: Sequence[Path | None] = (),
) -> MetricReport:
    """What every system command does with its processor: run it over ``log`` into ``out``
    (progress bar on a TTY, atomic output; no ``out``: report only), draw its figures, print the
    report (its headline, or one JSON object of the metrics and ``unmeasured`` with ``--json``),
    then apply ``--fail-if`` (exit 1; exit 2 on a metric that was not measured). ``inputs``:
    the other files the command reads (the output may be none of them)."""
    check_fail_if(fail_if, [processor.name])
    if out is not None:
        check_output(out, [log, *inputs])
    with progress(name, quiet) as bar:
        (report,) = run_processors(
            log, out, [processor], bar, outputs_only=outputs_only, inputs=inputs
        )
    if plot is not None:
        plot()
    if json_out:
        print_json({**jsonable_metrics(report.metrics), "unmeasured": dict(report.unmeasured)})
    else:
        print_reports([report], verbose=verbose, out=out)
    apply_fail_if(fail_if, [report], allow_unmeasured)
    return report
