"""Run processors over a log: copy the input, add each processor's channels and report."""

from __future__ import annotations

import json
import os
import tempfile
import time
import warnings
from collections.abc import Container, Sequence
from dataclasses import replace
from pathlib import Path

from trackctl.errors import OutputError
from trackctl.logs.copy import copy_log
from trackctl.logs.messages import MetricReport, MetricValue
from trackctl.logs.output import (
    check_output,
    forget_unfinished,
    signals_deferred,
    track_unfinished,
)
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.metrics.catalog import WALL_S, catalog
from trackctl.metrics.report import METADATA_PREFIX, jsonable_metrics, report_topic
from trackctl.processing.base import Processor, Progress

__all__ = ["run_processors", "copy_log", "store_report"]


def store_report(writer: LogWriter, report: MetricReport) -> None:
    """Store a report as a ``/metrics/<processor>`` message and ``metrics/<processor>`` metadata."""
    clean = replace(
        report, metrics=jsonable_metrics(report.metrics), params=jsonable_metrics(report.params)
    )
    writer.write(report_topic(report.processor), clean)
    flat = {k: json.dumps(v) for k, v in clean.metrics.items()}
    flat["report"] = json.dumps(clean.to_json())
    writer.add_metadata(METADATA_PREFIX + report.processor, flat)


def _settled(report: MetricReport, reader: LogReader, wall_s: float) -> MetricReport:
    """The report with its processing time, and with every figure the input could not give
    set to null and its reason beside it (unmeasured is null, never 0: metrics/catalog.py)."""
    metrics: dict[str, MetricValue] = dict(report.metrics)
    metrics.setdefault(WALL_S, wall_s)
    unmeasured = dict(report.unmeasured)
    cat = catalog(report.processor)
    if cat is not None:
        metrics, unmeasured = cat.settle(metrics, reader.topics(), unmeasured)
    return replace(report, metrics=metrics, unmeasured=unmeasured)


def _run_one(
    input_path: Path,
    out_path: Path,
    processor: Processor,
    inputs: Sequence[Path],
    progress: Progress | None,
    skip_topics: Container[str] = (),
    skip_metadata: Container[str] = (),
) -> MetricReport:
    reader = LogReader(input_path)
    with LogWriter(out_path, inputs=inputs) as writer:
        copy_log(
            reader,
            writer,
            skip_topics=skip_topics,
            skip_metadata=skip_metadata,
            attachments=not skip_topics,
        )
        started = time.perf_counter()
        report = processor.run(reader, writer, progress)
        report = _settled(report, reader, round(time.perf_counter() - started, 3))
        if reader.warnings:
            params = dict(report.params)
            params["input_warnings"] = len(reader.warnings)
            report = replace(report, params=params)
        store_report(writer, report)
    return report


def run_processors(
    input_path: str | os.PathLike[str],
    out_path: str | os.PathLike[str] | None,
    chain: Sequence[Processor],
    progress: Progress | None = None,
    *,
    outputs_only: bool = False,
    inputs: Sequence[str | os.PathLike[str] | None] = (),
) -> list[MetricReport]:
    """Run ``chain`` in order; each processor sees the input plus what the earlier ones wrote.

    The output is written atomically; intermediate logs live in temporary files beside it.

    Args:
        out_path: the output log, or None to only compute the reports (a CI gate): the derived
            channels then go to a temporary file that is deleted.
        outputs_only: the output holds only what the processors add (their channels, reports
            and metadata), not a copy of the input.
        inputs: other files the run reads (a site file, an EID list): the output may be none
            of them either.

    Raises:
        OutputError: the output rule (:func:`trackctl.logs.output.check_output`) refuses
            ``out_path``, or the chain is empty. Checked before any work.
    """
    if not chain:
        raise OutputError("no processor given; pass --with NAME (see `trackctl process --list`)")
    input_path = Path(input_path)
    if out_path is not None:
        check_output(out_path, [input_path, *inputs])  # before any work
    with warnings.catch_warnings():
        # the processor's own reader warns about a damaged input; say it once, not twice
        warnings.simplefilter("ignore")
        source = LogReader(input_path)  # fail early on a bad input, before creating anything
    if out_path is None:
        del source
        with tempfile.TemporaryDirectory(prefix="trackctl-") as tmp:
            return run_processors(
                input_path, Path(tmp) / "out.mcap", chain, progress, outputs_only=True
            )
    out_path = Path(out_path)
    skip_topics: Container[str] = ()
    skip_metadata: Container[str] = ()
    if outputs_only:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            skip_topics = set(source.topics())
            skip_metadata = set(source.metadata())
    del source  # a big log's summary is large; the processor's reader parses its own
    reports: list[MetricReport] = []
    current = input_path
    temps: list[Path] = []
    try:
        for i, processor in enumerate(chain):
            last = i == len(chain) - 1
            if last:
                target = out_path
            else:
                target = _stage_file(out_path, i)
                temps.append(target)
            reports.append(
                _run_one(
                    current,
                    target,
                    processor,
                    [input_path, *temps[:-1]],
                    progress,
                    # intermediate stages copy everything: the next processor reads them
                    skip_topics if last else (),
                    skip_metadata if last else (),
                )
            )
            current = target
    finally:
        with signals_deferred():
            for stage in temps:
                stage.unlink(missing_ok=True)
                forget_unfinished(stage)
    return reports


def _stage_file(out_path: Path, i: int) -> Path:
    """A hidden intermediate log beside the output, registered so an interrupt removes it."""
    with signals_deferred():
        fd, stage_name = tempfile.mkstemp(
            prefix=f".{out_path.name}.stage{i}.", suffix=".mcap", dir=out_path.parent
        )
        os.close(fd)
        track_unfinished(Path(stage_name))
    return Path(stage_name)
