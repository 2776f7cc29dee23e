"""vm-track on real footage (PETS 2009 S2L1 view 001) and the geometry it relies on.

The video is not in the repository: the real-footage test skips, saying how to get it, when
TRACKCTL_VTEST does not point at vtest.avi. The covariance test covers the same code on a
synthetic camera.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from tests.conftest import ROOT, run_cli, shared_file, vtest_video
from trackctl.geometry.camera import PinholeCamera, look_at
from trackctl.ingest.calibration import read_calibration
from trackctl.logs.messages import CameraModel
from trackctl.logs.reader import LogReader
from trackctl.metrics.footlabels import read_foot_labels, score_detections
from trackctl.vmtrack.frames import FrameConfig, FrameDetector


def test_far_detections_are_uncertain_along_the_line_of_sight() -> None:
    pose = look_at(np.array([0.0, 0.0, 3.0]), np.array([10.0, 0.0, 0.0]))
    cam = PinholeCamera(CameraModel(0, "c", 640, 480, 500, 500, 320, 240, world_from_camera=pose))
    det = FrameDetector.__new__(FrameDetector)
    det.config = FrameConfig()
    near, far = np.array([[3.0, 0.5, 0.0]]), np.array([[15.0, 0.5, 0.0]])
    feet = np.vstack([cam.project(near)[0], cam.project(far)[0]])
    boxes = np.array(
        [[feet[0, 0] - 20, feet[0, 1] - 150, 40, 150], [feet[1, 0] - 5, feet[1, 1] - 40, 10, 40]]
    )
    covs = det._ground_covariances(cam, feet, boxes)
    evals = [np.linalg.eigvalsh(c) for c in covs]
    assert np.sqrt(evals[1][1]) > 2 * np.sqrt(evals[0][1])  # far: larger
    w, v = np.linalg.eigh(covs[1])
    assert abs(v[0, 1]) > 0.95  # its major axis is the x axis, the camera's line of sight
    assert w[1] > 4 * w[0]


def test_pets_view_001_tracks_without_ghosts(tmp_path: Path) -> None:
    video = vtest_video()
    calib = shared_file("footage", "pets2009_view001.yaml")
    log, out = tmp_path / "pets.mcap", tmp_path / "out.mcap"
    rec = run_cli(
        "record",
        str(log),
        "--video",
        f"cam0={video}",
        "--calib",
        f"cam0={calib}",
        "--rate",
        "7",
        "--quiet",
        timeout=300,
    )
    assert rec.returncode == 0, rec.stderr.decode()
    proc = run_cli("vm-track", str(log), "--mode", "v-af", "--out", str(out), "--json", timeout=600)
    assert proc.returncode == 0, proc.stderr.decode()
    m = json.loads(proc.stdout)
    # 19 people walk through the sequence (some leave and come back)
    assert m["tracks_published"] <= 30
    assert m["coasting_share"] < 0.25
    cam = PinholeCamera(read_calibration(calib, "cam0"))
    dets = {
        round(msg.log_time_ns * 10 / 1e9): np.array(
            [(d.ground_m.x, d.ground_m.y) for d in msg.message.detections]
        ).reshape(-1, 2)
        for msg in LogReader(out).messages(["/vmtrack/cam0/detections"])
    }
    labels = read_foot_labels(ROOT / "tests" / "data" / "pets2009_view001_feet.csv")
    score = score_detections(labels, dets, cam)
    assert score.recall >= 0.85
    assert score.false_positives <= 6
    assert float(np.median(score.errors_m)) < 0.6
