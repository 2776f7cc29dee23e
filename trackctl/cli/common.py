"""Shared CLI plumbing: the one error catch point, warnings, JSON output, progress bars."""

from __future__ import annotations

import json
import math
import os
import signal
import sys
import threading
import time
import warnings
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from enum import Enum
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.progress import Progress as RichProgress
from typer.core import TyperGroup

from trackctl.errors import InputError, TrackctlError
from trackctl.logs.messages import MetricReport
from trackctl.logs.output import remove_unfinished
from trackctl.logs.reader import LogReader
from trackctl.metrics.report import (
    check_gate_keys,
    failed_conditions,
    jsonable_metrics,
    parse_fail_if,
)
from trackctl.progress import Progress

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
    "JsonOption",
    "QuietOption",
    "OutputsOnlyOption",
    "PlotOption",
    "SeedOption",
    "SiteOption",
    "out_option",
    "fail_if_option",
    "print_written",
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
        name_metavars(self)
        previous = warnings.showwarning
        warnings.showwarning = _show_warning
        handlers = _stop_on_signals()
        try:
            return super().invoke(ctx)
        except TrackctlError as err:
            stderr.print(f"[red]error:[/] {escape(one_line(str(err)))}", markup=True)
            raise typer.Exit(EXIT_BAD_INPUT) from None
        except KeyboardInterrupt as err:
            # every output is written to OUT.partial and renamed when complete: an interrupted
            # run leaves its inputs and any earlier OUT as they were (a live recording, which
            # keeps what it got, handles the signal itself and ends normally)
            remove_unfinished()  # OUT.partial and stage files an interrupt may have left
            how = f"by {err.args[0]}" if isinstance(err, Stopped) else "(Ctrl-C)"
            stderr.print(f"interrupted {how}: the unfinished output was removed, inputs untouched")
            raise typer.Exit(128 + (err.args[1] if isinstance(err, Stopped) else 2)) from None
        finally:
            warnings.showwarning = previous
            for signum, handler in handlers.items():
                signal.signal(signum, handler)


_METAVARS = {"path": "FILE", "str": "TEXT", "int": "N", "float": "NUMBER"}
_PATH_METAVARS = {"log": "LOG", "plot": "DIR", "out": "FILE", "site": "SITE.yaml"}


def _no_type(ctx: Any) -> None:
    return None


def name_metavars(command: Any) -> None:
    """Give every parameter of ``command`` and its subcommands that has none a metavar that
    reads as a word in ``--help`` (``LOG``, ``FILE``, ``TEXT``, ``N``; Typer's default shows
    Python types: ``<path>``, ``<list[str]>``, ``{log}``)."""
    for param in command.params:
        if param.metavar is not None or getattr(param, "is_flag", False):
            continue
        desc = getattr(param, "type_descriptor", None)
        if desc is None or getattr(desc, "is_choice", False):
            continue
        if param.param_type_name == "argument":
            param.metavar = (param.name or "value").upper()
            param.display_type_rich = _no_type  # "LOG  Input MCAP log.", not "LOG <path> ..."
        elif desc.is_path:
            param.metavar = _PATH_METAVARS.get(param.name or "", "FILE")
        elif desc.is_list:
            param.metavar = "NAME[,NAME]"
        else:
            param.metavar = _METAVARS.get(param.bare_type(), "VALUE")
    for sub in getattr(command, "commands", {}).values():
        name_metavars(sub)


class Stopped(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised where the program is so that it unwinds as on Ctrl-C."""


def _stop_on_signals() -> dict[int, Any]:
    """SIGTERM and SIGHUP (a CI runner or a closed terminal stopping us) end a command as
    Ctrl-C does; returns the handlers to put back (none off the main thread)."""

    def stop(signum: int, frame: Any) -> None:
        raise Stopped(signal.Signals(signum).name, signum)

    previous: dict[int, Any] = {}
    if threading.current_thread() is not threading.main_thread():
        return previous
    for signum in (signal.SIGTERM, signal.SIGHUP):
        previous[signum] = signal.signal(signum, stop)
    return previous


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
    """A progress bar on an interactive terminal (stderr) without --quiet."""
    return not quiet and stderr.is_terminal


HEARTBEAT_S = 10.0
"""Seconds between progress lines when stderr is not a terminal (a CI log, a file);
``TRACKCTL_PROGRESS_S`` overrides it."""


def _heartbeat_s() -> float:
    try:
        value = float(os.environ.get("TRACKCTL_PROGRESS_S", HEARTBEAT_S))
    except ValueError:
        return HEARTBEAT_S
    return value if math.isfinite(value) and value > 0 else HEARTBEAT_S


class _State:
    """The last ``(done, total, stage)`` reported, read by the bar or the heartbeat."""

    def __init__(self, description: str) -> None:
        self.description = description
        self.done: int = 0
        self.total: int | None = None
        self.stage: str | None = "starting"
        self.started = time.monotonic()

    def __call__(self, done: int, total: int | None, stage: str | None = None) -> None:
        self.done, self.total, self.stage = done, total, stage

    def label(self) -> str:
        return f"{self.description}: {self.stage}" if self.stage else self.description

    def line(self) -> str:
        elapsed = int(time.monotonic() - self.started)
        if self.total:
            count = f" {self.done}/{self.total} ({100 * self.done / self.total:.0f} %)"
        else:
            count = f" {self.done}" if self.done else ""
        return f"{self.label()}{count}, {elapsed // 60}:{elapsed % 60:02d} elapsed"


@contextmanager
def progress(description: str, quiet: bool) -> Iterator[Progress]:
    """A progress callback: a rich bar with its total and ETA when stderr is a terminal; else
    one short line on stderr every :data:`HEARTBEAT_S` (stage, done/total, elapsed), also while
    a stage reports nothing; nothing with ``quiet``."""
    state = _State(description)
    if quiet:
        yield state
    elif show_progress(quiet):
        with _bar(state) as update:
            yield update
    else:
        stop = threading.Event()

        def beat() -> None:
            while not stop.wait(_heartbeat_s()):
                stderr.print(escape(state.line()))

        thread = threading.Thread(target=beat, name="trackctl-progress", daemon=True)
        thread.start()
        try:
            yield state
        finally:
            stop.set()
            thread.join()


@contextmanager
def _bar(state: _State) -> Iterator[Progress]:
    with RichProgress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("eta"),
        TimeRemainingColumn(),
        console=stderr,
        transient=True,
    ) as bar:
        task = bar.add_task(state.label(), total=None)

        drawn = [0.0]

        def update(done: int, total: int | None, stage: str | None = None) -> None:
            state(done, total, stage)
            now = time.monotonic()
            if now - drawn[0] >= 0.1:  # rich redraws at its own rate; this bounds the cost
                drawn[0] = now
                bar.update(task, completed=done, total=total, description=escape(state.label()))

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
JsonOption = Annotated[bool, typer.Option("--json", help="Print one JSON object.")]
QuietOption = Annotated[bool, typer.Option("--quiet", "-q", help="No progress output.")]
OutputsOnlyOption = Annotated[
    bool, typer.Option("--outputs-only", help="Write only what the run adds, not the input.")
]
SiteOption = Annotated[Path | None, typer.Option(help=SITE_HELP)]
PlotOption = Annotated[
    Path | None,
    typer.Option(help="Draw the system's figures (PNG) into this folder (needs the plot extra)."),
]
SeedOption = Annotated[
    int, typer.Option(metavar="N", help="Random seed (same seed, same log, byte for byte).")
]


def out_option(adds: str) -> Any:
    """A system's ``--out``: ``out: Annotated[Path | None, out_option("input + ...")] = None``."""
    return typer.Option("--out", help=f"Output MCAP: {adds} (omit: report only).")


def fail_if_option(example: str) -> Any:
    """A system's ``--fail-if`` with an example condition on one of its metrics."""
    return typer.Option(
        "--fail-if", help=f'Exit 1 when a metric crosses a threshold, e.g. "{example}".'
    )


def print_written(out: Path, counts: Mapping[str, int], *, json_out: bool, quiet: bool) -> None:
    """What a simulator wrote: ``{"out", "topics"}`` with --json, else one line on stderr."""
    if json_out:
        print_json({"out": str(out), "topics": counts})
    elif not quiet:
        stderr.print(f"wrote {sum(counts.values())} messages on {len(counts)} topics to {out}")


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
