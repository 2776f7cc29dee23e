"""trackctl on MOTChallenge-style public detections against SORT, on the same det.txt files.

Scene: the office of ``trackctl simulate vm`` (6 x 5 m, two cameras 4 m up, 640x480) with
``--people`` walking for ``--duration`` s, truth at ``--fps``. Public detections are made from
the truth the way MOTChallenge ships them: each person a box 1.7 m tall and 0.41 x its height
wide, foot point (bottom centre) on the true ground position, projected through each camera;
then a detector's flaws: the box corners jittered by ``--jitter`` x the box height (std), a
share ``--miss`` of the boxes missed, and ``--false`` false boxes per frame at low scores. Each
camera's boxes go to a ``det.txt`` (``frame,id,bb_left,bb_top,bb_width,bb_height,conf,x,y,z``,
1-based pixels).

Trackers, both fed exactly those files with the same ``--min-score``:

* ``trackctl`` -- ``trackctl record --detections CAM=det.txt --calib CAM=... --fps F`` (the
  library call) then ``vm-track --mode v-af``: one set of ground-plane tracks fused over both
  cameras. To score it on image boxes, each track is drawn back into each camera as the same
  1.7 m box at its ground position.
* ``SORT`` -- the reference SORT of Bewley et al. 2016 ("Simple Online and Realtime Tracking",
  ICIP; github.com/abewley/sort) re-implemented here: per camera, a constant-velocity Kalman
  filter per track on (centre u, v, area s, aspect r) with filterpy, IoU cost with scipy's
  ``linear_sum_assignment``, IoU gate 0.3, ``min_hits`` 3, ``max_age`` 1 (its defaults).

Scoring: py-motmetrics (CLEAR MOT and IDF1), per camera, IoU >= 0.5 between a hypothesis box
and a true box (the truth: every person fully in that camera's image), summed over cameras
(``overall``). motmetrics 1.4's own ``iou_matrix`` calls ``np.asfarray`` (gone in NumPy 2), so
the distance matrix (1 - IoU, NaN below 0.5) is computed here and given to its accumulator.

Run from the repository root:

    python benchmarks/vm_sort.py [--duration 60] [--people 4] [--fps 10] [--seed 3]

Deterministic: same options -> same table (except the seconds).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import motmetrics as mm
import numpy as np
from filterpy.kalman import KalmanFilter
from scipy.optimize import linear_sum_assignment

from trackctl.geometry.camera import PinholeCamera
from trackctl.ingest.calibration import write_calibration
from trackctl.ingest.record import IngestPlan, RecordConfig, ingest
from trackctl.logs import LogReader, topics
from trackctl.processing import run_processors
from trackctl.sim.vm import VmScenario, simulate_vm
from trackctl.vmtrack import Mode, VmTrackConfig, VmTrackProcessor

Box = tuple[float, float, float, float]  # left, top, width, height (0-based px)
PerFrame = dict[int, list[tuple[str, Box]]]  # frame -> [(id, box)]


def person_box(cam: PinholeCamera, x: float, y: float) -> Box | None:
    """A 1.7 m person's box at (x, y), or None unless fully in the image."""
    px, front = cam.project(np.array([[x, y, 0.0], [x, y, 1.7]]))
    (fx, fy), (_, hy) = px
    h = float(fy - hy)
    w = 0.41 * h
    left, top = float(fx) - w / 2, float(hy)
    m = cam.model
    if not front.all() or h <= 0 or left < 0 or top < 0 or left + w > m.width_px:
        return None
    return (left, top, w, h) if fy <= m.height_px else None


# --- the reference SORT (Bewley et al. 2016), re-implemented -----------------------------------


def _z(b: Box) -> np.ndarray:
    return np.array([b[0] + b[2] / 2, b[1] + b[3] / 2, b[2] * b[3], b[2] / b[3]]).reshape(4, 1)


def _box(x: np.ndarray) -> Box:
    w = float(np.sqrt(max(x[2, 0] * x[3, 0], 1e-9)))
    h = float(x[2, 0]) / w
    return (float(x[0, 0]) - w / 2, float(x[1, 0]) - h / 2, w, h)


class KalmanBoxTracker:
    """SORT's track: state (u, v, s, r, du, dv, ds), constant velocity, r constant."""

    count = 0

    def __init__(self, box: Box) -> None:
        kf = KalmanFilter(dim_x=7, dim_z=4)
        kf.F = np.eye(7) + np.eye(7, k=4)[:7]
        kf.H = np.eye(4, 7)
        kf.R[2:, 2:] *= 10.0
        kf.P[4:, 4:] *= 1000.0
        kf.P *= 10.0
        kf.Q[-1, -1] *= 0.01
        kf.Q[4:, 4:] *= 0.01
        kf.x[:4] = _z(box)
        self.kf = kf
        KalmanBoxTracker.count += 1
        self.id = f"s{KalmanBoxTracker.count}"
        self.since_update = 0
        self.hit_streak = 0

    def predict(self) -> Box:
        if self.kf.x[6, 0] + self.kf.x[2, 0] <= 0:
            self.kf.x[6, 0] = 0.0
        self.kf.predict()
        if self.since_update > 0:
            self.hit_streak = 0
        self.since_update += 1
        return _box(self.kf.x)

    def update(self, box: Box) -> None:
        self.since_update = 0
        self.hit_streak += 1
        self.kf.update(_z(box))


def iou(a: list[Box], b: list[Box]) -> np.ndarray:
    """IoU matrix (len(a), len(b))."""
    if not a or not b:
        return np.zeros((len(a), len(b)))
    pa, pb = np.array(a)[:, None, :], np.array(b)[None, :, :]
    ix = np.clip(
        np.minimum(pa[..., 0] + pa[..., 2], pb[..., 0] + pb[..., 2])
        - np.maximum(pa[..., 0], pb[..., 0]),
        0,
        None,
    )
    iy = np.clip(
        np.minimum(pa[..., 1] + pa[..., 3], pb[..., 1] + pb[..., 3])
        - np.maximum(pa[..., 1], pb[..., 1]),
        0,
        None,
    )
    inter = ix * iy
    return inter / (pa[..., 2] * pa[..., 3] + pb[..., 2] * pb[..., 3] - inter)


def sort_track(
    dets: dict[int, list[Box]], frames: int, min_hits: int = 3, max_age: int = 1
) -> PerFrame:
    """SORT over frames 1..frames: per frame, the confirmed tracks' boxes."""
    tracks: list[KalmanBoxTracker] = []
    out: PerFrame = {}
    for frame in range(1, frames + 1):
        boxes = dets.get(frame, [])
        preds = [t.predict() for t in tracks]
        cost = iou(boxes, preds)
        rows, cols = linear_sum_assignment(-cost) if cost.size else ([], [])
        matched = {r: c for r, c in zip(rows, cols, strict=True) if cost[r, c] >= 0.3}
        for r, c in matched.items():
            tracks[c].update(boxes[r])
        tracks += [KalmanBoxTracker(b) for r, b in enumerate(boxes) if r not in matched]
        out[frame] = [
            (t.id, _box(t.kf.x))
            for t in tracks
            if t.since_update < 1 and (t.hit_streak >= min_hits or frame <= min_hits)
        ]
        tracks = [t for t in tracks if t.since_update <= max_age]
    return out


# --- scene, detections, trackctl --------------------------------------------------------------


Scene = tuple[dict[str, PinholeCamera], dict[str, PerFrame], dict[str, Path], int]
GroundTracks = dict[int, list[tuple[str, float, float]]]


def make_scene(args: argparse.Namespace, work: Path) -> Scene:
    """The simulated log; per camera the camera, the true boxes and the det.txt file."""
    log = work / "scene.mcap"
    scenario = VmScenario(
        field="office", users=0, nonusers=args.people, duration_s=args.duration,
        seed=args.seed, fps=args.fps, preset="paper",
    )  # fmt: skip
    simulate_vm(str(log), scenario)
    reader = LogReader(log)
    models = {}
    for topic in sorted(t for t in reader.topics() if t.endswith("/camera_model")):
        models[topic.split("/")[1]] = next(iter(reader.messages([topic]))).message
    truth = [m.message for m in reader.messages([topics.GROUND_TRUTH])]
    rng = np.random.default_rng(args.seed)
    cams: dict[str, PinholeCamera] = {}
    gt_boxes: dict[str, PerFrame] = {}
    det_files: dict[str, Path] = {}
    frames = 0
    for name, model in sorted(models.items()):
        cam = cams[name] = PinholeCamera(model)
        per: PerFrame = defaultdict(list)
        lines: list[tuple[int, Box, float]] = []
        for gt in truth:
            frame = round(gt.t_ns * args.fps / 1e9) + 1
            frames = max(frames, frame)
            for e in gt.entities:
                box = person_box(cam, e.position_m.x, e.position_m.y)
                if box is None:
                    continue
                per[frame].append((e.entity_id, box))
                if rng.random() < args.miss:
                    continue
                j = rng.normal(0, args.jitter * box[3], 4)
                b = (box[0] + j[0], box[1] + j[1], max(2.0, box[2] + j[2]), max(4.0, box[3] + j[3]))
                lines.append((frame, b, float(rng.uniform(0.5, 1.0))))
            for _ in range(rng.poisson(args.false)):
                h = rng.uniform(40, 120)
                x, y = rng.uniform(0, 600), rng.uniform(0, 480 - h)
                lines.append((frame, (x, y, 0.41 * h, h), float(rng.uniform(0.05, 0.6))))
        gt_boxes[name] = per
        det_files[name] = work / f"{name}-det.txt"
        det_files[name].write_text(
            "".join(
                f"{f},-1,{b[0] + 1:.2f},{b[1] + 1:.2f},{b[2]:.2f},{b[3]:.2f},{c:.3f},-1,-1,-1\n"
                for f, b, c in lines
            )
        )
        write_calibration(model, work / f"{name}.yaml")
    return cams, gt_boxes, det_files, frames


def read_det(path: Path, min_score: float) -> dict[int, list[Box]]:
    out: dict[int, list[Box]] = defaultdict(list)
    for line in path.read_text().splitlines():
        f = line.split(",")
        if float(f[6]) >= min_score:
            out[int(f[0])].append((float(f[2]) - 1, float(f[3]) - 1, float(f[4]), float(f[5])))
    return out


def run_trackctl(
    work: Path, det_files: dict[str, Path], fps: float, min_score: float
) -> GroundTracks:
    """record --detections + vm-track --mode v-af: per frame, every track's ground (x, y)."""
    rec = work / "det.mcap"
    cfg = RecordConfig(
        detections=det_files,
        calib={c: work / f"{c}.yaml" for c in det_files},
        fps=fps,
        min_score=min_score,
    )
    ingest(IngestPlan(cfg), rec)
    out = work / "tracked.mcap"
    run_processors(rec, out, [VmTrackProcessor(VmTrackConfig(mode=Mode.V_AF))])
    per: GroundTracks = {}
    for m in LogReader(out).messages(["/vmtrack/tracks"]):
        frame = round(m.message.t_ns * fps / 1e9) + 1
        per[frame] = [(t.track_id, t.position_m.x, t.position_m.y) for t in m.message.tracks]
    return per


def accumulate(gt: PerFrame, hyp: PerFrame, frames: int) -> mm.MOTAccumulator:
    acc = mm.MOTAccumulator(auto_id=True)
    ids: dict[str, int] = {}  # motmetrics 1.4 stores ids as floats
    for frame in range(1, frames + 1):
        g, h = gt.get(frame, []), hyp.get(frame, [])
        d = 1.0 - iou([b for _, b in g], [b for _, b in h])
        d[d > 0.5] = np.nan
        g_ids = [ids.setdefault(f"g{i}", len(ids)) for i, _ in g]
        h_ids = [ids.setdefault(f"h{i}", len(ids)) for i, _ in h]
        acc.update(g_ids, h_ids, d)
    return acc


METRICS = [
    "mota",
    "idf1",
    "num_switches",
    "num_false_positives",
    "num_misses",
    "num_unique_objects",
]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--people", type=int, default=4)
    ap.add_argument("--fps", type=float, default=10.0)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--jitter", type=float, default=0.03, help="box corner std / box height")
    ap.add_argument("--miss", type=float, default=0.1, help="share of boxes missed")
    ap.add_argument("--false", type=float, default=0.3, help="false boxes per camera frame")
    ap.add_argument("--min-score", type=float, default=0.3)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="vm_sort_") as tmp:
        work = Path(tmp)
        cams, gt_boxes, det_files, frames = make_scene(args, work)
        t0 = time.perf_counter()
        ground = run_trackctl(work, det_files, args.fps, args.min_score)
        t_ours = time.perf_counter() - t0
        t0 = time.perf_counter()
        sorted_ = {c: sort_track(read_det(det_files[c], args.min_score), frames) for c in cams}
        t_sort = time.perf_counter() - t0
    accs, names = [], []
    for c, cam in sorted(cams.items()):
        drawn: PerFrame = {
            f: [(i, b) for i, x, y in tr if (b := person_box(cam, x, y)) is not None]
            for f, tr in ground.items()
        }
        accs += [
            accumulate(gt_boxes[c], drawn, frames),
            accumulate(gt_boxes[c], sorted_[c], frames),
        ]
        names += [f"trackctl {c}", f"SORT {c}"]
    mh = mm.metrics.create()
    summary = mh.compute_many(accs, metrics=METRICS, names=names)
    print(
        f"public detections: office, {args.people} people, {args.duration:g} s at "
        f"{args.fps:g} fps, {len(cams)} cameras; jitter {args.jitter:g} x h, miss {args.miss:g}, "
        f"{args.false:g} false boxes/frame, --min-score {args.min_score:g}; IoU >= 0.5"
    )
    print(f"{'tracker':<16}{'MOTA':>8}{'IDF1':>8}{'IDsw':>6}{'FP':>6}{'FN':>6}{'GT':>5}")
    for name in names:
        r = summary.loc[name]
        print(
            f"{name:<16}{r.mota:>8.3f}{r.idf1:>8.3f}{int(r.num_switches):>6}"
            f"{int(r.num_false_positives):>6}{int(r.num_misses):>6}{int(r.num_unique_objects):>5}"
        )
    for label, idx in (("trackctl", 0), ("SORT", 1)):
        both = mh.compute_many(
            accs[idx::2], metrics=METRICS, names=names[idx::2], generate_overall=True
        )
        r = both.loc["OVERALL"]
        print(
            f"{label + ' overall':<16}{r.mota:>8.3f}{r.idf1:>8.3f}{int(r.num_switches):>6}"
            f"{int(r.num_false_positives):>6}{int(r.num_misses):>6}{int(r.num_unique_objects):>5}"
        )
    n_ours = len({i for tr in ground.values() for i, _, _ in tr})
    n_sort = {c: len({i for fr in s.values() for i, _ in fr}) for c, s in sorted(sorted_.items())}
    print(f"track ids: trackctl {n_ours} (both cameras), SORT {n_sort}; people {args.people}")
    print(f"seconds: trackctl (record + vm-track) {t_ours:.2f}, SORT {t_sort:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
