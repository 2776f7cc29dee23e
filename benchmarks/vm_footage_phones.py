"""VM-Tracking's default path on real footage with phones: carriers' identity and CPU seconds.

Records OpenCV's vtest.avi (PETS 2009 S2L1 view 001) with its published calibration as
``benchmarks/pets_footage.py`` does (``trackctl record --video cam0=vtest.avi --calib cam0=...
--rate 7``) and hands a simulated phone to each of the five people whose ground paths are in
``tests/data/pets2009_view001_paths.csv`` (``--paths``: tracks of a v-af run, each checked
against the identity labels and by eye, see the file): the phone follows that path (resampled
to 20 Hz and smoothed over 0.5 s; between two visits the person walks round the outside of
the camera's view: ``_carriers``), with the realistic preset's phone model
(:func:`trackctl.sim.phones.realistic_imu`: carry, heading offsets, gait, always on, own
clocks, IMU rates; seeded as ``trackctl simulate vm`` seeds it). The merged log is every record
of the recording plus the phones' ``/phone/<MID>/imu``, the ``phones`` / ``phone_truth``
metadata the simulator writes, and a ``/ground_truth`` at every frame holding the five carriers
where their paths put them (nobody else: the report's ``idf1`` / ``error_m_mean`` /
``wrong_binding_s`` are the carriers'; ``*_all`` figures are meaningless here). No APs in this
scene: no RSSI.

Then runs, each in its own process, the default ``trackctl vm-track MERGED --json --quiet``,
``--mode v-af`` and ``--no-retrack`` on the merged log, and prints the child's CPU seconds (user
+ system, all its threads: OpenCV's thread count is left at its default, the project sets none),
its wall seconds, the log's seconds (last minus first camera frame) and CPU s / log s (<= 1.0:
at least real time on one core), with the report's published tracks, bindings, the carriers'
IDF1, mean error and seconds bound to somebody else, and per phone ``searched/<MID>`` and
``clear_share/<MID>``. Then, for the default run, per carrier: the share of their frames in the
truth where their phone's MID is published within 1 m of them (named right), published farther
(named wrong), or not published (unnamed), with a one-character-per-second timeline (``X``
named right, ``o`` wrong, ``_`` unnamed, ``.`` not in the truth: each second's most frequent
frame): where the carriers' frames are lost. The check: the default row's CPU s / log s <= 1.0
(exit 1 otherwise).

    TRACKCTL_VTEST=.../vtest.avi python benchmarks/vm_footage_phones.py [--seed 0] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import asdict
from pathlib import Path

import numpy as np

from trackctl.geometry.camera import PinholeCamera
from trackctl.ingest.calibration import read_calibration
from trackctl.logs import topics
from trackctl.logs.messages import GroundTruth, GroundTruthEntity, Imu, Vec3
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.sim.phones import PhoneTruth, realistic_imu
from trackctl.sim.vm import PRESETS, mac_of
from trackctl.sim.walkers import Trajectory, hidden_route, walk_route

ROOT = Path(__file__).resolve().parent.parent
TRACKCTL = Path(sys.executable).parent / "trackctl"
VTEST = ROOT / ".ci-cache" / "vtest.avi"
CALIB = ROOT.parent / "shared" / "data" / "footage" / "pets2009_view001.yaml"
PATHS = ROOT / "tests" / "data" / "pets2009_view001_paths.csv"
DT_S = 0.05  # carriers' trajectory grid (the simulator's walkers use the same)
SMOOTH_S = 0.5  # moving average over the track: a walker's velocity has no frame-rate steps
MAX_RATIO = 1.0
GAP_S = 1.0  # rows farther apart than this: the person is out of view between them


def _cpu_run(args: list[str]) -> tuple[float, float, str]:
    """Run ``trackctl ARGS``; its CPU seconds (user + system), wall seconds and stdout."""
    before, t0 = os.times(), time.perf_counter()
    done = subprocess.run(
        [str(TRACKCTL), *args], capture_output=True, text=True, check=False, timeout=7200
    )
    wall, after = time.perf_counter() - t0, os.times()
    if done.returncode != 0:
        raise SystemExit(f"trackctl {' '.join(args)} failed ({done.returncode}):\n{done.stderr}")
    cpu = (after.children_user - before.children_user) + (
        after.children_system - before.children_system
    )
    return cpu, wall, done.stdout


def _carriers(path: Path, camera: PinholeCamera) -> list[Trajectory]:
    """The checked paths of ``path`` (person, t_s, x_m, y_m rows; ``#`` comments), each as a
    trajectory on the simulator's grid: interpolated over the rows, smoothed over ``SMOOTH_S``.
    A gap of more than ``GAP_S`` between two rows is the person out of view: they walk out
    where the rows leave off, along the way they were going, round to where the rows resume,
    out of ``camera``'s view (:func:`~trackctl.sim.walkers.hidden_route`, at least 1 m from
    it), at their own median speed, standing half way for the time the walk does not need."""
    rows: dict[str, list[tuple[float, float, float]]] = defaultdict(list)
    for line in path.read_text().splitlines():
        if line.startswith("#") or line.startswith("person,") or not line.strip():
            continue
        person, t, x, y = line.split(",")
        rows[person].append((float(t), float(x), float(y)))
    out = []
    taps = max(1, round(SMOOTH_S / DT_S)) | 1
    kernel = np.ones(taps) / taps
    for person in sorted(rows):
        a = np.array(sorted(rows[person]))
        grid = np.arange(a[0, 0], a[-1, 0] + 1e-9, DT_S)
        xy = np.column_stack([np.interp(grid, a[:, 0], a[:, j]) for j in (1, 2)])
        for k in np.flatnonzero(np.diff(a[:, 0]) > GAP_S):
            span = (grid >= a[k, 0]) & (grid <= a[k + 1, 0])
            xy[span] = _out_of_view(a, k, camera, int(span.sum()))
        pad = np.pad(xy, ((taps // 2, taps // 2), (0, 0)), mode="edge")
        xy = np.column_stack([np.convolve(pad[:, j], kernel, mode="valid") for j in (0, 1)])
        out.append(Trajectory(person, float(a[0, 0]), DT_S, xy))
    return out


def _out_of_view(a: np.ndarray, k: int, camera: PinholeCamera, n: int) -> np.ndarray:
    """``n`` positions, evenly in time, of the walk out of view between rows ``k`` and
    ``k + 1`` of ``a`` (t_s, x, y): :func:`_carriers`."""

    def heading(i: int, j: int) -> np.ndarray:
        return a[j, 1:] - a[i, 1:]

    before = int(np.searchsorted(a[:, 0], a[k, 0] - 1.0))
    after = int(np.searchsorted(a[:, 0], a[k + 1, 0] + 1.0)) - 1
    route = hidden_route(
        a[k, 1:],
        a[k + 1, 1:],
        lambda p: ~camera.visible(np.column_stack([p, np.zeros(len(p))])),
        away=(heading(before, k), heading(k + 1, max(after, k + 1))),
    )
    dt = np.diff(a[:, 0])
    step = np.linalg.norm(np.diff(a[:, 1:], axis=0), axis=1) / np.maximum(dt, 1e-9)
    speed = float(np.median(step[(dt <= GAP_S) & (step > 0.3)]))
    duration = float(a[k + 1, 0] - a[k, 0])
    walk = walk_route(route, duration, speed, duration / max(n - 1, 1))
    return walk[:n]


def _phones(
    carriers: list[Trajectory], duration_s: float, seed: int
) -> tuple[dict[str, list[Imu]], dict[str, PhoneTruth]]:
    """Each carrier's phone (``mac_of(i)``), the realistic preset's model, seeded as ``trackctl
    simulate vm --seed SEED`` seeds its phones (stream [seed, 4], site yaw drawn first)."""
    cfg = PRESETS["realistic"].phones
    assert cfg is not None
    rng = np.random.default_rng([seed, 4])
    site_yaw = (
        math.radians(cfg.site_yaw_deg)
        if cfg.site_yaw_deg is not None
        else float(rng.uniform(-math.pi, math.pi))
    )
    imus: dict[str, list[Imu]] = {}
    truths: dict[str, PhoneTruth] = {}
    for i, traj in enumerate(carriers):
        mac = mac_of(i)
        imus[mac], truths[mac], _ = realistic_imu(traj, mac, duration_s, rng, cfg, site_yaw)
    return imus, truths


def _merge(
    rec: Path,
    out: Path,
    imus: dict[str, list[Imu]],
    truths: dict[str, PhoneTruth],
    carriers: list[Trajectory],
) -> int:
    """``out`` = every message, metadata record and attachment of ``rec`` + the phones' IMU, in
    log-time order; returns the number of IMU messages written."""
    events = sorted(
        (imu.t_ns, topics.imu(mac.replace(":", "")), imu)
        for mac, samples in imus.items()
        for imu in samples
    )
    reader = LogReader(rec)
    frame_ns = [m.log_time_ns for m in reader.messages([topics.image("cam0")])]
    events += [_truth(t_ns, carriers) for t_ns in frame_ns]
    events.sort(key=lambda e: (e[0], e[1]))
    k = 0
    with LogWriter(out, inputs=[rec]) as w:
        for raw in reader.raw():
            while k < len(events) and events[k][0] < raw.log_time_ns:
                w.write(events[k][1], events[k][2], events[k][0])
                k += 1
            w.write_raw(raw)
        for t_ns, topic, imu in events[k:]:
            w.write(topic, imu, t_ns)
        for name, data in reader.metadata().items():
            w.add_metadata(name, data)
        for name, (media_type, blob) in reader.attachments().items():
            w.add_attachment(name, blob, media_type)
        w.add_metadata("phones", {mac_of(i): t.person for i, t in enumerate(carriers)})
        w.add_metadata(
            "phone_truth",
            {f"{mac}/{key}": v for mac, tr in truths.items() for key, v in asdict(tr).items()},
        )
    return len(events) - len(frame_ns)


def _truth(t_ns: int, carriers: list[Trajectory]) -> tuple[int, str, GroundTruth]:
    """The carriers' true positions at a frame: where the track each phone follows is (the
    paths the phones were simulated along); nobody else is in the truth."""
    ents = []
    for i, traj in enumerate(carriers):
        t = t_ns / 1e9
        if traj.t_s[0] <= t <= traj.t_s[-1]:
            x, y = (float(np.interp(t, traj.t_s, traj.xy[:, j])) for j in (0, 1))
            ents.append(GroundTruthEntity(traj.person, Vec3(x, y, 0.0), electronic_id=mac_of(i)))
    return (t_ns, topics.GROUND_TRUTH, GroundTruth(t_ns, tuple(ents)))


def _per_carrier(out: Path) -> list[str]:
    """Per carrier of ``out``'s truth: named right / wrong / unnamed shares and a timeline
    (module docstring). Reads the truth: a benchmark's score, like the report's."""
    truth: dict[int, dict[str, tuple[str, np.ndarray]]] = {}
    named: dict[int, dict[str, np.ndarray]] = {}
    for m in LogReader(out).messages([topics.GROUND_TRUTH, "/vmtrack/tracks"]):
        if m.topic == topics.GROUND_TRUTH:
            truth[m.log_time_ns] = {
                e.electronic_id.replace(":", "").lower(): (
                    e.entity_id,
                    np.array([e.position_m.x, e.position_m.y]),
                )
                for e in m.message.entities
                if e.electronic_id
            }
        else:
            named[m.log_time_ns] = {
                t.track_id.replace(":", "").lower(): np.array([t.position_m.x, t.position_m.y])
                for t in m.message.tracks
            }
    if not truth:
        return []
    t0 = min(truth)
    seconds = int((max(truth) - t0) / 1e9) + 1
    marks: dict[str, list[list[str]]] = defaultdict(lambda: [[] for _ in range(seconds)])
    who: dict[str, str] = {}
    for t_ns, carriers in truth.items():
        pub = named.get(t_ns, {})
        for mid, (person, xy) in carriers.items():
            who[mid] = person
            p = pub.get(mid)
            mark = "_" if p is None else ("X" if np.hypot(*(p - xy)) <= 1.0 else "o")
            marks[mid][int((t_ns - t0) / 1e9)].append(mark)
    lines = []
    for mid in sorted(marks):
        every = [c for sec in marks[mid] for c in sec]
        share = {c: every.count(c) / len(every) for c in "Xo_"}
        line = "".join(max(set(sec), key=sec.count) if sec else "." for sec in marks[mid])
        lines.append(
            f"{who[mid]:4s} {mid[-2:]}  right {share['X']:.3f}  wrong {share['o']:.3f}  "
            f"unnamed {share['_']:.3f}  |{line}|"
        )
    return lines


def _num(v: object, digits: int) -> str:
    return "-" if v is None else f"{float(v):.{digits}f}"  # type: ignore[arg-type]


def _per_phone(report: dict[str, object], prefix: str) -> str:
    """``prefix<MID>`` values as ``01=v 02=v ...`` (the MID's last byte), or ``-``."""
    vals = sorted((k[len(prefix) :], v) for k, v in report.items() if k.startswith(prefix))
    return " ".join(f"{mid[-2:]}={v}" for mid, v in vals) or "-"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--video", default=os.environ.get("TRACKCTL_VTEST", str(VTEST)))
    ap.add_argument("--calib", default=str(CALIB))
    ap.add_argument("--rate", default="7")
    ap.add_argument("--paths", type=Path, default=PATHS, help="the carriers' paths (CSV)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--keep", type=Path, help="copy the logs (recording, merged) here")
    args = ap.parse_args()
    video = Path(args.video)
    if not video.is_file():
        sys.exit(f"{video}: no such video; set TRACKCTL_VTEST or pass --video")
    with tempfile.TemporaryDirectory() as tmp:
        rec, merged = Path(tmp) / "pets.mcap", Path(tmp) / "merged.mcap"
        _cpu_run(
            ["record", str(rec), "--video", f"cam0={video}", "--calib", f"cam0={args.calib}",
             "--rate", args.rate, "--quiet"]
        )  # fmt: skip
        carriers = _carriers(args.paths, PinholeCamera(read_calibration(args.calib, "cam0")))
        reader = LogReader(rec)
        duration_s = (reader.end_ns or 0) / 1e9
        frames = reader.topics()[topics.image("cam0")]
        log_s = ((frames.last_ns or 0) - (frames.first_ns or 0)) / 1e9
        imus, truths = _phones(carriers, duration_s, args.seed)
        n_imu = _merge(rec, merged, imus, truths, carriers)
        print(f"footage {video.name}: {frames.count} frames at --rate {args.rate}, {log_s:.1f} s")
        for i, t in enumerate(carriers):
            mac = mac_of(i)
            tr = truths[mac]
            walked = float(np.linalg.norm(np.diff(t.xy, axis=0), axis=1).sum())
            print(
                f"phone {mac} <- {t.person}: {t.t_s[0]:.1f}-{t.t_s[-1]:.1f} s, "
                f"{walked:.1f} m; {tr.carry}, {tr.imu_hz:g} Hz, clock {tr.clock_offset_s:+.2f} s"
            )
        print(f"merged log: {n_imu} IMU messages added (seed {args.seed})")
        variants = [("default", []), ("--mode v-af", ["--mode", "v-af"]),
                    ("--no-retrack", ["--no-retrack"])]  # fmt: skip
        head = (
            f"{'variant':13s} {'log s':>6s} {'CPU s':>6s} {'wall s':>6s} {'CPU/log':>7s} "
            f"{'tracks':>6s} {'bind':>4s} {'IDF1':>6s} {'err m':>5s} {'wrong s':>7s}  "
            "searched/<MID>  clear_share/<MID>"
        )
        rows = []
        ok = False
        carriers_lines: list[str] = []
        for name, extra in variants:
            tracked = Path(tmp) / f"tracked-{len(rows)}.mcap"
            cpu, wall, out = _cpu_run(
                ["vm-track", str(merged), "--out", str(tracked), "--json", "--quiet", *extra]
            )
            report = json.loads(out)
            ratio = cpu / log_s
            if name == "default":
                ok = ratio <= MAX_RATIO
                carriers_lines = _per_carrier(tracked)
            rows.append(
                f"{name:13s} {log_s:6.1f} {cpu:6.1f} {wall:6.1f} {ratio:7.3f} "
                f"{report.get('tracks_published')!s:>6s} {report.get('bindings')!s:>4s} "
                f"{_num(report.get('idf1'), 4):>6s} {_num(report.get('error_m_mean'), 2):>5s} "
                f"{_num(report.get('wrong_binding_s'), 1):>7s}  "
                f"{_per_phone(report, 'searched/')}  {_per_phone(report, 'clear_share/')}"
            )
            print(rows[-1], file=sys.stderr, flush=True)
        if args.keep is not None:
            args.keep.mkdir(parents=True, exist_ok=True)
            for p in (rec, merged):
                shutil.copy2(p, args.keep / p.name)
    print(head)
    print("\n".join(rows))
    print("the default run's carriers (share of their frames; a character a second):")
    print("\n".join(carriers_lines))
    verdict = "PASS" if ok else "FAIL"
    print(f"default path at least real time on one core: {verdict}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
