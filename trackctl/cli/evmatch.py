"""``trackctl ev-match`` and ``trackctl simulate ev``."""

from __future__ import annotations

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
    VerboseOption,
    fail_if_option,
    out_option,
    parse_choice,
    print_json,
    stderr,
)
from trackctl.cli.process import figures_from_output, run_system
from trackctl.logs.output import check_output


def _read_eids(path: Path) -> tuple[str, ...]:
    from trackctl.errors import InputError

    try:
        text = path.read_text()
    except OSError as err:
        raise InputError(f"--eids {path}: cannot read: {err.strerror}") from None
    eids = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            eids.append(line)
    if not eids:
        raise InputError(f"--eids {path}: no EID in the file (one per line, # comments)")
    return tuple(dict.fromkeys(eids))


def _spark_conf(
    engine: str, master: str | None, spark_conf: list[str] | None
) -> tuple[tuple[str, str], ...]:
    """``--spark-conf KEY=VALUE`` pairs, checked (``--master``/``--spark-conf`` need spark)."""
    from trackctl.errors import InputError

    if master is not None and engine != "spark":
        raise InputError("--master is for --engine spark")
    if spark_conf and engine != "spark":
        raise InputError("--spark-conf is for --engine spark")
    conf = []
    for item in spark_conf or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip().startswith("spark."):
            raise InputError(f"--spark-conf {item!r}: expected spark.KEY=VALUE")
        conf.append((key.strip(), value.strip()))
    return tuple(conf)


def ev_match(
    log: Annotated[Path, typer.Argument(help="MCAP log with /ev/e and /ev/cell/<i>_<j>/v.")],
    out: Annotated[Path | None, out_option("input + /evmatch/matches + report")] = None,
    outputs_only: OutputsOnlyOption = False,
    eids: Annotated[
        Path | None, typer.Option(help="File with the EIDs to match, one per line.")
    ] = None,
    all_eids: Annotated[
        bool, typer.Option("--all", help="Universal matching: every EID in the log (default).")
    ] = False,
    algorithm: Annotated[
        str, typer.Option(help="ss (EID set splitting) or edp (single-EID baseline).")
    ] = "ss",
    engine: Annotated[str, typer.Option(help="local (pandas) or spark (pyspark).")] = "local",
    master: Annotated[
        str | None, typer.Option(help="Spark master: local[N] or a cluster URL.")
    ] = None,
    spark_conf: Annotated[
        list[str] | None,
        typer.Option(
            "--spark-conf",
            help="Spark property KEY=VALUE for a new session, e.g. spark.driver.memory=4g "
            "(repeatable).",
        ),
    ] = None,
    seed: Annotated[int, typer.Option(help="Order of the random windows.")] = 0,
    margin: Annotated[int, typer.Option(help="Votes the best VID must lead the runner-up by.")] = 1,
    max_evidence: Annotated[
        int, typer.Option(help="Most evidence scenarios per EID before giving up.")
    ] = 12,
    json_out: JsonOption = False,
    plot: PlotOption = None,
    fail_if: Annotated[str | None, fail_if_option("accuracy<0.9")] = None,
    allow_unmeasured: AllowUnmeasuredOption = False,
    verbose: VerboseOption = False,
    quiet: QuietOption = False,
) -> None:
    """EV-Matching: find the VID (person in video) of each EID (phone) reading little video.

    Example: trackctl ev-match sample_logs/ev.mcap --out matched.mcap --json
    """
    from trackctl.errors import InputError
    from trackctl.evmatch import Algorithm, EvMatchConfig, EvMatchProcessor, MatchParams

    if out is not None:
        check_output(out, [log, eids])  # before the EID list is read
    if eids is not None and all_eids:
        raise InputError("--eids and --all: give one of them")
    algo = parse_choice(Algorithm, algorithm, "--algorithm")
    if engine not in ("local", "spark"):
        raise InputError(f"--engine {engine!r}: expected local or spark")
    conf = _spark_conf(engine, master, spark_conf)
    if margin < 1 or max_evidence < 1:
        raise InputError("--margin and --max-evidence must be >= 1")
    requested = _read_eids(eids) if eids is not None else None
    if plot is not None:
        from trackctl.plots.evmatch import require_matplotlib

        require_matplotlib()
    config = EvMatchConfig(
        eids=requested,
        algorithm=algo,
        engine=engine,
        master=master,
        spark_conf=conf,
        seed=seed,
        params=MatchParams(margin=margin, max_evidence=max_evidence),
    )
    draw = figures_from_output(out, plot, "evmatch")
    run_system(
        "ev-match",
        log,
        out,
        EvMatchProcessor(config),
        json_out=json_out,
        fail_if=fail_if,
        quiet=quiet,
        allow_unmeasured=allow_unmeasured,
        verbose=verbose,
        plot=draw,
        outputs_only=outputs_only,
        inputs=[eids],
    )


def simulate_ev(
    out: Annotated[Path, typer.Option(help="MCAP log to write.")],
    people: Annotated[int, typer.Option(help="People in the area.")] = 1000,
    area: Annotated[float, typer.Option(help="Side of the square area, m.")] = 1000.0,
    cell: Annotated[float, typer.Option(help="Side of a square cell (E and camera), m.")] = 100.0,
    duration: Annotated[float, typer.Option(help="Seconds.")] = 1800.0,
    window: Annotated[float, typer.Option(help="Scenario window, s.")] = 60.0,
    eid_miss: Annotated[float, typer.Option(help="Share of people without a phone.")] = 0.1,
    vid_miss: Annotated[
        float, typer.Option(help="Chance a VID is missing from a V-scenario.")
    ] = 0.02,
    drift_m: Annotated[
        float,
        typer.Option(
            help="E-locations within this distance of a border may drift across it, m "
            "(> cell: beyond the adjacent cell)."
        ),
    ] = 15.0,
    hear_interval: Annotated[
        float | None,
        typer.Option(help="Mean seconds between a phone's network contacts (default: always)."),
    ] = None,
    reid_error: Annotated[
        float,
        typer.Option(help="Chance per person and window that video labels them with another VID."),
    ] = 0.0,
    shared_eids: Annotated[
        int, typer.Option(help="Pairs of people that carry one EID (cloned MAC, shared phone).")
    ] = 0,
    seed: SeedOption = 0,
    json_out: JsonOption = False,
    quiet: QuietOption = False,
) -> None:
    """People under cell-level E-location and per-cell cameras (EV-Matching scenarios).

    Example: trackctl simulate ev --out ev.mcap --people 400 --duration 1200 --seed 0
    """
    from trackctl.sim.ev import EvScenario
    from trackctl.sim.ev import simulate_ev as simulate

    check_output(out)
    cfg = EvScenario(
        people=people,
        area_m=area,
        cell_m=cell,
        duration_s=duration,
        window_s=window,
        eid_miss=eid_miss,
        vid_miss=vid_miss,
        drift_m=drift_m,
        hear_s=hear_interval,
        reid_error=reid_error,
        shared_eids=shared_eids,
        seed=seed,
    )
    counts = simulate(str(out), cfg)
    if json_out:
        print_json({"out": str(out), "messages": sum(counts.values()), "topics": len(counts)})
    elif not quiet:
        stderr.print(f"wrote {sum(counts.values())} messages on {len(counts)} topics to {out}")
