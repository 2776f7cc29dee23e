"""The Spark engine mirrors the local one exactly (one local[2] session for all of them)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from trackctl.cli.main import app
from trackctl.evmatch import Algorithm, EvMatchConfig, LocalEngine, SparkEngine, match_log
from trackctl.logs import topics
from trackctl.logs.reader import LogReader

# one worker holds the Spark session (a JVM and seconds of start-up): every Spark test runs there
pytestmark = pytest.mark.xdist_group("spark")


def test_split_step_is_identical(spark_session: object) -> None:
    rng = np.random.default_rng(1)
    spark, local = SparkEngine("local[2]"), LocalEngine()
    for _ in range(2):
        n = 40
        node = rng.integers(0, 5, n)
        eid = np.arange(n)
        listing = pd.DataFrame(
            {"eid": rng.integers(0, n, 60), "cell": rng.integers(0, 6, 60)}
        ).drop_duplicates()
        a = spark.split(node, eid, listing)
        b = local.split(node, eid, listing)
        pd.testing.assert_frame_equal(a, b)
    spark.close()  # a shared session is not stopped by an engine that did not start it
    assert spark_session.sparkContext._jsc is not None  # type: ignore[attr-defined]


def test_vote_step_is_identical(spark_session: object) -> None:
    eid = np.array([0, 0, 1, 1, 1])
    scen = np.array([10, 11, 10, 12, 13])
    vids = {10: ("a", "b"), 11: ("a",), 12: ("b", "c"), 13: ()}
    spark, local = SparkEngine("local[2]"), LocalEngine()
    a, b = spark.vote(eid, scen, vids), local.vote(eid, scen, vids)
    pd.testing.assert_frame_equal(a, b)
    # the best VID and the runner-up per EID, ties to the smaller VID
    assert b.values.tolist() == [[0, "a", 2], [0, "b", 1], [1, "b", 2], [1, "a", 1]]
    every = [[0, "a", 2], [0, "b", 1], [1, "b", 2], [1, "a", 1], [1, "c", 1]]
    a, b = spark.vote(eid, scen, vids, top=3), local.vote(eid, scen, vids, top=3)
    pd.testing.assert_frame_equal(a, b)
    assert b.values.tolist() == every
    # VIDs already matched to other EIDs are left out before ranking
    a, b = spark.vote(eid, scen, vids, {"b"}), local.vote(eid, scen, vids, {"b"})
    pd.testing.assert_frame_equal(a, b)
    assert b.values.tolist() == [[0, "a", 2], [1, "a", 1], [1, "c", 1]]


def test_edp_on_spark_equals_local(spark_session: object, small_log: Path) -> None:
    reader = LogReader(small_log)
    base, data, *_ = match_log(reader, EvMatchConfig(algorithm=Algorithm.EDP))
    eids = tuple(str(e) for e in data.eids[:25])
    a, *_ = match_log(reader, EvMatchConfig(eids=eids, algorithm=Algorithm.EDP))
    b, *_ = match_log(
        reader, EvMatchConfig(eids=eids, algorithm=Algorithm.EDP, engine="spark", master="local[2]")
    )
    assert a.matches == b.matches
    assert a.v_scenarios_read == b.v_scenarios_read


def _matches(log: Path) -> list[dict[str, object]]:
    msgs = list(LogReader(log).messages([topics.EV_MATCHES]))
    return msgs[-1].message.to_json()["matches"]


def test_cut_sample_log_through_the_cli_is_matched_alike_by_both_engines(
    spark_session: object, ev_sample: Path, tmp_path: Path
) -> None:
    """The shipped sample, cut off at 85 % as a crashed recorder leaves it, through
    ``trackctl ev-match`` on each engine: the same matches and the same report (one test for
    what were two runs of the whole sample on Spark, one whole and one cut)."""
    cut = tmp_path / "cut.mcap"
    data = ev_sample.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.85)])
    runner = CliRunner()
    outs = {}
    reports = {}
    for engine, extra in (("local", []), ("spark", ["--master", "local[2]"])):
        out = tmp_path / f"{engine}.mcap"
        res = runner.invoke(
            app, ["ev-match", str(cut), "--out", str(out), "--engine", engine, *extra, "--json"]
        )
        assert res.exit_code == 0, res.output
        reports[engine] = json.loads(res.stdout.strip().splitlines()[-1])
        outs[engine] = _matches(out)
    assert outs["spark"] == outs["local"]
    assert len(outs["local"]) > 300 and any(m["vid"] for m in outs["local"])
    assert reports["spark"]["engine"] == "spark"
    for key in ("requested", "matched", "correct", "accuracy", "v_scenarios_read", "v_bytes_read"):
        assert reports["spark"][key] == reports["local"][key], key
