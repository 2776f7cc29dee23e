"""Cut logs indexed once (LogReader.reindex): the same messages as a sequential read of the
complete chunks, seek-based window reads, topics from the rebuilt statistics."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from tests.conftest import ROOT
from trackctl.errors import TruncatedLogWarning
from trackctl.logs import LogReader
from trackctl.logs.reader import IndexedWindowReader

SAMPLES = sorted((ROOT / "sample_logs").glob("*.mcap"))


def _cut(src: Path, share: float, dst: Path) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * share)])
    return dst


def _quiet(path: Path) -> LogReader:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return LogReader(path)


@pytest.mark.parametrize("share", [0.3, 0.9])
@pytest.mark.parametrize("sample", SAMPLES, ids=lambda p: p.name)
def test_reindexed_cut_log_reads_the_complete_chunks(
    sample: Path, share: float, tmp_path: Path
) -> None:
    cut = _cut(sample, share, tmp_path / sample.name)
    sequential = [
        (r.topic, r.log_time_ns, r.data) for r in _quiet(cut).raw()
    ]  # includes the cut-off chunk's complete messages
    reader = _quiet(cut)
    if not reader.reindex():
        # the cut falls inside the first chunk: no index to rebuild, the sequential read stays
        assert [(r.topic, r.log_time_ns, r.data) for r in _quiet(cut).raw()] == sequential
        assert not reader._indexed
        return
    with pytest.warns(TruncatedLogWarning, match=r"log is cut .* at byte \d+ of \d+: indexed"):
        reader = _quiet(cut)
        assert reader.reindex()
    indexed = [(r.topic, r.log_time_ns, r.data) for r in reader.raw()]
    assert indexed
    # every indexed message is one of the sequential read's; only the cut-off chunk is left out
    assert set(indexed) <= set(sequential)
    assert sorted(indexed, key=lambda m: m[1]) == sorted(
        [m for m in sequential if m in set(indexed)], key=lambda m: m[1]
    )
    assert reader.message_count == len(indexed)
    counts: dict[str, int] = {}
    for topic, _, _ in indexed:
        counts[topic] = counts.get(topic, 0) + 1
    assert {t: i.count for t, i in reader.topics().items() if i.count} == counts
    assert reader.metadata() == _quiet(sample).metadata()


def test_window_reads_on_a_cut_log_equal_a_filtered_scan(tmp_path: Path) -> None:
    cut = _cut(ROOT / "sample_logs" / "ev.mcap", 0.8, tmp_path / "ev.mcap")
    reader = _quiet(cut)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert reader.reindex()
    v_topics = sorted(t for t in reader.topics() if t.startswith("/ev/cell/"))[:3]
    with IndexedWindowReader(reader) as window:
        for topic in v_topics:
            info = reader.topics()[topic]
            assert info.first_ns is not None and info.last_ns is not None
            for start in (info.first_ns, info.last_ns):
                got = window.read(topic, start, start + 60 * 10**9)
                want = list(reader.raw([topic], start, start + 60 * 10**9))
                assert [r.data for r in got] == [r.data for r in want] and len(got) == 1


def test_reindex_leaves_a_finished_log_alone() -> None:
    reader = LogReader(ROOT / "sample_logs" / "ev.mcap")
    summary = reader._summary
    assert reader.reindex() and reader._summary is summary
