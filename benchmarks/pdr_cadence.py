"""Pedestrian dead reckoning at other walking paces: step-count error on time-stretched real walks.

The six walks of ``../shared/data/phones/`` are one walker at ~1.8 steps/s. Other walkers step
slower or faster; to see where the step detector holds, each walk's time axis is stretched by a
factor (1.3: the same samples played 1.3x slower, steps at 1/1.3 the rate), which keeps the true
count and every carry's waveform. A stretched walk is not a slow walk (a real slow walker's
impacts are softer), so this bounds the detector's pace range from one side only. Prints the
error per walk and stretch at the walk's own rate (100 Hz, stretched with it) and, for the
unstretched walk, at 5 Hz (every 20th sample), the issue's two rates.

    python benchmarks/pdr_cadence.py [--stretch 0.75,1,1.3,1.45,1.6]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from trackctl.pdr import detect_steps

PHONES = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "phones"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stretch", default="0.75,0.85,1,1.15,1.3,1.45,1.6")
    args = ap.parse_args()
    stretches = [float(s) for s in args.stretch.split(",")]
    walks = []
    for path in sorted(PHONES.glob("user1_*.csv")):
        d = pd.read_csv(path, header=None).to_numpy(float)
        d = d[np.linalg.norm(d[:, 1:4], axis=1) > 1.0]  # the sensor warming up
        t = (d[:, 0] - d[0, 0]) / 1e9
        walking = detect_steps(t, d[:, 1:4])
        cadence = float(np.median(walking.cadence_hz[walking.cadence_hz > 0]))
        walks.append((path.name.split("_")[1], t, d[:, 1:4], d[-1, 5] - d[0, 5], cadence))
    print("step-count error (%) per stretch; the walk's median walking cadence / stretch, Hz")
    print(f"{'walk':12s} {'Hz':>5s} " + " ".join(f"{s:>7.2f}" for s in stretches) + "   5 Hz")
    for name, t, acc, true, cadence in walks:
        cells = []
        for s in stretches:
            r = detect_steps(t * s, acc)
            cells.append(f"{100 * (r.steps - true) / true:+7.1f}")
        r5 = detect_steps(t[::20], acc[::20])
        print(
            f"{name:12s} {cadence:5.2f} "
            + " ".join(cells)
            + f" {100 * (r5.steps - true) / true:+6.1f}"
        )
    mean_cad = float(np.mean([w[4] for w in walks]))
    print(f"{'cadence':12s} {'':5s} " + " ".join(f"{mean_cad / s:7.2f}" for s in stretches))


if __name__ == "__main__":
    main()
