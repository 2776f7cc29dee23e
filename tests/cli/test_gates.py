"""Reports and gates a CI job can trust, through the command line: nulls per system without
the truth, gates that exit 2 on them, the early key check, readable output, progress lines and
SIGTERM."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.cache import cached_file
from tests.conftest import ROOT, run_cli, trackctl_exe
from trackctl.cli.main import app
from trackctl.logs import LogReader
from trackctl.logs.copy import filter_log
from trackctl.metrics.catalog import TRUTH, catalog

runner = CliRunner()
SAMPLES = ROOT / "sample_logs"


def _no_truth(name: str) -> Path:
    """The shipped sample ``name`` without /ground_truth (built once)."""
    return cached_file(
        f"nogt-{name}",
        lambda out: filter_log(SAMPLES / name, out, exclude=("/ground_truth",)),
        name,
    )


def _truth_keys(processor: str, metrics: dict[str, object]) -> list[str]:
    cat = catalog(processor)
    assert cat is not None
    return [k for k in metrics if (spec := cat.spec(k)) is not None and TRUTH in spec.needs]


def _assert_declared(processor: str, metrics: dict[str, object]) -> None:
    """Every figure a run reported is declared in metrics/catalog.py (so --fail-if can check
    it before the run and its needs are known)."""
    cat = catalog(processor)
    assert cat is not None
    undeclared = [k for k in metrics if k != "unmeasured" and not cat.declares(k)]
    assert not undeclared, f"{processor} reports undeclared {undeclared}"


def _one_error_line(stderr: str) -> str:
    lines = [line for line in stderr.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, stderr
    return lines[0]


def test_vm_track_without_the_truth_reports_null_and_its_gate_exits_2(tmp_path: Path) -> None:
    proc = run_cli(
        "vm-track", str(_no_truth("vm-office.mcap")), "--no-retrack", "--out",
        str(tmp_path / "t.mcap"), "--json", "--fail-if", "id_switches>0",
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr.decode()
    line = _one_error_line(proc.stderr.decode())
    assert "id_switches was not measured" in line and "/ground_truth" in line
    report = json.loads(proc.stdout)
    _assert_declared("vm-track", report)
    assert report["id_switches"] is None and report["people"] is None
    truth = _truth_keys("vm-track", report)
    assert {"idf1", "mota", "id_switches", "loss_events", "det_recall"} <= set(truth)
    assert all(report[k] is None for k in truth)
    assert report["unmeasured"]["idf1"] == "the log has no /ground_truth"
    # what needs no truth is still measured
    assert report["tracks_published"] >= 1 and report["ambiguous_frames"] is not None
    # the same gate on the stored report: exit 2, or skipped with --allow-unmeasured
    res = runner.invoke(app, ["report", str(tmp_path / "t.mcap"), "--fail-if", "id_switches>0"])
    assert res.exit_code == 2 and "id_switches was not measured" in res.stderr
    res = runner.invoke(
        app,
        ["report", str(tmp_path / "t.mcap"), "--fail-if", "id_switches>0", "--allow-unmeasured"],
    )
    assert res.exit_code == 0, res.output


@pytest.mark.parametrize(
    ("command", "sample", "processor", "gate"),
    [
        (["smirror"], "smirror.mcap", "smirror", "unlocalized_samples>0"),
        (["bridgeloc", "eval"], "bridgeloc.mcap", "bridgeloc", "success_rate<0.5"),
    ],
)
def test_robot_systems_without_the_truth_report_null_and_gates_exit_2(
    command: list[str], sample: str, processor: str, gate: str
) -> None:
    log = str(_no_truth(sample))
    res = runner.invoke(app, [*command, log, "--json"])
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    truth = _truth_keys(processor, report)
    assert gate.split("<")[0].split(">")[0] in truth
    assert truth and all(report[k] is None for k in truth), {k: report[k] for k in truth}
    assert all(report["unmeasured"][k] == "the log has no /ground_truth" for k in truth)
    res = runner.invoke(app, [*command, log, "--json", "--fail-if", gate])
    assert res.exit_code == 2
    assert "was not measured: the log has no /ground_truth" in _one_error_line(res.stderr)
    # with the truth the same figures are measured and the gate is judged
    res = runner.invoke(app, [*command, str(SAMPLES / sample), "--json"])
    with_truth = json.loads(res.stdout)
    _assert_declared(processor, report)
    _assert_declared(processor, with_truth)
    assert with_truth["error_m_mean"] is not None
    assert with_truth["unmeasured"].get("error_m_mean") is None


def test_ev_match_without_the_truth_reports_null_accuracy(tmp_path: Path) -> None:
    log = tmp_path / "nogt-ev.mcap"
    filter_log(SAMPLES / "ev.mcap", log, exclude=("/ev/ground_truth",))
    res = runner.invoke(app, ["ev-match", str(log), "--json", "--fail-if", "accuracy<0.9"])
    assert res.exit_code == 2
    assert "accuracy was not measured: the log has no /ev/ground_truth" in res.stderr
    report = json.loads(res.stdout)
    _assert_declared("ev-match", report)
    assert report["correct"] is None and report["matched"] > 300


def test_unknown_gate_key_exits_2_before_any_work(tmp_path: Path) -> None:
    out = tmp_path / "x.mcap"
    res = runner.invoke(
        app, ["vm-track", str(SAMPLES / "vm-office.mcap"), "--fail-if", "nosuchkey>1", "--out",
              str(out)],
    )  # fmt: skip
    assert res.exit_code == 2
    assert "vm-track reports no metric 'nosuchkey'" in _one_error_line(res.stderr)
    assert not out.exists() and not list(tmp_path.iterdir())
    res = runner.invoke(
        app, ["process", str(SAMPLES / "demo.mcap"), "--with", "check,pdr", "--fail-if",
              "check.steps_total>0", "--out", str(out)],
    )  # fmt: skip
    assert res.exit_code == 2 and "check reports no metric 'steps_total'" in res.stderr
    assert not out.exists()


def test_human_output_is_a_headline_naming_the_file_written(tmp_path: Path) -> None:
    out = tmp_path / "vm-tracked.mcap"
    res = runner.invoke(
        app, ["vm-track", str(SAMPLES / "vm-office.mcap"), "--no-retrack", "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    lines = res.stdout.strip().splitlines()
    assert len(lines) <= 20, res.stdout
    assert lines[-1] == f"wrote {out}"
    assert re.search(r"idf1\s+│\s+0\.\d+", res.stdout) and "clock_offset_s" not in res.stdout
    full = runner.invoke(app, ["report", str(out), "--verbose"])
    assert "clock_offset_s/02:00:00:00:00:01" in full.stdout and "wall_s" in full.stdout


def test_report_csv_keeps_integers_and_is_not_cut_on_a_pipe(tmp_path: Path) -> None:
    out, csv = tmp_path / "o.mcap", tmp_path / "r.csv"
    res = runner.invoke(app, ["process", str(SAMPLES / "demo.mcap"), "--with", "check,pdr",
                              "--out", str(out)])  # fmt: skip
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["report", str(out), "--csv", str(csv), "--verbose", "--json"])
    for rep in json.loads(res.stdout)["reports"]:
        _assert_declared(rep["processor"], rep["metrics"])
    res = runner.invoke(app, ["report", str(out), "--csv", str(csv), "--verbose"])
    assert res.exit_code == 0, res.output
    header, *rows = csv.read_text().splitlines()
    check = dict(zip(header.split(","), rows[0].split(","), strict=True))
    assert check["messages"] == "1242" and check["gaps"] == "0"
    # on a pipe (CliRunner's output is not a terminal) no cell is cut to fit 80 columns
    assert "…" not in res.stdout and "duration_s/p1" in res.stdout
    # the log itself is refused as the CSV, and left as it was
    before = out.read_bytes()
    res = runner.invoke(app, ["report", str(out), "--csv", str(out)])
    assert res.exit_code == 2 and out.read_bytes() == before


def test_off_a_terminal_progress_is_a_line_on_stderr_every_interval() -> None:
    env = dict(os.environ, TRACKCTL_PROGRESS_S="0.2")
    log = str(SAMPLES / "bridgeloc.mcap")
    proc = subprocess.run(
        [*trackctl_exe(), "bridgeloc", "eval", log, "--json"],
        capture_output=True, env=env, stdin=subprocess.DEVNULL, timeout=900, check=True,
    )  # fmt: skip
    lines = [ln for ln in proc.stderr.decode().splitlines() if ln.startswith("bridgeloc: ")]
    assert len(lines) >= 2, proc.stderr.decode()
    assert all(re.search(r", \d+:\d\d elapsed$", ln) for ln in lines)
    assert any(re.search(r" \d+/\d+ \(\d+ %\)", ln) for ln in lines)  # a stage with its total
    json.loads(proc.stdout)  # stdout stays one JSON object
    quiet = subprocess.run(
        [*trackctl_exe(), "bridgeloc", "eval", log, "--json", "--quiet"],
        capture_output=True, env=env, stdin=subprocess.DEVNULL, timeout=900, check=True,
    )  # fmt: skip
    assert "elapsed" not in quiet.stderr.decode()


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_end_a_run_as_ctrl_c_does(tmp_path: Path, signum: int) -> None:
    out = tmp_path / "t.mcap"
    env = dict(os.environ, TRACKCTL_PROGRESS_S="0.2")
    child = subprocess.Popen(
        [*trackctl_exe(), "vm-track", str(SAMPLES / "vm-office.mcap"), "--out", str(out)],
        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env,
    )  # fmt: skip
    assert child.stderr is not None
    try:
        # wait until the run is under way (its first progress line), then stop it
        first = child.stderr.readline().decode()
        assert "elapsed" in first, first
        child.send_signal(signum)
        _, err = child.communicate(timeout=900)
    finally:
        child.kill()
    name = signal.Signals(signum).name
    assert child.returncode == 128 + signum, err.decode()
    assert f"interrupted by {name}: the unfinished output was removed" in err.decode()
    assert not out.exists() and list(tmp_path.iterdir()) == []
    assert LogReader(SAMPLES / "vm-office.mcap").message_count > 0  # the input is untouched


def test_every_command_help_reads_as_words_and_shows_an_example() -> None:
    commands = [
        ["info"], ["record"], ["recover"], ["filter"], ["replay"], ["process"], ["report"],
        ["vm-track"], ["ev-match"], ["smirror"], ["simulate", "vm"], ["simulate", "ev"],
        ["simulate", "smirror"], ["simulate", "bridgeloc"], ["simulate", "demo"],
        ["bridgeloc", "eval"], ["bridgeloc", "tags"], ["calib", "ground"], ["calib", "import"],
        ["calib", "check"],
    ]  # fmt: skip
    for cmd in commands:
        res = runner.invoke(app, [*cmd, "--help"])
        assert res.exit_code == 0, cmd
        assert "Example: trackctl " in res.stdout, cmd
        leaked = re.findall(r"<(?:bool|str|int|float|path|list\[[^]]*\])>", res.stdout)
        assert not leaked, (cmd, leaked)
    assert "--install-completion" in runner.invoke(app, ["--help"]).stdout
