"""The compact summary parses to the same chunk indexes as mcap's reader."""

from __future__ import annotations

import io
from pathlib import Path

from hypothesis import given
from hypothesis import strategies as st
from mcap.data_stream import RecordBuilder
from mcap.records import ChunkIndex, Footer
from mcap.stream_reader import StreamReader

from trackctl.logs.reader import MCAP_MAGIC
from trackctl.logs.summary import CompactOffsets, has_any_channel, parse_summary

offsets_maps = st.dictionaries(st.integers(0, 0xFFFF), st.integers(0, 2**64 - 1), max_size=40)


def _section(maps: list[dict[int, int]]) -> bytes:
    """A summary section holding one chunk index per map, written by mcap's record writer."""
    rb = RecordBuilder()
    for i, m in enumerate(maps):
        ChunkIndex(
            chunk_length=100 + i,
            chunk_start_offset=8 + i,
            compression="zstd" if i % 2 else "",
            compressed_size=7 * i,
            message_end_time=2 * i + 1,
            message_index_length=3 * i,
            message_index_offsets=m,
            message_start_time=2 * i,
            uncompressed_size=9 * i,
        ).write(rb)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(rb)
    return bytes(rb.end()) + MCAP_MAGIC


@given(st.lists(offsets_maps, max_size=5))
def test_chunk_indexes_equal_mcaps(maps: list[dict[int, int]]) -> None:
    section = _section(maps)
    mine = parse_summary(section).chunk_indexes
    theirs = [
        r
        for r in StreamReader(io.BytesIO(section), skip_magic=True).records
        if isinstance(r, ChunkIndex)
    ]
    assert len(mine) == len(theirs) == len(maps)
    for a, b in zip(mine, theirs, strict=True):
        assert isinstance(a.message_index_offsets, CompactOffsets)
        assert dict(a.message_index_offsets) == b.message_index_offsets
        assert a.message_index_offsets == b.message_index_offsets
        for name in (
            "chunk_length",
            "chunk_start_offset",
            "compression",
            "compressed_size",
            "message_end_time",
            "message_index_length",
            "message_start_time",
            "uncompressed_size",
        ):
            assert getattr(a, name) == getattr(b, name)


@given(offsets_maps, st.integers(-5, 0x10005))
def test_mapping_lookups(m: dict[int, int], key: int) -> None:
    import numpy as np

    ids = np.array(list(m), dtype=np.uint16)
    offs = np.array(list(m.values()), dtype=np.uint64)
    c = CompactOffsets(ids, offs)
    assert len(c) == len(m)
    assert (key in c) == (key in m)
    assert c.get(key) == m.get(key)
    assert set(c) == set(m)
    assert has_any_channel(c, [key]) == has_any_channel(m, [key]) == (key in m)


def test_real_log_summary_is_compact(tmp_path: Path) -> None:
    from trackctl.logs.messages import Imu
    from trackctl.logs.reader import LogReader
    from trackctl.logs.writer import LogWriter

    path = tmp_path / "a.mcap"
    with LogWriter(path) as w:
        for i in range(50):
            w.write(f"/imu/{i % 7}", Imu(t_ns=i, frame_id="p", accel_mps2=(0.0, 0.0, 9.8)), i)
    r = LogReader(path)
    cis = r.summary.chunk_indexes
    assert cis and all(isinstance(ci.message_index_offsets, CompactOffsets) for ci in cis)
    assert sum(1 for _ in r.messages()) == 50
    assert r.topics()["/imu/3"].count == 7
