"""Detections scored against hand-labelled foot points."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import ROOT
from trackctl.errors import InputError
from trackctl.geometry.camera import PinholeCamera, look_at
from trackctl.logs.messages import CameraModel
from trackctl.metrics.footlabels import FootLabel, read_foot_labels, score_detections


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


def test_shipped_pets_labels_read(tmp_path: Path) -> None:
    labels = read_foot_labels(ROOT / "tests" / "data" / "pets2009_view001_feet.csv")
    assert len({lab.frame for lab in labels}) >= 10
    assert sum(not lab.occluded for lab in labels) >= 50
    bad = tmp_path / "bad.csv"
    bad.write_text("frame,u,v,occ\n1,2,3,0\n1,x,3,0\n")
    with pytest.raises(InputError, match="bad.csv:3"):
        read_foot_labels(bad)
