"""Processors that need no system: log health checks and dead reckoning
(:mod:`trackctl.processing.dead_reckoning`)."""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field

from trackctl.logs.messages import MetricReport
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


# the dead-reckoning processor lives in its own module; its names stay importable from here
from trackctl.processing.dead_reckoning import (  # noqa: E402
    DEAD_RECKONING_PROCESSOR,
    DeadReckoningConfig,
    DeadReckoningProcessor,
)
