"""The EV scenario generator: deterministic, consistent sensor models, regenerable sample log."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.logcompare import assert_same_log
from trackctl.logs import topics
from trackctl.logs.reader import LogReader
from trackctl.sim.ev import EvScenario, simulate_ev

SAMPLE = Path(__file__).resolve().parents[2] / "sample_logs" / "ev.mcap"
SMALL = dict(people=60, area_m=300.0, duration_s=600.0)


def _windows(path: Path) -> dict[int, dict[str, object]]:
    out: dict[int, dict[str, object]] = {}
    for msg in LogReader(path).messages():
        if msg.topic == topics.EV_E or msg.topic.startswith(topics.EV_V_PREFIX):
            kind = "e" if msg.topic == topics.EV_E else "v"
            out.setdefault(msg.log_time_ns, {})[f"{kind}:{msg.message.cell}"] = msg.message
    return out


def test_same_seed_same_bytes(tmp_path: Path) -> None:
    a, b, c = tmp_path / "a.mcap", tmp_path / "b.mcap", tmp_path / "c.mcap"
    simulate_ev(str(a), EvScenario(**SMALL, seed=3))
    simulate_ev(str(b), EvScenario(**SMALL, seed=3))
    simulate_ev(str(c), EvScenario(**SMALL, seed=4))
    assert a.read_bytes() == b.read_bytes() != c.read_bytes()


def test_shipped_sample_log_is_regenerable(tmp_path: Path) -> None:
    fresh = tmp_path / "ev.mcap"
    simulate_ev(str(fresh), EvScenario(people=400, area_m=600.0, duration_s=1200.0, seed=0))
    assert_same_log(fresh, SAMPLE)
    assert SAMPLE.stat().st_size < 2_000_000


def test_without_noise_inclusive_eids_are_seen_by_the_camera(tmp_path: Path) -> None:
    path = tmp_path / "clean.mcap"
    simulate_ev(str(path), EvScenario(**SMALL, eid_miss=0.0, vid_miss=0.0, drift_m=0.0, seed=1))
    reader = LogReader(path)
    (gt,) = [m.message for m in reader.messages([topics.EV_GROUND_TRUTH])]
    vid_of = {e.electronic_id: e.visual_id for e in gt.entities}
    assert len(vid_of) == 60
    for scen in _windows(path).values():
        for key, msg in scen.items():
            if key.startswith("e:"):
                v = scen["v:" + key[2:]]
                for eid in msg.eids:  # type: ignore[attr-defined]
                    assert vid_of[eid] in v.vids  # type: ignore[attr-defined]


def test_drift_makes_vague_eids_and_missing_people(tmp_path: Path) -> None:
    path = tmp_path / "noisy.mcap"
    simulate_ev(str(path), EvScenario(**SMALL, eid_miss=0.5, vid_miss=0.2, drift_m=40.0, seed=2))
    reader = LogReader(path)
    (gt,) = [m.message for m in reader.messages([topics.EV_GROUND_TRUTH])]
    phones = sum(e.electronic_id is not None for e in gt.entities)
    assert 15 < phones < 45
    vague = [v for m in reader.messages([topics.EV_E]) for v in m.message.vague]
    calm = tmp_path / "calm.mcap"
    simulate_ev(str(calm), EvScenario(**SMALL, eid_miss=0.5, vid_miss=0.2, drift_m=0.0, seed=2))
    calm_vague = [v for m in LogReader(calm).messages([topics.EV_E]) for v in m.message.vague]
    # without drift only people crossing a border mid-window are vague; drift adds many more
    assert 0.0 < np.mean(calm_vague) < np.mean(vague) - 0.1
    # every person is somewhere each window; with 20% missed detections about 80% are listed
    seen = [
        len(m.message.vids) for m in reader.messages() if m.topic.startswith(topics.EV_V_PREFIX)
    ]
    per_window = sum(seen) / reader.topics()[topics.EV_E].count * 9
    assert 0.7 * 60 < per_window < 1.1 * 60 * 1.3


def _labels(path: Path) -> tuple[dict[str, str], list[tuple[int, str, tuple[str, ...]]]]:
    reader = LogReader(path)
    (gt,) = [m.message for m in reader.messages([topics.EV_GROUND_TRUTH])]
    vid_of = {e.entity_id: e.visual_id for e in gt.entities}
    v = [
        (m.log_time_ns, m.message.cell, m.message.vids)
        for m in reader.messages()
        if m.topic.startswith(topics.EV_V_PREFIX)
    ]
    return vid_of, v


def test_reid_errors_swap_labels_per_window() -> None:
    from trackctl.sim.ev import _reid_errors

    rng = np.random.default_rng(0)
    n = 2000
    # each person seen in one or two cells of 50 this window
    person = np.concatenate([np.arange(n), np.arange(0, n, 2)])
    cell = np.concatenate([rng.integers(0, 50, n), rng.integers(0, 50, n // 2)])
    lonely = 10_000  # a cell with one person: a swap there takes a random person's VID
    cell[0] = lonely
    got = _reid_errors(0.2, person, cell, n, rng)
    wrong = got != person
    # ~20% of people, all their detections of the window
    share = len(set(person[wrong].tolist())) / n
    assert 0.17 < share < 0.23
    for who in set(person[wrong].tolist()):
        subs = set(got[person == who].tolist())
        assert len(subs) == 1 and who not in subs
    # a switch lands on someone in the same cell when there is one
    same_cell = [
        bool(np.any((person == s) & (cell == c)))
        for s, c, w in zip(got.tolist(), cell.tolist(), wrong.tolist(), strict=True)
        if w and c != lonely
    ]
    assert np.mean(same_cell) > 0.45  # the first cell's pick wins for a person seen in two


def test_hear_interval_and_long_drift(tmp_path: Path) -> None:
    always, sparse = tmp_path / "always.mcap", tmp_path / "sparse.mcap"
    simulate_ev(str(always), EvScenario(**SMALL, seed=7))
    simulate_ev(str(sparse), EvScenario(**SMALL, hear_s=30.0, seed=7))

    def listings(path: Path) -> int:
        return sum(len(m.message.eids) for m in LogReader(path).messages([topics.EV_E]))

    # heard in ~1/6 of the samples: windows with a single sample make zones coarse but a phone
    # is still listed most windows; without any contact it is not listed at all
    assert listings(sparse) < listings(always)

    def far_listings(path: Path) -> int:
        """E listings two or more cells from every cell the person's camera saw them in."""
        reader = LogReader(path)
        (gt,) = [m.message for m in reader.messages([topics.EV_GROUND_TRUTH])]
        vid_of = {e.electronic_id: e.visual_id for e in gt.entities if e.electronic_id}
        seen: dict[tuple[int, str], list[tuple[int, int]]] = {}
        far = 0
        for m in reader.messages():
            ij = (
                tuple(int(x) for x in m.message.cell.split("_"))
                if m.topic != topics.EV_GROUND_TRUTH
                else None
            )
            if m.topic.startswith(topics.EV_V_PREFIX):
                for v in m.message.vids:
                    seen.setdefault((m.log_time_ns, v), []).append(ij)
        for m in reader.messages([topics.EV_E]):
            i, j = (int(x) for x in m.message.cell.split("_"))
            for e in m.message.eids:
                cells = seen.get((m.log_time_ns, vid_of[e]), [])
                far += bool(cells) and all(max(abs(i - a), abs(j - b)) >= 2 for a, b in cells)
        return far

    near, far = tmp_path / "near.mcap", tmp_path / "far.mcap"
    simulate_ev(str(near), EvScenario(**SMALL, vid_miss=0.0, drift_m=40.0, seed=7))
    simulate_ev(str(far), EvScenario(**SMALL, vid_miss=0.0, drift_m=250.0, seed=7))
    assert far_listings(near) == 0
    assert far_listings(far) > 10
