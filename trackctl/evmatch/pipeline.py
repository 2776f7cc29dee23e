"""``ev-match``: the library entry point (one function, one frozen config)."""

from __future__ import annotations

import enum
import time
import warnings
from dataclasses import dataclass, field

from trackctl.errors import IncompleteInputWarning, InputError
from trackctl.evmatch.data import EData, VStore, load_e, load_ground_truth
from trackctl.evmatch.eindex import ECatalog, EIndex
from trackctl.evmatch.engines import SparkEngine, make_engine
from trackctl.evmatch.matcher import AMBIGUOUS, MatchOutcome, MatchParams, match_edp, match_ss
from trackctl.evmatch.spark import SparkVStore, spark_index
from trackctl.logs import topics
from trackctl.logs.messages import EvMatches, MetricReport
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import Progress

__all__ = ["Algorithm", "EvMatchConfig", "run", "match_log", "MATCHES_TOPIC"]

MATCHES_TOPIC = topics.EV_MATCHES
MATCHES_PER_MESSAGE = 10_000


class Algorithm(enum.StrEnum):
    """``ss``: EID set splitting (the dissertation's); ``edp``: the single-EID baseline."""

    SS = "ss"
    EDP = "edp"


@dataclass(frozen=True)
class EvMatchConfig:
    """What to match and how.

    Attributes:
        eids: the EIDs to match, in output order; None for universal matching (every EID).
        algorithm: ss or edp.
        engine: local (pandas) or spark (pyspark).
        master: Spark master URL for the spark engine.
        spark_conf: Spark properties for a new session (``spark.driver.memory``, ...).
        seed: order of the random windows (same seed, same matches).
        params: acceptance rule and refining limit.
    """

    eids: tuple[str, ...] | None = None
    algorithm: Algorithm = Algorithm.SS
    engine: str = "local"
    master: str | None = None
    spark_conf: tuple[tuple[str, str], ...] = ()
    seed: int = 0
    params: MatchParams = field(default_factory=MatchParams)


def match_log(
    reader: LogReader, config: EvMatchConfig, progress: Progress | None = None
) -> tuple[MatchOutcome, ECatalog, VStore | SparkVStore, dict[str, float]]:
    """Run the matcher over a log without writing anything (benchmarks use this directly)."""
    if config.engine not in ("local", "spark"):
        raise InputError(f"--engine {config.engine!r}: expected local or spark")
    t0 = time.perf_counter()
    # a cut log is indexed once, so that V-scenario fetches seek instead of rescanning it
    reader.reindex()
    engine = make_engine(config.engine, config.master, dict(config.spark_conf))
    vstore: VStore | SparkVStore | None = None
    data: ECatalog | EIndex | None = None
    try:
        if isinstance(engine, SparkEngine) and config.algorithm == Algorithm.SS:
            # the E table and the V-scenarios stay on the executors (trackctl.evmatch.spark)
            data, _ = spark_index(reader, engine, config.seed)
            catalog = data.catalog
            vstore = SparkVStore(reader, catalog, engine)
        else:
            data = catalog = load_e(reader)
            vstore = VStore(reader, catalog)
        t1 = time.perf_counter()
        requested = list(config.eids) if config.eids is not None else catalog.eids.tolist()
        if config.algorithm == Algorithm.SS:
            outcome = match_ss(
                data, vstore, requested, engine, config.params, config.seed, progress
            )
        else:
            assert isinstance(data, EData) and isinstance(vstore, VStore)
            outcome = match_edp(
                data, vstore, requested, engine, config.params, config.seed, progress
            )
    finally:
        # whatever was opened before a failure is closed; the failure itself propagates
        if isinstance(data, EIndex):
            data.close()
        engine.close()
        if vstore is not None:
            vstore.close()
    _warn_incomplete(reader, catalog, vstore, outcome)
    stages = {"wall_s_load_e": t1 - t0, **outcome.stage_seconds}
    return outcome, catalog, vstore, stages


def _warn_incomplete(
    reader: LogReader, data: ECatalog, vstore: VStore | SparkVStore, outcome: MatchOutcome
) -> None:
    """Say what the run had to do without: no EIDs at all, V-scenarios that were not there."""
    if not len(data.eids):
        warnings.warn(
            f"{reader.path}: {topics.EV_E} lists no EID: nothing to match",
            IncompleteInputWarning,
            stacklevel=3,
        )
    elif not outcome.matches:
        warnings.warn("no EID requested: nothing to match", IncompleteInputWarning, stacklevel=3)
    if vstore.missing:
        gone = vstore.missing_topics()
        where = (
            f"; no V topic at all for {len(gone)} cell(s): {', '.join(gone[:5])}"
            + (", ..." if len(gone) > 5 else "")
            if gone
            else ""
        )
        warnings.warn(
            f"{reader.path}: {len(vstore.missing)} of the V-scenarios needed have no video "
            f"(camera down, gap or cut log){where}; matched with the rest, as missed detections",
            IncompleteInputWarning,
            stacklevel=3,
        )


def run(
    reader: LogReader,
    writer: LogWriter,
    config: EvMatchConfig | None = None,
    progress: Progress | None = None,
) -> MetricReport:
    """Match EIDs to VIDs; write ``/evmatch/matches``; return the report (issue's keys first)."""
    config = config or EvMatchConfig()
    started = time.perf_counter()
    outcome, data, vstore, stages = match_log(reader, config, progress)
    truth = load_ground_truth(reader)
    matched = sum(m.vid is not None for m in outcome.matches)
    ambiguous = sum(m.status == AMBIGUOUS for m in outcome.matches)
    correct = sum(m.vid is not None and truth.get(m.eid) == m.vid for m in outcome.matches)
    requested = len(outcome.matches)
    end_ns = int(data.windows_ns[-1]) + data.window_ns if len(data.windows_ns) else 0
    # in messages of at most MATCHES_PER_MESSAGE, in request order (a city's million matches
    # would otherwise be one message of hundreds of MB)
    for first in range(0, max(len(outcome.matches), 1), MATCHES_PER_MESSAGE):
        part = tuple(outcome.matches[first : first + MATCHES_PER_MESSAGE])
        writer.write(MATCHES_TOPIC, EvMatches(end_ns, str(config.algorithm), part))
    v_total = vstore.total()
    metrics = {
        "system": "ev-matching",
        "algorithm": str(config.algorithm),
        "engine": config.engine,
        "requested": requested,
        "matched": matched,
        "correct": correct if truth else None,
        "accuracy": round(correct / requested, 4) if truth and requested else None,
        "unresolved": requested - matched - ambiguous,
        "v_scenarios_read": outcome.v_scenarios_read,
        "v_scenarios_total": v_total,
        "v_bytes_read": outcome.v_bytes_read,
        "wall_s": round(time.perf_counter() - started, 3),
        "ambiguous": ambiguous,
        "precision": round(correct / matched, 4) if truth and matched else None,
        "v_scenarios_missing": len(vstore.missing),
        "v_topics_missing": len(vstore.missing_topics()),
        "v_scenarios_unique": outcome.v_scenarios_unique,
        "e_scenarios_total": data.e_scenarios,
        "eids_in_log": len(data.eids),
        "distinguished": outcome.distinguished,
        "split_iterations": outcome.split_iterations,
        "refine_rounds": outcome.refine_rounds,
        **{k: round(v, 3) for k, v in stages.items()},
    }
    params = {
        "eids": "all" if config.eids is None else len(config.eids),
        "master": config.master,
        "seed": config.seed,
        "margin": config.params.margin,
        "min_evidence": config.params.min_evidence,
        "support": config.params.support,
        "max_evidence": config.params.max_evidence,
        "ground_truth": bool(truth),
    }
    return MetricReport(t_ns=end_ns, processor="ev-match", metrics=metrics, params=params)
