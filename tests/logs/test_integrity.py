"""Damaged logs: CRCs checked, damaged chunks skipped and reported, never a changed message.

Includes the fuzz test: every sample log is mutated (bit flips, truncation, forged record lengths)
with a seeded mutator and ``info``, ``replay`` and ``process --with check`` run in-process on each
mutant: never a traceback, never an exit code other than 0/1/2, never a changed message.
"""

from __future__ import annotations

import json
import random
import struct
from collections import Counter
from functools import cache
from pathlib import Path

import pytest
from typer.testing import CliRunner

from tests.conftest import ROOT, run_cli
from trackctl.cli.main import app
from trackctl.logs import LogReader
from trackctl.logs.writer import LogWriter

SAMPLES = sorted((ROOT / "sample_logs").glob("*.mcap"))
FUZZ_CASES = 510
"""Mutants in the whole campaign (``pytest -m slow``); the default run takes a tenth of them
(51, the same mutants every run, each sample alike), in shards the workers share."""
FUZZ_SHARDS = 3
DEFAULT_CASES = [c for c in range(FUZZ_CASES) if c % 50 in (0, 11, 22, 33, 44)]
"""Case ``c`` mutates sample ``c % 5``: these residues take each sample equally often."""


def _middle_chunk(path: Path) -> tuple[int, int]:
    reader = LogReader(path)
    assert reader._summary is not None
    chunks = sorted(reader._summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    mid = chunks[len(chunks) // 2]
    return mid.chunk_start_offset, mid.chunk_length


@pytest.mark.parametrize("sample", SAMPLES, ids=lambda p: p.name)
def test_flipped_byte_in_the_middle_chunk(sample: Path, tmp_path: Path) -> None:
    start, length = _middle_chunk(sample)
    data = bytearray(sample.read_bytes())
    data[start + length // 2] ^= 0x40
    bad = tmp_path / sample.name
    bad.write_bytes(bytes(data))
    original = {line.encode() for line in _original_lines()[sample]}
    proc = run_cli("replay", str(bad), "--speed", "0")
    assert proc.returncode == 0
    got = proc.stdout.splitlines()
    assert set(got) <= original, "a damaged chunk must never yield a changed message"
    assert f"damaged chunk at byte {start}".encode() in proc.stderr
    assert b"messages lost" in proc.stderr
    check = run_cli("process", str(bad), "--with", "check", "--json")
    assert check.returncode == 0, check.stderr.decode()
    metrics = json.loads(check.stdout)["reports"][0]["metrics"]
    assert metrics["crc_errors"] == 1
    assert metrics["messages"] + metrics["lost_messages"] == len(original)


def _build(path: Path, n: int = 300, chunk_size: int = 2000, compression: str = "zstd") -> None:
    from trackctl.logs.messages import Imu, Vec3

    with LogWriter(path, chunk_size=chunk_size, compression=compression) as w:
        for i in range(n):
            w.write("/imu", Imu(i * 10_000_000, "p", Vec3(0.0, 0.0, 9.8), Vec3(0.0, 0.0, i * 1e-3)))
        w.add_metadata("m", {"k": "v"})


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_data_section_crc_is_written_and_checked(tmp_path: Path, compression: str) -> None:
    path = tmp_path / "a.mcap"
    _build(path, compression=compression)
    reader = LogReader(path)
    assert reader.verify_data_crc() is True
    start, length = _middle_chunk(path)
    data = bytearray(path.read_bytes())
    data[start + length - 3] ^= 0x01
    path.write_bytes(bytes(data))
    reader = LogReader(path)
    assert reader.verify_data_crc() is False
    n = sum(1 for _ in reader.raw())
    assert len(reader.damage) == 1 and n + reader.lost_messages == 300


def test_damaged_summary_falls_back_to_a_sequential_read(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _build(path)
    data = bytearray(path.read_bytes())
    data[-60] ^= 0xFF  # inside the summary section
    path.write_bytes(bytes(data))
    with pytest.warns(UserWarning, match="summary CRC mismatch"):
        reader = LogReader(path)
    assert sum(1 for _ in reader.raw()) == 300
    assert reader.metadata() == {"m": {"k": "v"}}


def test_forged_chunk_length_is_a_cut_not_a_crash(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _build(path)
    start, _ = _middle_chunk(path)
    data = bytearray(path.read_bytes())
    data[start + 1 : start + 9] = struct.pack("<Q", (1 << 63) - 1)
    path.write_bytes(bytes(data))
    with pytest.warns(UserWarning):
        reader = LogReader(path)
        got = [m.log_time_ns for m in reader.raw()]
    assert len(reader.damage) == 1
    assert got == sorted(got) and len(got) + reader.lost_messages == 300


def test_forged_uncompressed_size_does_not_allocate(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _build(path)
    start, _ = _middle_chunk(path)
    data = bytearray(path.read_bytes())
    data[start + 9 + 16 : start + 9 + 24] = struct.pack("<Q", 1 << 62)
    path.write_bytes(bytes(data))
    with pytest.warns(UserWarning, match="implausible uncompressed size"):
        reader = LogReader(path)
        n = sum(1 for _ in reader.raw())
    assert n + reader.lost_messages == 300


# -- the fuzz test -----------------------------------------------------------------------------


def _mutate(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    kind = rng.choice(["flip", "flips", "truncate", "forge-length", "zero-block"])
    out = bytearray(data)
    if kind == "flip":
        pos = rng.randrange(8, len(out))
        out[pos] ^= 1 << rng.randrange(8)
    elif kind == "flips":
        for _ in range(rng.randint(2, 16)):
            out[rng.randrange(8, len(out))] ^= rng.randrange(1, 256)
    elif kind == "truncate":
        out = out[: rng.randrange(8, len(out))]
    elif kind == "forge-length":
        # overwrite 8 bytes that follow a plausible opcode with a huge or random length
        positions = [i for i in range(8, len(out) - 9) if 0x01 <= out[i] <= 0x0F]
        pos = rng.choice(positions) + 1
        value = rng.choice([(1 << 64) - 1, 1 << 62, rng.randrange(1 << 32), 0])
        out[pos : pos + 8] = struct.pack("<Q", value)
    else:
        pos = rng.randrange(8, len(out))
        out[pos : pos + rng.randint(1, 4096)] = bytes(min(4096, len(out) - pos))
    return kind, bytes(out)


@cache
def _original_lines() -> dict[Path, set[str]]:
    runner = CliRunner()
    out = {}
    for sample in SAMPLES:
        res = runner.invoke(app, ["replay", str(sample), "--speed", "0"])
        assert res.exit_code == 0
        out[sample] = set(res.stdout.splitlines())
    return out


def _fuzz(cases: list[int], tmp_path: Path) -> None:
    """Each case mutates one sample (its own seeded mutator: a case is the same mutant whichever
    shard runs it) and runs info, replay and (every third case) the check processor on it."""
    runner = CliRunner()
    originals = _original_lines()
    contents = {s: s.read_bytes() for s in SAMPLES}
    codes: Counter[tuple[str, int]] = Counter()
    kinds: Counter[str] = Counter()
    for case in cases:
        rng = random.Random(f"20261126/{case}")
        sample = SAMPLES[case % len(SAMPLES)]
        kind, data = _mutate(contents[sample], rng)
        kinds[kind] += 1
        bad = tmp_path / f"m{case}.mcap"
        bad.write_bytes(data)
        commands = [
            ["info", str(bad), "--json"],
            ["replay", str(bad), "--speed", "0"],
        ]
        if case % 3 == 0:  # the check processor copies the log: a third of the cases run it
            commands.append(["process", str(bad), "--with", "check", "--json"])
        for args in commands:
            res = runner.invoke(app, args)
            where = f"case {case} ({kind} of {sample.name}): trackctl {args[0]}"
            assert res.exception is None or isinstance(res.exception, SystemExit), (
                f"{where} raised {res.exception!r}"
            )
            assert res.exit_code in (0, 1, 2), f"{where} exited {res.exit_code}"
            assert "Traceback" not in res.output, where
            codes[(args[0], res.exit_code)] += 1
            if args[0] == "replay" and res.exit_code == 0:
                changed = set(res.stdout.splitlines()) - originals[sample]
                assert not changed, f"{where} emitted a changed message: {sorted(changed)[0][:200]}"
        bad.unlink()
    exits = ", ".join(f"{cmd} exit {code}: {n}" for (cmd, code), n in sorted(codes.items()))
    print(f"\nfuzz: {len(cases)} mutated logs ({dict(kinds)}), 0 tracebacks, 0 changed messages")
    print(f"fuzz: {exits}")


@pytest.mark.parametrize("shard", range(FUZZ_SHARDS))
def test_fuzz_mutated_logs_never_crash_or_change_a_message(shard: int, tmp_path: Path) -> None:
    """A tenth of the campaign's mutants, a shard of them per test."""
    _fuzz(DEFAULT_CASES[shard::FUZZ_SHARDS], tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("shard", range(3 * FUZZ_SHARDS))
def test_fuzz_campaign_mutated_logs_never_crash_or_change_a_message(
    shard: int, tmp_path: Path
) -> None:
    """The whole campaign: the mutants the default run leaves out."""
    rest = [c for c in range(FUZZ_CASES) if c not in DEFAULT_CASES]
    _fuzz(rest[shard :: 3 * FUZZ_SHARDS], tmp_path)


def test_info_uses_the_summary_without_reading_any_chunk(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "a.mcap"
    _build(path, n=3000)
    assert len(LogReader(path)._summary.chunk_indexes) > 10  # type: ignore[union-attr]

    def no_chunks(*args: object, **kwargs: object) -> None:
        raise AssertionError("info must not decompress chunks")

    monkeypatch.setattr("trackctl.logs.reader.decode_chunk", no_chunks)
    from trackctl.logs.info import log_info

    info = log_info(LogReader(path))
    assert info["message_count"] == 3000
    assert info["topics"]["/imu"]["first_ns"] == 0
    assert info["topics"]["/imu"]["last_ns"] == 2999 * 10_000_000
    assert info["topics"]["/imu"]["rate_hz"] == pytest.approx(100.0)
