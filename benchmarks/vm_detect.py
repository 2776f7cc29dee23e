"""Motion-predicted vs full-frame person detection on rendered frames, and real-time factor.

VM-Tracking's claim (§3.1.2 C): motion sensors tell where (image region) and how big (pyramid
level) each person will be, so the sliding-window detector need not search whole frames. This
script renders a lobby (6 cameras, 640x480, 3 fps) and runs ``vm-track`` twice on the same log,
once with ``--search full`` (the baseline, measured in the same run) and once with
``--search predicted``, alternating the two ``--repeat`` times and keeping each one's fastest run.
OpenCV is pinned to one thread, so the figures are for one core.

Printed: detection ms per frame time (all 6 cameras), the speed-up, detection recall (people with
a detection within 1 m), tracking figures, and the whole pipeline's real-time factor (log duration
over processing time; > 1 is faster than real time).

    python benchmarks/vm_detect.py [--duration 60] [--repeat 2] [--seed 7]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import cv2

from trackctl.processing import run_processors
from trackctl.sim.vm import VmScenario, simulate_vm
from trackctl.vmtrack import FrameConfig, VmTrackConfig, VmTrackProcessor


def _run(log: Path, out: Path, predicted: bool) -> tuple[dict, float]:
    cfg = VmTrackConfig(frames=FrameConfig(predicted=predicted))
    t0 = time.perf_counter()
    (rep,) = run_processors(log, out, [VmTrackProcessor(cfg)])
    return dict(rep.metrics), time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--users", type=int, default=5)
    ap.add_argument("--nonusers", type=int, default=2)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "lobby-frames.mcap"
        t0 = time.perf_counter()
        simulate_vm(
            str(log),
            VmScenario(
                field="lobby",
                users=args.users,
                nonusers=args.nonusers,
                duration_s=args.duration,
                seed=args.seed,
                frames=True,
            ),
        )
        print(
            f"rendered {args.duration:g} s lobby, 6 cameras 640x480 @ 3 fps "
            f"({log.stat().st_size / 1e6:.1f} MB) in {time.perf_counter() - t0:.1f} s"
        )
        best: dict[str, tuple[dict, float]] = {}
        for _ in range(args.repeat):
            for name, predicted in (("full", False), ("predicted", True)):
                metrics, wall = _run(log, Path(tmp) / f"{name}.mcap", predicted)
                old = best.get(name)
                if (
                    old is None
                    or metrics["ms_per_frame_detection"] < old[0]["ms_per_frame_detection"]
                ):
                    best[name] = (metrics, wall)
    keys = [
        ("ms_per_frame_detection", "detection ms / frame time (6 cams)"),
        ("ms_per_frame_decode", "JPEG decode ms / frame time"),
        ("ms_per_frame", "whole pipeline ms / frame time"),
        ("det_recall", "detection recall"),
        ("det_error_m_mean", "detection ground error m"),
        ("full_searches", "full-frame searches"),
        ("region_searches", "region searches"),
        ("idf1", "IDF1 (phone carriers)"),
        ("error_m_mean", "tracking error m"),
    ]
    print(f"\n{'':40s} {'full (baseline)':>16s} {'predicted':>12s}")
    for key, label in keys:
        a, b = best["full"][0].get(key), best["predicted"][0].get(key)
        print(f"{label:40s} {a!s:>16s} {b!s:>12s}")
    full_ms = best["full"][0]["ms_per_frame_detection"]
    pred_ms = best["predicted"][0]["ms_per_frame_detection"]
    print(f"\nspeed-up of motion-predicted detection: {full_ms / pred_ms:.2f}x (target >= 2x)")
    recall_ok = best["predicted"][0]["det_recall"] >= best["full"][0]["det_recall"] - 0.005
    print(
        "recall predicted vs full: "
        f"{best['predicted'][0]['det_recall']} vs {best['full'][0]['det_recall']} "
        f"({'equal or better' if recall_ok else 'LOWER'}; within 0.5 points counts as equal)"
    )
    for name in ("predicted", "full"):
        wall = best[name][1]
        print(
            f"real-time factor ({name}): {args.duration / wall:.2f} "
            f"({args.duration:g} s of log in {wall:.1f} s, one core)"
        )


if __name__ == "__main__":
    main()
