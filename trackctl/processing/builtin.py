"""Processors that need no system: log health checks and wheel dead reckoning."""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field

from trackctl.geometry.odometry import DiffDrive, increment, integrate_step
from trackctl.logs import topics
from trackctl.logs.foxglove import pose_in_frame
from trackctl.logs.messages import MetricReport, WheelOdometry
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
        nonmono = nonfinite = stamp_mismatch = decode_errors = messages = 0
        first_problem = ""
        total = reader.message_count
        for raw in reader.raw():
            messages += 1
            if progress is not None and messages % 5000 == 0:
                progress(messages, total)
            st = states[raw.topic]
            if st.last_log is not None:
                st.add_period(raw.log_time_ns - st.last_log, self.config.gap_factor)
            st.last_log = raw.log_time_ns
            try:
                msg = reader.codec(raw).decode(raw.data)
            except Exception:  # noqa: BLE001 - counting undecodable messages is the point
                decode_errors += 1
                continue
            stamp = getattr(msg, "t_ns", None)
            if stamp is not None:
                if st.last_stamp is not None and stamp < st.last_stamp:
                    nonmono += 1
                    first_problem = first_problem or (
                        f"{raw.topic}: stamp {stamp} ns after {st.last_stamp} ns"
                    )
                if stamp != raw.log_time_ns:
                    stamp_mismatch += 1
                st.last_stamp = stamp
            finite = getattr(msg, "finite_values", None)
            if finite is not None:
                for key, value in finite().items():
                    if not math.isfinite(value):
                        nonfinite += 1
                        first_problem = first_problem or f"{raw.topic}: {key} = {value}"
        gaps = sum(st.finish(self.config.gap_factor) for st in states.values())
        max_gap_s = max((st.max_period for st in states.values()), default=0) / 1e9
        return MetricReport(
            t_ns=reader.end_ns or 0,
            processor=self.name,
            metrics={
                "messages": messages,
                "topics": len(states),
                "nonmonotonic_stamps": nonmono,
                "nonfinite_values": nonfinite,
                "stamp_mismatches": stamp_mismatch,
                "decode_errors": decode_errors,
                "gaps": gaps,
                "max_gap_s": round(max_gap_s, 6),
                "truncated": reader.truncated,
                "crc_errors": len(reader.damage),
                "lost_messages": reader.lost_messages,
                "data_crc_ok": reader.verify_data_crc(),
                "first_problem": first_problem or None,
            },
            params={"gap_factor": self.config.gap_factor},
        )


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
        odom_topics = sorted(
            t
            for t, info in reader.topics().items()
            if info.schema_name == WheelOdometry.SCHEMA and t.startswith("/robot/")
        )
        if not odom_topics:
            reader.require([topics.odom("<NAME>")], self.name, "wheel odometry to integrate")
        robots = {t.split("/")[2]: t for t in odom_topics}
        has_truth = topics.GROUND_TRUTH in reader.topics()
        align: dict[str, _Align] = {}
        metadata = reader.metadata()
        errors = _ErrorStats()
        path_m = 0.0
        poses = 0
        state: dict[str, tuple[float, float, float, int, WheelOdometry]] = {}
        # Ground-truth samples wait (a few at a time) for the dead-reckoned poses around them.
        pending: dict[str, list[tuple[int, float, float, float | None]]] = {
            name: [] for name in robots
        }
        stream = reader.messages(odom_topics + ([topics.GROUND_TRUTH] if has_truth else []))
        for msg in stream:
            if msg.topic == topics.GROUND_TRUTH:
                for ent in msg.message.entities:
                    if ent.entity_id not in pending:
                        continue
                    gt = (msg.log_time_ns, ent.position_m.x, ent.position_m.y, ent.yaw_rad)
                    latest = state.get(ent.entity_id)
                    if latest is not None and latest[3] >= msg.log_time_ns:
                        # same stamp as the pose already integrated (log-time order)
                        pose = (latest[3], latest[0], latest[1], latest[2])
                        self._score([gt], None, pose, errors, align, ent.entity_id)
                    else:
                        pending[ent.entity_id].append(gt)
                continue
            name = msg.topic.split("/")[2]
            odo: WheelOdometry = msg.message
            prev = state.get(name)
            if prev is None:
                x, y, yaw = 0.0, 0.0, 0.0
                pending[name] = [g for g in pending[name] if g[0] >= msg.log_time_ns]
            else:
                x, y, yaw, t_prev, last = prev
                ds, dyaw = self._motion(name, last, odo, (msg.log_time_ns - t_prev) / 1e9, metadata)
                path_m += abs(ds)
                x, y, yaw = integrate_step(x, y, yaw, ds, dyaw)
            self._score(pending[name], prev, (msg.log_time_ns, x, y, yaw), errors, align, name)
            state[name] = (x, y, yaw, msg.log_time_ns, odo)
            writer.write(
                f"/robot/{name}/dead_reckoning",
                pose_in_frame(msg.log_time_ns, x, y, yaw, frame_id=f"{name}/odom"),
                msg.log_time_ns,
            )
            poses += 1
            if progress is not None and poses % 5000 == 0:
                progress(poses, None)
        metrics: dict[str, float | int | None] = {
            "robots": len(robots),
            "poses": poses,
            "path_m": round(path_m, 4),
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


DEAD_RECKONING_PROCESSOR = ProcessorInfo(
    name="dead-reckoning",
    description="Wheel dead reckoning of each robot -> /robot/NAME/dead_reckoning poses",
    factory=DeadReckoningProcessor,
)
"""Registry entry (entry point ``trackctl.processors``)."""
