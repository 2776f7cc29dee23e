"""Detections scored against hand-labelled foot points."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import ROOT
from trackctl.errors import InputError
from trackctl.geometry.camera import PinholeCamera, look_at
from trackctl.logs.messages import CameraModel
from trackctl.metrics.footlabels import (
    FootLabel,
    PersonLabel,
    read_foot_labels,
    read_person_labels,
    score_detections,
    score_tracks,
)


def _cam() -> PinholeCamera:
    pose = look_at(np.array([0.0, 0.0, 4.0]), np.array([6.0, 0.0, 0.0]))
    return PinholeCamera(CameraModel(0, "c", 640, 480, 500, 500, 320, 240, world_from_camera=pose))


def test_score_counts_hits_misses_and_false_positives() -> None:
    cam = _cam()
    people = np.array([[5.0, 0.0, 0.0], [7.0, 1.0, 0.0], [6.0, -1.5, 0.0]])
    px, _ = cam.project(people)
    labels = [FootLabel(3, u, v) for u, v in px] + [FootLabel(3, 10.0, 400.0, occluded=True)]
    dets = {3: np.array([[5.2, 0.0], [7.0, 1.5], [12.0, 3.0]]), 4: np.array([[1.0, 1.0]])}
    score = score_detections(labels, dets, cam)
    assert score.labels == 3 and score.found == 2
    assert score.false_positives == 1  # frame 4 has no labels: not scored
    assert score.errors_m == pytest.approx((0.2, 0.5), abs=1e-6)
    assert score.summary()["label_recall"] == pytest.approx(2 / 3, abs=1e-4)
    assert score.detections == 3 and score.precision == pytest.approx(2 / 3)


def test_shipped_pets_labels_read(tmp_path: Path) -> None:
    labels = read_foot_labels(ROOT / "tests" / "data" / "pets2009_view001_feet.csv")
    assert len({lab.frame for lab in labels}) >= 10
    assert sum(not lab.occluded for lab in labels) >= 50
    bad = tmp_path / "bad.csv"
    bad.write_text("frame,u,v,occ\n1,2,3,0\n1,x,3,0\n")
    with pytest.raises(InputError, match="bad.csv:3"):
        read_foot_labels(bad)


def _people_case() -> tuple[PinholeCamera, list[PersonLabel], dict[int, dict[str, tuple]]]:
    """Two people over four labelled frames; track "a" follows A, then jumps to B at frame 30
    (one switch), "b" starts on B and goes to A; a stray track at frame 20; an occluded label
    with a track on it (don't-care); frame 25 is not labelled (its tracks do not count)."""
    cam = _cam()
    truth = {
        0: {"A": (5.0, 0.0), "B": (7.0, 1.0)},
        10: {"A": (5.2, 0.0), "B": (7.0, 1.2)},
        20: {"A": (5.4, 0.0), "B": (7.0, 1.4)},
        30: {"A": (5.6, 0.0), "B": (7.0, 1.6), "C": (6.0, -1.5)},
    }
    labels = []
    for frame, people in truth.items():
        xyz = np.array([[x, y, 0.0] for x, y in people.values()])
        px, _ = cam.project(xyz)
        labels += [
            PersonLabel(frame, name, float(u), float(v), occluded=name == "C")
            for name, (u, v) in zip(people, px, strict=True)
        ]
    tracks = {
        0: {"a": (5.1, 0.0), "b": (7.0, 1.1)},
        10: {"a": (5.3, 0.0)},  # B missed
        20: {"a": (5.4, 0.1), "b": (7.1, 1.4), "x": (9.0, 3.0)},  # x: false positive
        25: {"zz": (0.0, 0.0)},
        30: {"a": (7.0, 1.5), "c": (5.6, 0.1), "o": (6.0, -1.4)},  # a now on B, c on A
    }
    return cam, labels, tracks


def test_score_tracks_mot_and_track_ids_per_person() -> None:
    cam, labels, tracks = _people_case()
    score = score_tracks(labels, tracks, cam)
    mot = score.mot
    assert mot.frames == 4 and mot.gt == 8
    assert mot.misses == 1 and mot.false_positives == 1
    assert mot.id_switches == 2  # A: a -> c, B: b -> a
    assert mot.mota == pytest.approx(1 - 4 / 8)
    assert score.ids_per_person == {"A": 2, "B": 2}  # C is only ever occluded
    assert score.track_ids == 3  # a, b, c ("o" sits on the occluded C, "zz" on no label frame)
    summary = score.summary()
    assert summary["track_ids_per_person_max"] == 2
    assert summary["track_people_untracked"] == 0


def test_score_tracks_matches_py_motmetrics() -> None:
    mm = pytest.importorskip("motmetrics")
    cam, labels, tracks = _people_case()
    score = score_tracks(labels, tracks, cam)
    acc = mm.MOTAccumulator(auto_id=True)
    ids: dict[str, int] = {}
    for frame in sorted({lab.frame for lab in labels}):
        labs = [lab for lab in labels if lab.frame == frame and not lab.occluded]
        g = cam.ground_point(np.array([[lab.u_px, lab.v_px] for lab in labs]))[:, :2]
        hyp = {k: v for k, v in tracks[frame].items() if k != "o"}  # motmetrics: no don't-care
        h = np.array(list(hyp.values()), float).reshape(-1, 2)
        d = np.linalg.norm(g[:, None, :] - h[None, :, :], axis=2)
        d[d >= 1.0] = np.nan
        acc.update(
            [ids.setdefault(lab.person, len(ids)) for lab in labs],
            [ids.setdefault("h" + k, len(ids)) for k in hyp],
            d,
        )
    ref = mm.metrics.create().compute(acc, metrics=["mota", "idf1", "num_switches"])
    assert score.mot.mota == pytest.approx(float(ref["mota"].iloc[0]))
    assert score.mot.idf1 == pytest.approx(float(ref["idf1"].iloc[0]))
    assert score.mot.id_switches == int(ref["num_switches"].iloc[0])


def test_score_tracks_without_tracks_misses_everyone() -> None:
    cam, labels, _ = _people_case()
    score = score_tracks(labels, {}, cam)
    assert score.mot.misses == 8 and score.mot.mota == 0.0
    assert score.ids_per_person == {"A": 0, "B": 0} and score.track_ids == 0


def test_shipped_pets_people_labels_read(tmp_path: Path) -> None:
    people = read_person_labels(ROOT / "tests" / "data" / "pets2009_view001_people.csv")
    feet = read_foot_labels(ROOT / "tests" / "data" / "pets2009_view001_feet.csv")
    assert len({lab.person for lab in people if lab.person.startswith("P")}) >= 15
    assert len({lab.frame for lab in people}) >= 20
    # every foot point is there, at the same pixel, with an identity
    assert {(f.frame, f.u_px, f.v_px) for f in feet} <= {(p.frame, p.u_px, p.v_px) for p in people}
    twice = tmp_path / "twice.csv"
    twice.write_text("frame,person,u,v,occ\n1,P1,2,3,0\n1,P1,5,6,0\n")
    with pytest.raises(InputError, match=r"twice.csv:3: person 'P1' labelled twice in frame 1"):
        read_person_labels(twice)
    bad = tmp_path / "bad.csv"
    bad.write_text("frame,person,u,v,occ\n1,P1,2,3,0\n2,P1,2,3,yes\n")
    with pytest.raises(InputError, match="bad.csv:3: expected frame,person,u_px,v_px,occluded"):
        read_person_labels(bad)
