"""Ground-plane MOT metrics, including a cross-check against py-motmetrics on the same data."""

from __future__ import annotations

import numpy as np
import pytest

from trackctl.metrics.tracking import MotAccumulator


def test_perfect_tracking() -> None:
    acc = MotAccumulator(1.0)
    for k in range(10):
        acc.update({"a": (k, 0.0), "b": (k, 5.0)}, {"1": (k + 0.1, 0.0), "2": (k, 5.1)})
    s = acc.summary()
    assert (s.mota, s.idf1, s.id_switches, s.false_positives, s.misses) == (1.0, 1.0, 0, 0, 0)
    assert s.motp_m == pytest.approx(0.1)


def test_identity_swap_counts_two_switches_and_halves_idf1() -> None:
    acc = MotAccumulator(1.0)
    for k in range(10):
        hyp = {"1": (k, 0.0), "2": (k, 5.0)} if k < 5 else {"2": (k, 0.0), "1": (k, 5.0)}
        acc.update({"a": (k, 0.0), "b": (k, 5.0)}, hyp)
    s = acc.summary()
    assert s.id_switches == 2
    assert s.idf1 == pytest.approx(0.5)
    assert s.mota == pytest.approx(1 - 2 / 20)


def test_ignored_people_are_dont_care() -> None:
    acc = MotAccumulator(1.0)
    acc.update(
        {"user": (0.0, 0.0), "other": (5.0, 0.0)},
        {"1": (0.0, 0.0), "2": (5.0, 0.2)},
        ignore=["other"],
    )
    s = acc.summary()
    assert (s.gt, s.false_positives, s.idf1) == (1, 0, 1.0)


def test_matches_py_motmetrics_on_random_data() -> None:
    mm = pytest.importorskip("motmetrics")
    rng = np.random.default_rng(3)
    ours = MotAccumulator(1.0)
    theirs = mm.MOTAccumulator(auto_id=True)
    gt_ids = list(range(6))
    pos = rng.uniform(0, 10, (6, 2))
    for _k in range(120):
        pos += rng.normal(0, 0.3, pos.shape)
        present = [g for g in gt_ids if rng.random() > 0.1]
        hyp = {}
        for g in present:
            if rng.random() < 0.9:
                hid = g if rng.random() > 0.03 else (g + 1) % 6  # occasional identity error
                if hid not in hyp:
                    hyp[hid] = pos[g] + rng.normal(0, 0.3, 2)
        if rng.random() < 0.3:
            hyp[100 + _k] = rng.uniform(0, 10, 2)  # false positive
        gt = {str(g): tuple(pos[g]) for g in present}
        h = {str(k): tuple(v) for k, v in hyp.items()}
        ours.update(gt, h)
        g_xy = np.array([pos[g] for g in present]).reshape(-1, 2)
        h_xy = np.array(list(hyp.values())).reshape(-1, 2)
        dist = mm.distances.norm2squared_matrix(g_xy, h_xy, max_d2=1.0)
        theirs.update([int(g) for g in present], [int(k) for k in hyp], dist)
    s = ours.summary()
    ref = mm.metrics.create().compute(
        theirs, metrics=["mota", "idf1", "num_switches", "num_false_positives", "num_misses"]
    )
    assert s.misses == int(ref["num_misses"].iloc[0])
    assert s.false_positives == int(ref["num_false_positives"].iloc[0])
    assert s.id_switches == int(ref["num_switches"].iloc[0])
    assert s.mota == pytest.approx(float(ref["mota"].iloc[0]), abs=1e-9)
    assert s.idf1 == pytest.approx(float(ref["idf1"].iloc[0]), abs=1e-9)


def test_initial_identity_follows_the_first_track_through_a_swap() -> None:
    from trackctl.metrics.tracking import InitialIdentity

    ident = InitialIdentity(1.0)
    # person a starts next to track "1"; at k=5 the tracker swaps the two tracks
    errs = []
    for k in range(10):
        hyp = {"1": (k, 0.0), "2": (k, 5.0)} if k < 5 else {"2": (k, 0.0), "1": (k, 5.0)}
        errs.append(ident.error("a", (k, 0.0), hyp))
    assert errs[:5] == [0.0] * 5
    assert errs[5:] == [5.0] * 5
    # nobody within the threshold: not followed (yet)
    assert InitialIdentity(1.0).error("b", (0.0, 0.0), {"1": (3.0, 0.0)}) is None
