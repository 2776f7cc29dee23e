"""Replay throughput and memory: `trackctl replay LOG --speed 0 --format jsonl`.

Builds logs of 10k and 100k messages (two phones' IMU at 100 Hz, RSSI scans, wheel odometry),
then measures, in the same run:

* baseline: the plain ``mcap`` reader iterating raw records in log-time order (no decoding);
* in-process: ``trackctl.logs.replay.replay_jsonl`` producing every JSON line;
* end to end: ``trackctl replay`` as a subprocess writing to /dev/null (interpreter start
  included), with the child's peak RSS.

It prints messages per second, the ratio to the baseline, and the peak-RSS ratio between the two
sizes (flat memory: replay streams chunk by chunk). Run:

    python benchmarks/replay_throughput.py [--sizes 10000,100000]
"""

from __future__ import annotations

import argparse
import io
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mcap.reader import make_reader

from trackctl.logs import (
    Imu,
    LogReader,
    LogWriter,
    Quat,
    RssiReading,
    RssiScan,
    Vec3,
    WheelOdometry,
)
from trackctl.logs.replay import replay_jsonl

TARGET_MSG_S = 20_000

_CHILD = """
import resource, subprocess, sys, time
t0 = time.perf_counter()
with open("/dev/null", "wb") as sink:
    rc = subprocess.run(sys.argv[1:], stdout=sink).returncode
wall = time.perf_counter() - t0
peak_kib = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
print(rc, wall, peak_kib)
"""


def make_log(path: Path, n: int, seed: int = 0) -> None:
    """A log of exactly ``n`` messages, in time order."""
    import random

    rng = random.Random(seed)
    with LogWriter(path) as w:
        t = 0
        i = 0
        while i < n:
            for phone in ("p1", "p2"):
                if i >= n:
                    break
                w.write(
                    f"/phone/{phone}/imu",
                    Imu(
                        t,
                        f"phone/{phone}",
                        Vec3(rng.gauss(0, 0.3), rng.gauss(0, 0.3), 9.81 + rng.gauss(0, 0.3)),
                        Vec3(rng.gauss(0, 0.05), rng.gauss(0, 0.05), rng.gauss(0, 0.1)),
                        Quat(0.0, 0.0, 0.0, 1.0),
                    ),
                )
                i += 1
            if i < n and (t // 10_000_000) % 4 == 0:
                w.write(
                    "/robot/r1/odom", WheelOdometry(t, "robot/r1", t // 1_000_000, t // 990_000)
                )
                i += 1
            if i < n and (t // 10_000_000) % 100 == 0:
                w.write(
                    "/rssi",
                    RssiScan(
                        t,
                        "ap1",
                        tuple(RssiReading(f"aa:bb:cc:00:00:{k:02x}", -40.0 - k) for k in range(5)),
                    ),
                )
                i += 1
            t += 10_000_000


def baseline(path: Path) -> float:
    t0 = time.perf_counter()
    n = 0
    with path.open("rb") as f:
        for _ in make_reader(f).iter_messages(log_time_order=True):
            n += 1
    return n / (time.perf_counter() - t0)


def in_process(path: Path) -> float:
    t0 = time.perf_counter()
    out = io.StringIO()
    n = 0
    for _, line in replay_jsonl(LogReader(path), speed=0):
        out.write(line)
        out.write("\n")
        n += 1
    return n / (time.perf_counter() - t0)


def end_to_end(path: Path, n: int) -> tuple[float, float]:
    exe = Path(sys.executable).parent / "trackctl"
    cmd = [str(exe), "replay", str(path), "--speed", "0", "--format", "jsonl"]
    res = subprocess.run(
        [sys.executable, "-c", _CHILD, *cmd], capture_output=True, text=True, check=True
    )
    rc, wall, peak_kib = res.stdout.split()
    if int(rc) != 0:
        raise SystemExit(f"trackctl replay failed with exit code {rc}")
    return n / float(wall), int(peak_kib) / 1024


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="10000,100000")
    parser.add_argument("--json", action="store_true", help="also print one JSON object")
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            path = Path(tmp) / f"{n}.mcap"
            make_log(path, n)
            base = baseline(path)
            ours = in_process(path)
            e2e, rss = end_to_end(path, n)
            rows.append(
                {
                    "messages": n,
                    "mib": path.stat().st_size / 2**20,
                    "baseline": base,
                    "in_process": ours,
                    "subprocess": e2e,
                    "peak_rss_mib": rss,
                }
            )
    print("replay --speed 0 --format jsonl (msg/s; baseline = raw mcap record iteration)")
    print(
        f"{'messages':>9} {'log MiB':>8} {'baseline':>10} {'in-proc':>10} {'ratio':>6} "
        f"{'subproc':>10} {'ratio':>6} {'peak RSS MiB':>13}"
    )
    for r in rows:
        print(
            f"{r['messages']:>9} {r['mib']:>8.2f} {r['baseline']:>10.0f} {r['in_process']:>10.0f} "
            f"{r['in_process'] / r['baseline']:>6.2f} {r['subprocess']:>10.0f} "
            f"{r['subprocess'] / r['baseline']:>6.2f} {r['peak_rss_mib']:>13.1f}"
        )
    big = rows[-1]
    verdict = "PASS" if big["subprocess"] >= TARGET_MSG_S else "FAIL"
    print(
        f"target >= {TARGET_MSG_S} msg/s end to end on {big['messages']} messages: "
        f"{big['subprocess']:.0f} msg/s {verdict}"
    )
    if len(rows) > 1:
        ratio = rows[-1]["peak_rss_mib"] / rows[0]["peak_rss_mib"]
        flat = "PASS" if ratio < 1.5 else "FAIL"
        print(
            f"peak RSS {rows[-1]['messages']} / {rows[0]['messages']} messages: {ratio:.2f} "
            f"(flat if < 1.5) {flat}"
        )
    if args.json:
        print(json.dumps({"rows": rows}))


if __name__ == "__main__":
    main()
