"""``trackctl info`` on a large log: O(1) in message count through the summary.

Writes a log of N small IMU messages on 4 topics (default 2,000,000), then times, in the same run:

* baseline: ``mcap``'s ``SeekingReader(f).get_summary()`` (footer + summary section only);
* ``trackctl.logs.info.log_info(LogReader(path))`` (what ``trackctl info --json`` prints);
* ``trackctl info --json`` as a subprocess (interpreter start included).

Target: the library call within 3x of the baseline.

    python benchmarks/info_speed.py [--messages 2000000] [--keep PATH]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from mcap.reader import SeekingReader

from trackctl.logs.codecs import codec_for_type
from trackctl.logs.info import log_info
from trackctl.logs.messages import Imu, Vec3
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter


def build(path: Path, n: int) -> None:
    codec = codec_for_type(Imu)
    topics = [f"/phone/p{k}/imu" for k in range(4)]
    payloads = [
        codec.encode(Imu(0, f"phone/p{k}", Vec3(0.1, 0.2, 9.8), Vec3(0.0, 0.0, 0.1)))
        for k in range(4)
    ]
    with LogWriter(path) as w:
        for i in range(n):
            k = i % 4
            w.write_encoded(topics[k], codec, payloads[k], i * 2_500_000)


def best_of(fn, repeat: int = 5) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--messages", type=int, default=2_000_000)
    ap.add_argument("--keep", type=Path, help="write the log here and keep it")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = args.keep or Path(tmp) / "big.mcap"
        t0 = time.perf_counter()
        build(path, args.messages)
        print(
            f"built {args.messages} messages, {path.stat().st_size / 2**20:.1f} MiB "
            f"in {time.perf_counter() - t0:.1f} s"
        )

        def baseline() -> None:
            with path.open("rb") as f:
                SeekingReader(f).get_summary()

        def ours() -> None:
            log_info(LogReader(path))

        base = best_of(baseline)
        lib = best_of(ours)
        t0 = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-m", "trackctl.cli.main", "info", str(path), "--json"],
            capture_output=True,
            check=True,
        )
        sub = time.perf_counter() - t0
        info = json.loads(proc.stdout)
        assert info["message_count"] == args.messages, info["message_count"]
        ratio = lib / base
        print("info on a large log (seconds, median of 5; baseline = mcap get_summary)")
        print(" messages   baseline   log_info  ratio  subprocess")
        print(f" {args.messages:8d}   {base:8.4f}   {lib:8.4f}  {ratio:5.2f}  {sub:10.3f}")
        verdict = "PASS" if ratio <= 3 else "FAIL"
        print(f"target log_info within 3x of get_summary: {ratio:.2f}x {verdict}")


if __name__ == "__main__":
    main()
