"""EV-Matching at scale: universal matching of 10k to 1M people (dissertation §3.2.4).

The density of the paper's setting is kept (1000 people per km², 30 min in 1 min windows), so
100k people walk in 10 x 10 km with 10 000 cells of 100 m: 300 000 V-scenarios on 10 000 topics.
One V topic per cell meets MCAP's limit of 65 535 channels per log at 1M people (1000 km²), so
cells grow to 125 m there (64 009 cells, 1.9M V-scenarios). Each run is the real processor on the
log (``ev-match LOG --all``), started in a child process that reports its own peak RSS (for Spark:
the driver's Python process, and the JVM's peak, which in ``local[2]`` also hosts the executors).
Engines: the local engine for every size, Spark ``local[2]`` for the sizes in ``--spark-sizes``.

    python benchmarks/ev_scale.py [--sizes 10000,100000,1000000] [--spark-sizes 10000,1000000]
                                  [--local-sizes ...] [--workdir DIR]

Logs are simulated once into ``--workdir`` (default: a temporary folder) and reused when present.
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SPARK_HEAP = "3g"


def child(log: str, out: str, engine: str) -> None:
    """Run ev-match in this process; print the report plus this process's peak RSS."""
    from trackctl.evmatch import EvMatchConfig, EvMatchProcessor
    from trackctl.metrics.report import jsonable_metrics
    from trackctl.processing import run_processors

    config = EvMatchConfig(engine=engine, master="local[2]" if engine == "spark" else None)
    session = None
    if engine == "spark":
        from pyspark.sql import SparkSession

        # started here so that it outlives the run and its JVM's peak can be read
        session = (
            SparkSession.builder.master("local[2]")
            # local mode: one JVM is driver and executors; the cached E shards need the heap
            .config("spark.driver.memory", SPARK_HEAP)
            .config("spark.ui.enabled", "false")
            .config("spark.ui.showConsoleProgress", "false")
            .getOrCreate()
        )
    t0 = time.perf_counter()
    # report only (no copy of the input): the output holds the matches and the report
    (report,) = run_processors(log, out, [EvMatchProcessor(config)], outputs_only=True)
    metrics = jsonable_metrics(report.metrics)
    metrics["wall_seconds"] = round(time.perf_counter() - t0, 1)
    metrics["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
    metrics["jvm_peak_rss_mb"] = 0.0
    if session is not None:
        pid = session.sparkContext._gateway.proc.pid  # type: ignore[union-attr]
        status = Path(f"/proc/{pid}/status").read_text()
        hwm = next(line for line in status.splitlines() if line.startswith("VmHWM:"))
        metrics["jvm_peak_rss_mb"] = round(int(hwm.split()[1]) / 1024, 1)
        session.stop()
    print(json.dumps(metrics))


def cell_m(n: int) -> float:
    """100 m cells, or 125 m when 100 m would need more V topics than an MCAP log can hold."""
    side = 1000.0 * math.sqrt(n / 1000.0)
    return 100.0 if math.ceil(side / 100.0) ** 2 + 2 <= 65535 else 125.0


def simulate(n: int, path: Path) -> tuple[float, float]:
    """Simulate ``n`` people at the paper's density (in a child, for its peak RSS)."""
    area = 1000.0 * math.sqrt(n / 1000.0)
    code = (
        "import resource, sys\n"
        "from trackctl.sim.ev import EvScenario, simulate_ev\n"
        f"simulate_ev({str(path)!r}, EvScenario(people={n}, area_m={area}, cell_m={cell_m(n)}, "
        "seed=4))\n"
        "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)\n"
    )
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return time.perf_counter() - t0, float(proc.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="10000,100000,1000000")
    ap.add_argument("--spark-sizes", default="10000,1000000")
    ap.add_argument("--local-sizes", help="sizes run on the local engine (default: --sizes)")
    ap.add_argument("--workdir", type=Path)
    ap.add_argument("--child", nargs=3, metavar=("LOG", "OUT", "ENGINE"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(*args.child)
        return 0
    sizes = [int(s) for s in args.sizes.split(",") if s]
    spark_sizes = {int(s) for s in args.spark_sizes.split(",") if s}
    local_sizes = (
        set(sizes)
        if args.local_sizes is None
        else {int(s) for s in args.local_sizes.split(",") if s}
    )
    tmp = None
    if args.workdir is None:
        tmp = tempfile.TemporaryDirectory()
        workdir = Path(tmp.name)
    else:
        workdir = args.workdir
        workdir.mkdir(parents=True, exist_ok=True)
    print(
        f"{'people':>7} {'engine':>6} | {'EIDs':>6} {'accuracy':>8} {'unres':>5} | "
        f"{'V read':>7} {'V total':>7} {'V MB read':>9} | {'match s':>7} {'wall s':>7} "
        f"{'peak MB':>7} {'JVM MB':>6}"
    )
    for n in sizes:
        log = workdir / f"ev_{n}.mcap"
        if not log.exists():
            sim_s, sim_mb = simulate(n, log)
            print(
                f"# simulated {n} people ({cell_m(n):.0f} m cells): {sim_s:.0f} s, peak "
                f"{sim_mb:.0f} MB, {log.stat().st_size / 1e6:.0f} MB log"
            )
        engines = (["local"] if n in local_sizes else []) + (["spark"] if n in spark_sizes else [])
        for engine in engines:
            out = workdir / f"ev_{n}_{engine}_out.mcap"
            proc = subprocess.run(
                [sys.executable, __file__, "--child", str(log), str(out), engine],
                capture_output=True,
                text=True,
            )
            if proc.returncode != 0:
                print(f"{n:>7} {engine:>6} | failed: {proc.stderr.strip().splitlines()[-1:]}")
                continue
            m = json.loads(proc.stdout.strip().splitlines()[-1])
            jvm = m["jvm_peak_rss_mb"] if engine == "spark" else "-"
            print(
                f"{n:>7} {engine:>6} | {m['requested']:>6} {100 * m['accuracy']:>7.2f}% "
                f"{m['unresolved']:>5} | {m['v_scenarios_read']:>7} {m['v_scenarios_total']:>7} "
                f"{m['v_bytes_read'] / 1e6:>9.1f} | {m['wall_s']:>7.1f} "
                f"{m['wall_seconds']:>7.1f} {m['peak_rss_mb']:>7.0f} "
                f"{jvm:>6}"
            )
            print("#   stages:", {k: v for k, v in m.items() if k.startswith("wall_s_")})
            out.unlink(missing_ok=True)
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
