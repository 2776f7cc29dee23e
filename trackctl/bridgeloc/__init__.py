"""BridgeLoc (dissertation §4.2): robot localization by bridging infrastructure and robot camera
views through simple rotation-symmetric tags, with an EKF over odometry for blind spots."""

from trackctl.bridgeloc.config import POSE_TOPIC, BridgeLocConfig, Mode, PoseMethod
from trackctl.bridgeloc.pipeline import run
from trackctl.bridgeloc.tags import (
    BORDER_RATIO,
    Mount,
    Placement,
    PracticalTag,
    count_practical,
    count_universal,
    enumerate_practical,
    enumerate_universal,
    theorem5,
    theorem6,
)
from trackctl.logs.messages import MetricReport
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import ProcessorInfo, Progress

__all__ = [
    "PROCESSOR",
    "BORDER_RATIO",
    "POSE_TOPIC",
    "BridgeLocConfig",
    "BridgeLocProcessor",
    "Mode",
    "Mount",
    "Placement",
    "PoseMethod",
    "PracticalTag",
    "count_practical",
    "count_universal",
    "enumerate_practical",
    "enumerate_universal",
    "run",
    "theorem5",
    "theorem6",
]


class BridgeLocProcessor:
    """The ``bridgeloc`` processor (registry entry of :func:`run`)."""

    name = "bridgeloc"

    def __init__(self, config: BridgeLocConfig | None = None) -> None:
        self.config = config or BridgeLocConfig()

    def run(
        self, reader: LogReader, writer: LogWriter, progress: Progress | None = None
    ) -> MetricReport:
        return run(reader, writer, self.config, progress)


PROCESSOR = ProcessorInfo(
    name="bridgeloc",
    description="BridgeLoc: robot poses from tag bridging + EKF over odometry (§4.2)",
    factory=BridgeLocProcessor,
)
"""Registry entry (entry point ``trackctl.processors``)."""
