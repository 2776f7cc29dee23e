"""VM-Tracking's visual tracker on real footage: PETS 2009 S2L1 view 001 (OpenCV's vtest.avi).

Records the video with its published calibration (``trackctl record --video cam0=vtest.avi
--calib cam0=... --rate 7``), runs ``vm-track --mode v-af`` (no phones) and prints what a log
without ground truth reports (tracks, coasting share, detections per frame) plus the detections
scored against the hand-labelled foot points in ``tests/data/pets2009_view001_feet.csv`` (ten
frames, 56 people: recall and precision within 1 m on the floor, floor error, false positives),
and the tracks scored against the same points with identities,
``tests/data/pets2009_view001_people.csv`` (``trackctl.metrics.footlabels.score_tracks``: MOTA,
IDF1, ID switches at 1 m on the ground on the labelled frames; how many track ids cover each
labelled person, and how many distinct track ids are matched to the labelled people). The
sequence has 19 people; published trackers reach MOTA ~0.8-0.9 on it.

    TRACKCTL_VTEST=.../vtest.avi python benchmarks/pets_footage.py [--rate 7] [--fps F]
        [--search predicted]

``--rate 7`` keeps 7 of the file's 10 frames a second at the file's time stamps; ``--fps 7``
restamps every frame at the sequence's true 7 fps (frame k at k/7 s). The trackctl CLI runs as
``python -m trackctl`` with this interpreter, so ``PYTHONPATH`` decides which code runs.

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
from trackctl.metrics.footlabels import (
    read_foot_labels,
    read_person_labels,
    score_detections,
    score_tracks,
)

ROOT = Path(__file__).resolve().parent.parent
LABELS = ROOT / "tests" / "data" / "pets2009_view001_feet.csv"
PEOPLE = ROOT / "tests" / "data" / "pets2009_view001_people.csv"
CALIB = ROOT.parent / "shared" / "data" / "footage" / "pets2009_view001.yaml"


def _trackctl(*args: str) -> str:
    cmd = [sys.executable, "-m", "trackctl", *args]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode:
        sys.exit(f"{' '.join(cmd)} failed:\n{proc.stderr}")
    return proc.stdout


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--video", default=os.environ.get("TRACKCTL_VTEST", "vtest.avi"))
    ap.add_argument("--calib", default=str(CALIB))
    ap.add_argument("--rate", default="7", help="keep this many frames a second ('' for all)")
    ap.add_argument("--fps", default="", help="restamp every frame at this rate (true: 7)")
    ap.add_argument("--search", default="predicted")
    args = ap.parse_args()
    video = Path(args.video)
    if not video.is_file():
        sys.exit(f"{video}: no such video; set TRACKCTL_VTEST or pass --video")
    cap = cv2.VideoCapture(str(video))
    file_fps = cap.get(cv2.CAP_PROP_FPS)
    cap.release()
    stamp_fps = float(args.fps) if args.fps else file_fps
    timing = ["--rate", args.rate] if args.rate else []
    timing += ["--fps", args.fps] if args.fps else []
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
            *timing,
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
            frame = round(m.log_time_ns * stamp_fps / 1e9)
            pts = [(d.ground_m.x, d.ground_m.y) for d in m.message.detections if d.ground_m]
            dets[frame] = np.array(pts).reshape(-1, 2)
        tracks: dict[int, dict[str, tuple[float, float]]] = {}
        for m in LogReader(out).messages(["/vmtrack/tracks"]):
            frame = round(m.log_time_ns * stamp_fps / 1e9)
            tracks[frame] = {t.track_id: (t.position_m.x, t.position_m.y) for t in m.message.tracks}
        score = score_detections(read_foot_labels(LABELS), dets, cam).summary()
        scored = score_tracks(read_person_labels(PEOPLE), tracks, cam)
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
    for k, v in scored.summary().items():
        print(f"{k:28s} {v}")
    per = " ".join(f"{p}:{n}" for p, n in scored.ids_per_person.items())
    print(f"{'track_ids_per_person':28s} {per}")


if __name__ == "__main__":
    main()
