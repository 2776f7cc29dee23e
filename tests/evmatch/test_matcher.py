"""EV-Matching algorithms on hand-made and simulated logs (local engine)."""

from __future__ import annotations

from pathlib import Path

import pytest

from trackctl.errors import MissingTopicError
from trackctl.evmatch import (
    Algorithm,
    EvMatchConfig,
    LocalEngine,
    MatchParams,
    VStore,
    load_e,
    load_ground_truth,
    match_log,
    match_ss,
)
from trackctl.logs import topics
from trackctl.logs.reader import IndexedWindowReader, LogReader

from .conftest import write_ev_log

LOOSE = MatchParams(margin=1, min_evidence=1)


def _ss(path: Path, eids: list[str], params: MatchParams = LOOSE) -> dict[str, object]:
    reader = LogReader(path)
    data = load_e(reader)
    out = match_ss(data, VStore(reader, data), eids, LocalEngine(), params, seed=0)
    return {m.eid: m for m in out.matches}


def test_paper_example_two_eids_split_by_a_second_scenario(tmp_path: Path) -> None:
    # §3.2.3: {EID1, EID2} together, then EID1 and EID2 apart: each VID follows its EID
    log = write_ev_log(
        tmp_path / "ideal.mcap",
        [
            {"A": ({"e1": False, "e2": False}, ["v1", "v2"])},
            {"A": ({"e1": False}, ["v1"]), "B": ({"e2": False}, ["v2"])},
        ],
    )
    got = _ss(log, ["e1", "e2"])
    assert got["e1"].vid == "v1" and got["e2"].vid == "v2"
    assert got["e1"].scenarios == ("A@60000000000",)
    assert got["e2"].scenarios == ("B@60000000000",)


def test_unknown_eid_is_unmatched_with_reason(tmp_path: Path) -> None:
    log = write_ev_log(
        tmp_path / "l.mcap",
        [{"A": ({"e1": False}, ["v1"])}, {"A": ({"e1": False}, ["v1"])}],
    )
    got = _ss(log, ["nope", "e1"])
    assert got["nope"].vid is None
    assert got["nope"].reason == "EID never appears in the E-observations"
    assert got["e1"].vid == "v1"


def test_eid_only_ever_vague_is_unresolved_with_reason(tmp_path: Path) -> None:
    log = write_ev_log(
        tmp_path / "l.mcap",
        [
            {"A": ({"e1": False, "e3": True}, ["v1", "v3"])},
            {"A": ({"e1": False}, ["v1"]), "B": ({"e3": True}, ["v3"])},
        ],
    )
    got = _ss(log, ["e3"])
    assert got["e3"].vid is None
    assert "never in an inclusive zone" in got["e3"].reason


def test_vague_scenarios_are_never_evidence(small_log: Path) -> None:
    reader = LogReader(small_log)
    data = load_e(reader)
    vague = {
        (data.scenario_name(int(w) * data.n_cells + int(c)), str(data.eids[e]))
        for w, c, e in data.rows[data.rows["vague"]][["w", "cell", "eid"]].itertuples(index=False)
    }
    out, *_ = match_log(reader, EvMatchConfig())
    used = [(s, m.eid) for m in out.matches for s in m.scenarios]
    assert used and not any(pair in vague for pair in used)


def test_missing_v_topic_is_vid_missing_evidence(tmp_path: Path) -> None:
    # cell B's camera is down: e2's own scenario has no video, so refining takes another one
    log = write_ev_log(
        tmp_path / "l.mcap",
        [
            {"A": ({"e1": False, "e2": False}, ["v1", "v2"])},
            {"A": ({"e1": False}, ["v1"]), "B": ({"e2": False}, ["v2"])},
        ],
        skip_v=("B",),
    )
    reader = LogReader(log)
    data = load_e(reader)
    store = VStore(reader, data)
    out = match_ss(data, store, ["e1", "e2"], LocalEngine(), LOOSE, seed=0)
    got = {m.eid: m for m in out.matches}
    assert got["e1"].vid == "v1"
    assert got["e2"].vid == "v2" and got["e2"].scenarios == ("A@0",)
    assert store.missing == {data.n_cells + data.cells.index("B")}
    assert store.missing_topics() == ["/ev/cell/B/v"]


def test_ss_beats_edp_and_reads_less_video(small_log: Path) -> None:
    reader = LogReader(small_log)
    truth = load_ground_truth(reader)

    def accuracy(algo: Algorithm) -> tuple[float, int, object]:
        out, *_ = match_log(reader, EvMatchConfig(algorithm=algo))
        ok = sum(m.vid is not None and truth[m.eid] == m.vid for m in out.matches)
        return ok / len(out.matches), out.v_scenarios_read, out

    ss_acc, ss_reads, ss = accuracy(Algorithm.SS)
    edp_acc, edp_reads, _ = accuracy(Algorithm.EDP)
    assert ss_acc >= 0.9
    assert ss_acc >= edp_acc
    assert ss_reads < edp_reads
    # every V-scenario read serves as some EID's evidence, and each is read once
    used = {s for m in ss.matches for s in m.scenarios}  # type: ignore[attr-defined]
    assert len(used) == ss_reads


def test_v_reads_count_exactly_the_messages_fetched(small_log: Path) -> None:
    reader = LogReader(small_log)
    data = load_e(reader)
    store = VStore(reader, data)
    got = store.fetch([0, 1, 0, data.n_cells + 2])
    assert store.reads == 3 and len(got) == 3
    expected_bytes = 0
    for s in (0, 1, data.n_cells + 2):
        w, c = divmod(s, data.n_cells)
        start = int(data.windows_ns[w])
        (raw,) = list(reader.raw([topics.ev_v(data.cells[c])], start, start + data.window_ns))
        expected_bytes += len(raw.data)
    assert store.bytes_read == expected_bytes
    store.fetch([1])  # cached: no new read
    assert store.reads == 3
    store.close()


def test_indexed_window_read_equals_a_filtered_scan(small_log: Path) -> None:
    reader = LogReader(small_log)
    span = reader.topics()[topics.EV_E]
    v_topics = sorted(t for t in reader.topics() if t.startswith(topics.EV_V_PREFIX))[:4]
    with IndexedWindowReader(reader) as indexed:
        for topic in v_topics:
            for start in (span.first_ns, span.first_ns + 60 * 10**9, span.last_ns):
                assert start is not None
                a = indexed.read(topic, start, start + 60 * 10**9)
                b = list(reader.raw([topic], start, start + 60 * 10**9))
                assert [(r.log_time_ns, r.data) for r in a] == [(r.log_time_ns, r.data) for r in b]
                assert len(a) == 1
        with pytest.raises(MissingTopicError, match="/ev/cell/nope/v"):
            indexed.read("/ev/cell/nope/v", 0, 1)


def test_elastic_size_one_eid_reads_less_than_universal(small_log: Path) -> None:
    reader = LogReader(small_log)
    truth = load_ground_truth(reader)
    universal, data, *_ = match_log(reader, EvMatchConfig())
    eid = str(data.eids[3])
    single, *_ = match_log(reader, EvMatchConfig(eids=(eid,)))
    assert single.matches[0].vid == truth[eid]
    assert single.v_scenarios_read < universal.v_scenarios_read / 5


def test_same_seed_same_matches(small_log: Path) -> None:
    reader = LogReader(small_log)
    a, *_ = match_log(reader, EvMatchConfig(seed=5))
    b, *_ = match_log(reader, EvMatchConfig(seed=5))
    assert a.matches == b.matches


def test_split_sends_a_vague_eid_to_every_cell_it_is_listed_in() -> None:
    import numpy as np
    import pandas as pd

    node = np.array([0, 0, 0, 1])
    eid = np.array([0, 1, 2, 3])
    # EID 1 is heard in cells 5 and 6 (vague in both); EID 2 in no selected scenario
    listing = pd.DataFrame({"eid": [0, 1, 1, 3], "cell": [5, 5, 6, 6]})
    out = LocalEngine().split(node, eid, listing)
    assert out.values.tolist() == [[0, -1, 2], [0, 5, 0], [0, 5, 1], [0, 6, 1], [1, 6, 3]]


@pytest.mark.parametrize("chunk", [1, 7, 4_000_000])
def test_local_vote_equals_a_plain_count_whatever_the_chunk(
    chunk: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    import collections

    import numpy as np

    from trackctl.evmatch import engines

    monkeypatch.setattr(engines, "VOTE_CHUNK", chunk)
    rng = np.random.default_rng(chunk)
    vids = {
        int(s): tuple(sorted({f"v{x}" for x in rng.integers(0, 9, rng.integers(0, 5))}))
        for s in range(40)
    }
    eid = rng.integers(0, 15, 300)
    scen = rng.integers(0, 45, 300)  # scenarios 40..44 have no video: they do not vote
    exclude = {"v3"}
    got = LocalEngine().vote(eid, scen, vids, exclude).values.tolist()
    want = []
    for e in sorted(set(eid.tolist())):
        c = collections.Counter(
            v
            for ee, s in zip(eid.tolist(), scen.tolist(), strict=True)
            if ee == e
            for v in vids.get(s, ())
            if v not in exclude
        )
        want += [[e, v, n] for v, n in sorted(c.items(), key=lambda x: (-x[1], x[0]))[:2]]
    assert got == want
