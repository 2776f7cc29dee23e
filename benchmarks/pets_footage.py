"""VM-Tracking's visual tracker on real footage: PETS 2009 S2L1 view 001 (OpenCV's vtest.avi).

Records the video with its published calibration (``trackctl record --video cam0=vtest.avi
--calib cam0=... --rate 7``), runs ``vm-track --mode v-af`` (no phones) and prints what a log
without ground truth reports (tracks, coasting share, detections per frame) plus the detections
scored against the hand-labelled foot points in ``tests/data/pets2009_view001_feet.csv`` (ten
frames, 56 people: recall within 1 m on the floor, floor error, false positives). The sequence
has 19 people; published trackers reach MOTA ~0.8-0.9 on it.

    TRACKCTL_VTEST=.../vtest.avi python benchmarks/pets_footage.py [--rate 7] [--search predicted]

Get the video with ``apt-get download opencv-doc`` (see ../shared/data/footage/README.md).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from trackctl.geometry.camera import PinholeCamera
from trackctl.ingest.calibration import read_calibration
from trackctl.logs.reader import LogReader
from trackctl.metrics.footlabels import read_foot_labels, score_detections

ROOT = Path(__file__).resolve().parent.parent
LABELS = ROOT / "tests" / "data" / "pets2009_view001_feet.csv"
CALIB = ROOT.parent / "shared" / "data" / "footage" / "pets2009_view001.yaml"


def _trackctl(*args: str) -> str:
    exe = Path(sys.executable).parent / "trackctl"
    proc = subprocess.run([str(exe), *args], capture_output=True, text=True, check=True)
    return proc.stdout


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--video", default=os.environ.get("TRACKCTL_VTEST", "vtest.avi"))
    ap.add_argument("--calib", default=str(CALIB))
    ap.add_argument("--rate", default="7")
    ap.add_argument("--search", default="predicted")
    args = ap.parse_args()
    video = Path(args.video)
    if not video.is_file():
        sys.exit(f"{video}: no such video; set TRACKCTL_VTEST or pass --video")
    cap = cv2.VideoCapture(str(video))
    file_fps = cap.get(cv2.CAP_PROP_FPS)
    cap.release()
    with tempfile.TemporaryDirectory() as tmp:
        log, out = Path(tmp) / "pets.mcap", Path(tmp) / "pets-vaf.mcap"
        t0 = time.perf_counter()
        _trackctl(
            "record",
            str(log),
            "--video",
            f"cam0={video}",
            "--calib",
            f"cam0={args.calib}",
            "--rate",
            args.rate,
            "--quiet",
        )
        t1 = time.perf_counter()
        report = json.loads(
            _trackctl(
                "vm-track",
                str(log),
                "--mode",
                "v-af",
                "--search",
                args.search,
                "--out",
                str(out),
                "--json",
                "--quiet",
            )
        )
        t2 = time.perf_counter()
        cam = PinholeCamera(read_calibration(args.calib, "cam0"))
        dets: dict[int, np.ndarray] = {}
        for m in LogReader(out).messages(["/vmtrack/cam0/detections"]):
            frame = round(m.log_time_ns * file_fps / 1e9)
            pts = [(d.ground_m.x, d.ground_m.y) for d in m.message.detections if d.ground_m]
            dets[frame] = np.array(pts).reshape(-1, 2)
        score = score_detections(read_foot_labels(LABELS), dets, cam).summary()
    print(f"record {t1 - t0:.1f} s, vm-track {t2 - t1:.1f} s ({report['frames']} frames)")
    keys = (
        "frames",
        "detections_per_frame_mean",
        "detections_per_frame_max",
        "tracks_started",
        "tracks_published",
        "tracks_stitched",
        "tracks_dropped_short",
        "track_frames_median",
        "coasting_share",
        "ms_per_frame_detection",
        "ms_per_frame_association",
    )
    for k in keys:
        print(f"{k:28s} {report[k]}")
    for k, v in score.items():
        print(f"{k:28s} {v}")


if __name__ == "__main__":
    main()
