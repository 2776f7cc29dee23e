"""Seeded mutations of the text inputs of ``record``: sensor CSV files (IMU, odometry, RSSI),
an image folder's frame-times CSV with hostile video options, and live JSON lines on stdin."""

from __future__ import annotations

import json
import random
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.fuzz.common import Fuzz, mutate_text

CSV_TOKENS = (
    "nan",
    "inf",
    "-inf",
    "1e308",
    "1e999",
    "-1",
    "0",
    "9" * 30,
    "9" * 5000,
    "",
    "x",
    "1,2,3",
    "\x00",
    "1e-300",
    "0x10",
    "1_000",
    " 1",
    '"1"',
)
SENSORS = {
    "imu": "t_s,ax,ay,az,gx,gy,gz\n"
    + "".join(f"{i * 0.02:.2f},0.1,0.0,9.81,0.0,0.0,0.05\n" for i in range(30)),
    "odom": "t_s,left_ticks,right_ticks\n"
    + "".join(f"{i * 0.04:.2f},{10 * i},{11 * i}\n" for i in range(30)),
    "rssi": "t_s,observer,eid,rssi_dbm\n"
    + "".join(f"{i:.1f},ap1,aa:bb:cc:00:00:01,{-50 - i}\n" for i in range(10)),
}


def _csv_mutant(text: str, rng: random.Random) -> str:
    if rng.random() < 0.6:  # a cell replaced
        rows = [r.split(",") for r in text.splitlines()]
        for _ in range(rng.choice([1, 1, 3])):
            r = rng.randrange(len(rows))
            rows[r][rng.randrange(len(rows[r]))] = rng.choice(CSV_TOKENS)
        return "\n".join(",".join(r) for r in rows) + "\n"
    return mutate_text(text, rng, CSV_TOKENS)


def test_fuzz_sensor_csv(tmp_path: Path, record_property: pytest.RecordProperty) -> None:
    fuzz = Fuzz("sensor CSV", record_property)
    kinds = sorted(SENSORS)
    last: Path | None = None
    for case in range(45):
        rng = random.Random(f"csv/{case}")
        kind = kinds[case % len(kinds)]
        path = tmp_path / f"{kind}{case}.csv"
        path.write_bytes(_csv_mutant(SENSORS[kind], rng).encode("utf-8", "surrogateescape"))
        option = ["--rssi", str(path)] if kind == "rssi" else [f"--{kind}", f"x={path}"]
        unit = ["--time-unit", rng.choice(["s", "ms", "ns"])] if case % 5 == 0 else []
        fuzz.cases += 1
        fuzz.invoke(["record", str(tmp_path / "o.mcap"), *option, *unit, "-q"], [path])
        last = path
    assert last is not None
    fuzz.cases += 1
    fuzz.measure(["record", str(tmp_path / "m.mcap"), "--imu", f"x={last}", "-q"], [last])
    fuzz.check()


VIDEO_VALUES = ("0", "-1", "1e-300", "1e300", "nan", "inf", "-inf", "1e30", "9" * 30, "0.5")


def test_fuzz_video_frame_times_and_args(
    tmp_path: Path, record_property: pytest.RecordProperty
) -> None:
    fuzz = Fuzz("video frame-times/args", record_property)
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(4):
        cv2.imwrite(str(folder / f"f{i}.png"), np.full((8, 8, 3), 40 * i, np.uint8))
    video = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (16, 16))
    for i in range(5):
        writer.write(np.full((16, 16, 3), 40 * i, np.uint8))
    writer.release()
    times = "file,t\n" + "".join(f"f{i}.png,{0.1 * i:.1f}\n" for i in range(4))
    for case in range(40):
        rng = random.Random(f"video/{case}")
        args = ["record", str(tmp_path / "o.mcap"), "-q"]
        inputs = [folder, video]
        if case % 2:
            csv = tmp_path / f"t{case}.csv"
            csv.write_bytes(_csv_mutant(times, rng).encode("utf-8", "surrogateescape"))
            args += ["--video", f"c={folder}", "--frame-times", str(csv)]
            inputs.append(csv)
        else:
            args += ["--video", f"c={video}"]
        for option in rng.sample(["--fps", "--video-start", "--start", "--end", "--rate"], 2):
            args.append(f"{option}={rng.choice(VIDEO_VALUES)}")
        fuzz.cases += 1
        fuzz.invoke(args, inputs)
    fuzz.cases += 1
    fuzz.measure(
        ["record", str(tmp_path / "m.mcap"), "--video", f"c={video}", "--fps=1e-300"], [video]
    )
    fuzz.check()


GOOD = {
    "topic": "/phone/p1/imu",
    "schema": "trackctl.Imu",
    "log_time_ns": 1,
    "message": {
        "timestamp": {"sec": 0, "nsec": 0},
        "frame_id": "phone/p1",
        "accel_mps2": {"x": 0.5, "y": 0.1, "z": 9.8},
        "gyro_rps": {"x": 0.0, "y": 0.0, "z": 0.29},
    },
}
JSON_TOKENS = (
    "NaN",
    "Infinity",
    "1e999",
    "9" * 5000,
    "-1",
    "null",
    "[]",
    "{}",
    '"x"',
    "true",
    "1e308",
    str(1 << 64),
    "0.0",
)


def _line_mutant(rng: random.Random, t: int) -> bytes:
    line = json.dumps({**GOOD, "log_time_ns": t})
    kind = rng.choice(["token", "token", "topic", "schema", "cut", "flip", "long"])
    if kind == "token":
        spots = [i for i, ch in enumerate(line) if ch == ":"]
        i = rng.choice(spots)
        end = min((line.find(c, i + 1) for c in ",}" if line.find(c, i + 1) > 0), default=i + 1)
        return (line[: i + 1] + " " + rng.choice(JSON_TOKENS) + line[end:]).encode()
    if kind == "topic":
        return line.replace(
            "/phone/p1/imu", rng.choice(["", "/a" * 300, "/x\u0000", "imu"])
        ).encode()
    if kind == "schema":
        return line.replace("trackctl.Imu", rng.choice(["trackctl.Detections", "x", ""])).encode()
    if kind == "cut":
        return line[: rng.randrange(len(line))].encode()
    if kind == "flip":
        data = bytearray(line.encode())
        data[rng.randrange(len(data))] = rng.randrange(256)
        return bytes(data)
    return b'{"topic": "/' + b"a" * 200_000 + b'"}'


def test_fuzz_live_json_lines(tmp_path: Path, record_property: pytest.RecordProperty) -> None:
    """Live recording reads the process's own stdin (a file descriptor): each case is a child
    process fed a file of lines, a third of them mutated; the recording must go on (exit 0)."""
    fuzz = Fuzz("live JSON lines", record_property)
    for case in range(5):
        rng = random.Random(f"live/{case}")
        lines = []
        for t in range(1, 120):
            good = json.dumps({**GOOD, "log_time_ns": t}).encode()
            lines.append(_line_mutant(rng, t) if rng.random() < 0.33 else good)
        stdin = tmp_path / f"stdin{case}.jsonl"
        stdin.write_bytes(b"\n".join(lines) + b"\n")
        fuzz.cases += len(lines)
        run = fuzz.measure(
            ["record", str(tmp_path / f"l{case}.mcap"), "--stdin", "--json"], [stdin], stdin=stdin
        )
        assert run.code == 0, f"case {case}: a bad line ended the recording: {run.stderr[-300:]}"
        summary = json.loads(run.stdout)
        # every line is recorded or rejected (a blank line is neither; a flipped byte may have
        # split a line in two)
        expected = sum(1 for x in stdin.read_bytes().split(b"\n") if x.strip())
        assert summary["messages"] + summary["rejected"] == expected, summary
    fuzz.check()
