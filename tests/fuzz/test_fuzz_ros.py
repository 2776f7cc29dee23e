"""ROS bags a robot should never have written (tests/ingest/ros2_bags.py builds them) and seeded
byte mutations of a small bag, through ``record --ros``: messages skipped with a warning per
topic, a damaged bag read up to the damage, never a traceback."""

from __future__ import annotations

import random
import shutil
from pathlib import Path

import pytest

from tests.fuzz.common import Fuzz
from tests.ingest.ros2_bags import HOSTILE_BAGS, hostile_bag

MUTANTS = 16


def _mutate_bag(src: Path, dst: Path, rng: random.Random) -> Path:
    """A copy of the rosbag2 folder ``src`` with its storage file's bytes flipped, zeroed or
    cut (its metadata.yaml too, now and then)."""
    shutil.copytree(src, dst)
    files = sorted(p for p in dst.iterdir() if p.suffix in (".mcap", ".db3"))
    target = dst / "metadata.yaml" if rng.random() < 0.2 else files[0]
    data = bytearray(target.read_bytes())
    kind = rng.choice(["flip", "flips", "zero", "cut"])
    if kind == "flip":
        data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    elif kind == "flips":
        for _ in range(rng.randint(2, 12)):
            data[rng.randrange(len(data))] = rng.randrange(256)
    elif kind == "zero":
        pos = rng.randrange(len(data))
        data[pos : pos + 64] = bytes(len(data[pos : pos + 64]))
    else:
        data = data[: rng.randrange(len(data))]
    target.write_bytes(bytes(data))
    return dst


def test_fuzz_ros_bags(tmp_path: Path, record_property: pytest.RecordProperty) -> None:
    fuzz = Fuzz("ROS bag", record_property)
    bags = [hostile_bag(tmp_path / case, case) for case in HOSTILE_BAGS]
    for case, bag in zip(HOSTILE_BAGS, bags, strict=True):
        fuzz.cases += 1
        code = fuzz.invoke(
            ["record", str(tmp_path / f"out-{case}.mcap"), "--ros", str(bag), "-q"], [bag]
        )
        assert code == 0, f"{case}: the bag's good messages were not recorded"
    base = tmp_path / "short_image"
    for case in range(MUTANTS):
        rng = random.Random(f"ros/{case}")
        bag = _mutate_bag(base, tmp_path / f"mutant{case}", rng)
        fuzz.cases += 1
        fuzz.invoke(["record", str(tmp_path / f"m{case}.mcap"), "--ros", str(bag), "-q"], [bag])
    fuzz.cases += 1
    fuzz.measure(["record", str(tmp_path / "rss.mcap"), "--ros", str(bags[-1]), "-q"], [bags[-1]])
    fuzz.check()
