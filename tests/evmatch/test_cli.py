"""``trackctl ev-match`` and ``trackctl simulate ev``: in-process and as a real subprocess."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from trackctl.cli.main import app
from trackctl.logs import topics
from trackctl.logs.reader import LogReader

from ..conftest import run_cli
from .conftest import write_ev_log

ISSUE_KEYS = [
    "system",
    "algorithm",
    "engine",
    "requested",
    "matched",
    "correct",
    "accuracy",
    "unresolved",
    "v_scenarios_read",
    "v_scenarios_total",
    "v_bytes_read",
    "wall_s",
]


def test_json_report_has_the_issue_keys_in_order(ev_sample: Path, tmp_path: Path) -> None:
    res = CliRunner().invoke(
        app, ["ev-match", str(ev_sample), "--out", str(tmp_path / "o.mcap"), "--json"]
    )
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    assert list(report)[: len(ISSUE_KEYS)] == ISSUE_KEYS
    assert report["system"] == "ev-matching" and report["algorithm"] == "ss"
    assert report["requested"] == report["matched"] + report["unresolved"] + report["ambiguous"]
    assert report["accuracy"] >= 0.9
    assert 0 < report["v_scenarios_read"] < report["v_scenarios_total"]


def test_subprocess_edp_and_fail_if_gate(ev_sample: Path, tmp_path: Path) -> None:
    out = tmp_path / "edp.mcap"
    proc = run_cli(
        "ev-match",
        str(ev_sample),
        "--out",
        str(out),
        "--algorithm",
        "edp",
        "--json",
        "--fail-if",
        "accuracy<1.01",
    )
    assert proc.returncode == 1  # the gate holds; the report is still printed and written
    report = json.loads(proc.stdout)
    assert report["algorithm"] == "edp"
    assert LogReader(out).topics()[topics.EV_MATCHES].count == 1


def test_eids_file_with_an_unknown_eid(ev_sample: Path, tmp_path: Path) -> None:
    known = LogReader(ev_sample)
    first = next(known.messages([topics.EV_E])).message.eids[0]
    eids = tmp_path / "eids.txt"
    eids.write_text(f"# wanted\n{first}\naa:bb:cc:dd:ee:ff\n")
    out = tmp_path / "o.mcap"
    res = CliRunner().invoke(
        app, ["ev-match", str(ev_sample), "--out", str(out), "--eids", str(eids), "--json"]
    )
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    assert report["requested"] == 2 and report["unresolved"] == 1
    (msg,) = list(LogReader(out).messages([topics.EV_MATCHES]))
    by_eid = {m.eid: m for m in msg.message.matches}
    assert by_eid["aa:bb:cc:dd:ee:ff"].vid is None
    assert by_eid["aa:bb:cc:dd:ee:ff"].reason == "EID never appears in the E-observations"
    assert by_eid[first].vid is not None and by_eid[first].scenarios


def test_missing_v_topic_is_absorbed_with_one_warning(tmp_path: Path) -> None:
    """A camera down (no V topic for cell B): its scenarios are VID-missing evidence."""
    log = write_ev_log(
        tmp_path / "l.mcap",
        [
            {"A": ({"e1": False, "e2": False}, ["v1", "v2"])},
            {"A": ({"e1": False}, ["v1"]), "B": ({"e2": False}, ["v2"])},
        ],
        skip_v=("B",),
    )
    out = tmp_path / "o.mcap"
    proc = run_cli("ev-match", str(log), "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    (warning,) = proc.stderr.decode().strip().splitlines()
    assert warning.startswith("warning: ") and "/ev/cell/B/v" in warning
    report = json.loads(proc.stdout)
    assert report["v_scenarios_missing"] == 1 and report["v_topics_missing"] == 1
    (msg,) = list(LogReader(out).messages([topics.EV_MATCHES]))
    by_eid = {m.eid: m for m in msg.message.matches}
    assert by_eid["e1"].vid == "v1" and by_eid["e1"].status == "matched"
    # e2's only own scenario had no video: never matched to a VID it was not seen with
    assert by_eid["e2"].vid in (None, "v2")
    assert all("B@" not in s for s in by_eid["e2"].scenarios)


def test_bad_options_exit_2(ev_sample: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    out = str(tmp_path / "o.mcap")
    for args, msg in (
        (["--algorithm", "xx"], "expected ss or edp"),
        (["--engine", "gpu"], "expected local or spark"),
        (["--master", "local[2]"], "--master is for --engine spark"),
        (["--spark-conf", "spark.driver.memory=2g"], "--spark-conf is for --engine spark"),
        (["--engine", "spark", "--spark-conf", "memory=2g"], "expected spark.KEY=VALUE"),
        (["--all", "--eids", str(ev_sample)], "give one of them"),
    ):
        res = runner.invoke(app, ["ev-match", str(ev_sample), "--out", out, *args])
        assert res.exit_code == 2, args
        assert msg in res.output
    res = runner.invoke(app, ["simulate", "ev", "--out", out, "--eid-miss", "2"])
    assert res.exit_code == 2 and "--eid-miss 2.0" in res.output


def test_plot_writes_a_figure(ev_sample: Path, tmp_path: Path) -> None:
    res = CliRunner().invoke(
        app,
        [
            "ev-match",
            str(ev_sample),
            "--out",
            str(tmp_path / "o.mcap"),
            "--plot",
            str(tmp_path / "fig"),
            "-q",
        ],
    )
    assert res.exit_code == 0, res.output
    assert (tmp_path / "fig" / "ev_match.png").stat().st_size > 1000


def test_simulate_ev_subprocess_json(tmp_path: Path) -> None:
    out = tmp_path / "s.mcap"
    proc = run_cli(
        "simulate",
        "ev",
        "--out",
        str(out),
        "--people",
        "50",
        "--area",
        "300",
        "--duration",
        "300",
        "--json",
        check=True,
    )
    info = json.loads(proc.stdout)
    assert info["topics"] == 2 + 9  # E, ground truth, one V topic per cell
    assert info["messages"] == 1 + 5 * 9 * 2
