"""Typed messages of trackctl's custom channels.

Every class here is a frozen dataclass with its units in field names or docstrings, and has one
JSON schema in ``formats/<SCHEMA_NAME>.json``. Conventions (see ``formats/README.md``):

* time is an integer nanosecond count (``t_ns``); in JSON it is written as Foxglove's
  ``{"sec": int, "nsec": int}`` object under ``timestamp`` so viewers order and plot it natively;
* lengths are metres, angles radians, rates per second;
* the world frame is right-handed with z up; quaternions are ``(x, y, z, w)``.

``to_json(msg)`` and ``from_json(cls, obj)`` convert between a message and its JSON object; the
codec in :mod:`trackctl.logs.codecs` adds the bytes layer.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, NamedTuple

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
    "EObservations",
    "VScenario",
    "EvMatch",
    "EvMatches",
    "MirrorTransmission",
    "time_to_json",
    "time_from_json",
]

NS_PER_S = 1_000_000_000
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

    def to_json(self) -> dict[str, float]:
        return {"x": self.x, "y": self.y, "z": self.z}

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> Vec3:
        return cls(float(obj["x"]), float(obj["y"]), float(obj["z"]))


class Quat(NamedTuple):
    """A unit quaternion in Foxglove/ROS order ``(x, y, z, w)``."""

    x: float
    y: float
    z: float
    w: float

    def to_json(self) -> dict[str, float]:
        return {"x": self.x, "y": self.y, "z": self.z, "w": self.w}

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> Quat:
        return cls(float(obj["x"]), float(obj["y"]), float(obj["z"]), float(obj["w"]))


IDENTITY_QUAT = Quat(0.0, 0.0, 0.0, 1.0)


class Pose2D(NamedTuple):
    """A planar pose in the world frame: position in metres, heading (yaw about z) in radians."""

    x_m: float
    y_m: float
    yaw_rad: float

    def to_json(self) -> dict[str, float]:
        return {"x_m": self.x_m, "y_m": self.y_m, "yaw_rad": self.yaw_rad}

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> Pose2D:
        return cls(float(obj["x_m"]), float(obj["y_m"]), float(obj["yaw_rad"]))


class Transform(NamedTuple):
    """A rigid transform ``parent <- child``: translation (metres) and rotation."""

    translation: Vec3
    rotation: Quat

    def to_json(self) -> dict[str, Any]:
        return {"translation": self.translation.to_json(), "rotation": self.rotation.to_json()}

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> Transform:
        return cls(Vec3.from_json(obj["translation"]), Quat.from_json(obj["rotation"]))


def _opt(obj: Mapping[str, Any], key: str, conv: Any) -> Any:
    value = obj.get(key)
    return None if value is None else conv(value)


@dataclass(frozen=True, slots=True)
class Imu:
    """One inertial sample of a phone or robot.

    Attributes:
        t_ns: sample time (ns).
        frame_id: the sensor's frame (``phone/<id>``).
        accel_mps2: specific force in the device frame, m/s^2, *including* gravity (a phone lying
            still reads about +9.81 on z).
        gyro_rps: angular rate in the device frame, rad/s; None for accelerometer-only devices.
        orientation: optional device-to-world rotation (Android rotation vector), world z up.
    """

    SCHEMA: ClassVar[str] = "trackctl.Imu"
    t_ns: int
    frame_id: str
    accel_mps2: Vec3
    gyro_rps: Vec3 | None = None
    orientation: Quat | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "timestamp": time_to_json(self.t_ns),
            "frame_id": self.frame_id,
            "accel_mps2": self.accel_mps2.to_json(),
            "gyro_rps": None if self.gyro_rps is None else self.gyro_rps.to_json(),
            "orientation": None if self.orientation is None else self.orientation.to_json(),
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> Imu:
        return cls(
            t_ns=time_from_json(obj["timestamp"]),
            frame_id=str(obj["frame_id"]),
            accel_mps2=Vec3.from_json(obj["accel_mps2"]),
            gyro_rps=_opt(obj, "gyro_rps", Vec3.from_json),
            orientation=_opt(obj, "orientation", Quat.from_json),
        )

    def finite_values(self) -> dict[str, float]:
        """Every float field by dotted name (for NaN/inf checks)."""
        out = {f"accel_mps2.{k}": v for k, v in self.accel_mps2._asdict().items()}
        if self.gyro_rps is not None:
            out.update({f"gyro_rps.{k}": v for k, v in self.gyro_rps._asdict().items()})
        if self.orientation is not None:
            out.update({f"orientation.{k}": v for k, v in self.orientation._asdict().items()})
        return out


@dataclass(frozen=True, slots=True)
class RssiReading:
    """Signal strength of one electronic ID (MAC/IMSI) heard by an observer, in dBm."""

    eid: str
    rssi_dbm: float

    def to_json(self) -> dict[str, Any]:
        return {"eid": self.eid, "rssi_dbm": self.rssi_dbm}

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> RssiReading:
        return cls(str(obj["eid"]), float(obj["rssi_dbm"]))


@dataclass(frozen=True, slots=True)
class RssiScan:
    """Everything one observer (AP, cell, sniffer) heard in one scan.

    Attributes:
        t_ns: scan time (ns).
        observer: the AP/cell id.
        readings: one entry per electronic ID heard.
        observer_position_m: where the observer is in the world frame, if known.
    """

    SCHEMA: ClassVar[str] = "trackctl.RssiScan"
    t_ns: int
    observer: str
    readings: tuple[RssiReading, ...]
    observer_position_m: Vec3 | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "timestamp": time_to_json(self.t_ns),
            "observer": self.observer,
            "readings": [r.to_json() for r in self.readings],
            "observer_position_m": None
            if self.observer_position_m is None
            else self.observer_position_m.to_json(),
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> RssiScan:
        return cls(
            t_ns=time_from_json(obj["timestamp"]),
            observer=str(obj["observer"]),
            readings=tuple(RssiReading.from_json(r) for r in obj["readings"]),
            observer_position_m=_opt(obj, "observer_position_m", Vec3.from_json),
        )

    def finite_values(self) -> dict[str, float]:
        return {f"readings[{i}].rssi_dbm": r.rssi_dbm for i, r in enumerate(self.readings)}


@dataclass(frozen=True, slots=True)
class WheelOdometry:
    """Wheel odometry of a differential-drive robot: encoder ticks, or body velocities, or both.

    Attributes:
        t_ns: sample time (ns).
        frame_id: the robot's base frame (``robot/<id>``).
        left_ticks, right_ticks: cumulative encoder counts, if the robot reports ticks.
        v_mps: forward speed (m/s), if reported.
        omega_rps: yaw rate (rad/s, counter-clockwise positive), if reported.
        pose: the robot's own dead-reckoned pose in its odometry frame, if reported.
    """

    SCHEMA: ClassVar[str] = "trackctl.WheelOdometry"
    t_ns: int
    frame_id: str
    left_ticks: int | None = None
    right_ticks: int | None = None
    v_mps: float | None = None
    omega_rps: float | None = None
    pose: Pose2D | None = None

    def __post_init__(self) -> None:
        has_ticks = self.left_ticks is not None and self.right_ticks is not None
        has_vel = self.v_mps is not None and self.omega_rps is not None
        if not (has_ticks or has_vel):
            raise ValueError(
                "WheelOdometry needs left_ticks and right_ticks, or v_mps and omega_rps"
            )

    def to_json(self) -> dict[str, Any]:
        return {
            "timestamp": time_to_json(self.t_ns),
            "frame_id": self.frame_id,
            "left_ticks": self.left_ticks,
            "right_ticks": self.right_ticks,
            "v_mps": self.v_mps,
            "omega_rps": self.omega_rps,
            "pose": None if self.pose is None else self.pose.to_json(),
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> WheelOdometry:
        return cls(
            t_ns=time_from_json(obj["timestamp"]),
            frame_id=str(obj["frame_id"]),
            left_ticks=_opt(obj, "left_ticks", int),
            right_ticks=_opt(obj, "right_ticks", int),
            v_mps=_opt(obj, "v_mps", float),
            omega_rps=_opt(obj, "omega_rps", float),
            pose=_opt(obj, "pose", Pose2D.from_json),
        )

    def finite_values(self) -> dict[str, float]:
        out = {k: v for k, v in (("v_mps", self.v_mps), ("omega_rps", self.omega_rps))}
        if self.pose is not None:
            out.update({f"pose.{k}": v for k, v in self.pose._asdict().items()})
        return {k: v for k, v in out.items() if v is not None}


class BBox(NamedTuple):
    """An axis-aligned image box: top-left corner and size, in pixels."""

    x_px: float
    y_px: float
    w_px: float
    h_px: float

    def to_json(self) -> dict[str, float]:
        return {"x_px": self.x_px, "y_px": self.y_px, "w_px": self.w_px, "h_px": self.h_px}

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> BBox:
        return cls(float(obj["x_px"]), float(obj["y_px"]), float(obj["w_px"]), float(obj["h_px"]))


@dataclass(frozen=True, slots=True)
class Detection:
    """One detected object in one camera frame.

    Attributes:
        box: image box in pixels.
        score: detector confidence in [0, 1].
        label: class name (``person``, ``robot``, ``tag``...).
        ground_m: the object's ground point in the world frame (z = 0), when known.
        visual_id: a per-camera visual id (VID) if the detector or simulator assigns one.
    """

    box: BBox
    score: float
    label: str = "person"
    ground_m: Vec3 | None = None
    visual_id: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "box": self.box.to_json(),
            "score": self.score,
            "label": self.label,
            "ground_m": None if self.ground_m is None else self.ground_m.to_json(),
            "visual_id": self.visual_id,
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> Detection:
        return cls(
            box=BBox.from_json(obj["box"]),
            score=float(obj["score"]),
            label=str(obj.get("label", "person")),
            ground_m=_opt(obj, "ground_m", Vec3.from_json),
            visual_id=_opt(obj, "visual_id", str),
        )


@dataclass(frozen=True, slots=True)
class Detections:
    """Every detection of one camera frame (an empty tuple is a frame with nobody in it)."""

    SCHEMA: ClassVar[str] = "trackctl.Detections"
    t_ns: int
    camera: str
    detections: tuple[Detection, ...]

    def to_json(self) -> dict[str, Any]:
        return {
            "timestamp": time_to_json(self.t_ns),
            "camera": self.camera,
            "detections": [d.to_json() for d in self.detections],
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> Detections:
        return cls(
            t_ns=time_from_json(obj["timestamp"]),
            camera=str(obj["camera"]),
            detections=tuple(Detection.from_json(d) for d in obj["detections"]),
        )


class TrackState(enum.StrEnum):
    """Lifecycle of a track at one instant."""

    TENTATIVE = "tentative"
    TRACKED = "tracked"
    PREDICTED = "predicted"
    LOST = "lost"


@dataclass(frozen=True, slots=True)
class Track:
    """One tracked object at one instant.

    Attributes:
        track_id: stable identity (a phone's MID, a robot id, or a visual id).
        position_m: position in the world frame.
        velocity_mps: velocity in the world frame, if estimated.
        covariance_m2: 3x3 position covariance, row-major (9 values), if estimated.
        state: lifecycle state.
        visual_id: the visual id (VID) the track is bound to at this instant, if any.
        score: association confidence in [0, 1], if any.
    """

    track_id: str
    position_m: Vec3
    velocity_mps: Vec3 | None = None
    covariance_m2: tuple[float, ...] | None = None
    state: TrackState = TrackState.TRACKED
    visual_id: str | None = None
    score: float | None = None

    def __post_init__(self) -> None:
        if self.covariance_m2 is not None and len(self.covariance_m2) != 9:
            raise ValueError(
                f"Track.covariance_m2 needs 9 values (3x3 row-major), got {len(self.covariance_m2)}"
            )

    def to_json(self) -> dict[str, Any]:
        return {
            "track_id": self.track_id,
            "position_m": self.position_m.to_json(),
            "velocity_mps": None if self.velocity_mps is None else self.velocity_mps.to_json(),
            "covariance_m2": None if self.covariance_m2 is None else list(self.covariance_m2),
            "state": self.state.value,
            "visual_id": self.visual_id,
            "score": self.score,
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> Track:
        cov = obj.get("covariance_m2")
        return cls(
            track_id=str(obj["track_id"]),
            position_m=Vec3.from_json(obj["position_m"]),
            velocity_mps=_opt(obj, "velocity_mps", Vec3.from_json),
            covariance_m2=None if cov is None else tuple(float(c) for c in cov),
            state=TrackState(obj.get("state", "tracked")),
            visual_id=_opt(obj, "visual_id", str),
            score=_opt(obj, "score", float),
        )


@dataclass(frozen=True, slots=True)
class Tracks:
    """Every track a processor holds at one instant, in ``frame_id`` (normally ``world``)."""

    SCHEMA: ClassVar[str] = "trackctl.Tracks"
    t_ns: int
    tracks: tuple[Track, ...]
    frame_id: str = "world"

    def to_json(self) -> dict[str, Any]:
        return {
            "timestamp": time_to_json(self.t_ns),
            "frame_id": self.frame_id,
            "tracks": [t.to_json() for t in self.tracks],
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> Tracks:
        return cls(
            t_ns=time_from_json(obj["timestamp"]),
            frame_id=str(obj.get("frame_id", "world")),
            tracks=tuple(Track.from_json(t) for t in obj["tracks"]),
        )


@dataclass(frozen=True, slots=True)
class GroundTruthEntity:
    """The true state of one person or robot.

    Attributes:
        entity_id: the simulator's id of the person/robot.
        position_m: true position in the world frame.
        yaw_rad: true heading, if meaningful.
        electronic_id: the EID (phone MAC/IMSI) it carries, if any.
        visual_id: the VID it appears under, if the scenario defines one.
    """

    entity_id: str
    position_m: Vec3
    yaw_rad: float | None = None
    electronic_id: str | None = None
    visual_id: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "entity_id": self.entity_id,
            "position_m": self.position_m.to_json(),
            "yaw_rad": self.yaw_rad,
            "electronic_id": self.electronic_id,
            "visual_id": self.visual_id,
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> GroundTruthEntity:
        return cls(
            entity_id=str(obj["entity_id"]),
            position_m=Vec3.from_json(obj["position_m"]),
            yaw_rad=_opt(obj, "yaw_rad", float),
            electronic_id=_opt(obj, "electronic_id", str),
            visual_id=_opt(obj, "visual_id", str),
        )


@dataclass(frozen=True, slots=True)
class GroundTruth:
    """True states of every entity at one instant (simulated logs, or surveyed references)."""

    SCHEMA: ClassVar[str] = "trackctl.GroundTruth"
    t_ns: int
    entities: tuple[GroundTruthEntity, ...]
    frame_id: str = "world"

    def to_json(self) -> dict[str, Any]:
        return {
            "timestamp": time_to_json(self.t_ns),
            "frame_id": self.frame_id,
            "entities": [e.to_json() for e in self.entities],
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> GroundTruth:
        return cls(
            t_ns=time_from_json(obj["timestamp"]),
            frame_id=str(obj.get("frame_id", "world")),
            entities=tuple(GroundTruthEntity.from_json(e) for e in obj["entities"]),
        )


@dataclass(frozen=True, slots=True)
class CameraModel:
    """A calibrated pinhole camera: intrinsics, distortion and (optionally) its pose in the world.

    Attributes:
        t_ns: time from which the model holds (ns).
        camera: camera name (the ``NAME`` of ``/NAME/image``).
        width_px, height_px: image size.
        fx_px, fy_px, cx_px, cy_px: pinhole intrinsics in pixels.
        distortion_model: ``plumb_bob`` (k1 k2 p1 p2 k3, OpenCV order), ``rational_polynomial``,
            ``equidistant`` (fisheye k1..k4) or ``none``.
        distortion: the coefficients of that model.
        world_from_camera: camera pose, world <- camera optical frame (x right, y down, z forward).
    """

    SCHEMA: ClassVar[str] = "trackctl.CameraModel"
    t_ns: int
    camera: str
    width_px: int
    height_px: int
    fx_px: float
    fy_px: float
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

    def to_json(self) -> dict[str, Any]:
        return {
            "timestamp": time_to_json(self.t_ns),
            "camera": self.camera,
            "width_px": self.width_px,
            "height_px": self.height_px,
            "fx_px": self.fx_px,
            "fy_px": self.fy_px,
            "cx_px": self.cx_px,
            "cy_px": self.cy_px,
            "distortion_model": self.distortion_model,
            "distortion": list(self.distortion),
            "world_from_camera": None
            if self.world_from_camera is None
            else self.world_from_camera.to_json(),
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> CameraModel:
        return cls(
            t_ns=time_from_json(obj["timestamp"]),
            camera=str(obj["camera"]),
            width_px=int(obj["width_px"]),
            height_px=int(obj["height_px"]),
            fx_px=float(obj["fx_px"]),
            fy_px=float(obj["fy_px"]),
            cx_px=float(obj["cx_px"]),
            cy_px=float(obj["cy_px"]),
            distortion_model=str(obj.get("distortion_model", "plumb_bob")),
            distortion=tuple(float(d) for d in obj.get("distortion", ())),
            world_from_camera=_opt(obj, "world_from_camera", Transform.from_json),
        )


@dataclass(frozen=True, slots=True)
class MetricReport:
    """The outcome of one processor run: named figures plus the parameters that produced them.

    Attributes:
        t_ns: log time the report refers to (the end of the processed span).
        processor: registry name of the processor (``check``, ``vm-track``...).
        metrics: figure name -> value; names carry units (``error_m_mean``, ``seconds``).
        params: the configuration of the run, for reproducibility.
    """

    SCHEMA: ClassVar[str] = "trackctl.MetricReport"
    t_ns: int
    processor: str
    metrics: Mapping[str, MetricValue] = field(default_factory=dict)
    params: Mapping[str, MetricValue] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "timestamp": time_to_json(self.t_ns),
            "processor": self.processor,
            "metrics": dict(self.metrics),
            "params": dict(self.params),
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> MetricReport:
        return cls(
            t_ns=time_from_json(obj["timestamp"]),
            processor=str(obj["processor"]),
            metrics=dict(obj.get("metrics", {})),
            params=dict(obj.get("params", {})),
        )


# -- EV-Matching (dissertation §3.2) -------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class EObservations:
    """The E-scenario of one cell in one time window: the EIDs its base station/APs heard.

    Each EID is listed with a vague flag: inclusive (heard in this cell for most of the window's
    samples) or vague (heard here only part of the time, e.g. near a border where the E-location
    drifts into the neighbour cell). EIDs heard only occasionally are in the exclusive zone and
    not listed (§3.2.3 B, vague zones).

    Attributes:
        t_ns: start of the window (ns); the window is ``[t_ns, t_ns + window_ns)``.
        window_ns: window length (ns).
        cell: cell name ``<i>_<j>`` (column i along x, row j along y).
        eids: the EIDs listed (MAC/IMSI strings), sorted.
        vague: one flag per EID, True for the vague zone.
        samples: number of E-location samples per EID in the window (occurrence denominator).
    """

    SCHEMA: ClassVar[str] = "trackctl.EObservations"
    t_ns: int
    window_ns: int
    cell: str
    eids: tuple[str, ...] = ()
    vague: tuple[bool, ...] = ()
    samples: int = 1

    def __post_init__(self) -> None:
        if len(self.eids) != len(self.vague):
            raise ValueError(
                f"EObservations {self.cell}: eids ({len(self.eids)}) and vague "
                f"({len(self.vague)}) must have the same length"
            )

    def to_json(self) -> dict[str, Any]:
        return {
            "timestamp": time_to_json(self.t_ns),
            "window_ns": self.window_ns,
            "cell": self.cell,
            "eids": list(self.eids),
            "vague": list(self.vague),
            "samples": self.samples,
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> EObservations:
        return cls(
            t_ns=time_from_json(obj["timestamp"]),
            window_ns=int(obj["window_ns"]),
            cell=str(obj["cell"]),
            eids=tuple(str(e) for e in obj.get("eids", ())),
            vague=tuple(bool(v) for v in obj.get("vague", ())),
            samples=int(obj.get("samples", 1)),
        )


@dataclass(frozen=True, slots=True)
class VScenario:
    """The V-scenario of one camera cell in one time window: the people (VIDs) its video shows.

    Attributes:
        t_ns: start of the window (ns); the window is ``[t_ns, t_ns + window_ns)``.
        window_ns: window length (ns).
        cell: cell name ``<i>_<j>``.
        vids: visual IDs detected in the window, sorted.
        x_m, y_m: each VID's mean ground position (world frame, metres) while in the cell.
        frames: number of sampled frames in which each VID was detected.
    """

    SCHEMA: ClassVar[str] = "trackctl.VScenario"
    t_ns: int
    window_ns: int
    cell: str
    vids: tuple[str, ...] = ()
    x_m: tuple[float, ...] = ()
    y_m: tuple[float, ...] = ()
    frames: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        n = len(self.vids)
        if not (len(self.x_m) == len(self.y_m) == len(self.frames) == n):
            raise ValueError(
                f"VScenario {self.cell}: vids, x_m, y_m and frames must have the same length"
            )

    def to_json(self) -> dict[str, Any]:
        return {
            "timestamp": time_to_json(self.t_ns),
            "window_ns": self.window_ns,
            "cell": self.cell,
            "vids": list(self.vids),
            "x_m": list(self.x_m),
            "y_m": list(self.y_m),
            "frames": list(self.frames),
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> VScenario:
        return cls(
            t_ns=time_from_json(obj["timestamp"]),
            window_ns=int(obj["window_ns"]),
            cell=str(obj["cell"]),
            vids=tuple(str(v) for v in obj.get("vids", ())),
            x_m=tuple(float(v) for v in obj.get("x_m", ())),
            y_m=tuple(float(v) for v in obj.get("y_m", ())),
            frames=tuple(int(v) for v in obj.get("frames", ())),
        )


@dataclass(frozen=True, slots=True)
class EvMatch:
    """The outcome for one requested EID.

    Attributes:
        eid: the electronic ID.
        vid: the matched visual ID, or None when unresolved.
        confidence: share of the EID's evidence scenarios that show the VID, scaled by the
            margin over the runner-up (0..1); 0 when unresolved.
        scenarios: the EV-scenarios used as evidence, as ``<cell>@<window start ns>``.
        reason: why the EID is unresolved (empty when matched).
    """

    eid: str
    vid: str | None
    confidence: float
    scenarios: tuple[str, ...] = ()
    reason: str = ""

    def to_json(self) -> dict[str, Any]:
        return {
            "eid": self.eid,
            "vid": self.vid,
            "confidence": self.confidence,
            "scenarios": list(self.scenarios),
            "reason": self.reason,
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> EvMatch:
        return cls(
            eid=str(obj["eid"]),
            vid=_opt(obj, "vid", str),
            confidence=float(obj.get("confidence", 0.0)),
            scenarios=tuple(str(s) for s in obj.get("scenarios", ())),
            reason=str(obj.get("reason", "")),
        )


@dataclass(frozen=True, slots=True)
class EvMatches:
    """EV-Matching results: one entry per requested EID (matched or unresolved)."""

    SCHEMA: ClassVar[str] = "trackctl.EvMatches"
    t_ns: int
    algorithm: str
    matches: tuple[EvMatch, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {
            "timestamp": time_to_json(self.t_ns),
            "algorithm": self.algorithm,
            "matches": [m.to_json() for m in self.matches],
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> EvMatches:
        return cls(
            t_ns=time_from_json(obj["timestamp"]),
            algorithm=str(obj["algorithm"]),
            matches=tuple(EvMatch.from_json(m) for m in obj.get("matches", ())),
        )


@dataclass(frozen=True, slots=True)
class MirrorTransmission:
    """What one S-Mirror node sent at one instant (an image answer or an E-beacon).

    Attributes:
        t_ns: send time (the frame's time for images).
        node: the node's name (its camera).
        kind: ``image`` (foreground-only answer to requests) or ``beacon`` (periodic E-beacon).
        cast_mode: ``unicast`` (one copy per requester) or ``broadcast`` (one copy for all).
        requesters: robots that requested this image (0 for beacons).
        image: ``new`` (changed regions encoded now) or ``old`` (nothing moved, the previous
            image re-sent); None for beacons.
        regions: changed regions in the image payload.
        payload_bytes: bytes of one copy (headers + JPEG data, or the beacon's JSON).
        bytes_sent: bytes on the link (payload x requesters in unicast, payload once otherwise).
        full_frame_bytes: bytes of the whole frame at the same JPEG quality, for comparison.
        node_ms: measured node processing time of this answer (ms).
    """

    SCHEMA: ClassVar[str] = "trackctl.MirrorTransmission"
    t_ns: int
    node: str
    kind: str
    cast_mode: str
    requesters: int
    payload_bytes: int
    bytes_sent: int
    image: str | None = None
    regions: int = 0
    full_frame_bytes: int | None = None
    node_ms: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in ("image", "beacon"):
            raise ValueError(f"MirrorTransmission.kind must be image or beacon, got {self.kind!r}")
        if self.cast_mode not in ("unicast", "broadcast"):
            raise ValueError(
                f"MirrorTransmission.cast_mode must be unicast or broadcast, got {self.cast_mode!r}"
            )

    def to_json(self) -> dict[str, Any]:
        return {
            "timestamp": time_to_json(self.t_ns),
            "node": self.node,
            "kind": self.kind,
            "cast_mode": self.cast_mode,
            "requesters": self.requesters,
            "payload_bytes": self.payload_bytes,
            "bytes_sent": self.bytes_sent,
            "image": self.image,
            "regions": self.regions,
            "full_frame_bytes": self.full_frame_bytes,
            "node_ms": self.node_ms,
        }

    @classmethod
    def from_json(cls, obj: Mapping[str, Any]) -> MirrorTransmission:
        return cls(
            t_ns=time_from_json(obj["timestamp"]),
            node=str(obj["node"]),
            kind=str(obj["kind"]),
            cast_mode=str(obj["cast_mode"]),
            requesters=int(obj["requesters"]),
            payload_bytes=int(obj["payload_bytes"]),
            bytes_sent=int(obj["bytes_sent"]),
            image=_opt(obj, "image", str),
            regions=int(obj.get("regions", 0)),
            full_frame_bytes=_opt(obj, "full_frame_bytes", int),
            node_ms=_opt(obj, "node_ms", float),
        )


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
)
"""Every message type with a schema in ``formats/`` (one registration each, in codecs)."""
