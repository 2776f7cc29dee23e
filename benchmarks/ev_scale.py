"""EV-Matching at scale: universal matching of 10k and 100k people (dissertation §3.2.4).

The density of the paper's setting is kept (1000 people per km², 100 m cells, 30 min in 1 min
windows), so 100k people walk in 10 x 10 km with 10 000 cells: 300 000 V-scenarios on 10 000
topics. Each run is the real command, ``trackctl ev-match LOG --out OUT --all --json``, started in
a child process that reports its own peak RSS. Engines: the local engine for every size, Spark
``local[2]`` for the sizes in ``--spark-sizes``.

    python benchmarks/ev_scale.py [--sizes 10000,100000] [--spark-sizes 10000] [--local-sizes ...]
                                  [--workdir DIR]

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


def child(log: str, out: str, engine: str) -> None:
    """Run ev-match in this process; print the report plus this process's peak RSS."""
    from trackctl.evmatch import EvMatchConfig, EvMatchProcessor
    from trackctl.metrics.report import jsonable_metrics
    from trackctl.processing import run_processors

    config = EvMatchConfig(engine=engine, master="local[2]" if engine == "spark" else None)
    t0 = time.perf_counter()
    (report,) = run_processors(log, out, [EvMatchProcessor(config)])
    metrics = jsonable_metrics(report.metrics)
    metrics["wall_seconds_with_copy"] = round(time.perf_counter() - t0, 1)
    metrics["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)
    # the Spark JVM is a child of this process: its peak shows here only if it was reaped
    # (pyspark does not always wait for it; 0 then means "not measured")
    metrics["children_peak_rss_mb"] = round(
        resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024, 1
    )
    print(json.dumps(metrics))


def simulate(n: int, path: Path) -> tuple[float, float]:
    """Simulate ``n`` people at the paper's density (in a child, for its peak RSS)."""
    area = 1000.0 * math.sqrt(n / 1000.0)
    code = (
        "import resource, sys\n"
        "from trackctl.sim.ev import EvScenario, simulate_ev\n"
        f"simulate_ev({str(path)!r}, EvScenario(people={n}, area_m={area}, seed=4))\n"
        "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)\n"
    )
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return time.perf_counter() - t0, float(proc.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="10000,100000")
    ap.add_argument("--spark-sizes", default="10000")
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
        f"{'V read':>7} {'V total':>7} {'V MB read':>9} | {'match s':>7} {'with copy s':>11} "
        f"{'peak MB':>7} {'JVM MB':>6}"
    )
    for n in sizes:
        log = workdir / f"ev_{n}.mcap"
        if not log.exists():
            sim_s, sim_mb = simulate(n, log)
            print(
                f"# simulated {n} people: {sim_s:.0f} s, peak {sim_mb:.0f} MB, "
                f"{log.stat().st_size / 1e6:.0f} MB log"
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
            jvm = (
                m["children_peak_rss_mb"]
                if engine == "spark" and m["children_peak_rss_mb"]
                else "-"
            )
            print(
                f"{n:>7} {engine:>6} | {m['requested']:>6} {100 * m['accuracy']:>7.2f}% "
                f"{m['unresolved']:>5} | {m['v_scenarios_read']:>7} {m['v_scenarios_total']:>7} "
                f"{m['v_bytes_read'] / 1e6:>9.1f} | {m['seconds']:>7.1f} "
                f"{m['wall_seconds_with_copy']:>11.1f} {m['peak_rss_mb']:>7.0f} "
                f"{jvm:>6}"
            )
            print("#   stages:", {k: v for k, v in m.items() if k.startswith("seconds_")})
            out.unlink(missing_ok=True)
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
