"""Typed messages of trackctl's custom channels: one definition each.

Every message is a frozen dataclass; its field types and its docstring are the only definition.
JSON encoding and decoding (``to_json``/``from_json``) and the JSON Schema in
``formats/<SCHEMA>.json`` are derived from them by :mod:`trackctl.logs.jsonmap`
(``make formats`` regenerates the schemas; a test keeps the committed files current). Adding a
message type = one class here + one entry in :data:`MESSAGE_TYPES`.

Conventions (see ``formats/README.md``):

* time is an integer nanosecond count (``t_ns``); in JSON it is written as Foxglove's
  ``{"sec": int, "nsec": int}`` object under ``timestamp`` so viewers order and plot it natively;
* lengths are metres, angles radians, rates per second;
* the world frame is right-handed with z up; quaternions are ``(x, y, z, w)``.

Docstrings: the first paragraph and ``TOPIC`` describe the schema; each ``Attributes:`` entry
describes its field in the schema (written for a reader of the JSON).
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar, Literal, NamedTuple

from trackctl.logs.jsonmap import NS_PER_S, JsonMessage, Length, Range

__all__ = [
    "Vec3",
    "Quat",
    "Pose2D",
    "Transform",
    "Imu",
    "RssiReading",
    "RssiScan",
    "WheelOdometry",
    "BBox",
    "Detection",
    "Detections",
    "TrackState",
    "Track",
    "Tracks",
    "GroundTruthEntity",
    "GroundTruth",
    "CameraModel",
    "MetricValue",
    "MetricReport",
    "MESSAGE_TYPES",
    "Step",
    "EObservations",
    "VScenario",
    "EvMatch",
    "EvMatches",
    "MirrorTransmission",
    "time_to_json",
    "time_from_json",
]

MetricValue = float | int | str | bool | None


def time_to_json(t_ns: int) -> dict[str, int]:
    """Nanoseconds to Foxglove's ``{"sec", "nsec"}`` time object."""
    sec, nsec = divmod(int(t_ns), NS_PER_S)
    return {"sec": sec, "nsec": nsec}


def time_from_json(obj: Mapping[str, Any]) -> int:
    """Foxglove's ``{"sec", "nsec"}`` time object to nanoseconds."""
    return int(obj["sec"]) * NS_PER_S + int(obj.get("nsec", 0))


class Vec3(NamedTuple):
    """A 3-vector; its unit is given by the field that holds it."""

    x: float
    y: float
    z: float


class Quat(NamedTuple):
    """A unit quaternion in Foxglove/ROS order ``(x, y, z, w)``."""

    x: float
    y: float
    z: float
    w: float


IDENTITY_QUAT = Quat(0.0, 0.0, 0.0, 1.0)


class Pose2D(NamedTuple):
    """A planar pose in the world frame: position in metres, heading (yaw about z) in radians."""

    x_m: float
    y_m: float
    yaw_rad: float


class Transform(NamedTuple):
    """A rigid transform ``parent <- child``: translation (metres) and rotation."""

    translation: Vec3
    rotation: Quat


@dataclass(frozen=True, slots=True)
class Imu(JsonMessage):
    """One inertial sample of a phone or robot.

    Attributes:
        t_ns: Sample time.
        frame_id: Sensor frame, e.g. phone/p1.
        accel_mps2: Specific force in the device frame, m/s^2, INCLUDING gravity (a phone lying
            flat and still reads z = +9.81).
        gyro_rps: Angular rate in the device frame, rad/s, right-handed; null for
            accelerometer-only devices.
        orientation: Optional device-to-world rotation (x, y, z, w), world frame z up (Android
            rotation vector); null when the device gives none.
    """

    SCHEMA: ClassVar[str] = "trackctl.Imu"
    TOPIC: ClassVar[str] = "/phone/<NAME>/imu (or /robot/<NAME>/imu)"
    t_ns: int
    frame_id: str
    accel_mps2: Vec3
    gyro_rps: Vec3 | None = None
    orientation: Quat | None = None

    def finite_values(self) -> dict[str, float]:
        """Every float field by dotted name (for NaN/inf checks)."""
        out = {f"accel_mps2.{k}": v for k, v in self.accel_mps2._asdict().items()}
        if self.gyro_rps is not None:
            out.update({f"gyro_rps.{k}": v for k, v in self.gyro_rps._asdict().items()})
        if self.orientation is not None:
            out.update({f"orientation.{k}": v for k, v in self.orientation._asdict().items()})
        return out


@dataclass(frozen=True, slots=True)
class RssiReading(JsonMessage):
    """Signal strength of one electronic ID (MAC/IMSI) heard by an observer, in dBm.

    Attributes:
        eid: Electronic id heard (MAC, IMSI, ...).
        rssi_dbm: Received signal strength, dBm.
    """

    eid: str
    rssi_dbm: float


@dataclass(frozen=True, slots=True)
class RssiScan(JsonMessage):
    """Everything one observer (WiFi AP, cell, BLE sniffer) heard in one scan.

    Attributes:
        t_ns: Sample time.
        observer: Observer (AP / cell) id.
        readings: One entry per electronic ID heard.
        observer_position_m: Observer position in the world frame, metres, when known.
    """

    SCHEMA: ClassVar[str] = "trackctl.RssiScan"
    TOPIC: ClassVar[str] = "/rssi"
    t_ns: int
    observer: str
    readings: tuple[RssiReading, ...]
    observer_position_m: Vec3 | None = None

    def finite_values(self) -> dict[str, float]:
        """Every float field by dotted name (for NaN/inf checks)."""
        return {f"readings[{i}].rssi_dbm": r.rssi_dbm for i, r in enumerate(self.readings)}


@dataclass(frozen=True, slots=True)
class WheelOdometry(JsonMessage):
    """Wheel odometry of a differential-drive robot: cumulative encoder ticks, or body
    velocities, or both.

    Attributes:
        t_ns: Sample time.
        frame_id: Robot base frame, e.g. robot/r1.
        left_ticks: Cumulative left encoder count.
        right_ticks: Cumulative right encoder count.
        v_mps: Forward speed, m/s.
        omega_rps: Yaw rate, rad/s, counter-clockwise positive.
        pose: The robot's own dead-reckoned pose in its odometry frame.
        vy_mps: Lateral speed, m/s, +y to the left (holonomic robots, or a skidding one; ROS
            twist.linear.y); null when not reported.
    """

    SCHEMA: ClassVar[str] = "trackctl.WheelOdometry"
    TOPIC: ClassVar[str] = "/robot/<NAME>/odom"
    t_ns: int
    frame_id: str
    left_ticks: int | None = None
    right_ticks: int | None = None
    v_mps: float | None = None
    omega_rps: float | None = None
    pose: Pose2D | None = None
    vy_mps: float | None = None

    def __post_init__(self) -> None:
        has_ticks = self.left_ticks is not None and self.right_ticks is not None
        has_vel = self.v_mps is not None and self.omega_rps is not None
        if not (has_ticks or has_vel):
            raise ValueError(
                "WheelOdometry needs left_ticks and right_ticks, or v_mps and omega_rps"
            )

    def finite_values(self) -> dict[str, float]:
        """Every float field by dotted name (for NaN/inf checks)."""
        out = {
            k: v
            for k, v in (
                ("v_mps", self.v_mps),
                ("omega_rps", self.omega_rps),
                ("vy_mps", self.vy_mps),
            )
        }
        if self.pose is not None:
            out.update({f"pose.{k}": v for k, v in self.pose._asdict().items()})
        return {k: v for k, v in out.items() if v is not None}


class BBox(NamedTuple):
    """An axis-aligned image box: top-left corner and size, in pixels."""

    x_px: float
    y_px: float
    w_px: float
    h_px: float


@dataclass(frozen=True, slots=True)
class Detection(JsonMessage):
    """One detected object in one camera frame.

    Attributes:
        box: Image box: top-left corner and size, pixels.
        score: Detector confidence.
        label: Class: person, robot, tag, ...
        ground_m: Ground point (foot point) in the world frame, metres, z = 0; null when unknown.
        visual_id: Per-camera visual id (VID), if assigned.
    """

    box: BBox
    score: Annotated[float, Range(ge=0, le=1)]
    label: str = "person"
    ground_m: Vec3 | None = None
    visual_id: str | None = None


@dataclass(frozen=True, slots=True)
class Detections(JsonMessage):
    """Every detection of one camera frame (an empty list is a frame with nobody in it).

    Attributes:
        t_ns: Sample time.
        camera: Camera name (the NAME of /NAME/image).
        detections: The detections, nearest first when the detector orders them.
    """

    SCHEMA: ClassVar[str] = "trackctl.Detections"
    TOPIC: ClassVar[str] = "/<CAMERA>/detections"
    t_ns: int
    camera: str
    detections: tuple[Detection, ...]


class TrackState(enum.StrEnum):
    """Lifecycle of a track at one instant."""

    TENTATIVE = "tentative"
    TRACKED = "tracked"
    PREDICTED = "predicted"
    LOST = "lost"


@dataclass(frozen=True, slots=True)
class Track(JsonMessage):
    """One tracked object at one instant.

    Attributes:
        track_id: Stable identity: a phone's MID, a robot id or a visual id.
        position_m: Position, metres.
        velocity_mps: Velocity, m/s.
        covariance_m2: 3x3 position covariance, row-major, m^2.
        state: Lifecycle state.
        visual_id: Visual id the track is bound to now.
        score: Association confidence in [0, 1].
    """

    track_id: str
    position_m: Vec3
    velocity_mps: Vec3 | None = None
    covariance_m2: Annotated[tuple[float, ...], Length(9)] | None = None
    state: TrackState = TrackState.TRACKED
    visual_id: str | None = None
    score: float | None = None

    def __post_init__(self) -> None:
        if self.covariance_m2 is not None and len(self.covariance_m2) != 9:
            raise ValueError(
                f"Track.covariance_m2 needs 9 values (3x3 row-major), got {len(self.covariance_m2)}"
            )


@dataclass(frozen=True, slots=True)
class Tracks(JsonMessage):
    """Every track a processor holds at one instant.

    Attributes:
        t_ns: Sample time.
        tracks: The tracks.
        frame_id: Frame of positions, normally world.
    """

    SCHEMA: ClassVar[str] = "trackctl.Tracks"
    TOPIC: ClassVar[str] = "/<processor>/tracks (e.g. /vmtrack/tracks)"
    t_ns: int
    tracks: tuple[Track, ...]
    frame_id: str = "world"


@dataclass(frozen=True, slots=True)
class GroundTruthEntity(JsonMessage):
    """The true state of one person or robot.

    Attributes:
        entity_id: The simulator's id of the person or robot.
        position_m: True position, metres.
        yaw_rad: True heading, radians.
        electronic_id: EID (MAC/IMSI) carried, if any.
        visual_id: VID, if the scenario defines one.
    """

    entity_id: str
    position_m: Vec3
    yaw_rad: float | None = None
    electronic_id: str | None = None
    visual_id: str | None = None


@dataclass(frozen=True, slots=True)
class GroundTruth(JsonMessage):
    """True states of every entity at one instant (simulated logs or surveyed references).

    Attributes:
        t_ns: Sample time.
        entities: One entry per person or robot.
        frame_id: Frame of positions, normally world.
    """

    SCHEMA: ClassVar[str] = "trackctl.GroundTruth"
    TOPIC: ClassVar[str] = "/ground_truth"
    t_ns: int
    entities: tuple[GroundTruthEntity, ...]
    frame_id: str = "world"


@dataclass(frozen=True, slots=True)
class CameraModel(JsonMessage):
    """A calibrated pinhole camera with its pose in the world.

    Attributes:
        t_ns: Time from which the model holds.
        camera: Camera name (the NAME of /NAME/image).
        width_px: Image width, pixels.
        height_px: Image height, pixels.
        fx_px, fy_px: Focal lengths, pixels.
        cx_px, cy_px: Principal point, pixels.
        distortion_model: plumb_bob (k1 k2 p1 p2 k3, OpenCV order), rational_polynomial,
            equidistant or none.
        distortion: The coefficients of that model.
        world_from_camera: Camera pose world <- camera optical frame (x right, y down,
            z forward); null when unknown.
    """

    SCHEMA: ClassVar[str] = "trackctl.CameraModel"
    TOPIC: ClassVar[str] = (
        "/<CAMERA>/camera_model (published beside foxglove.CameraCalibration on "
        "/<CAMERA>/calibration)"
    )
    t_ns: int
    camera: str
    width_px: Annotated[int, Range(ge=1)]
    height_px: Annotated[int, Range(ge=1)]
    fx_px: Annotated[float, Range(gt=0)]
    fy_px: Annotated[float, Range(gt=0)]
    cx_px: float
    cy_px: float
    distortion_model: str = "plumb_bob"
    distortion: tuple[float, ...] = ()
    world_from_camera: Transform | None = None

    def __post_init__(self) -> None:
        if self.width_px <= 0 or self.height_px <= 0:
            raise ValueError(
                f"CameraModel {self.camera!r}: image size must be positive, "
                f"got {self.width_px}x{self.height_px}"
            )
        if self.fx_px <= 0 or self.fy_px <= 0:
            raise ValueError(
                f"CameraModel {self.camera!r}: focal lengths must be positive, "
                f"got fx={self.fx_px} fy={self.fy_px}"
            )


@dataclass(frozen=True, slots=True)
class MetricReport(JsonMessage):
    """The outcome of one processor run.

    Attributes:
        t_ns: Log time the report refers to (the end of the processed span).
        processor: Registry name of the processor.
        metrics: Figure name -> value; names carry units (error_m_mean, wall_s); null when
            the run could not measure it.
        params: Configuration of the run.
        unmeasured: Figure name -> why it is null (e.g. ``idf1``: "the log has no
            /ground_truth"); a gate on such a figure is an error, not a pass.
    """

    SCHEMA: ClassVar[str] = "trackctl.MetricReport"
    TOPIC: ClassVar[str] = (
        "/metrics/<processor>; also stored as MCAP metadata named metrics/<processor>"
    )
    t_ns: int
    processor: str
    metrics: Mapping[str, MetricValue] = field(default_factory=dict)
    params: Mapping[str, MetricValue] = field(default_factory=dict)
    unmeasured: Mapping[str, str] = field(default_factory=dict)


# -- EV-Matching (dissertation §3.2) -------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class EObservations(JsonMessage):
    """E-scenario of one cell in one time window: the EIDs heard there, each inclusive or vague
    (EV-Matching, dissertation 3.2.3 B).

    An EID is inclusive when heard in this cell for most of the window's samples, vague when heard
    here only part of the time (near a border where the E-location drifts into the neighbour
    cell); EIDs heard only occasionally are in the exclusive zone and not listed.

    Attributes:
        t_ns: Start of the time window.
        window_ns: Window length, nanoseconds; the window is [timestamp, timestamp + window_ns).
        cell: Cell name <i>_<j>: column i along world x, row j along world y, cells of equal size
            from the origin.
        eids: Electronic IDs (MAC/IMSI) listed for the cell, sorted.
        vague: Per EID: true when it is in the vague zone (heard here only part of the window),
            false when inclusive.
        samples: E-location samples per EID in the window (occurrence denominator).
    """

    SCHEMA: ClassVar[str] = "trackctl.EObservations"
    TOPIC: ClassVar[str] = "/ev/e"
    t_ns: int
    window_ns: Annotated[int, Range(ge=0)]
    cell: str
    eids: tuple[str, ...] = ()
    vague: tuple[bool, ...] = ()
    samples: Annotated[int, Range(ge=0)] = 1

    def __post_init__(self) -> None:
        if len(self.eids) != len(self.vague):
            raise ValueError(
                f"EObservations {self.cell}: eids ({len(self.eids)}) and vague "
                f"({len(self.vague)}) must have the same length"
            )


@dataclass(frozen=True, slots=True)
class VScenario(JsonMessage):
    """V-scenario of one camera cell in one time window: the VIDs detected in its video, with
    ground positions.

    Attributes:
        t_ns: Start of the time window.
        window_ns: Window length, nanoseconds; the window is [timestamp, timestamp + window_ns).
        cell: Cell name <i>_<j>: column i along world x, row j along world y, cells of equal size
            from the origin.
        vids: Visual IDs detected in the window, sorted.
        x_m: Per VID: mean ground x while in the cell, metres, world frame.
        y_m: Per VID: mean ground y while in the cell, metres, world frame.
        frames: Per VID: sampled frames in which it was detected.
    """

    SCHEMA: ClassVar[str] = "trackctl.VScenario"
    TOPIC: ClassVar[str] = "/ev/cell/<i>_<j>/v (one topic per cell, one message per window)"
    t_ns: int
    window_ns: Annotated[int, Range(ge=0)]
    cell: str
    vids: tuple[str, ...] = ()
    x_m: tuple[float, ...] = ()
    y_m: tuple[float, ...] = ()
    frames: tuple[Annotated[int, Range(ge=0)], ...] = ()

    def __post_init__(self) -> None:
        n = len(self.vids)
        if not (len(self.x_m) == len(self.y_m) == len(self.frames) == n):
            raise ValueError(
                f"VScenario {self.cell}: vids, x_m, y_m and frames must have the same length"
            )


@dataclass(frozen=True, slots=True)
class EvMatch(JsonMessage):
    """The outcome for one requested EID.

    Attributes:
        eid: The electronic ID.
        vid: Matched VID, null when unresolved.
        confidence: The best VID's lead over the runner-up, as a share of the evidence
            scenarios that had video (0..1); 0 when not matched.
        scenarios: Evidence EV-scenarios (those with video) as <cell>@<window start ns>.
        reason: Why the EID is not matched; empty when matched.
        status: matched, ambiguous (the evidence fits several VIDs, or several devices carry the
            EID: see candidates) or unresolved; empty in logs written before this field existed
            (then a null vid means unresolved).
        candidates: The VIDs the evidence shows most, best first (at most two).
    """

    eid: str
    vid: str | None
    confidence: Annotated[float, Range(ge=0, le=1)]
    scenarios: tuple[str, ...] = ()
    reason: str = ""
    status: str = ""
    candidates: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class EvMatches(JsonMessage):
    """EV-Matching result: one entry per requested EID, matched to a VID or unresolved with the
    reason.

    Attributes:
        t_ns: End of the processed span.
        algorithm: ss (EID set splitting) or edp (baseline).
        matches: One entry per requested EID, in the order requested.
    """

    SCHEMA: ClassVar[str] = "trackctl.EvMatches"
    TOPIC: ClassVar[str] = "/evmatch/matches"
    t_ns: int
    algorithm: str
    matches: tuple[EvMatch, ...] = ()


@dataclass(frozen=True, slots=True)
class MirrorTransmission(JsonMessage):
    """What one S-Mirror node sent at one instant: a foreground-only image answer to robot
    requests, or a periodic E-beacon.

    Attributes:
        t_ns: Send time (the frame's time for images).
        node: The node's name (its camera: /<node>/image).
        kind: image: answer to requests; beacon: periodic E-beacon with the node's configuration.
        cast_mode: unicast: one copy per requester; broadcast: one copy for all.
        requesters: Robots that requested this image (0 for beacons).
        payload_bytes: Bytes of one copy: message and region headers + JPEG data (or the beacon's
            JSON).
        bytes_sent: Bytes on the link: payload x requesters in unicast, payload once in
            broadcast.
        image: new: changed regions encoded now; old: nothing moved, previous image re-sent; null
            for beacons.
        regions: Changed regions (JPEG crops) in the payload.
        full_frame_bytes: Bytes of the whole frame at the same JPEG quality, for comparison
            (images only).
        node_ms: Measured node processing time of this answer, milliseconds.
    """

    SCHEMA: ClassVar[str] = "trackctl.MirrorTransmission"
    TOPIC: ClassVar[str] = (
        "/smirror/<node>/sent. Sizes are bytes measured from the actual encoder output"
    )
    t_ns: int
    node: str
    kind: Literal["image", "beacon"]
    cast_mode: Literal["unicast", "broadcast"]
    requesters: Annotated[int, Range(ge=0)]
    payload_bytes: Annotated[int, Range(ge=0)]
    bytes_sent: Annotated[int, Range(ge=0)]
    image: Literal["new", "old"] | None = None
    regions: Annotated[int, Range(ge=0)] = 0
    full_frame_bytes: Annotated[int, Range(ge=0)] | None = None
    node_ms: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in ("image", "beacon"):
            raise ValueError(f"MirrorTransmission.kind must be image or beacon, got {self.kind!r}")
        if self.cast_mode not in ("unicast", "broadcast"):
            raise ValueError(
                f"MirrorTransmission.cast_mode must be unicast or broadcast, got {self.cast_mode!r}"
            )


@dataclass(frozen=True, slots=True)
class Step(JsonMessage):
    """One step of a walker, found in a phone's accelerometer (pedestrian dead reckoning).

    Attributes:
        t_ns: Time of the step.
        phone: The phone's name (the NAME of /phone/NAME/imu).
        index: Steps so far, this one included (1-based).
        cadence_hz: Step rate at this step, steps per second.
        speed_mps: Walking speed (cadence x step length), m/s.
        heading_rad: Walking direction in the world frame (yaw about +z from +x); null when the
            phone gives no orientation (accelerometer only).
        position_m: Dead-reckoned position from where the phone's first step was (z = 0); along
            +x when the heading is unknown.
    """

    SCHEMA: ClassVar[str] = "trackctl.Step"
    TOPIC: ClassVar[str] = "/pdr/<PHONE>/steps"
    t_ns: int
    phone: str
    index: Annotated[int, Range(ge=1)]
    cadence_hz: Annotated[float, Range(ge=0)]
    speed_mps: Annotated[float, Range(ge=0)]
    position_m: Vec3
    heading_rad: float | None = None


MESSAGE_TYPES: tuple[type, ...] = (
    Imu,
    RssiScan,
    WheelOdometry,
    Detections,
    Tracks,
    GroundTruth,
    CameraModel,
    MetricReport,
    EObservations,
    VScenario,
    EvMatches,
    MirrorTransmission,
    Step,
)
"""Every message type with a schema in ``formats/`` (one registration each, in codecs)."""
