"""Processors that need no system: log health checks and wheel dead reckoning."""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field

from trackctl.geometry.odometry import DiffDrive, increment, integrate_step
from trackctl.logs import topics
from trackctl.logs.foxglove import odom_base_transform, pose_in_frame
from trackctl.logs.messages import GroundTruth, MetricReport, WheelOdometry
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import ProcessorInfo, Progress

__all__ = [
    "CHECK_PROCESSOR",
    "DEAD_RECKONING_PROCESSOR",
    "CheckProcessor",
    "CheckConfig",
    "DeadReckoningProcessor",
    "DeadReckoningConfig",
]


@dataclass(frozen=True, slots=True)
class CheckConfig:
    """Options of the ``check`` processor."""

    gap_factor: float = 5.0
    """A gap counts when it exceeds this many times the topic's median period."""


_MEDIAN_WINDOW = 256


@dataclass
class _TopicState:
    """Per-topic state with bounded memory: the median period is fixed from the first
    ``_MEDIAN_WINDOW`` periods; later periods are judged against it as they come."""

    last_stamp: int | None = None
    last_log: int | None = None
    first_periods: list[int] = field(default_factory=list)
    median: int | None = None
    gaps: int = 0
    max_period: int = 0

    def add_period(self, period: int, factor: float) -> None:
        self.max_period = max(self.max_period, period)
        if self.median is None:
            self.first_periods.append(period)
            if len(self.first_periods) >= _MEDIAN_WINDOW:
                self._settle(factor)
        elif self.median > 0 and period > factor * self.median:
            self.gaps += 1

    def _settle(self, factor: float) -> None:
        ordered = sorted(self.first_periods)
        self.median = ordered[len(ordered) // 2]
        self.gaps += sum(
            1 for p in self.first_periods if self.median > 0 and p > factor * self.median
        )
        self.first_periods = []

    def finish(self, factor: float) -> int:
        if self.median is None and len(self.first_periods) >= 3:
            self._settle(factor)
        return self.gaps


class CheckProcessor:
    """Health check of a log: non-monotonic sensor stamps, NaN/inf values, gaps, decode errors.

    Writes nothing but its report, so ``trackctl process LOG --with check --fail-if
    "nonfinite_values>0"`` gates a CI pipeline on the quality of a recording.
    """

    name = "check"

    def __init__(self, config: CheckConfig | None = None) -> None:
        self.config = config or CheckConfig()

    def run(
        self, reader: LogReader, writer: LogWriter, progress: Progress | None = None
    ) -> MetricReport:
        states: dict[str, _TopicState] = defaultdict(_TopicState)
        tally = _CheckTally()
        total = reader.message_count
        for raw in reader.raw():
            tally.messages += 1
            if progress is not None and tally.messages % 5000 == 0:
                progress(tally.messages, total)
            st = states[raw.topic]
            if st.last_log is not None:
                st.add_period(raw.log_time_ns - st.last_log, self.config.gap_factor)
            st.last_log = raw.log_time_ns
            try:
                msg = reader.codec(raw).decode(raw.data)
            except Exception:  # noqa: BLE001 - counting undecodable messages is the point
                tally.decode_errors += 1
                continue
            tally.check_stamp(raw.topic, raw.log_time_ns, st, getattr(msg, "t_ns", None))
            tally.check_values(raw.topic, msg)
        gaps = sum(st.finish(self.config.gap_factor) for st in states.values())
        max_gap_s = max((st.max_period for st in states.values()), default=0) / 1e9
        return MetricReport(
            t_ns=reader.end_ns or 0,
            processor=self.name,
            metrics={
                "messages": tally.messages,
                "topics": len(states),
                "nonmonotonic_stamps": tally.nonmono,
                "nonfinite_values": tally.nonfinite,
                "stamp_mismatches": tally.stamp_mismatch,
                "decode_errors": tally.decode_errors,
                "gaps": gaps,
                "max_gap_s": round(max_gap_s, 6),
                "truncated": reader.truncated,
                "crc_errors": len(reader.damage),
                "lost_messages": reader.lost_messages,
                "data_crc_ok": reader.verify_data_crc(),
                "first_problem": tally.first_problem or None,
            },
            params={"gap_factor": self.config.gap_factor},
        )


@dataclass
class _CheckTally:
    """The problems the ``check`` processor counts, and the first one it met."""

    messages: int = 0
    nonmono: int = 0
    nonfinite: int = 0
    stamp_mismatch: int = 0
    decode_errors: int = 0
    first_problem: str = ""

    def check_stamp(self, topic: str, log_time_ns: int, st: _TopicState, stamp: int | None) -> None:
        """A message's sensor stamp: before the topic's previous one, or not its log time."""
        if stamp is None:
            return
        if st.last_stamp is not None and stamp < st.last_stamp:
            self.nonmono += 1
            self.first_problem = self.first_problem or (
                f"{topic}: stamp {stamp} ns after {st.last_stamp} ns"
            )
        if stamp != log_time_ns:
            self.stamp_mismatch += 1
        st.last_stamp = stamp

    def check_values(self, topic: str, msg: object) -> None:
        """NaN or infinite values of a message that lists its float fields."""
        finite = getattr(msg, "finite_values", None)
        if finite is None:
            return
        for key, value in finite().items():
            if not math.isfinite(value):
                self.nonfinite += 1
                self.first_problem = self.first_problem or f"{topic}: {key} = {value}"


CHECK_PROCESSOR = ProcessorInfo(
    name="check",
    description="Log health: non-monotonic stamps, NaN/inf values, gaps, undecodable messages",
    factory=CheckProcessor,
)
"""Registry entry (entry point ``trackctl.processors``)."""


@dataclass(frozen=True, slots=True)
class DeadReckoningConfig:
    """Options of the ``dead-reckoning`` processor."""

    drive: DiffDrive = field(default_factory=DiffDrive)
    prefer_ticks: bool = False
    """Integrate encoder ticks even when the robot also reports v/omega."""


class DeadReckoningProcessor:
    """Wheel-odometry dead reckoning of every ``/robot/<NAME>/odom`` topic.

    Writes ``/robot/<NAME>/dead_reckoning`` (foxglove.PoseInFrame) in the robot's odometry frame
    ``<NAME>/odom``: the robot starts at its origin, heading +x (REP 105). Against ground truth
    it reports the position error after aligning the start (the first truth sample's pose, as
    evo's ``--align_origin`` does); the truth never moves the poses. The error grows with
    distance because nothing corrects the drift (S-Mirror and BridgeLoc add the fixes).
    Wheel geometry comes from metadata ``robot/<NAME>`` (``ticks_per_m``, ``wheel_base_m``) when
    present, else from the configuration.
    """

    name = "dead-reckoning"

    def __init__(self, config: DeadReckoningConfig | None = None) -> None:
        self.config = config or DeadReckoningConfig()

    def run(
        self, reader: LogReader, writer: LogWriter, progress: Progress | None = None
    ) -> MetricReport:
        odom_topics = self._odom_topics(reader)
        robots = {t.split("/")[2]: t for t in odom_topics}
        has_truth = topics.GROUND_TRUTH in reader.topics()
        # Ground-truth samples wait (a few at a time) for the dead-reckoned poses around them.
        rk = _Reckoning(metadata=reader.metadata(), pending={name: [] for name in robots})
        stream = reader.messages(odom_topics + ([topics.GROUND_TRUTH] if has_truth else []))
        for msg in stream:
            if msg.topic == topics.GROUND_TRUTH:
                self._on_truth(msg.log_time_ns, msg.message, rk)
                continue
            self._on_odometry(msg.topic, msg.log_time_ns, msg.message, rk, writer)
            if progress is not None and rk.poses % 5000 == 0:
                progress(rk.poses, None)
        errors = rk.errors
        metrics: dict[str, float | int | None] = {
            "robots": len(robots),
            "poses": rk.poses,
            "path_m": round(rk.path_m, 4),
            "error_m_mean": errors.mean(),
            "error_m_max": None if errors.n == 0 else round(errors.max, 4),
            "error_m_final": None if errors.n == 0 else round(errors.last, 4),
        }
        return MetricReport(
            t_ns=reader.end_ns or 0,
            processor=self.name,
            metrics=metrics,
            params={
                "ticks_per_m": self.config.drive.ticks_per_m,
                "wheel_base_m": self.config.drive.wheel_base_m,
            },
        )

    def _odom_topics(self, reader: LogReader) -> list[str]:
        """The wheel-odometry topics of the robots (``/robot/<NAME>/...``), sorted.

        Raises:
            MissingTopicError: the log has none.
        """
        odom_topics = sorted(
            t
            for t, info in reader.topics().items()
            if info.schema_name == WheelOdometry.SCHEMA and t.startswith("/robot/")
        )
        if not odom_topics:
            reader.require([topics.odom("<NAME>")], self.name, "wheel odometry to integrate")
        return odom_topics

    def _on_truth(self, t_ns: int, gt: GroundTruth, rk: _Reckoning) -> None:
        """A ground-truth sample: scored now against a pose of the same stamp, else queued for
        the robot's next pose."""
        for ent in gt.entities:
            if ent.entity_id not in rk.pending:
                continue
            sample = (t_ns, ent.position_m.x, ent.position_m.y, ent.yaw_rad)
            latest = rk.state.get(ent.entity_id)
            if latest is not None and latest[3] >= t_ns:
                # same stamp as the pose already integrated (log-time order)
                pose = (latest[3], latest[0], latest[1], latest[2])
                self._score([sample], None, pose, rk.errors, rk.align, ent.entity_id)
            else:
                rk.pending[ent.entity_id].append(sample)

    def _on_odometry(
        self, topic: str, t_ns: int, odo: WheelOdometry, rk: _Reckoning, writer: LogWriter
    ) -> None:
        """One odometry sample: integrate it, score the truth waiting for it, write the pose."""
        name = topic.split("/")[2]
        prev = rk.state.get(name)
        if prev is None:
            x, y, yaw = 0.0, 0.0, 0.0
            rk.pending[name] = [g for g in rk.pending[name] if g[0] >= t_ns]
        else:
            x, y, yaw, t_prev, last = prev
            ds, dyaw = self._motion(name, last, odo, (t_ns - t_prev) / 1e9, rk.metadata)
            rk.path_m += abs(ds)
            x, y, yaw = integrate_step(x, y, yaw, ds, dyaw)
        self._score(rk.pending[name], prev, (t_ns, x, y, yaw), rk.errors, rk.align, name)
        rk.state[name] = (x, y, yaw, t_ns, odo)
        writer.write(
            f"/robot/{name}/dead_reckoning",
            pose_in_frame(t_ns, x, y, yaw, frame_id=f"{name}/odom"),
            t_ns,
        )
        # the same pose as a frame tree NAME/odom -> NAME/base_link (formats/README.md)
        tf_topic = topics.transforms(f"/robot/{name}/dead_reckoning")
        writer.write(tf_topic, odom_base_transform(t_ns, name, x, y, yaw), t_ns)
        rk.poses += 1

    def _motion(
        self,
        name: str,
        last: WheelOdometry,
        odo: WheelOdometry,
        dt: float,
        metadata: dict[str, dict[str, str]],
    ) -> tuple[float, float]:
        md = metadata.get(f"robot/{name}", {})
        drive = DiffDrive(
            float(md.get("ticks_per_m", self.config.drive.ticks_per_m)),
            float(md.get("wheel_base_m", self.config.drive.wheel_base_m)),
        )
        # ticks (preferred only when asked, if the robot also reports v/omega), else v/omega
        # held over the interval, else the robot's own poses
        return increment(last, odo, drive, prefer_ticks=self.config.prefer_ticks) or (0.0, 0.0)

    @staticmethod
    def _score(
        waiting: list[tuple[int, float, float, float | None]],
        prev: tuple[float, float, float, int, WheelOdometry] | None,
        now: tuple[int, float, float, float],
        errors: _ErrorStats,
        align: dict[str, _Align],
        name: str,
    ) -> None:
        """Score ground-truth samples that fall between the previous and the current pose (the
        first one fixes the alignment of the odometry frame to the world)."""
        t1, x1, y1, yaw1 = now
        while waiting and waiting[0][0] <= t1:
            t_gt, gx, gy, gyaw = waiting.pop(0)
            if prev is None or t1 == prev[3]:
                x, y, yaw = x1, y1, yaw1
            else:
                a = (t_gt - prev[3]) / (t1 - prev[3])
                x, y = prev[0] + a * (x1 - prev[0]), prev[1] + a * (y1 - prev[1])
                yaw = prev[2] + a * (yaw1 - prev[2])
            if name not in align:
                align[name] = _Align.fixing(x, y, yaw, gx, gy, gyaw)
            wx, wy = align[name].apply(x, y)
            errors.add(math.hypot(wx - gx, wy - gy))


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


_Truth = tuple[int, float, float, float | None]
"""A ground-truth sample of a robot: (log time ns, x m, y m, yaw rad or None)."""


@dataclass
class _Reckoning:
    """State of a dead-reckoning pass over every robot of a log."""

    metadata: dict[str, dict[str, str]]
    pending: dict[str, list[_Truth]]
    """Per robot: ground-truth samples waiting for the poses around them."""
    state: dict[str, tuple[float, float, float, int, WheelOdometry]] = field(default_factory=dict)
    """Per robot: the latest pose (x, y, yaw), its time and its odometry sample."""
    align: dict[str, _Align] = field(default_factory=dict)
    errors: _ErrorStats = field(default_factory=_ErrorStats)
    path_m: float = 0.0
    poses: int = 0


DEAD_RECKONING_PROCESSOR = ProcessorInfo(
    name="dead-reckoning",
    description="Wheel dead reckoning of each robot -> /robot/NAME/dead_reckoning poses",
    factory=DeadReckoningProcessor,
)
"""Registry entry (entry point ``trackctl.processors``)."""
