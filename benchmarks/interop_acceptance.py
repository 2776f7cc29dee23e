"""Issue 46's acceptance, end to end: trackctl's results read by the field's own tools.

Runs the real command lines (``python -m trackctl ...`` in subprocesses, as a user would) and
reads what they wrote with each tool's own loader:

a. quickstart ``vm-track`` -> ``export --format mot``: ``motmetrics.io.loadtxt`` reads the tracks
   and the log's truth, and py-motmetrics' MOTA equals the report's (``mota_all``: every track
   against every person; ``mota``: the phone carriers against the tracks named by their phone).
b. ``process --with dead-reckoning`` -> ``export --format tum``:
   ``evo.tools.file_interface.read_tum_trajectory_file`` reads it.
c. ``record --detections`` of MOTChallenge det.txt files plus calibrations, then ``vm-track
   --mode v-af``: a track per person; then ``benchmarks/vm_sort.py`` (trackctl beside SORT).
d. the real ROS 1 bag: ``record --ros``, dead reckoning of ``/wheel_odometry``: its end against
   the bag's own odometry pose (read with rosbags), the warning(s), robots, the APE line.
e. Foxglove: the quickstart output's ``foxglove.ImageAnnotations`` channels decoded with
   ``mcap_protobuf.decoder.DecoderFactory``.

Run from the repository root (about two minutes on two cores; ``--skip-sort`` leaves out the SORT
benchmark):

    python benchmarks/interop_acceptance.py [--work /tmp/h46] [--skip-sort]
        [--bag ../shared/data/robots/mustang_ros1.bag]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_BAG = ROOT.parent / "shared" / "data" / "robots" / "mustang_ros1.bag"
MOT_THRESHOLD_M = 1.0  # VmTrackConfig.eval_threshold_m


def trackctl(*args: str) -> subprocess.CompletedProcess[str]:
    """Run ``trackctl ARGS`` (this checkout's code), echo the command and what it printed."""
    print(f"$ trackctl {' '.join(args)}", flush=True)
    env = dict(os.environ, PYTHONPATH=str(ROOT), COLUMNS="160")
    proc = subprocess.run(
        [sys.executable, "-m", "trackctl", *args], capture_output=True, text=True, env=env
    )
    for stream in (proc.stdout, proc.stderr):
        if stream.strip():
            print(stream.rstrip())
    if proc.returncode != 0:
        raise SystemExit(f"trackctl {' '.join(args)} exited {proc.returncode}")
    return proc


def section(title: str) -> None:
    print(f"\n=== {title} ===", flush=True)


# -- a. MOT export scored by py-motmetrics ------------------------------------------------------


def _mota(gt, hyp, keep_gt: set[int], keep_hyp: set[int]) -> float:  # type: ignore[no-untyped-def]
    """py-motmetrics' MOTA on the ground plane (world x, y are MOT columns 8-9, which loadtxt
    names ClassId and Visibility), gated at the report's 1 m."""
    import motmetrics as mm

    acc = mm.MOTAccumulator(auto_id=False)
    frames, hyp_frames = gt.index.get_level_values(0), hyp.index.get_level_values(0)
    xy = ["ClassId", "Visibility"]
    for f in sorted(set(frames)):
        g = gt[frames == f].droplevel(0)
        h = hyp[hyp_frames == f].droplevel(0)
        g, h = g[g.index.isin(keep_gt)], h[h.index.isin(keep_hyp)]
        d = mm.distances.norm2squared_matrix(
            g[xy].to_numpy(), h[xy].to_numpy(), max_d2=MOT_THRESHOLD_M**2
        )
        acc.update(g.index.to_numpy(), h.index.to_numpy(), d, frameid=f)
    summary = mm.metrics.create().compute(acc, metrics=["mota"], name="export")
    return float(summary["mota"].iloc[0])


def quickstart_mot(work: Path) -> Path:
    import motmetrics as mm
    import pandas as pd

    from trackctl.export import ids_path
    from trackctl.logs import LogReader

    section("a. quickstart -> MOTChallenge txt -> py-motmetrics")
    vm = work / "vm.mcap"
    trackctl("vm-track", "sample_logs/vm-office.mcap", "--out", str(vm))
    tracks, truth = work / "t.txt", work / "gt.txt"
    trackctl(
        "export", str(vm), "--topic", "/vmtrack/tracks", "--format", "mot", "--out", str(tracks)
    )
    trackctl("export", str(vm), "--topic", "/ground_truth", "--format", "mot", "--out", str(truth))
    report = json.loads(trackctl("report", str(vm), "--json").stdout)["reports"][-1]["metrics"]
    hyp = mm.io.loadtxt(str(tracks), fmt="mot15-2D")
    gt = mm.io.loadtxt(str(truth), fmt="mot15-2D")
    print(f"motmetrics.io.loadtxt: {len(hyp)} track rows, {len(gt)} truth rows")

    def ids(path: Path) -> dict[str, int]:
        table = pd.read_csv(ids_path(path), dtype={"track_id": str})
        return dict(zip(table.track_id, table.mot_id, strict=True))

    hyp_ids, gt_ids = ids(tracks), ids(truth)
    every = _mota(gt, hyp, set(gt_ids.values()), set(hyp_ids.values()))
    carriers: dict[str, str] = {}
    for msg in LogReader(vm).messages(["/ground_truth"]):
        carriers.update(
            {e.entity_id: e.electronic_id for e in msg.message.entities if e.electronic_id}
        )
    users = {gt_ids[p] for p in carriers}
    named = {hyp_ids[m] for m in carriers.values() if m in hyp_ids}
    headline = _mota(gt, hyp, users, named)
    for label, ours, key in (
        ("every track, every person", every, "mota_all"),
        ("phone carriers, tracks named by their phone", headline, "mota"),
    ):
        theirs = report[key]
        ok = "OK" if abs(ours - theirs) <= 0.01 else "MISMATCH"
        print(
            f"MOTA ({label}): py-motmetrics {ours:.4f}, report {key} {theirs:.4f} "
            f"(|diff| {abs(ours - theirs):.4f}) {ok}"
        )
    return vm


# -- b. TUM export read by evo ------------------------------------------------------------------


def dead_reckoning_tum(work: Path) -> None:
    from evo.tools import file_interface

    section("b. dead reckoning -> TUM -> evo")
    dr = work / "demo-dr.mcap"
    trackctl("process", "sample_logs/demo.mcap", "--with", "dead-reckoning", "--out", str(dr))
    topics = json.loads(trackctl("info", str(dr), "--json").stdout)["topics"]
    topic = next(t for t in sorted(topics) if t.endswith("/dead_reckoning"))
    tum = work / "demo-dr.tum"
    trackctl("export", str(dr), "--topic", topic, "--format", "tum", "--out", str(tum))
    traj = file_interface.read_tum_trajectory_file(str(tum))
    print(
        f"evo read_tum_trajectory_file({tum.name}): {traj.num_poses} poses, "
        f"{traj.path_length:.2f} m path, {traj.timestamps[-1] - traj.timestamps[0]:.2f} s"
    )


# -- c. public detections, then SORT beside trackctl --------------------------------------------


def public_detections(work: Path, skip_sort: bool) -> None:
    section("c. record --detections (MOTChallenge det.txt) -> vm-track --mode v-af; vs SORT")
    spec = importlib.util.spec_from_file_location("vm_sort", ROOT / "benchmarks" / "vm_sort.py")
    assert spec is not None and spec.loader is not None
    vm_sort = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(vm_sort)
    args = argparse.Namespace(
        duration=30.0, people=4, fps=10.0, seed=3, jitter=0.03, miss=0.1, false=0.3
    )
    det_dir = work / "det"
    det_dir.mkdir(exist_ok=True)
    cams, _, det_files, frames = vm_sort.make_scene(args, det_dir)
    print(
        f"det.txt per camera ({frames} frames, {args.people} people): "
        + ", ".join(f"{c}: {sum(1 for _ in p.open())} boxes" for c, p in sorted(det_files.items()))
    )
    sources = []
    for cam, path in sorted(det_files.items()):
        sources += [
            "--detections",
            f"{cam}={path}",
            "--calib",
            f"{cam}={det_dir / (cam + '.yaml')}",
        ]
    rec = work / "det.mcap"
    trackctl("record", str(rec), *sources, "--fps", "10", "--min-score", "0.3")
    out = work / "det-tracked.mcap"
    run = trackctl("vm-track", str(rec), "--mode", "v-af", "--out", str(out), "--json")
    metrics = json.loads(run.stdout)
    print(f"people {args.people}, tracks_published {metrics['tracks_published']}")
    ground_truth_per_person(det_dir / "scene.mcap", out, args.fps)
    if skip_sort:
        return
    print("$ python benchmarks/vm_sort.py", flush=True)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    bench = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "vm_sort.py")],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )
    print(bench.stdout.rstrip())


def ground_truth_per_person(scene: Path, tracked: Path, fps: float) -> None:
    """Each simulated person's main track (the id nearest to them, within 1 m, most often) and
    py-motmetrics' ground-plane MOTA/IDF1 (1 m gate): the det.txt log has no truth of its own."""
    import motmetrics as mm
    import numpy as np

    from trackctl.logs import LogReader

    hyps: dict[int, dict[str, tuple[float, float]]] = {}
    for m in LogReader(tracked).messages(["/vmtrack/tracks"]):
        hyps[round(m.message.t_ns * fps / 1e9)] = {
            t.track_id: (t.position_m.x, t.position_m.y) for t in m.message.tracks
        }
    acc = mm.MOTAccumulator(auto_id=True)
    nearest: dict[str, Counter[str]] = {}
    num = {k: i for i, k in enumerate(sorted({k for h in hyps.values() for k in h}))}
    for m in LogReader(scene).messages(["/ground_truth"]):
        truth = {e.entity_id: (e.position_m.x, e.position_m.y) for e in m.message.entities}
        hyp = hyps.get(round(m.message.t_ns * fps / 1e9), {})
        g = np.array(list(truth.values())).reshape(-1, 2)
        h = np.array(list(hyp.values())).reshape(-1, 2)
        d = mm.distances.norm2squared_matrix(g, h, max_d2=1.0)
        acc.update([int(p.lstrip("nu")) for p in truth], [num[k] for k in hyp], d)
        for i, person in enumerate(truth):
            if len(h) and not np.isnan(d[i]).all():
                nearest.setdefault(person, Counter())[list(hyp)[int(np.nanargmin(d[i]))]] += 1
    for person in sorted(nearest):
        (track, n), *_ = nearest[person].most_common(1)
        total = sum(nearest[person].values())
        print(f"  {person}: track {track} in {n} of its {total} matched frames")
    r = mm.metrics.create().compute(acc, metrics=["mota", "idf1", "num_switches"], name="v-af")
    print(
        f"ground plane (1 m gate) against the scene's truth: MOTA {r['mota'].iloc[0]:.3f}, "
        f"IDF1 {r['idf1'].iloc[0]:.3f}, ID switches {int(r['num_switches'].iloc[0])}"
    )


# -- d. the real ROS 1 bag ----------------------------------------------------------------------


def _bag_end(bag: Path, topic: str) -> tuple[float, float]:
    """Where the bag's own odometry pose ends, in its first pose's frame (forward, left), m."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    poses = []
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        for conn, _, raw in reader.messages(connections=conns):
            p = reader.deserialize(raw, conn.msgtype).pose.pose
            q = p.orientation
            poses.append(
                (
                    p.position.x,
                    p.position.y,
                    math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y**2 + q.z**2)),
                )
            )
    (x0, y0, yaw0), (x1, y1, _) = poses[0], poses[-1]
    c, s = math.cos(yaw0), math.sin(yaw0)
    return c * (x1 - x0) + s * (y1 - y0), -s * (x1 - x0) + c * (y1 - y0)


def ros1_bag(work: Path, bag: Path) -> None:
    from evo.tools import file_interface

    from trackctl.logs import LogReader

    section("d. the real ROS 1 bag: record --ros, dead reckoning of /wheel_odometry")
    rec = work / "bag.mcap"
    trackctl("record", str(rec), "--ros", str(bag))
    dr = work / "bag-dr.mcap"
    run = trackctl("process", str(rec), "--with", "dead-reckoning", "--out", str(dr), "--json")
    m = json.loads(run.stdout)["reports"][-1]["metrics"]
    warned = [ln for ln in run.stderr.splitlines() if "warning" in ln]
    print(f"warning lines: {len(warned)}")
    for ln in warned:
        print(f"  {ln}")
    print(
        f"robots {m['robots']}, sources {m['sources']}, method of /wheel_odometry: "
        f"{m['method/mustang/wheel_odometry']}"
    )
    *_, last = LogReader(dr).messages(["/robot/mustang/wheel_odometry/dead_reckoning"])
    fwd, left = _bag_end(bag, "/wheel_odometry")
    end = last.message.pose.position
    print(
        f"end of dead reckoning ({end.x:.3f}, {end.y:.3f}) m; the bag's own /wheel_odometry pose "
        f"ends at ({fwd:.3f}, {left:.3f}) m ({math.hypot(fwd, left):.2f} m from its start): "
        f"distance {math.hypot(end.x - fwd, end.y - left):.4f} m"
    )
    print(
        f"APE of the stereo odometry against {m['reference/mustang/stereo_odometer']}: rmse "
        f"{m['ape_m_rmse/mustang/stereo_odometer']} m, mean "
        f"{m['ape_m_mean/mustang/stereo_odometer']} m, max "
        f"{m['ape_m_max/mustang/stereo_odometer']} m; RPE rmse "
        f"{m['rpe_m_rmse/mustang/stereo_odometer']} m"
    )
    named = trackctl(
        "process",
        str(rec),
        "--with",
        "dead-reckoning",
        "--source",
        "/wheel_odometry",
        "--reference",
        "/stereo_odometer/odometry",
        "--align",
        "--json",
    )
    n = json.loads(named.stdout)["reports"][-1]["metrics"]
    print(
        f"named reference: APE of /wheel_odometry against {n['reference']} (--align, SE(3)): "
        f"rmse {n['ape_m_rmse']} m"
    )
    tum = work / "wheels.tum"
    trackctl(
        "export",
        str(dr),
        "--topic",
        "/robot/mustang/wheel_odometry/dead_reckoning",
        "--format",
        "tum",
        "--out",
        str(tum),
    )
    print(
        f"evo read_tum_trajectory_file({tum.name}): "
        f"{file_interface.read_tum_trajectory_file(str(tum)).num_poses} poses"
    )


# -- e. Foxglove ImageAnnotations decoded by mcap_protobuf --------------------------------------


def foxglove_annotations(vm: Path) -> None:
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    section("e. Foxglove: foxglove.ImageAnnotations decoded with mcap_protobuf")
    counts: Counter[str] = Counter()
    boxes: Counter[str] = Counter()
    with vm.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None
        wanted = [
            c.topic
            for c in summary.channels.values()
            if summary.schemas[c.schema_id].name == "foxglove.ImageAnnotations"
        ]
        for schema, channel, _, msg in reader.iter_decoded_messages(topics=wanted):
            if schema is not None and schema.name == "foxglove.ImageAnnotations":
                counts[channel.topic] += 1
                boxes[channel.topic] += len(msg.points)
                assert type(msg).__name__ == "ImageAnnotations"
    for topic in sorted(counts):
        print(f"{topic}: {counts[topic]} messages, {boxes[topic]} boxes (PointsAnnotation)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/h46"))
    ap.add_argument("--bag", type=Path, default=DEFAULT_BAG)
    ap.add_argument("--skip-sort", action="store_true", help="leave out benchmarks/vm_sort.py")
    args = ap.parse_args(argv)
    os.chdir(ROOT)
    sys.path.insert(0, str(ROOT))
    args.work.mkdir(parents=True, exist_ok=True)
    vm = quickstart_mot(args.work)
    dead_reckoning_tum(args.work)
    public_detections(args.work, args.skip_sort)
    if args.bag.exists():
        ros1_bag(args.work, args.bag)
    else:
        section(f"d. skipped: {args.bag} is absent")
    foxglove_annotations(vm)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
