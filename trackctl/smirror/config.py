"""Configuration and per-sample results of an S-Mirror run, and its output topics."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum

from trackctl.smirror.link import LinkConfig
from trackctl.smirror.node import NodeConfig
from trackctl.smirror.robot import FilterConfig

__all__ = ["Mode", "SmirrorConfig", "SmirrorResult", "pose_topic", "sent_topic"]


def pose_topic(robot: str) -> str:
    """Localized poses of a robot: ``/smirror/NAME/pose`` (foxglove.PoseInFrame)."""
    return f"/smirror/{robot}/pose"


def sent_topic(node: str) -> str:
    """What a node sent: ``/smirror/NODE/sent`` (trackctl.MirrorTransmission)."""
    return f"/smirror/{node}/sent"


class Mode(StrEnum):
    """``mirror+odom``: S-Mirror + motion sensor; ``centralized``: vision-only baseline."""

    MIRROR_ODOM = "mirror+odom"
    CENTRALIZED = "centralized"


@dataclass(frozen=True, slots=True)
class SmirrorConfig:
    """Configuration of an S-Mirror run (defaults follow §4.1.3)."""

    mode: Mode = Mode.MIRROR_ODOM
    broadcast_threshold: int = 15
    """A node broadcasts an image from this many requests on (Table 4.2)."""
    requesters: int | None = None
    """Robots requesting images (ours + others); None: the log's ``smirror/requesters`` metadata."""
    robot: str | None = None
    """The one robot to localize; None: every robot of the log (``robot/<NAME>`` metadata, or
    odometry topics without it)."""
    node: NodeConfig = field(default_factory=NodeConfig)
    filter: FilterConfig = field(default_factory=FilterConfig)
    beacon_period_s: float = 1.0
    sensing_ms: float = 40.0
    """Sensing delay: the sensors' sampling period (25 Hz, §4.1.3 B)."""
    link: LinkConfig = field(default_factory=LinkConfig)
    """Each node's link: throughput, latency, DTIM wait, broadcast loss, queue limit."""
    processing_ms: float = 15.0
    """Processing time used to time a fix's arrival (measured times go into the delay figures;
    a fixed budget keeps the output poses deterministic)."""
    max_range_m: float = 11.0
    """Beyond this ground range a node does not count as covering a point."""
    margin_px: int = 8
    seed: int = 0
    """Seeds the queue positions and broadcast losses."""
    site: Mapping[str, Mapping[str, str]] = field(default_factory=dict)
    """Site records laid over the log's metadata (``--site``: :mod:`trackctl.ingest.site`)."""
    start: tuple[float, float, float] | None = None
    """The robot's start pose (x m, y m, yaw rad, world frame) when it is known (a dock); None:
    unknown, the robot asks every node for images until one of them shows its LEDs."""

    def __post_init__(self) -> None:
        if self.broadcast_threshold < 1:
            raise ValueError(f"broadcast_threshold must be >= 1, got {self.broadcast_threshold}")
        if self.requesters is not None and self.requesters < 1:
            raise ValueError(f"requesters must be >= 1, got {self.requesters}")


@dataclass
class SmirrorResult:
    """Per-sample figures of a run (one row per ground-truth sample of the robot)."""

    t_s: list[float] = field(default_factory=list)
    error_m: list[float] = field(default_factory=list)
    in_coverage: list[bool] = field(default_factory=list)
    range_m: list[float] = field(default_factory=list)
    """Ground distance to the covering node (NaN outside coverage)."""
    delay_ms: list[float] = field(default_factory=list)
    path_m: list[float] = field(default_factory=list)
    """Distance the robot has travelled (ground truth) at the sample."""
    events: list[tuple[float, int, int, int]] = field(default_factory=list)
    """Transmissions: (t_s, bytes sent, bytes if unicast, bytes to our robot)."""
    node_ms: list[float] = field(default_factory=list)
    robot_ms: list[float] = field(default_factory=list)
    full_frame_bytes: int = 0
    foreground_bytes: int = 0
    image_messages: int = 0
    images_new: int = 0
    images_old: int = 0
    beacons: int = 0
    cast_modes: set[str] = field(default_factory=set)
    queue_ms: list[float] = field(default_factory=list)
    """Time each answer waited in its node's transmit queue."""
    answers_dropped: int = 0
    """Answers not sent: the node's queue already held more than its limit."""
    ours_requested: int = 0
    """Answers our robot asked for; ``fix_attempts`` of them arrived."""
    decode_failures: int = 0
    fix_attempts: int = 0
    fixes: int = 0
    fixes_used: int = 0
    broadcast_lost: int = 0
    requesters: int = 1
    duration_s: float = 0.0
    robot: str = ""
    localized_s: float = 0.0
    """Odometry time during which the robot had a pose (from its start pose or first fix)."""
    odometry_s: float = 0.0
    """Odometry time in all."""
    first_fix_s: float | None = None
    """Log time (s from the first message) when the robot first had a pose."""
    unlocalized_samples: int = 0
    """Ground-truth samples at which the robot had no pose yet (not scored as errors)."""
    nis: list[float] = field(default_factory=list)
    """Normalized innovation squared of each fix fused (3 dof; mean ~3 when consistent)."""
    per_robot: dict[str, SmirrorResult] = field(default_factory=dict)
    """Each localized robot's own figures (the run's are all robots' together)."""
