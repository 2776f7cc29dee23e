"""Issue 45's examples by hand: every way in, fed what a hostile user would feed it.

Builds one input per example of the issue's "Why" list in a temporary folder, runs the real CLI
(``python -m trackctl`` in a child process) on each and prints, per case: the exit code, what it
said on stderr (one line expected), and whether every input's sha256 is unchanged. Then runs
``process --with check`` on a ~200 kB log whose lz4 chunk header claims 3 GB uncompressed and
prints its peak RSS (bound: 500 MB) and its warning count (expected: 1).

Run from the repository root: ``python benchmarks/hostile_inputs.py`` (exit 1 when a case
breaks its expectation).
"""

from __future__ import annotations

import hashlib
import json
import os
import random
import stat
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tests.fuzz.hostile import (  # noqa: E402
    claimed_chunk_log,
    garbage_metadata,
    hostile_numbers,
    read_parts,
    run_measured,
    swap_schema,
    write_parts,
)
from tests.ingest.ros2_bags import hostile_bag  # noqa: E402

SAMPLES = ROOT / "sample_logs"
RSS_BOUND_MB = 500.0


def sha256(path: Path) -> str:
    """Digest of a file, or of every file under a folder (names included)."""
    h = hashlib.sha256()
    if path.is_dir():
        for p in sorted(path.rglob("*")):
            if p.is_file():
                h.update(str(p.relative_to(path)).encode())
                h.update(p.read_bytes())
    elif path.is_file():
        h.update(path.read_bytes())
    else:  # a FIFO or device: its type and device number
        st = os.stat(path)
        h.update(f"{stat.S_IFMT(st.st_mode)}:{st.st_rdev}".encode())
    return h.hexdigest()


@dataclass
class Case:
    name: str
    args: list[str]
    inputs: list[Path]
    expect: tuple[int, ...] = (2,)
    """Accepted exit codes (0 where the data can be skipped with a warning)."""
    must_say: str = ""
    """Text the stderr line must hold (the file or field)."""
    after: Callable[[], str] | None = field(default=None, repr=False)
    """An extra check after the run: '' when fine, else what went wrong."""


def _yaml(path: Path, data: object) -> Path:
    path.write_text(yaml.safe_dump(data))
    return path


def site_cases(d: Path) -> list[Case]:
    bl, sm = str(SAMPLES / "bridgeloc.mcap"), str(SAMPLES / "smirror.mcap")
    out = str(d / "site_out.mcap")
    tag0 = _yaml(d / "tag0.yaml", {"bridgeloc": {"tag_n": 0}})
    ticks = d / "ticks.yaml"
    ticks.write_text("robots:\n  r1:\n    ticks_per_m: 1.0e-300\n")
    short = _yaml(d / "short.yaml", {"smirror": {"floorplan": {"size_m": [27.0], "walls": []}}})
    date = d / "date.yaml"
    date.write_text("robots:\n  r1:\n    wheel_base_m: 2026-12-04\n")
    binary = d / "binary.yaml"
    binary.write_text("bridgeloc:\n  robot: !!binary aGVsbG8=\n")
    huge = d / "huge.yaml"
    huge.write_text(f"smirror:\n  requesters: {'9' * 30}\n")
    fifo = d / "fifo.yaml"
    os.mkfifo(fifo)
    rng = random.Random(45)
    walls = [
        [[rng.uniform(0, 27), rng.uniform(0, 8)], [rng.uniform(0, 27), rng.uniform(0, 8)]]
        for _ in range(20_000)
    ]
    many = d / "walls.yaml"
    many.write_text(
        json.dumps({"smirror": {"floorplan": {"size_m": [27, 8], "walls": walls, "rooms": []}}})
    )
    return [
        Case(
            "site: tag N 0",
            ["bridgeloc", "eval", bl, "--site", str(tag0), "--out", out],
            [tag0, SAMPLES / "bridgeloc.mcap"],
            must_say="bridgeloc.tag_n",
        ),
        Case(
            "site: ticks_per_m 1e-300",
            ["smirror", sm, "--site", str(ticks), "--out", out],
            [ticks],
            must_say="ticks_per_m",
        ),
        Case(
            "site: short floor size",
            ["smirror", sm, "--site", str(short), "--out", out],
            [short],
            must_say="size_m",
        ),
        Case(
            "site: a date value",
            ["smirror", sm, "--site", str(date), "--out", out],
            [date],
            must_say="wheel_base_m",
        ),
        Case(
            "site: a binary value",
            ["record", out, "--site", str(binary)],
            [binary],
            must_say="bridgeloc.robot",
        ),
        Case(
            "site: a 30-digit int",
            ["smirror", sm, "--site", str(huge), "--out", out],
            [huge],
            must_say="requesters",
        ),
        Case(
            "site: a FIFO",
            ["smirror", sm, "--site", str(fifo), "--out", out],
            [fifo],
            must_say="FIFO",
        ),
        Case(
            "site: 20,000 walls",
            ["smirror", sm, "--site", str(many), "--out", out],
            [many],
            must_say="walls",
        ),
    ]


def video_cases(d: Path) -> list[Case]:
    folder = d / "frames"
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(str(folder / f"f{i}.png"), np.full((8, 8, 3), 40 * i, np.uint8))
    times = d / "times.csv"
    times.write_text("file,t\nf0.png,0\nf1.png,nan\nf2.png,0.2\n")
    video = d / "v.avi"
    w = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (16, 16))
    for i in range(5):
        w.write(np.full((16, 16, 3), 40 * i, np.uint8))
    w.release()
    out = str(d / "video_out.mcap")
    return [
        Case(
            "video: NaN frame time",
            ["record", out, "--video", f"c={folder}", "--frame-times", str(times), "-q"],
            [folder, times],
            must_say="times.csv:3",
        ),
        Case(
            "video: --fps 1e-300",
            ["record", out, "--video", f"c={video}", "--fps", "1e-300", "-q"],
            [video],
            must_say="--fps",
        ),
        Case(
            "video: --video-start 1e30",
            ["record", out, "--video", f"c={video}", "--video-start", "1e30", "-q"],
            [video],
            must_say="--video-start",
        ),
    ]


def calibration_cases(d: Path) -> list[Case]:
    digits = d / "digits.yaml"
    digits.write_text(f"image_width: {'9' * 5000}\nimage_height: 480\n")
    nested = d / "nested.yaml"
    nested.write_text("%YAML:1.0\n---\nk: " + "[" * 10_000 + "]" * 10_000 + "\n")
    bomb = d / "bomb.yaml"
    lines = ["a0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 10)}]" for i in range(1, 9)]
    bomb.write_text("\n".join(lines) + "\nimage_width: *a8\n")
    tsai = d / "tsai.xml"
    tsai.write_text(
        '<?xml version="1.0"?>\n<Camera name="v">\n'
        '<Geometry width="768" height="576" ncx="795" nfx="752" dx="0" dy="0" dpx="0" dpy="0"/>\n'
        '<Intrinsic focal="0" kappa1="0" cx="324" cy="282" sx="1"/>\n'
        '<Extrinsic tx="0" ty="0" tz="0" rx="0" ry="0" rz="0"/>\n</Camera>\n'
    )
    deep_xml = d / "deep.xml"
    deep_xml.write_text(
        '<?xml version="1.0"?>\n<opencv_storage>'
        + "<a>" * 10_000
        + "</a>" * 10_000
        + "</opencv_storage>\n"
    )
    out = str(d / "calib_out.yaml")
    return [
        Case(
            "calib: 5000-digit integer",
            ["calib", "check", str(digits)],
            [digits],
            must_say="image_width",
        ),
        Case(
            "calib: YAML nested 10k deep",
            ["calib", "check", str(nested)],
            [nested],
            must_say="nested",
        ),
        Case(
            "calib: YAML alias bomb",
            ["calib", "import", str(bomb), "--out", out],
            [bomb],
            must_say="alias",
        ),
        Case(
            "calib: degenerate Tsai XML",
            ["calib", "import", str(tsai), "--out", out],
            [tsai],
            must_say="tsai.xml",
        ),
        Case(
            "calib: XML nested 10k deep",
            [
                "record",
                str(d / "c.mcap"),
                "--video",
                f"cam0={ROOT / 'tests/data'}",
                "--calib",
                f"cam0={deep_xml}",
                "-q",
            ],
            [deep_xml],
            must_say="nested",
        ),
    ]


def ros_cases(d: Path) -> list[Case]:
    out: list[Case] = []
    for case, say in (
        ("nan_odometry", "/r1/odom"),
        ("zero_quaternion", "zero quaternion"),
        ("short_image", "height*step"),
        ("lying_schema", "/r2/odom"),
        ("forged_length", "damaged"),
        ("damaged_zstd", "Zstd"),
    ):
        bag = hostile_bag(d / f"bag_{case}", case)
        out.append(
            Case(
                f"ros: {case.replace('_', ' ')}",
                ["record", str(d / f"{case}.mcap"), "--ros", str(bag), "-q"],
                [bag],
                expect=(0,),
                must_say=say,
            )
        )
    return out


def log_cases(d: Path) -> list[Case]:
    sm = SAMPLES / "smirror.mcap"
    swapped = swap_schema(sm, d / "swapped.mcap", "/node1/image", "trackctl.CameraModel")
    dets = swap_schema(
        SAMPLES / "vm-office.mcap",
        d / "swapped_dets.mcap",
        "/cam0/camera_model",
        "trackctl.Detections",
    )
    parts = read_parts(sm)
    parts.metadata["robot/r1"]["wheel_base_m"] = "1e400"
    garbage = write_parts(parts, d / "garbage.mcap")
    parts = read_parts(sm)
    parts.metadata["smirror/floorplan"] = {"plan": '{"size_m": [1], "walls": 3}'}
    parts_meta = write_parts(parts, d / "garbage_plan.mcap")
    random_meta = garbage_metadata(sm, d / "random_meta.mcap", random.Random(3), n=5)
    numbers = hostile_numbers(sm, d / "numbers.mcap", random.Random(0), share=0.2)
    out = str(d / "log_out.mcap")
    return [
        Case(
            "log: image topic claims CameraModel",
            ["smirror", str(swapped), "--json", "-q"],
            [swapped],
            expect=(0,),
            must_say="/node1/image",
        ),
        Case(
            "log: camera_model claims Detections (vm-track)",
            ["vm-track", str(dets), "--json", "-q"],
            [dets],
            must_say="camera_model",
        ),
        Case(
            "log: swapped schema (process --with check)",
            ["process", str(swapped), "--with", "check", "--json"],
            [swapped],
            expect=(0,),
            must_say="",
        ),
        Case(
            "log: garbage metadata value",
            ["smirror", str(garbage), "--out", out, "-q"],
            [garbage],
            must_say="wheel_base_m",
        ),
        Case(
            "log: random garbage metadata (process --with check)",
            ["process", str(random_meta), "--with", "check", "--json"],
            [random_meta],
            expect=(0,),
            must_say="",
        ),
        Case(
            "log: malformed floor plan record",
            ["smirror", str(parts_meta), "--out", out, "-q"],
            [parts_meta],
            must_say="smirror/floorplan",
        ),
        Case(
            "log: huge ints in messages",
            ["smirror", str(numbers), "--json", "-q"],
            [numbers],
            expect=(0,),
            must_say="cannot decode",
        ),
        Case(
            "log: huge ints (replay)",
            ["replay", str(numbers), "--speed", "0"],
            [numbers],
            expect=(0,),
            must_say="",
        ),
    ]


def path_cases(d: Path) -> list[Case]:
    folder = d / "pframes"
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(str(folder / f"f{i}.png"), np.full((8, 8, 3), 40 * i, np.uint8))
    times = d / "ptimes.csv"
    times.write_text("file,t\nf0.png,0\nf1.png,0.1\nf2.png,0.2\n")
    intr = d / "intr.yaml"
    fs = cv2.FileStorage(str(intr), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 768)
    fs.write("image_height", 576)
    fs.write("camera_matrix", np.array([[800.0, 0, 384], [0, 800.0, 288], [0, 0, 1]]))
    fs.release()
    points = d / "points.csv"
    points.write_bytes((ROOT / "tests/data/pets2009_view001_floor_points.csv").read_bytes())
    log = d / "report.mcap"
    log.write_bytes((SAMPLES / "demo.mcap").read_bytes())
    site = _yaml(d / "psite.yaml", {"smirror": {"requesters": 1}})
    bag = hostile_bag(d / "pbag", "nan_odometry")
    damaged = d / "damaged.mcap.partial"
    damaged.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 4)
    node = d / "null_device"
    os.mknod(node, stat.S_IFCHR | 0o666, os.makedev(1, 3))  # a /dev/null of our own
    fifo = d / "out.fifo"
    os.mkfifo(fifo)
    sm = str(SAMPLES / "smirror.mcap")
    return [
        Case(
            "paths: record --out = frame-times CSV",
            ["record", str(times), "--video", f"c={folder}", "--frame-times", str(times), "-q"],
            [times, folder],
            must_say=str(times),
        ),
        Case(
            "paths: record --out inside the --ros bag",
            ["record", str(bag / "metadata.yaml"), "--ros", str(bag), "-q"],
            [bag],
            must_say="metadata.yaml",
        ),
        Case(
            "paths: calib ground --out = points CSV",
            [
                "calib",
                "ground",
                "cam0",
                "--intrinsics",
                str(intr),
                "--points",
                str(points),
                "--out",
                str(points),
            ],
            [points, intr],
            must_say=str(points),
        ),
        Case(
            "paths: report --csv = the log",
            ["report", str(log), "--csv", str(log)],
            [log],
            must_say=str(log),
        ),
        Case(
            "paths: report --csv into a missing folder",
            ["report", str(log), "--csv", str(d / "nowhere" / "r.csv")],
            [log],
            must_say="nowhere",
        ),
        Case(
            "paths: smirror --out = --site",
            ["smirror", sm, "--site", str(site), "--out", str(site)],
            [site],
            must_say=str(site),
        ),
        Case(
            "paths: recover a log with nothing to recover",
            ["recover", str(damaged)],
            [damaged],
            expect=(0, 2),
            must_say=str(damaged),
            after=lambda: "" if damaged.is_file() else "the input was deleted",
        ),
        Case(
            "paths: calib import --out a device node",
            ["calib", "import", str(intr), "--out", str(node)],
            [node, intr],
            must_say="device",
        ),
        Case(
            "paths: calib ground --out a FIFO",
            [
                "calib",
                "ground",
                "cam0",
                "--intrinsics",
                str(intr),
                "--points",
                str(points),
                "--out",
                str(fifo),
            ],
            [fifo, points],
            must_say="FIFO",
        ),
    ]


def _once_per_topic(lines: list[str]) -> bool:
    """Exit 0 with warnings: no warning is repeated per message (the same text but for the
    message's time); the reader says each topic's kind of failure once."""
    import re

    texts = [re.sub(r" at \d+ ns:", ":", line) for line in lines if line.startswith("warning:")]
    return len(texts) == len(set(texts))


def run_case(case: Case) -> bool:
    before = {p: sha256(p) for p in case.inputs}
    run = run_measured(case.args, timeout_s=120)
    changed = [p.name for p in case.inputs if sha256(p) != before[p]]
    lines = [x for x in run.stderr.splitlines() if x.strip()]
    tb = "Traceback" in run.stderr or "Traceback" in run.stdout
    extra = case.after() if case.after else ""
    ok = (
        run.code in case.expect
        and not tb
        and not changed
        and not extra
        and (case.must_say in run.stderr)
        and (len(lines) == 1 or (run.code == 0 and _once_per_topic(lines)))
    )
    unchanged = "inputs unchanged" if not changed else f"CHANGED: {', '.join(changed)}"
    print(f"{'ok ' if ok else 'BAD'} {case.name}: exit {run.code}; {unchanged}; {extra}")
    for line in lines or ["(nothing on stderr)"]:
        print(f"    {line[:300]}")
    return ok


def chunk_claim(d: Path) -> bool:
    log = claimed_chunk_log(d / "claims_3gb.mcap")
    before = sha256(log)
    run = run_measured(["process", str(log), "--with", "check", "--json"])
    warnings_ = [x for x in run.stderr.splitlines() if x.startswith("warning:")]
    ok = (
        run.code == 0
        and run.peak_rss_mb < RSS_BOUND_MB
        and len(warnings_) == 1
        and sha256(log) == before
    )
    print(
        f"{'ok ' if ok else 'BAD'} process --with check on a {log.stat().st_size / 1e3:.0f} kB "
        f"log whose lz4 chunk claims 3 GB: exit {run.code}, peak RSS {run.peak_rss_mb:.0f} MB "
        f"(bound {RSS_BOUND_MB:.0f}), {len(warnings_)} warning"
    )
    for w in warnings_:
        print(f"    {w}")
    return ok


def main() -> int:
    results = []
    with tempfile.TemporaryDirectory(prefix="hostile-") as tmp:
        d = Path(tmp)
        for build in (site_cases, video_cases, calibration_cases, ros_cases, log_cases, path_cases):
            for case in build(d):
                results.append(run_case(case))
        results.append(chunk_claim(d))
    bad = results.count(False)
    print(f"hostile inputs: {len(results)} cases, {bad} not as expected")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
