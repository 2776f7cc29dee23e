"""MCAP logs whose content lies (tests/fuzz/hostile.py): a channel's schema name swapped for
another, garbage metadata values, huge or mistyped numbers in JSON payloads; through ``info``,
``process --with check``, ``replay``, ``vm-track`` and ``smirror``. Byte-level damage is
tests/logs/test_integrity.py's fuzz test."""

from __future__ import annotations

import random
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.conftest import ROOT
from tests.fuzz.common import Fuzz
from tests.fuzz.hostile import (
    claimed_chunk_log,
    garbage_metadata,
    hostile_numbers,
    read_parts,
    swap_schema,
)
from trackctl.cli.main import app

CASES = 18
SCHEMAS = (
    "trackctl.CameraModel",
    "trackctl.Detections",
    "trackctl.WheelOdometry",
    "trackctl.GroundTruth",
    "trackctl.Imu",
    "trackctl.RssiScan",
    "foxglove.CompressedImage",
    "foxglove.CameraCalibration",
    "someone.Else",
)


def _mutant(src: Path, dst: Path, rng: random.Random) -> Path:
    kind = rng.choice(["swap", "swap", "metadata", "numbers"])
    if kind == "swap":
        topics = sorted({t for t, _, _ in read_parts(src).channels.values()})
        return swap_schema(src, dst, rng.choice(topics), rng.choice(SCHEMAS))
    if kind == "metadata":
        return garbage_metadata(src, dst, rng)
    return hostile_numbers(src, dst, rng, share=0.1)


def test_fuzz_hostile_mcap_logs(tmp_path: Path, record_property: pytest.RecordProperty) -> None:
    fuzz = Fuzz("MCAP log", record_property)
    vm = tmp_path / "vm.mcap"
    made = CliRunner().invoke(
        app,
        [
            "simulate",
            "vm",
            "--out",
            str(vm),
            "--duration",
            "4",
            "--field",
            "office",
            "--users",
            "2",
            "--nonusers",
            "1",
            "--json",
        ],
    )
    assert made.exit_code == 0, made.output
    smirror = ROOT / "sample_logs" / "smirror.mcap"
    for case in range(CASES):
        rng = random.Random(f"mcap/{case}")
        src = smirror if case == 5 else vm
        log = _mutant(src, tmp_path / f"m{case}.mcap", rng)
        commands = [["info", str(log), "--json"], ["replay", str(log), "--speed", "0"]]
        if src is smirror:
            commands.append(["smirror", str(log), "--json", "-q"])
        elif case % 2:
            commands.append(["vm-track", str(log), "--json", "-q"])
        else:
            commands.append(["process", str(log), "--with", "check", "--json"])
        fuzz.cases += 1
        for args in commands:
            fuzz.invoke(args, [log, src])
        log.unlink()
    claim = claimed_chunk_log(tmp_path / "claims_3gb.mcap")
    numbers = hostile_numbers(vm, tmp_path / "numbers.mcap", random.Random(45), share=0.3)
    for args in (
        ["process", str(claim), "--with", "check", "--json"],
        ["vm-track", str(numbers), "--json", "-q"],
    ):
        fuzz.cases += 1
        fuzz.measure(args, [claim, numbers])
    fuzz.check()
