"""Pedestrian dead reckoning at other walking paces and at 5 Hz: step-count error on real walks.

The six walks of ``../shared/data/phones/`` are one walker at ~1.8 steps/s. Other walkers step
slower or faster; to see where the step detector holds, each walk's time axis is stretched by a
factor (1.3: the same samples played 1.3x slower, steps at 1/1.3 the rate), which keeps the true
count and every carry's waveform. A stretched walk is not a slow walk (a real slow walker's
impacts are softer), so this bounds the detector's pace range from one side only.

Three tables:

1. the error per walk and stretch at the walk's own rate (100 Hz, stretched with it);
2. 5 Hz at every decimation phase: every 20th sample starting at sample 0..19 (plain decimation,
   no anti-alias filter: every harmonic of the gait folds into 0-2.5 Hz), worst and mean error
   over the 20 phases, then the same for the walk stretched to +-15 % cadence and re-sampled at
   5 Hz at 20 phases (0.01 s apart; linear interpolation of the 100 Hz samples), and for a phone
   that low-pass filters before decimating (8th-order Butterworth at 2.25 Hz, zero phase);
3. with ``--holdout``, the held-out protocol for the aliased path's tuned parameters (comb
   harmonics, tooth weight, cadence-change cost, amplitude gap): a grid is scored on three walks,
   the best setting (smallest worst error over every variant of table 2, then smallest mean) is
   checked on the other three, then the halves swap. Every 2nd phase, to keep it to minutes.

    python benchmarks/pdr_cadence.py [--stretch 0.75,1,1.3,1.45,1.6] [--holdout]
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import signal

from trackctl.pdr import StepConfig, detect_steps

PHONES = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "phones"
DECIMATE = 20
"""100 Hz to 5 Hz."""
CADENCE_SCALES = (1.15, 1 / 1.15)
"""Stretches of the 5 Hz variants: cadence -13 % and +15 %."""
SPLITS = (("armband", "bag", "neckpouch"), ("backpocket", "frontpocket", "hand"))
GRID = {
    "aliased_harmonics": (4, 6, 8),
    "aliased_tooth_weight": (0.25, 0.5, 0.75),
    "cadence_change_cost": (0.0, 3.0, 10.0, 30.0),
    "aliased_gap_s": (0.0, 3.0),
}


@dataclasses.dataclass
class Walk:
    name: str
    t: np.ndarray
    acc: np.ndarray
    true: float
    cadence: float


def _walks() -> list[Walk]:
    walks = []
    for path in sorted(PHONES.glob("user1_*.csv")):
        d = pd.read_csv(path, header=None).to_numpy(float)
        true = d[-1, 5] - d[0, 5]
        d = d[np.linalg.norm(d[:, 1:4], axis=1) > 1.0]  # the sensor warming up
        t = (d[:, 0] - d[0, 0]) / 1e9
        walking = detect_steps(t, d[:, 1:4])
        cadence = float(np.median(walking.cadence_hz[walking.cadence_hz > 0]))
        walks.append(Walk(path.name.split("_")[1], t, d[:, 1:4], true, cadence))
    return walks


def _variants(w: Walk, every: int = 1) -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    """5 Hz versions of a walk: plain decimation at each phase, stretched and re-sampled,
    low-pass filtered then decimated."""
    phases = range(0, DECIMATE, every)
    out: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {
        "5 Hz": [(w.t[o::DECIMATE], w.acc[o::DECIMATE]) for o in phases]
    }
    for s in CADENCE_SCALES:
        runs = []
        for o in phases:
            tau = np.arange(o / 100, w.t[-1] * s, DECIMATE / 100)
            acc = np.column_stack([np.interp(tau / s, w.t, w.acc[:, i]) for i in range(3)])
            runs.append((tau, acc))
        out[f"cadence x{1 / s:.2f}"] = runs
    sos = signal.butter(8, 2.25, fs=100.0, output="sos")
    smooth = signal.sosfiltfilt(sos, w.acc, axis=0)
    out["low-passed"] = [(w.t[o::DECIMATE], smooth[o::DECIMATE]) for o in phases]
    return out


def _errors(w: Walk, runs: list[tuple[np.ndarray, np.ndarray]], cfg: StepConfig) -> np.ndarray:
    return np.array([100 * (detect_steps(t, a, cfg).steps - w.true) / w.true for t, a in runs])


def _stretch_table(walks: list[Walk], stretches: list[float]) -> None:
    print("step-count error (%) per stretch at the walk's own rate; median walking cadence, Hz")
    print(f"{'walk':12s} {'Hz':>5s} " + " ".join(f"{s:>7.2f}" for s in stretches))
    for w in walks:
        cells = []
        for s in stretches:
            r = detect_steps(w.t * s, w.acc)
            cells.append(f"{100 * (r.steps - w.true) / w.true:+7.1f}")
        print(f"{w.name:12s} {w.cadence:5.2f} " + " ".join(cells))
    mean_cad = float(np.mean([w.cadence for w in walks]))
    print(f"{'cadence':12s} {'':5s} " + " ".join(f"{mean_cad / s:7.2f}" for s in stretches))


def _phase_table(walks: list[Walk]) -> None:
    print()
    print("5 Hz at every decimation phase (20): step-count error (%), worst and mean over phases")
    cfg = StepConfig()
    worst_all = 0.0
    for w in walks:
        for label, runs in _variants(w).items():
            e = _errors(w, runs, cfg)
            worst = float(e[np.argmax(np.abs(e))])
            worst_all = max(worst_all, abs(worst))
            cells = " ".join(f"{x:+.1f}" for x in e)
            print(
                f"{w.name:12s} {label:14s} true {w.true:4.0f} worst {worst:+5.1f} "
                f"mean {e.mean():+5.1f} | {cells}"
            )
    print(f"worst over every walk, variant and phase: {worst_all:.1f} %")


def _holdout(walks: list[Walk]) -> None:
    print()
    print("held-out protocol: tune on three walks (every 2nd phase, every variant), check on three")
    variants = {w.name: [r for runs in _variants(w, every=2).values() for r in runs] for w in walks}
    by_name = {w.name: w for w in walks}
    keys = list(GRID)
    scores: dict[tuple[float, ...], dict[str, np.ndarray]] = {}
    for values in itertools.product(*GRID.values()):
        cfg = dataclasses.replace(StepConfig(), **dict(zip(keys, values, strict=True)))
        scores[values] = {n: _errors(by_name[n], variants[n], cfg) for n in by_name}

    def summary(values: tuple[float, ...], names: tuple[str, ...]) -> tuple[float, float]:
        e = np.abs(np.concatenate([scores[values][n] for n in names]))
        return float(e.max()), float(e.mean())

    default = tuple(getattr(StepConfig(), k) for k in keys)
    for tune, check in (SPLITS, SPLITS[::-1]):
        best = min(scores, key=lambda v, tune=tune: summary(v, tune))
        print(
            f"tuned on {', '.join(tune)}: "
            + ", ".join(f"{k}={v}" for k, v in zip(keys, best, strict=True))
        )
        for label, v in (("tuned", best), ("shipped", default)):
            (tw, tm), (cw, cm) = summary(v, tune), summary(v, check)
            print(
                f"  {label:8s} tuning walks worst {tw:4.1f} % mean {tm:3.1f} %; "
                f"held-out {', '.join(check)} worst {cw:4.1f} % mean {cm:3.1f} %"
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stretch", default="0.75,0.85,1,1.15,1.3,1.45,1.6")
    ap.add_argument("--holdout", action="store_true", help="run the held-out tuning protocol")
    args = ap.parse_args()
    walks = _walks()
    _stretch_table(walks, [float(s) for s in args.stretch.split(",")])
    _phase_table(walks)
    if args.holdout:
        _holdout(walks)


if __name__ == "__main__":
    main()
