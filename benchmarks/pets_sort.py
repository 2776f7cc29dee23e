"""trackctl V-AF against SORT on the same detections of real footage (PETS 2009 S2L1 view 001).

The detections are trackctl's own: ``trackctl record --video cam0=vtest.avi --calib cam0=...``
then ``vm-track --mode v-af``; the boxes of every frame's ``/vmtrack/cam0/detections`` are
written as a MOTChallenge ``det.txt`` (``frame,-1,bb_left,bb_top,bb_width,bb_height,conf,-1,-1,-1``,
1-based pixels and frames, one frame per recorded video frame). Both trackers then read exactly
that file:

* ``trackctl`` -- ``record --detections cam0=det.txt --calib cam0=... --fps F`` (the library
  call) then ``vm-track --mode v-af``: ground-plane tracks (``/vmtrack/tracks``).
* ``SORT`` -- the reference SORT of ``benchmarks/vm_sort.py`` (Bewley et al. 2016, re-implemented:
  box Kalman filter, IoU + Hungarian, IoU gate 0.3, min_hits 3, max_age 1); each box's foot
  point (bottom centre) is placed on the ground through the same calibration.

Scored the same way (``trackctl.metrics.footlabels.score_tracks``): on the ground plane, 1 m,
against the hand-labelled identities of ``tests/data/pets2009_view001_people.csv`` on its
labelled frames; "ids" is how many distinct track ids are matched to the labelled people. The
first row is the video run's own tracks (same detector, the tracker also sees the frames); the
detections themselves are scored against the same labels first (recall, precision at 1 m).

    TRACKCTL_VTEST=.../vtest.avi python benchmarks/pets_sort.py [--fps 7] [--rate R]
        [--det PETS09-S2L1/det.txt]

``--det`` (or ``TRACKCTL_PETS_DET``) gives both trackers a det.txt of the sequence instead of
trackctl's own detections: the public detections of MOTChallenge's PETS09-S2L1 (795 frames, its
frame k the file's frame k - 1; e.g. ``data/train/PETS09-S2L1/det/det.txt`` of Bewley's SORT
repository, which SORT's paper ran on; never committed here). It needs every frame (no
``--rate``). The first row stays the video run's own tracks.

Default timing: every frame of the file restamped at the sequence's true 7 fps (``--fps 7``);
``--rate 7 --fps ''`` is ``pets_footage.py``'s (7 of the file's 10 frames a second at the file's
stamps; det.txt then numbers the kept frames 1, 2, ... and is recorded at 7 fps).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from vm_sort import read_det, sort_track

from trackctl.geometry.camera import PinholeCamera
from trackctl.ingest.calibration import read_calibration
from trackctl.ingest.record import IngestPlan, RecordConfig, ingest
from trackctl.logs.reader import LogReader
from trackctl.metrics.footlabels import (
    FootLabel,
    TrackScore,
    read_person_labels,
    score_detections,
    score_tracks,
)
from trackctl.processing import run_processors
from trackctl.vmtrack import Mode, VmTrackConfig, VmTrackProcessor

ROOT = Path(__file__).resolve().parent.parent
PEOPLE = ROOT / "tests" / "data" / "pets2009_view001_people.csv"
CALIB = ROOT.parent / "shared" / "data" / "footage" / "pets2009_view001.yaml"

GroundTracks = dict[int, dict[str, tuple[float, float]]]  # file frame -> track id -> (x, y)


def _trackctl(*args: str) -> str:
    cmd = [sys.executable, "-m", "trackctl", *args]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode:
        sys.exit(f"{' '.join(cmd)} failed:\n{proc.stderr}")
    return proc.stdout


def video_run(args: argparse.Namespace, work: Path) -> Path:
    """record --video + vm-track --mode v-af; the output log."""
    log, out = work / "pets.mcap", work / "pets-vaf.mcap"
    timing = ["--rate", args.rate] if args.rate else []
    timing += ["--fps", args.fps] if args.fps else []
    _trackctl("record", str(log), "--video", f"cam0={args.video}", "--calib",
              f"cam0={args.calib}", *timing, "--quiet")  # fmt: skip
    _trackctl("vm-track", str(log), "--mode", "v-af", "--out", str(out), "--quiet")
    return out


def write_det(out: Path, det: Path, stamp_fps: float) -> list[int]:
    """The v-af run's detections as det.txt; returns the file frame of each det.txt frame."""
    frames: list[int] = []
    lines: list[str] = []
    for i, m in enumerate(LogReader(out).messages(["/vmtrack/cam0/detections"]), 1):
        frames.append(round(m.log_time_ns * stamp_fps / 1e9))
        for d in m.message.detections:
            b = d.box
            lines.append(
                f"{i},-1,{b.x_px + 1:.2f},{b.y_px + 1:.2f},{b.w_px:.2f},{b.h_px:.2f},"
                f"{d.score:.4f},-1,-1,-1\n"
            )
    det.write_text("".join(lines))
    return frames


def det_frames(det: Path) -> list[int]:
    """The file frame of each det.txt frame of a det.txt of the whole sequence (frame k is
    the file's k - 1), up to its last frame."""
    last = max((int(line.split(",", 1)[0]) for line in det.read_text().splitlines()), default=0)
    return list(range(last))


def det_ground(det: Path, cam: PinholeCamera, frames: list[int]) -> dict[int, np.ndarray]:
    """The boxes' foot points (bottom centres) on the ground, per file frame."""
    out: dict[int, np.ndarray] = {f: np.empty((0, 2)) for f in frames}
    for k, boxes in read_det(det, 0.0).items():
        feet = np.array([[b[0] + b[2] / 2, b[1] + b[3]] for b in boxes]).reshape(-1, 2)
        g = cam.ground_point(feet)[:, :2] if len(feet) else np.empty((0, 2))
        out[frames[k - 1]] = g[~np.isnan(g).any(axis=1)]
    return out


def tracks_of(log: Path, frame_of: dict[int, int]) -> GroundTracks:
    """``/vmtrack/tracks`` per file frame; ``frame_of`` maps a message's time (ns) to it."""
    out: GroundTracks = {}
    for m in LogReader(log).messages(["/vmtrack/tracks"]):
        frame = frame_of.get(m.log_time_ns)
        if frame is not None:
            out[frame] = {t.track_id: (t.position_m.x, t.position_m.y) for t in m.message.tracks}
    return out


def trackctl_on_det(
    work: Path, det: Path, calib: Path, frames: list[int], fps: float
) -> GroundTracks:
    rec, out = work / "det.mcap", work / "det-vaf.mcap"
    cfg = RecordConfig(detections={"cam0": det}, calib={"cam0": calib}, fps=fps)
    ingest(IngestPlan(cfg), rec)
    run_processors(rec, out, [VmTrackProcessor(VmTrackConfig(mode=Mode.V_AF))])
    # det.txt frame k is at (k - 1) / fps s
    stamps = {round((k - 1) / fps * 1e9): f for k, f in enumerate(frames, 1)}
    return tracks_of(out, stamps)


def sort_on_det(det: Path, cam: PinholeCamera, frames: list[int]) -> GroundTracks:
    boxes = sort_track(read_det(det, 0.0), len(frames))
    out: GroundTracks = {}
    for k, per in boxes.items():
        if not per:
            out[frames[k - 1]] = {}
            continue
        feet = np.array([[b[0] + b[2] / 2, b[1] + b[3]] for _, b in per])
        ground = cam.ground_point(feet)[:, :2]
        out[frames[k - 1]] = {
            i: (float(g[0]), float(g[1]))
            for (i, _), g in zip(per, ground, strict=True)
            if not np.isnan(g).any()
        }
    return out


def _row(name: str, s: TrackScore) -> str:
    m = s.mot
    return (
        f"{name:<22}{m.mota:>7.3f}{m.idf1:>7.3f}{m.id_switches:>6}{m.false_positives:>5}"
        f"{m.misses:>5}{s.track_ids:>5}{max(s.ids_per_person.values(), default=0):>8}"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--video", default=os.environ.get("TRACKCTL_VTEST", "vtest.avi"))
    ap.add_argument("--calib", default=str(CALIB))
    ap.add_argument("--fps", default="7", help="restamp every frame at this rate ('' keeps)")
    ap.add_argument("--rate", default="", help="keep this many frames a second ('': all)")
    ap.add_argument(
        "--det",
        default=os.environ.get("TRACKCTL_PETS_DET", ""),
        help="a det.txt of the whole sequence for both trackers (default: trackctl's own)",
    )
    args = ap.parse_args(argv)
    if args.det and (args.rate or not args.fps):
        sys.exit("--det needs every frame at the sequence's rate (--fps 7, no --rate)")
    if not Path(args.video).is_file():
        sys.exit(f"{args.video}: no such video; set TRACKCTL_VTEST or pass --video")
    cap = cv2.VideoCapture(args.video)
    file_fps = cap.get(cv2.CAP_PROP_FPS)
    cap.release()
    stamp_fps = float(args.fps) if args.fps else file_fps
    det_fps = float(args.fps or args.rate or file_fps)
    cam = PinholeCamera(read_calibration(args.calib, "cam0"))
    labels = read_person_labels(PEOPLE)
    with tempfile.TemporaryDirectory(prefix="pets_sort_") as tmp:
        work = Path(tmp)
        t0 = time.perf_counter()
        out = video_run(args, work)
        if args.det:
            det = Path(args.det)
            frames = det_frames(det)
        else:
            det = work / "det.txt"
            frames = write_det(out, det, stamp_fps)
        t1 = time.perf_counter()
        video_stamps = {
            m.log_time_ns: round(m.log_time_ns * stamp_fps / 1e9)
            for m in LogReader(out).messages(["/vmtrack/cam0/detections"])
        }
        ours_video = tracks_of(out, video_stamps)
        ground = (
            det_ground(det, cam, frames)
            if args.det
            else {
                video_stamps[m.log_time_ns]: np.array(
                    [(d.ground_m.x, d.ground_m.y) for d in m.message.detections if d.ground_m]
                ).reshape(-1, 2)
                for m in LogReader(out).messages(["/vmtrack/cam0/detections"])
            }
        )
        ours = trackctl_on_det(work, det, Path(args.calib), frames, det_fps)
        t2 = time.perf_counter()
        sort = sort_on_det(det, cam, frames)
        t3 = time.perf_counter()
        n_boxes = len(det.read_text().splitlines())
    people = len({lab.person for lab in labels if not lab.occluded})
    source = args.det or "trackctl's own detector"
    feet = [FootLabel(lab.frame, lab.u_px, lab.v_px, lab.occluded) for lab in labels]
    dscore = score_detections(feet, ground, cam)
    print(
        f"PETS09-S2L1 view 001: det.txt of {source}, {len(frames)} frames, "
        f"{n_boxes} boxes, recorded at {det_fps:g} fps; scored on the ground at 1 m against "
        f"{len({lab.frame for lab in labels})} labelled frames, {people} people"
    )
    print(
        f"the detections against the labels: recall {dscore.recall:.3f}, precision "
        f"{dscore.precision:.3f} ({dscore.found} of {dscore.labels} people, "
        f"{dscore.false_positives} false of {dscore.detections})"
    )
    print(
        f"{'tracker':<22}{'MOTA':>7}{'IDF1':>7}{'IDsw':>6}{'FP':>5}{'FN':>5}{'ids':>5}{'ids/p':>8}"
    )
    print(_row("trackctl (video)", score_tracks(labels, ours_video, cam)))
    print(_row("trackctl (det.txt)", score_tracks(labels, ours, cam)))
    print(_row("SORT (det.txt)", score_tracks(labels, sort, cam)))
    print(
        f"seconds: video record + vm-track {t1 - t0:.1f}, trackctl on det.txt {t2 - t1:.1f}, "
        f"SORT {t3 - t2:.1f}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
