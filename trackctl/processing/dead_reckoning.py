"""The ``dead-reckoning`` processor: each odometry source of each robot integrated on its own,
and scored against the robot's references.

A robot may have several odometry sources (``/robot/NAME/odom``, or ``/robot/NAME/SOURCE/odom``
for each of several, e.g. wheels and a stereo odometer); each is integrated, written and scored
on its own, and the report counts robots, not sources. An odometry sample that carries the
robot's own pose (``nav_msgs/Odometry``) is followed by its pose, the robot's own integration;
otherwise ticks or the whole planar twist (forward, lateral and yaw rate) are integrated. When
the twist and the pose of one source disagree, one warning says so.

References, in this order: ``--reference`` (a ``/robot/NAME/reference/*`` topic, its last
segment, the ROS topic it came from, or ``ground_truth``), the log's ``/ground_truth``, then the
robot's other references (``/robot/NAME/reference/*``: GPS and poses before other odometry
sources' poses; never the source's own pose). APE and RPE come from evo
(:mod:`trackctl.metrics.trajectory`) after ``origin`` or ``se3`` alignment.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

from trackctl.errors import InputError
from trackctl.geometry.odometry import DiffDrive, compose, planar_increment, pose_increment
from trackctl.logs import topics
from trackctl.logs.foxglove import odom_base_transform, pose_in_frame
from trackctl.logs.messages import GroundTruth, MetricReport, MetricValue, WheelOdometry
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.metrics.trajectory import (
    ALIGNMENTS,
    PlanarTrack,
    TrajectoryErrors,
    evo_missing,
    trajectory_errors,
)
from trackctl.processing.base import ProcessorInfo, Progress

__all__ = [
    "DEAD_RECKONING_PROCESSOR",
    "DeadReckoningConfig",
    "DeadReckoningProcessor",
    "TRUTH_REFERENCE",
]

TRUTH_REFERENCE = "ground_truth"
"""The name of the ground truth as a reference (``--reference ground_truth``)."""
_POSE_SCHEMA = "foxglove.PoseInFrame"


@dataclass(frozen=True, slots=True)
class DeadReckoningConfig:
    """Options of the ``dead-reckoning`` processor."""

    drive: DiffDrive = field(default_factory=DiffDrive)
    prefer_ticks: bool = False
    """Integrate encoder ticks even when the robot also reports v/omega."""
    use_pose: bool = True
    """Follow the odometry's own pose when it has one (False: integrate its twist)."""
    sources: tuple[str, ...] = ()
    """Odometry sources to integrate (trackctl topic, ROS topic, SOURCE or robot NAME); all
    when empty."""
    reference: str | None = None
    """The reference to score against (see the module docstring); automatic when None."""
    align: str = "origin"
    """``origin`` (evo's ``--align_origin``) or ``se3`` (evo's ``--align``, Umeyama)."""
    rpe_delta_m: float = 1.0
    """RPE step, metres of the reference's path."""
    disagreement: float = 0.5
    """Warn when the twist's steps differ from the pose's by more than this share of the path."""

    def __post_init__(self) -> None:
        if self.align not in ALIGNMENTS:
            raise InputError(f"align {self.align!r}: expected one of {', '.join(ALIGNMENTS)}")
        if not (self.rpe_delta_m > 0 and math.isfinite(self.rpe_delta_m)):
            raise InputError(f"rpe_delta_m {self.rpe_delta_m}: expected a positive number")


_Truth = tuple[int, float, float, float | None]
"""A ground-truth sample of a robot: (log time ns, x m, y m, yaw rad or None)."""


@dataclass(frozen=True)
class _Align:
    """The rigid 2-D transform from a robot's odometry frame to the world (metrics only)."""

    c: float
    s: float
    tx: float
    ty: float

    @classmethod
    def fixing(
        cls, x: float, y: float, yaw: float, gx: float, gy: float, gyaw: float | None
    ) -> _Align:
        """The transform taking the pose (x, y, yaw) onto the truth (gx, gy, gyaw); without a
        true heading, a translation."""
        rot = 0.0 if gyaw is None else gyaw - yaw
        c, s = math.cos(rot), math.sin(rot)
        return cls(c, s, gx - (c * x - s * y), gy - (s * x + c * y))

    def apply(self, x: float, y: float) -> tuple[float, float]:
        return self.c * x - self.s * y + self.tx, self.s * x + self.c * y + self.ty


@dataclass
class _ErrorStats:
    """Running error statistics (constant memory)."""

    n: int = 0
    total: float = 0.0
    max: float = 0.0
    last: float = 0.0

    def add(self, err: float) -> None:
        self.n += 1
        self.total += err
        self.max = max(self.max, err)
        self.last = err

    def mean(self) -> float | None:
        return None if self.n == 0 else round(self.total / self.n, 4)


@dataclass
class _Disagreement:
    """Twist against pose steps of one source: their difference and both paths (metres)."""

    diff_m: float = 0.0
    pose_m: float = 0.0
    twist_m: float = 0.0

    def add(self, last: WheelOdometry, now: WheelOdometry) -> None:
        if last.pose is None or now.pose is None or last.v_mps is None:
            return
        dt = (now.t_ns - last.t_ns) / 1e9
        fwd, left, _ = pose_increment(last.pose, now.pose)
        tf, tl = last.v_mps * dt, (last.vy_mps or 0.0) * dt
        self.diff_m += math.hypot(fwd - tf, left - tl)
        self.pose_m += math.hypot(fwd, left)
        self.twist_m += math.hypot(tf, tl)

    def share(self) -> float | None:
        """The difference as a share of the longer path (None: no motion to compare)."""
        path = max(self.pose_m, self.twist_m)
        return None if path <= 0 else self.diff_m / path


@dataclass
class _Source:
    """One odometry source being integrated."""

    topic: str
    robot: str
    label: str
    """``NAME`` or ``NAME/SOURCE`` (the key of its per-source figures)."""
    own_reference: str | None
    reference: str | None = None
    method: str | None = None
    last: WheelOdometry | None = None
    last_log_ns: int = 0
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    first_own: Any = None
    pending: list[_Truth] = field(default_factory=list)
    align: _Align | None = None
    track: PlanarTrack = field(default_factory=PlanarTrack)
    twist_vs_pose: _Disagreement = field(default_factory=_Disagreement)

    @property
    def out_topic(self) -> str:
        return f"/robot/{self.label}/dead_reckoning"

    def own_gap_m(self) -> float | None:
        """How far the final pose is from the source's own final pose, both from its first."""
        if self.first_own is None or self.last is None or self.last.pose is None:
            return None
        fwd, left, _ = pose_increment(self.first_own, self.last.pose)
        return round(math.hypot(self.pose[0] - fwd, self.pose[1] - left), 4)


def _ros_topics(metadata: dict[str, dict[str, str]]) -> dict[str, dict[str, str]]:
    """The ``ros/topic/...`` records of a ROS import, by ROS topic."""
    return {
        rec["ros_topic"]: rec
        for name, rec in metadata.items()
        if name.startswith("ros/topic/") and "ros_topic" in rec
    }


def _label(topic: str) -> tuple[str, str]:
    """(robot, label) of ``/robot/NAME[/SOURCE]/odom``."""
    parts = topic.split("/")
    return parts[2], "/".join(parts[2:-1]) if len(parts) > 4 else parts[2]


def _own_reference(topic: str, ros: dict[str, dict[str, str]]) -> str | None:
    """The reference topic holding an odometry source's own poses."""
    for rec in ros.values():
        targets = rec.get("targets", "").split(",")
        if topic in targets:
            return next((t for t in targets if "/reference/" in t), None)
    robot, label = _label(topic)
    return f"/robot/{robot}/reference/{label.split('/')[-1]}" if "/" in label else None


class DeadReckoningProcessor:
    """Dead reckoning of every odometry source of every robot (``/robot/NAME[/SOURCE]/odom``).

    Writes ``/robot/NAME[/SOURCE]/dead_reckoning`` (foxglove.PoseInFrame) in the robot's
    odometry frame ``NAME/odom``: the robot starts at its origin, heading +x (REP 105). Against
    ground truth it reports the position error after aligning the start (``error_m_*``); against
    the chosen reference the APE and RPE of each source (evo). References never move the poses.
    Wheel geometry comes from metadata ``robot/NAME`` (``ticks_per_m``, ``wheel_base_m``) when
    present, else from the configuration.
    """

    name = "dead-reckoning"

    def __init__(self, config: DeadReckoningConfig | None = None) -> None:
        self.config = config or DeadReckoningConfig()

    def run(
        self, reader: LogReader, writer: LogWriter, progress: Progress | None = None
    ) -> MetricReport:
        metadata = reader.metadata()
        sources = self._sources(reader, _ros_topics(metadata))
        refs = {s.reference for s in sources if s.reference and s.reference != TRUTH_REFERENCE}
        has_truth = topics.GROUND_TRUTH in reader.topics()
        tracks: dict[str, PlanarTrack] = {r: PlanarTrack() for r in refs}
        truth: dict[str, PlanarTrack] = {s.robot: PlanarTrack() for s in sources}
        run = _Run(metadata, {s.topic: s for s in sources}, self.config)
        wanted = [s.topic for s in sources] + sorted(refs)
        stream = reader.messages(wanted + ([topics.GROUND_TRUTH] if has_truth else []))
        for msg in stream:
            run.on_message(msg.topic, msg.log_time_ns, msg.message, writer, tracks, truth)
            if progress is not None and run.poses % 5000 == 0:
                progress(run.poses, None)
        for s in sources:
            self._warn_disagreement(reader, s)
        tracks.update({f"{TRUTH_REFERENCE}:{r}": t for r, t in truth.items()})
        return self._report(reader, sources, run, tracks)

    # -- setup --------------------------------------------------------------------------------
    def _sources(self, reader: LogReader, ros: dict[str, dict[str, str]]) -> list[_Source]:
        """The odometry sources to integrate, each with its reference.

        Raises:
            MissingTopicError: the log has no odometry.
            InputError: a ``sources`` entry or the reference names nothing in the log.
        """
        present = reader.topics()
        odom = sorted(
            t
            for t, info in present.items()
            if info.schema_name == WheelOdometry.SCHEMA and t.startswith("/robot/")
        )
        if not odom:
            reader.require([topics.odom("<NAME>")], self.name, "wheel odometry to integrate")
        chosen = _select(reader, odom, self.config.sources, ros)
        references = sorted(
            t for t, i in present.items() if i.schema_name == _POSE_SCHEMA and "/reference/" in t
        )
        has_truth = topics.GROUND_TRUTH in present
        out = []
        for topic in chosen:
            robot, label = _label(topic)
            src = _Source(topic, robot, label, _own_reference(topic, ros))
            src.reference = self._reference(reader, src, references, has_truth, ros)
            out.append(src)
        return out

    def _reference(
        self,
        reader: LogReader,
        src: _Source,
        references: list[str],
        has_truth: bool,
        ros: dict[str, dict[str, str]],
    ) -> str | None:
        """The reference of one source (None: none; its own pose never counts)."""
        named = self.config.reference
        if named:
            ref = _resolve_reference(reader, named, src.robot, references, has_truth, ros)
            return None if ref == src.own_reference else ref
        if has_truth:
            return TRUTH_REFERENCE
        mine = [
            r for r in references if r.startswith(f"/robot/{src.robot}/") and r != src.own_reference
        ]
        odometry_poses = {
            t
            for rec in ros.values()
            if rec.get("role") == "odometry"
            for t in rec.get("targets", "").split(",")
        }
        # external references (GPS, localisation) before another odometry's own integration
        mine.sort(key=lambda r: (r in odometry_poses, r))
        return mine[0] if mine else None

    # -- end ----------------------------------------------------------------------------------
    def _warn_disagreement(self, reader: LogReader, s: _Source) -> None:
        share = s.twist_vs_pose.share()
        path = max(s.twist_vs_pose.pose_m, s.twist_vs_pose.twist_m)
        if share is None or share <= self.config.disagreement or path < 1.0:
            return
        follows = "the pose" if s.method == "pose" else f"the {s.method}"
        warnings.warn(
            f"{reader.path}: {s.topic}: its twist disagrees with its pose (their steps differ by "
            f"{share:.0%} of the {path:.0f} m path: twist {s.twist_vs_pose.twist_m:.0f} m, pose "
            f"{s.twist_vs_pose.pose_m:.0f} m); dead reckoning follows {follows}",
            UserWarning,
            stacklevel=3,
        )

    def _report(
        self,
        reader: LogReader,
        sources: list[_Source],
        run: _Run,
        tracks: dict[str, PlanarTrack],
    ) -> MetricReport:
        errors = run.errors
        metrics: dict[str, MetricValue] = {
            "robots": len({s.robot for s in sources}),
            "sources": len(sources),
            "poses": run.poses,
            "path_m": round(run.path_m, 4),
            "error_m_mean": errors.mean(),
            "error_m_max": None if errors.n == 0 else round(errors.max, 4),
            "error_m_final": None if errors.n == 0 else round(errors.last, 4),
        }
        reasons: dict[str, str] = {}
        worst: dict[str, float] = {}
        used = []
        for s in sources:
            res = self._score(s, tracks, reasons)
            if res is not None and s.reference is not None:
                used.append(_reference_name(s.reference, s.robot))
            metrics.update(_source_metrics(s, res))
            for key in ("ape_m_rmse", "rpe_m_rmse"):
                value = None if res is None else getattr(res, key)
                if value is not None:
                    worst[key] = max(worst.get(key, value), value)
        metrics["reference"] = ", ".join(sorted(set(used))) or None
        metrics["ape_m_rmse"] = worst.get("ape_m_rmse")
        metrics["rpe_m_rmse"] = worst.get("rpe_m_rmse")
        for key in ("reference", "ape_m_rmse", "rpe_m_rmse"):
            if metrics[key] is None:
                reasons[key] = evo_missing() or "no source has a reference to be scored against"
        return MetricReport(
            t_ns=reader.end_ns or 0,
            processor=self.name,
            metrics=metrics,
            params={
                "ticks_per_m": self.config.drive.ticks_per_m,
                "wheel_base_m": self.config.drive.wheel_base_m,
                "align": self.config.align,
                "rpe_delta_m": self.config.rpe_delta_m,
                "reference": self.config.reference,
                "use_pose": self.config.use_pose,
            },
            unmeasured=reasons,
        )

    def _score(
        self, s: _Source, tracks: dict[str, PlanarTrack], reasons: dict[str, str]
    ) -> TrajectoryErrors | None:
        """APE/RPE of one source against its reference (reasons filled when unmeasured)."""
        keys = [f"{k}/{s.label}" for k in ("ape_m_rmse", "ape_m_mean", "ape_m_max", "rpe_m_rmse")]
        ref = s.reference
        if ref is None:
            why = (
                f"robot {s.robot} has no reference (no /ground_truth, no other "
                f"/robot/{s.robot}/reference/*)"
            )
        else:
            key = f"{TRUTH_REFERENCE}:{s.robot}" if ref == TRUTH_REFERENCE else ref
            res = trajectory_errors(
                s.track, tracks[key], self.config.align, self.config.rpe_delta_m
            )
            if res is not None and res.ape_m_rmse is not None:
                if res.rpe_m_rmse is None:
                    reasons[keys[3]] = f"the path is shorter than {self.config.rpe_delta_m} m"
                return res
            why = evo_missing() or f"{ref} does not overlap the source in time (or is degenerate)"
        reasons.update({k: why for k in keys})
        return None


def _select(
    reader: LogReader, odom: list[str], wanted: tuple[str, ...], ros: dict[str, dict[str, str]]
) -> list[str]:
    """The odometry topics ``wanted`` names (all when empty).

    Raises:
        InputError: an entry that names no odometry source.
    """
    if not wanted:
        return odom
    chosen: list[str] = []
    for name in wanted:
        targets = ros.get(name, {}).get("targets", "").split(",")
        hits = [
            t
            for t in odom
            if t == name
            or t in targets
            or _label(t)[1] in (name, name.strip("/"))
            or _label(t)[1].split("/")[-1] == name.strip("/")
        ]
        if not hits:
            raise InputError(
                f"{reader.path}: --source {name}: no such odometry source "
                f"(sources: {', '.join(odom)})"
            )
        chosen += [t for t in hits if t not in chosen]
    return chosen


def _resolve_reference(
    reader: LogReader,
    named: str,
    robot: str,
    references: list[str],
    has_truth: bool,
    ros: dict[str, dict[str, str]],
) -> str:
    """The reference topic ``named`` means for ``robot``.

    Raises:
        InputError: it names no reference of the log.
    """
    if named.strip("/") == TRUTH_REFERENCE and has_truth:
        return TRUTH_REFERENCE
    ros_targets = ros.get(named, {}).get("targets", "").split(",")
    for candidate in (named, f"/robot/{robot}/reference/{named.strip('/')}", *ros_targets):
        if candidate in references:
            return candidate
    known = references + ([TRUTH_REFERENCE] if has_truth else [])
    raise InputError(
        f"{reader.path}: --reference {named}: no such reference "
        f"(references: {', '.join(known) or 'none'})"
    )


def _reference_name(ref: str, robot: str) -> str:
    return f"{TRUTH_REFERENCE} ({robot})" if ref == TRUTH_REFERENCE else ref


def _source_metrics(s: _Source, res: TrajectoryErrors | None) -> dict[str, MetricValue]:
    """The per-source figures (``KEY/NAME[/SOURCE]``)."""
    share = s.twist_vs_pose.share()
    return {
        f"method/{s.label}": s.method,
        f"reference/{s.label}": None
        if s.reference is None
        else _reference_name(s.reference, s.robot),
        f"ape_m_rmse/{s.label}": None if res is None else res.ape_m_rmse,
        f"ape_m_mean/{s.label}": None if res is None else res.ape_m_mean,
        f"ape_m_max/{s.label}": None if res is None else res.ape_m_max,
        f"rpe_m_rmse/{s.label}": None if res is None else res.rpe_m_rmse,
        f"own_pose_gap_m_final/{s.label}": s.own_gap_m(),
        f"twist_pose_disagreement/{s.label}": None if share is None else round(share, 4),
    }


def _add_pose(track: PlanarTrack, t_ns: int, msg: Any) -> None:
    """A foxglove.PoseInFrame reference pose (planar: x, y and yaw; an identity orientation,
    as a GPS reference carries, is an unknown heading)."""
    p, q = msg.pose.position, msg.pose.orientation
    if not all(math.isfinite(v) for v in (p.x, p.y, q.x, q.y, q.z, q.w)):
        return
    unknown = (q.x, q.y, q.z, q.w) == (0.0, 0.0, 0.0, 1.0) and msg.frame_id.endswith("/enu")
    yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    track.add(t_ns, float(p.x), float(p.y), math.nan if unknown else yaw)


@dataclass
class _Run:
    """State of a dead-reckoning pass over every source of a log."""

    metadata: dict[str, dict[str, str]]
    sources: dict[str, _Source]
    config: DeadReckoningConfig
    errors: _ErrorStats = field(default_factory=_ErrorStats)
    path_m: float = 0.0
    poses: int = 0

    def on_message(
        self,
        topic: str,
        t_ns: int,
        msg: Any,
        writer: LogWriter,
        tracks: dict[str, PlanarTrack],
        truth: dict[str, PlanarTrack],
    ) -> None:
        """One message of the pass: a ground truth, a reference pose or an odometry sample."""
        if topic == topics.GROUND_TRUTH:
            self.on_truth(t_ns, msg, truth)
        elif topic in tracks:
            _add_pose(tracks[topic], t_ns, msg)
        else:
            self.on_odometry(topic, t_ns, msg, writer)

    def on_truth(self, t_ns: int, gt: GroundTruth, truth: dict[str, PlanarTrack]) -> None:
        """A ground-truth sample: kept for APE, scored now against a pose of the same stamp,
        else queued for the source's next pose."""
        for ent in gt.entities:
            if ent.entity_id in truth:
                yaw = math.nan if ent.yaw_rad is None else ent.yaw_rad
                truth[ent.entity_id].add(t_ns, ent.position_m.x, ent.position_m.y, yaw)
            for s in self.sources.values():
                if s.robot != ent.entity_id:
                    continue
                sample = (t_ns, ent.position_m.x, ent.position_m.y, ent.yaw_rad)
                if s.last is not None and s.last_log_ns >= t_ns:  # same stamp as the latest pose
                    self._score_now(s, sample)
                else:
                    s.pending.append(sample)

    def _score_now(self, s: _Source, sample: _Truth) -> None:
        x, y, yaw = s.pose
        if s.align is None:
            s.align = _Align.fixing(x, y, yaw, sample[1], sample[2], sample[3])
        wx, wy = s.align.apply(x, y)
        self.errors.add(math.hypot(wx - sample[1], wy - sample[2]))

    def _method(self, last: WheelOdometry, now: WheelOdometry) -> str:
        if self.config.use_pose and last.pose is not None:
            return "pose"
        ticks = last.left_ticks is not None and last.right_ticks is not None
        velocity = last.v_mps is not None and last.omega_rps is not None
        return "ticks" if ticks and (self.config.prefer_ticks or not velocity) else "twist"

    def _drive(self, robot: str) -> DiffDrive:
        from trackctl.ingest.site import record_number

        md = self.metadata.get(f"robot/{robot}", {})
        where = f"metadata robot/{robot}"
        return DiffDrive(
            record_number(md, "ticks_per_m", self.config.drive.ticks_per_m, where),
            record_number(md, "wheel_base_m", self.config.drive.wheel_base_m, where),
        )

    def _step(self, s: _Source, last: WheelOdometry, odo: WheelOdometry) -> tuple[float, ...]:
        """The body-frame step from ``last`` to ``odo`` and whether it is a pose step."""
        if s.method == "pose" and last.pose is not None and odo.pose is not None:
            return (*pose_increment(last.pose, odo.pose), 0.0)
        step = planar_increment(last, odo, self._drive(s.robot), self.config.prefer_ticks)
        return (*(step or (0.0, 0.0, 0.0)), 1.0)

    def on_odometry(self, topic: str, t_ns: int, odo: WheelOdometry, writer: LogWriter) -> None:
        """One odometry sample: integrate it, score the truth waiting for it, write the pose."""
        s = self.sources[topic]
        prev = None
        if s.last is None:
            s.first_own = odo.pose
            s.pending = [g for g in s.pending if g[0] >= t_ns]
        else:
            s.method = s.method or self._method(s.last, odo)
            *step, mid = self._step(s, s.last, odo)
            self.path_m += math.hypot(step[0], step[1])
            s.twist_vs_pose.add(s.last, odo)
            prev = (*s.pose, float(s.last_log_ns))
            s.pose = compose(*s.pose, (step[0], step[1], step[2]), mid=bool(mid))
        self._score_pending(s, prev, t_ns)
        s.last = odo
        s.last_log_ns = t_ns
        s.track.add(t_ns, *s.pose)
        x, y, yaw = s.pose
        writer.write(s.out_topic, pose_in_frame(t_ns, x, y, yaw, frame_id=f"{s.robot}/odom"), t_ns)
        # the same pose as a frame tree LABEL/odom -> LABEL/base_link (formats/README.md); one
        # tree per source, so two sources of one robot never publish the same frame twice
        writer.write(
            topics.transforms(s.out_topic), odom_base_transform(t_ns, s.label, x, y, yaw), t_ns
        )
        self.poses += 1

    def _score_pending(self, s: _Source, prev: tuple[float, ...] | None, t1: int) -> None:
        """Score ground-truth samples between the previous and the current pose (the first
        one fixes the alignment of the odometry frame to the world)."""
        x1, y1, yaw1 = s.pose
        while s.pending and s.pending[0][0] <= t1:
            sample = s.pending.pop(0)
            if prev is None or t1 == prev[3]:
                x, y, yaw = x1, y1, yaw1
            else:
                a = (sample[0] - prev[3]) / (t1 - prev[3])
                x, y = prev[0] + a * (x1 - prev[0]), prev[1] + a * (y1 - prev[1])
                yaw = prev[2] + a * (yaw1 - prev[2])
            if s.align is None:
                s.align = _Align.fixing(x, y, yaw, sample[1], sample[2], sample[3])
            wx, wy = s.align.apply(x, y)
            self.errors.add(math.hypot(wx - sample[1], wy - sample[2]))


DEAD_RECKONING_PROCESSOR = ProcessorInfo(
    name="dead-reckoning",
    description="Dead reckoning of each robot's odometry sources -> /robot/NAME/dead_reckoning "
    "poses, with APE/RPE against a reference",
    factory=DeadReckoningProcessor,
)
"""Registry entry (entry point ``trackctl.processors``)."""
