"""S-Mirror under load: 1..500 requesters on a 1 MB/s link, unicast vs broadcast (Table 4.2 analog).

Each node has one transmit queue drained at the link's throughput (trackctl.smirror.link). The log
holds a fleet of three robots (each with its own LED colours); from 3 requesters on all three ask
the nodes for images and are localized and scored, and requesters beyond them are traffic on every
node frame. The 1-requester row localizes r1 alone. For each requester count the script runs
unicast only, broadcast only and
the paper's rule (broadcast from 15 requests) and prints the localization delay of image answers
in coverage, the share of our answers that arrive, the queueing, the link's kB/s, the mean error
of all localized robots and the worst robot's.
The baseline is the single-requester row of each mode, measured in the same run. Run:

    python benchmarks/smirror_requesters.py [--workdir DIR] [--counts 1,5,10,15,20,50,100,200,500]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from trackctl.logs import LogReader
from trackctl.sim.smirror import SmirrorScenario, simulate_smirror
from trackctl.smirror import SmirrorConfig, localize, report_metrics

MODES = {"unicast": 10**9, "broadcast": 1, "paper rule (15)": 15}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", type=Path)
    ap.add_argument("--counts", default="1,3,5,10,15,20,50,100,200,500")
    args = ap.parse_args(argv)
    counts = [int(c) for c in args.counts.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        work = args.workdir or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        log = work / "requesters.mcap"
        if not log.exists():
            t = time.perf_counter()
            simulate_smirror(str(log), SmirrorScenario(paths=1, people=6, seed=1, robots=3))
            print(f"# generated {log.name} in {time.perf_counter() - t:.0f} s")
        print(
            f"{'requesters':>10} {'mode':>16} | {'delay ms':>9} {'x 1 req':>8} "
            f"{'delivered':>9} {'queue ms':>9} {'dropped':>7} {'kB/s':>8} {'err m':>6} "
            f"{'robots':>6} {'worst':>6}"
        )
        base: dict[str, float] = {}
        for n in counts:
            for mode, threshold in MODES.items():
                cfg = SmirrorConfig(
                    requesters=n, broadcast_threshold=threshold, robot="r1" if n < 3 else None
                )
                res = localize(LogReader(log), cfg)
                m = report_metrics(res, cfg)
                errs = [report_metrics(one, cfg)["error_m_mean"] for one in res.per_robot.values()]
                worst = max((e for e in errs if isinstance(e, float)), default=None)
                delay = float(m["delay_ms_mean_in_coverage"] or 0.0)
                base.setdefault(mode, delay)
                print(
                    f"{n:>10} {mode:>16} | {delay:>9.1f} {delay / base[mode]:>8.2f} "
                    f"{m['delivered_share']!s:>9} {m['queue_ms_mean']!s:>9} "
                    f"{m['answers_dropped']:>7} {m['kbps_mean']!s:>8} {m['error_m_mean']!s:>6} "
                    f"{len(res.per_robot):>6} {worst!s:>6}"
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
