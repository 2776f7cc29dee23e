"""Shared CLI plumbing: the one error catch point, warnings, JSON output, progress bars."""

from __future__ import annotations

import json
import math
import sys
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from enum import Enum
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from typer.core import TyperGroup

from trackctl.errors import InputError, TrackctlError
from trackctl.logs.messages import MetricReport
from trackctl.logs.reader import LogReader
from trackctl.metrics.report import (
    check_gate_keys,
    failed_conditions,
    jsonable_metrics,
    parse_fail_if,
)

__all__ = [
    "TrackctlGroup",
    "console",
    "stderr",
    "print_json",
    "progress",
    "split_csv",
    "apply_fail_if",
    "check_fail_if",
    "AllowUnmeasuredOption",
    "VerboseOption",
    "check_topics",
    "check_window",
    "report_dict",
    "EXIT_BAD_INPUT",
    "EXIT_GATE",
    "parse_choice",
]

EXIT_BAD_INPUT = 2
EXIT_GATE = 1

PIPE_WIDTH = 1000
"""Line width for output that is not a terminal: tables are never cut at 80 columns there."""


def console(*, err: bool = False, soft_wrap: bool = False) -> Console:
    """A rich console on stdout (or stderr) that never cuts a table: a terminal's own width,
    else :data:`PIPE_WIDTH` (a pipe, a file, a CI log)."""
    probe = Console(stderr=err)
    width = None if probe.is_terminal else PIPE_WIDTH
    return Console(stderr=err, highlight=False, soft_wrap=soft_wrap, width=width)


stderr = console(err=True, soft_wrap=True)


def _show_warning(
    message: Any,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: Any = None,
    line: str | None = None,
) -> None:
    stderr.print(f"[yellow]warning:[/] {escape(str(message))}", markup=True)


class TrackctlGroup(TyperGroup):
    """Root command group: the single place where :class:`TrackctlError` becomes exit code 2."""

    def invoke(self, ctx: Any) -> Any:
        previous = warnings.showwarning
        warnings.showwarning = _show_warning
        try:
            return super().invoke(ctx)
        except TrackctlError as err:
            stderr.print(f"[red]error:[/] {escape(one_line(str(err)))}", markup=True)
            raise typer.Exit(EXIT_BAD_INPUT) from None
        except KeyboardInterrupt:
            stderr.print("interrupted")
            raise typer.Exit(130) from None
        finally:
            warnings.showwarning = previous


def one_line(text: str) -> str:
    """``text`` on one line (error messages quote user input, which may hold newlines)."""
    return " ".join(text.split("\n"))


E = TypeVar("E", bound=Enum)


def parse_choice(enum_cls: type[E], value: str, option: str) -> E:
    """``value`` as a member of ``enum_cls``, or an InputError naming ``option`` and the choices."""
    try:
        return enum_cls(value)
    except ValueError:
        choices = [str(m.value) for m in enum_cls]
        expected = (
            ", ".join(choices[:-1]) + f" or {choices[-1]}" if len(choices) > 1 else choices[0]
        )
        raise InputError(f"{option} {value!r}: expected {expected}") from None


def parse_pose(value: str, option: str) -> tuple[float, float, float]:
    """``X,Y,YAW`` (metres, metres, radians) as three finite floats.

    Raises:
        InputError: not three finite numbers.
    """
    import math

    parts = [p.strip() for p in value.split(",")]
    try:
        nums = tuple(float(p) for p in parts)
    except ValueError:
        nums = ()
    if len(nums) != 3 or not all(math.isfinite(x) for x in nums):
        raise InputError(f"{option} {value!r}: expected X,Y,YAW (m, m, rad), e.g. 1.5,2.0,0.0")
    return nums[0], nums[1], nums[2]


SITE_HELP = (
    "Site YAML (robot geometry, LEDs, tags, IR light, floor plan; docs/site.md), laid over the "
    "log's own records."
)


def load_site_file(path: Path | None) -> dict[str, dict[str, str]]:
    """The metadata records of ``--site FILE`` (empty without one).

    Raises:
        InputError: the file is missing or malformed.
    """
    if path is None:
        return {}
    from trackctl.ingest.site import read_site

    return read_site(path)


def print_json(obj: Any) -> None:
    """Print exactly one JSON object on stdout."""
    sys.stdout.write(json.dumps(obj, separators=(",", ":"), default=str) + "\n")
    sys.stdout.flush()


def show_progress(quiet: bool) -> bool:
    """Progress bars only on an interactive terminal and without --quiet."""
    return not quiet and stderr.is_terminal and sys.stdout.isatty()


@contextmanager
def progress(description: str, quiet: bool) -> Iterator[Callable[[int, int | None], None]]:
    """A ``(done, total)`` callback drawing a rich progress bar on a TTY, or doing nothing."""
    if not show_progress(quiet):
        yield lambda done, total: None
        return
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=stderr,
        transient=True,
    ) as bar:
        task = bar.add_task(description, total=None)

        def update(done: int, total: int | None) -> None:
            bar.update(task, completed=done, total=total)

        yield update


def split_csv(values: Sequence[str] | None) -> list[str] | None:
    """``["a,b", "c"]`` -> ``["a", "b", "c"]``; None stays None."""
    if not values:
        return None
    return [v.strip() for value in values for v in value.split(",") if v.strip()]


def report_dict(report: MetricReport) -> dict[str, Any]:
    """A report as the ``--json`` object of one processor run."""
    return {
        "processor": report.processor,
        "t_ns": report.t_ns,
        "metrics": jsonable_metrics(report.metrics),
        "params": jsonable_metrics(report.params),
        "unmeasured": dict(report.unmeasured),
    }


def check_window(start: float | None, end: float | None) -> None:
    """Raise InputError unless ``--start``/``--end`` are finite, >= 0 and in order."""
    for name, value in (("--start", start), ("--end", end)):
        if value is not None and (not math.isfinite(value) or value < 0):
            raise InputError(f"{name} {value}: expected seconds >= 0 after the log's first message")
    if start is not None and end is not None and end <= start:
        raise InputError(f"--end {end} is not after --start {start}: the window would be empty")


def check_topics(reader: LogReader, wanted: Sequence[str] | None) -> None:
    """Raise InputError naming the first ``--topics`` entry the log does not hold."""
    if not wanted:
        return
    present = reader.topics()
    for topic in wanted:
        if topic not in present:
            raise InputError(
                f"{reader.path}: no topic {topic}; the log has: "
                + (", ".join(sorted(present)) or "no topics")
            )


ALLOW_UNMEASURED_HELP = (
    "Let a --fail-if condition on a metric the run could not measure (null: e.g. no "
    "/ground_truth) pass instead of exiting 2."
)


AllowUnmeasuredOption = Annotated[
    bool, typer.Option("--allow-unmeasured", help=ALLOW_UNMEASURED_HELP)
]
VerboseOption = Annotated[
    bool,
    typer.Option("--verbose", "-v", help="Print every figure of the report, not its headline."),
]


def check_fail_if(expr: str | None, processors: Sequence[str] = ()) -> None:
    """Raise InputError now, before any work, when ``--fail-if`` does not parse or names a
    metric none of ``processors`` reports."""
    if expr:
        check_gate_keys(parse_fail_if(expr), processors)


def apply_fail_if(
    expr: str | None, reports: Sequence[MetricReport], allow_unmeasured: bool = False
) -> None:
    """Exit 1 (after printing why) when any ``--fail-if`` condition holds on the reports.

    Keys are plain metric names (the last report that has it wins) or ``processor.metric``. A
    condition on a null (unmeasured) metric raises an InputError (exit 2) naming the reason,
    unless ``allow_unmeasured``.
    """
    if not expr:
        return
    conditions = parse_fail_if(expr)
    merged: dict[str, Any] = {}
    why: dict[str, str] = {}
    for rep in reports:
        merged.update(rep.metrics)
        merged.update({f"{rep.processor}.{k}": v for k, v in rep.metrics.items()})
        why.update(rep.unmeasured)
        why.update({f"{rep.processor}.{k}": v for k, v in rep.unmeasured.items()})
    failed = failed_conditions(merged, conditions, why, allow_unmeasured=allow_unmeasured)
    if failed:
        stderr.print("[red]fail-if:[/] " + "; ".join(failed), markup=True)
        raise typer.Exit(EXIT_GATE)
