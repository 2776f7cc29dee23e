"""VM-Tracking in crowds: association time and identity as people in view grow (10/20/40/80).

Lobby (20 x 15 m, 6 cameras), 5 phone carriers among N people, simulated detections (the
paper's 0.35 m noise), 120 s. Printed per N: ``ms_per_frame_association`` (association,
cross-camera merging, track management and identity, per frame time), IDF1 of the carriers and
their mean error. The baseline is N = 10 in the same run (time ratio column). Each log is
processed ``--repeat`` times and the time printed is the fastest run (as ``timeit`` does: on a
shared or throttled machine the same run varies by half; the median is printed beside it).

    python benchmarks/vm_crowd.py [--duration 120] [--seed 3] [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path

from trackctl.processing import run_processors
from trackctl.sim.vm import VmScenario, simulate_vm
from trackctl.vmtrack import VmTrackProcessor


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=120.0)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    base = None
    print(
        f"{'people':>6s} {'ms/frame assoc':>14s} {'median':>7s} {'x of 10':>7s} "
        f"{'IDF1':>6s} {'error m':>7s}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for n in (10, 20, 40, 80):
            log = Path(tmp) / f"crowd{n}.mcap"
            simulate_vm(
                str(log),
                VmScenario(
                    field="lobby", users=5, nonusers=n - 5, duration_s=args.duration, seed=args.seed
                ),
            )
            times = []
            for _ in range(max(1, args.repeat)):
                (rep,) = run_processors(log, None, [VmTrackProcessor()])
                m = rep.metrics
                times.append(float(m["ms_per_frame_association"]))  # type: ignore[arg-type]
            ms, med = min(times), statistics.median(times)
            base = base or ms
            print(
                f"{n:6d} {ms:14.2f} {med:7.2f} {ms / base:7.1f} "
                f"{m['idf1']:>6} {m['error_m_mean']:>7}"
            )


if __name__ == "__main__":
    main()
