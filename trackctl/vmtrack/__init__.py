"""VM-Tracking (dissertation §3.1): people identified by fusing camera detections with their
phones' motion sensors."""

from trackctl.logs.messages import MetricReport
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.processing.base import ProcessorInfo, Progress
from trackctl.vmtrack.align import AlignConfig, Alignment
from trackctl.vmtrack.config import (
    AssociationConfig,
    BindingConfig,
    Identity,
    Mode,
    ReportConfig,
    Source,
    VmTrackConfig,
)
from trackctl.vmtrack.cost import AssociationCost, VisualCost, VisualMotionCost, fused_probability
from trackctl.vmtrack.detect import BackgroundModel, DetectorConfig, detect_people, predict_region
from trackctl.vmtrack.frames import FrameConfig, FrameDetector
from trackctl.vmtrack.identify import IdentifyConfig
from trackctl.vmtrack.motion import MotionConfig, PhoneMotion
from trackctl.vmtrack.pipeline import TRACKS_TOPIC, VmResult, run, run_stages
from trackctl.vmtrack.retrack import RetrackConfig
from trackctl.vmtrack.tracker import TrackerConfig

__all__ = [
    "PROCESSOR",
    "TRACKS_TOPIC",
    "AlignConfig",
    "Alignment",
    "AssociationConfig",
    "AssociationCost",
    "BackgroundModel",
    "BindingConfig",
    "DetectorConfig",
    "FrameConfig",
    "FrameDetector",
    "Identity",
    "IdentifyConfig",
    "Mode",
    "Source",
    "detect_people",
    "predict_region",
    "MotionConfig",
    "PhoneMotion",
    "ReportConfig",
    "RetrackConfig",
    "TrackerConfig",
    "VisualCost",
    "VisualMotionCost",
    "VmResult",
    "VmTrackConfig",
    "VmTrackProcessor",
    "fused_probability",
    "run",
    "run_stages",
]


class VmTrackProcessor:
    """The ``vm-track`` processor (registry entry of :func:`run`)."""

    name = "vm-track"

    def __init__(self, config: VmTrackConfig | None = None) -> None:
        self.config = config or VmTrackConfig()

    def run(
        self, reader: LogReader, writer: LogWriter, progress: Progress | None = None
    ) -> MetricReport:
        return run(reader, writer, self.config, progress)


PROCESSOR = ProcessorInfo(
    name="vm-track",
    description="VM-Tracking: identified people tracks from detections + phone IMU (§3.1)",
    factory=VmTrackProcessor,
)
"""Registry entry (entry point ``trackctl.processors``)."""
