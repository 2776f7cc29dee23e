"""Processors that need no system: log health checks."""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field

from trackctl.logs.messages import MetricReport
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import ProcessorInfo, Progress, register_processor

__all__ = ["CheckProcessor", "CheckConfig"]


@dataclass(frozen=True, slots=True)
class CheckConfig:
    """Options of the ``check`` processor."""

    gap_factor: float = 5.0
    """A gap counts when it exceeds this many times the topic's median period."""


@dataclass
class _TopicState:
    last_stamp: int | None = None
    last_log: int | None = None
    periods: list[int] = field(default_factory=list)


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
                st.periods.append(raw.log_time_ns - st.last_log)
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
        gaps = 0
        max_gap_s = 0.0
        for st in states.values():
            if len(st.periods) < 3:
                continue
            periods = sorted(st.periods)
            median = periods[len(periods) // 2]
            gaps += sum(1 for p in st.periods if median > 0 and p > self.config.gap_factor * median)
            max_gap_s = max(max_gap_s, periods[-1] / 1e9)
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
                "first_problem": first_problem or None,
            },
            params={"gap_factor": self.config.gap_factor},
        )


register_processor(
    ProcessorInfo(
        name="check",
        description="Log health: non-monotonic stamps, NaN/inf values, gaps, undecodable messages",
        factory=CheckProcessor,
    )
)
