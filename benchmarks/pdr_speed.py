"""Pedestrian dead reckoning on real phone traces: step-count error and speed against a baseline.

For each walk of ``../shared/data/phones/`` (Oxford step-counter validation set, 100 Hz
accelerometer, true step counts), prints the step count of ``trackctl.pdr.detect_steps`` at
100 Hz and decimated to 5 Hz, its error, and how many times faster than real time it runs. The
baseline, measured in the same run on the same samples, is VM-Tracking's per-sample
periodogram (``trackctl.vmtrack.motion.PhoneMotion``, which the issue measured at 15x slower
than real time per phone at 100 Hz).

    python benchmarks/pdr_speed.py [--baseline-seconds 30]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pandas as pd

from trackctl.logs.messages import Imu, Vec3
from trackctl.pdr import detect_steps
from trackctl.vmtrack.motion import PhoneMotion

PHONES = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "phones"


def _best(fn, repeat: int = 3) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def _baseline_rate(t: np.ndarray, acc: np.ndarray, seconds: float) -> float:
    """Real-time factor of PhoneMotion on the first ``seconds`` of a walk."""
    n = int(np.searchsorted(t - t[0], seconds))
    pm = PhoneMotion("p")
    for ti, a in zip(t[:n], acc[:n], strict=True):
        pm.add(Imu(int(ti * 1e9), "phone/p", Vec3(*map(float, a))))
    t0 = time.perf_counter()
    pm.finish()
    return seconds / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline-seconds", type=float, default=30.0)
    args = ap.parse_args()
    print(
        f"{'walk':12s} {'true':>5s} {'100 Hz':>7s} {'err':>6s} {'5 Hz':>5s} {'err':>6s} "
        f"{'x real time':>11s} {'baseline x':>10s} {'speed-up':>8s}"
    )
    for path in sorted(PHONES.glob("user1_*.csv")):
        d = pd.read_csv(path, header=None).to_numpy()
        t, acc, true = d[:, 0] / 1e9, d[:, 1:4], d[-1, 5] - d[0, 5]
        dur = t[-1] - t[0]
        r100 = detect_steps(t, acc)
        r5 = detect_steps(t[::20], acc[::20])
        rt = dur / _best(lambda t=t, acc=acc: detect_steps(t, acc))
        base = _baseline_rate(t, acc, args.baseline_seconds)
        name = path.name.split("_")[1]
        print(
            f"{name:12s} {true:5.0f} {r100.steps:7d} {100 * (r100.steps - true) / true:+5.1f}% "
            f"{r5.steps:5d} {100 * (r5.steps - true) / true:+5.1f}% {rt:11.0f} {base:10.1f} "
            f"{rt / base:8.0f}"
        )


if __name__ == "__main__":
    main()
