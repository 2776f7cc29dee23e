"""S-Mirror (dissertation §4.1): camera nodes mirror foreground views to robots on request; the
robot localizes itself from its LEDs in them and dead-reckons in between."""

from trackctl.logs.messages import MetricReport
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import ProcessorInfo, Progress
from trackctl.smirror.node import CastMode, MirrorNode, NodeConfig, decide_cast
from trackctl.smirror.pipeline import (
    Mode,
    SmirrorConfig,
    SmirrorResult,
    error_by_range,
    localize,
    pose_topic,
    report_metrics,
    run,
    run_detailed,
    sent_topic,
)
from trackctl.smirror.robot import FilterConfig, LedConfig, PoseFilter, detect_leds, fix_from_leds

__all__ = [
    "PROCESSOR",
    "CastMode",
    "FilterConfig",
    "LedConfig",
    "MirrorNode",
    "Mode",
    "NodeConfig",
    "PoseFilter",
    "SmirrorConfig",
    "SmirrorProcessor",
    "SmirrorResult",
    "decide_cast",
    "detect_leds",
    "error_by_range",
    "fix_from_leds",
    "localize",
    "pose_topic",
    "report_metrics",
    "run",
    "run_detailed",
    "sent_topic",
]


class SmirrorProcessor:
    """The ``smirror`` processor (registry entry of :func:`run`)."""

    name = "smirror"

    def __init__(self, config: SmirrorConfig | None = None) -> None:
        self.config = config or SmirrorConfig()
        self.last_result: SmirrorResult | None = None
        """Per-sample figures of the last run (for plots)."""

    def run(
        self, reader: LogReader, writer: LogWriter, progress: Progress | None = None
    ) -> MetricReport:
        report, self.last_result = run_detailed(reader, writer, self.config, progress)
        return report


PROCESSOR = ProcessorInfo(
    name="smirror",
    description="S-Mirror: robot localization from node images (LEDs) + wheel odometry (§4.1)",
    factory=SmirrorProcessor,
)
"""Registry entry (entry point ``trackctl.processors``)."""
