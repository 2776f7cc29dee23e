"""VM-Tracking's default path against its no-refinement path: CPU seconds and IDF1.

For each seed, simulates the 300 s lobby (``trackctl simulate vm --field lobby --users 5
--nonusers 2 --duration 300 --seed S``), then runs ``trackctl vm-track LOG --json`` (the
default: phone re-tracking, ``--refine auto``) and ``--no-retrack`` on it, each in its own
process, and prints the child's CPU seconds (user + system, one core), the IDF1 and the phones
whose alignment was searched. The ratio is default / ``--no-retrack`` in the same run; the
check is ratio <= 3.0 and IDF1 >= 0.99 per seed (exit 1 otherwise). ``--full`` adds the
``--refine full`` row (every phone's alignment searched: ~10 min per seed on one core).

    python benchmarks/vm_speed.py [--seeds 7,8] [--duration 300] [--full]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

TRACKCTL = Path(sys.executable).parent / "trackctl"
MAX_RATIO = 3.0
MIN_IDF1 = 0.99


def _cpu_run(args: list[str]) -> tuple[float, str]:
    """Run ``trackctl ARGS``; its CPU seconds (user + system) and stdout."""
    before = os.times()
    done = subprocess.run(
        [str(TRACKCTL), *args], capture_output=True, text=True, check=False, timeout=7200
    )
    after = os.times()
    if done.returncode != 0:
        raise SystemExit(f"trackctl {' '.join(args)} failed:\n{done.stderr}")
    cpu = (after.children_user - before.children_user) + (
        after.children_system - before.children_system
    )
    return cpu, done.stdout


def _row(log: Path, extra: list[str]) -> tuple[float, float, int]:
    cpu, out = _cpu_run(["vm-track", str(log), "--json", "--quiet", *extra])
    report = json.loads(out)
    searched = sum(int(v or 0) for k, v in report.items() if k.startswith("searched/"))
    return cpu, float(report["idf1"]), searched


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="7,8")
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--full", action="store_true", help="also run --refine full (slow)")
    args = ap.parse_args()
    variants = [("--no-retrack", ["--no-retrack"]), ("default", [])]
    if args.full:
        variants.append(("--refine full", ["--refine", "full"]))
    print(f"{'seed':>4s} {'variant':14s} {'CPU s':>7s} {'IDF1':>7s} {'searched':>8s} {'ratio':>6s}")
    ok = True
    with tempfile.TemporaryDirectory() as tmp:
        for seed in (int(s) for s in args.seeds.split(",")):
            log = Path(tmp) / f"lobby{seed}.mcap"
            _cpu_run(
                ["simulate", "vm", "--field", "lobby", "--users", "5", "--nonusers", "2",
                 "--duration", str(args.duration), "--seed", str(seed), "--out", str(log), "-q"]
            )  # fmt: skip
            base = None
            for name, extra in variants:
                cpu, idf1, searched = _row(log, extra)
                base = cpu if base is None else base
                ratio = cpu / base
                print(f"{seed:4d} {name:14s} {cpu:7.1f} {idf1:7.4f} {searched:8d} {ratio:6.2f}")
                if name == "default":
                    ok &= ratio <= MAX_RATIO and idf1 >= MIN_IDF1
    verdict = "PASS" if ok else "FAIL"
    print(f"default / --no-retrack <= {MAX_RATIO} and IDF1 >= {MIN_IDF1} on every seed: {verdict}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
