"""Configuration of a VM-Tracking run."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

from trackctl.vmtrack.align import AlignConfig
from trackctl.vmtrack.appearance import AppearanceConfig
from trackctl.vmtrack.frames import FrameConfig
from trackctl.vmtrack.identify import IdentifyConfig
from trackctl.vmtrack.motion import MotionConfig
from trackctl.vmtrack.retrack import RetrackConfig
from trackctl.vmtrack.stitch import StitchConfig
from trackctl.vmtrack.tracker import TrackerConfig

__all__ = [
    "AssociationConfig",
    "BindingConfig",
    "Identity",
    "Mode",
    "ReportConfig",
    "Source",
    "VmTrackConfig",
]


class Mode(StrEnum):
    """``vm``: visual + motion sensors; ``v-af``: the paper's appearance-free visual baseline."""

    VM = "vm"
    V_AF = "v-af"


class Identity(StrEnum):
    """Who names the tracks: ``offline`` decides over the whole log (:mod:`~trackctl.vmtrack.
    identify`); ``online`` publishes the paper's frame-by-frame bindings."""

    OFFLINE = "offline"
    ONLINE = "online"


class Source(StrEnum):
    """Where person detections come from."""

    AUTO = "auto"
    FRAMES = "frames"
    DETECTIONS = "detections"


@dataclass(frozen=True, slots=True)
class AssociationConfig:
    """Online association (:mod:`~trackctl.vmtrack.online`): detections to ground tracks."""

    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    """Each ground track's Kalman model (also the smoother's)."""
    merge_m: float = 1.0
    """Detections of one instant from different cameras closer than this are one person."""
    spawn_m: float = 1.0
    """An unmatched detection closer than this to a track does not start a new track."""
    clutter_radius_m: float = 0.5
    clutter_min: int = 5
    clutter_memory_s: float = 120.0
    """Clutter map: where ``clutter_min`` tracks were born and died without moving more than
    ``clutter_radius_m`` in the last ``clutter_memory_s``, no new track starts (a poster or a
    plant the detector keeps firing on; a door sees people walk away from it)."""
    duplicate_m: float = 0.45
    """Two tracks closer than this are one person (the younger, unbound one is dropped)."""


@dataclass(frozen=True, slots=True)
class BindingConfig:
    """Online binding of phones to tracks (:mod:`~trackctl.vmtrack.binder`, Theorems 1-2)."""

    bind_frames: int = 9
    """Frames of consistent motion before a phone is bound to a visual track (Theorem 1)."""
    bind_frames_free: int = 24
    """...for a phone whose alignment (carry yaw, step scale, clock offset) is not known yet:
    every candidate gets its own best fit, so only turns, stops and pace tell them apart."""
    reject_mps: float = 0.45
    """A candidate whose mean velocity disagreement exceeds this is filtered away."""
    loss_gross: float = 2.0
    """A bound track whose detections disagree with its phone by this many times the loss limit
    loses it even when no other track explains the phone better."""
    loss_better: float = 0.5
    """...or when an unbound track's detections disagree with the phone less than this share."""
    converge_hits: int = 6
    """Detections a track needs before its velocity is compared with phones."""
    ratio: float = 3.0
    """Bind early when the best candidate's disagreement is this many times below the next."""
    offline_reject_mps: float = 0.6
    """End of log (online identity): a never-bound phone takes its clear best track if it
    disagrees less."""
    checkpoint_dbm: float = -40.0
    """RSSI of a phone held within ~1 m of a check-point AP (the paper: "less than 1 meter")."""
    checkpoint_radius_m: float = 1.5
    """A check-point binds only the one track within this distance of the AP."""
    rssi_at_1m_dbm: float = -40.0
    """Check-point AP path-loss model: RSSI at 1 m, exponent, shadowing std (calibrate per site)."""
    path_loss_exponent: float = 2.5
    shadowing_db: float = 3.0
    rssi_evidence_m: float = 4.0
    """Tracks within this distance of an AP compare their distance with a phone's RSSI there."""


@dataclass(frozen=True, slots=True)
class ReportConfig:
    """The metric report (:mod:`~trackctl.vmtrack.score`)."""

    eval_threshold_m: float = 1.0
    """A track within this distance of a person matches them (MOTA, IDF1, errors)."""


@dataclass(frozen=True, slots=True)
class VmTrackConfig:
    """Configuration of a VM-Tracking run, one field per stage (the stages' order in
    :func:`~trackctl.vmtrack.pipeline.run_stages`)."""

    mode: Mode = Mode.VM
    source: Source = Source.AUTO
    """Detections from camera frames or from detections topics (auto: frames when present)."""
    frames: FrameConfig = field(default_factory=FrameConfig)
    """Person detection in camera frames."""
    motion: MotionConfig = field(default_factory=MotionConfig)
    """Pedestrian dead reckoning of each phone."""
    phones_aligned: bool = False
    """The paper's assumption, only for sites whose phone app guarantees it: each phone's
    rotation-vector heading is its carrier's walking direction in the site frame, and its clock
    is the cameras'. Off (the default), both are estimated per phone (:mod:`~trackctl.vmtrack.
    align`)."""
    align: AlignConfig = field(default_factory=AlignConfig)
    """Search ranges of each phone's unknowns (:mod:`~trackctl.vmtrack.align`), shared by the
    binding, the offline identity and the refinement."""
    association: AssociationConfig = field(default_factory=AssociationConfig)
    binding: BindingConfig = field(default_factory=BindingConfig)
    smooth: bool = True
    """RTS-smooth every track (offline)."""
    appearance: AppearanceConfig = field(default_factory=AppearanceConfig)
    """The tracks' colour signatures, from the frames in the log (re-identification)."""
    stitch: StitchConfig = field(default_factory=StitchConfig)
    """Offline clean-up of visual-only tracks (coasting tails, fragments, short tracks) and
    their re-identification by colour."""
    identity: Identity = Identity.OFFLINE
    identify: IdentifyConfig = field(default_factory=IdentifyConfig)
    """Offline identity parameters."""
    refinement: RetrackConfig = field(default_factory=RetrackConfig)
    """Offline identity refinement: each carrier followed through the raw detections by their
    phone (:mod:`~trackctl.vmtrack.retrack`); it names the tracks where it finds the carrier.
    ``RetrackConfig(enabled=False)`` skips it."""
    report: ReportConfig = field(default_factory=ReportConfig)
