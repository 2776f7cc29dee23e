"""EV-Matching fixtures: a small scenario log, the shipped sample, one Spark session."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.cache import simulated
from trackctl.sim.ev import EvScenario, simulate_ev

ROOT = Path(__file__).resolve().parents[2]
EV_SAMPLE = ROOT / "sample_logs" / "ev.mcap"
# what `make sample-logs` runs for sample_logs/ev.mcap
SAMPLE_SCENARIO = EvScenario(people=400, area_m=600.0, duration_s=1200.0, seed=0)


@pytest.fixture(scope="session")
def ev_sample() -> Path:
    return EV_SAMPLE


@pytest.fixture(scope="session")
def small_log() -> Path:
    """150 people, 5 x 5 cells, 15 windows, 30% without a phone, 5% missed VIDs."""
    return simulated(
        "ev-small.mcap",
        simulate_ev,
        EvScenario(people=150, area_m=500, duration_s=900, eid_miss=0.3, vid_miss=0.05, seed=11),
    )


@pytest.fixture(scope="session")
def spark_session() -> Iterator[object]:
    """One local[2] SparkSession for the whole test session (startup takes seconds)."""
    import warnings

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*pandas >= 3.*")
        from pyspark.sql import SparkSession  # the dev extra installs pyspark: no skip

        # workers run this interpreter, as trackctl's own local sessions do (engines.py)
        os.environ.setdefault("PYSPARK_PYTHON", sys.executable)
        session = (
            SparkSession.builder.master("local[2]")
            .appName("trackctl-tests")
            .config("spark.ui.enabled", "false")
            .config("spark.ui.showConsoleProgress", "false")
            .getOrCreate()
        )
    session.sparkContext.setLogLevel("ERROR")
    yield session
    session.stop()


def write_ev_log(
    path: Path,
    windows: list[dict[str, tuple[dict[str, bool], list[str]]]],
    truth: dict[str, str] | None = None,
    skip_v: tuple[str, ...] = (),
) -> Path:
    """A hand-made EV log: per window, cell -> ({eid: vague}, [vids]); 60 s windows."""
    from trackctl.logs import topics
    from trackctl.logs.messages import (
        EObservations,
        GroundTruth,
        GroundTruthEntity,
        Vec3,
        VScenario,
    )
    from trackctl.logs.writer import LogWriter

    win = 60 * 10**9
    with LogWriter(path) as w:
        if truth:
            ents = tuple(
                GroundTruthEntity(f"p{i}", Vec3(0, 0, 0), electronic_id=e, visual_id=v)
                for i, (e, v) in enumerate(sorted(truth.items()))
            )
            w.write(topics.EV_GROUND_TRUTH, GroundTruth(0, ents))
        cells = sorted({c for win_cells in windows for c in win_cells})
        for k, cells_of in enumerate(windows):
            t = k * win
            for c in cells:
                eids, vids = cells_of.get(c, ({}, []))
                names = sorted(eids)
                w.write(
                    topics.EV_E,
                    EObservations(t, win, c, tuple(names), tuple(eids[n] for n in names), 12),
                )
            for c in cells:
                if c in skip_v:
                    continue
                _, vids = cells_of.get(c, ({}, []))
                vs = sorted(vids)
                w.write(
                    topics.ev_v(c),
                    VScenario(
                        t, win, c, tuple(vs), (0.0,) * len(vs), (0.0,) * len(vs), (12,) * len(vs)
                    ),
                )
    return path
