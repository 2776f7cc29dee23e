"""The ``pdr`` processor: steps, cadence, speed, heading and a dead-reckoned path per phone.

``trackctl process LOG --with pdr --out OUT --json``. Reads every ``/phone/<NAME>/imu``
(trackctl.Imu: accelerometer, optional gyro and orientation, any rate from 5 to 200 Hz),
writes per phone

* ``/pdr/<NAME>/steps`` (trackctl.Step): one message per step;
* ``/pdr/<NAME>/pose`` (foxglove.PoseInFrame): the dead-reckoned pose at each step;
* ``/pdr/<NAME>/path`` (foxglove.PosesInFrame): the whole path, once, at the phone's last step;

in the phone's own frame ``pdr/<NAME>`` (it starts at the origin; the world is unknown to a
phone alone). Heading is the orientation's yaw (Android rotation vector) when the phone gives
one, else the integrated gyro about the vertical; an accelerometer-only phone has none and its
path is drawn along +x (a warning says so). Speed = cadence x ``step_length_m``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame
from scipy.spatial.transform import Rotation

from trackctl.errors import IncompleteInputWarning
from trackctl.logs.foxglove import pose_in_frame
from trackctl.logs.messages import Imu, MetricReport, Step, Vec3
from trackctl.logs.reader import LogReader
from trackctl.logs.writer import LogWriter
from trackctl.pdr.steps import StepConfig, detect_steps
from trackctl.processing.base import ProcessorInfo, Progress

__all__ = ["PdrConfig", "PdrProcessor", "PDR_PROCESSOR", "steps_topic"]


def steps_topic(phone: str) -> str:
    return f"/pdr/{phone}/steps"


@dataclass(frozen=True, slots=True)
class PdrConfig:
    """Options of the ``pdr`` processor."""

    step_length_m: float = 0.7
    """Step length (a typical adult walking step; calibrate per person for better distance)."""
    steps: StepConfig = field(default_factory=StepConfig)


@dataclass
class _Phone:
    """One phone's samples (arrays grow with the recording: 8 floats per sample)."""

    t_ns: list[int] = field(default_factory=list)
    acc: list[tuple[float, float, float]] = field(default_factory=list)
    yaw: list[float] = field(default_factory=list)
    gyro_up: list[float] = field(default_factory=list)

    def add(self, imu: Imu) -> None:
        self.t_ns.append(imu.t_ns)
        self.acc.append((imu.accel_mps2.x, imu.accel_mps2.y, imu.accel_mps2.z))
        if imu.orientation is not None:
            q = imu.orientation
            rot = Rotation.from_quat([q.x, q.y, q.z, q.w])
            self.yaw.append(float(rot.as_euler("ZYX")[0]))
        else:
            self.yaw.append(math.nan)
        if imu.gyro_rps is not None:
            # rate about the vertical: the gyro along gravity's direction in the device frame
            a = np.array(self.acc[-1])
            g = a / max(float(np.linalg.norm(a)), 1e-9)
            w = np.array([imu.gyro_rps.x, imu.gyro_rps.y, imu.gyro_rps.z])
            self.gyro_up.append(float(w @ g))
        else:
            self.gyro_up.append(math.nan)


class PdrProcessor:
    """Pedestrian dead reckoning of every phone (see the module docstring)."""

    name = "pdr"

    def __init__(self, config: PdrConfig | None = None) -> None:
        self.config = config or PdrConfig()

    def run(
        self, reader: LogReader, writer: LogWriter, progress: Progress | None = None
    ) -> MetricReport:
        imu_topics = sorted(
            t
            for t, info in reader.topics().items()
            if info.schema_name == Imu.SCHEMA and t.startswith("/phone/")
        )
        if not imu_topics:
            reader.require(["/phone/<NAME>/imu"], self.name, "phone accelerometer samples")
        phones: dict[str, _Phone] = {}
        total = reader.count(imu_topics)
        for n, msg in enumerate(reader.messages(imu_topics), 1):
            phones.setdefault(msg.topic.split("/")[2], _Phone()).add(msg.message)
            if progress is not None and n % 5000 == 0:
                progress(n, total, "reading the phones' IMU")
        metrics: dict[str, float | int | str | None] = {"phones": len(phones)}
        total = 0
        seconds = 0.0
        no_heading = []
        for name, ph in sorted(phones.items()):
            steps, secs, heading_known = self._phone(name, ph, writer, metrics)
            total += steps
            seconds += secs
            if not heading_known:
                no_heading.append(name)
        if no_heading:
            warnings.warn(
                f"{reader.path}: {', '.join(no_heading)}: accelerometer only (no orientation or "
                "gyro): steps and speed are measured, the heading is not; paths are drawn along +x",
                IncompleteInputWarning,
                stacklevel=2,
            )
        metrics["steps_total"] = total
        metrics["duration_s"] = round(seconds, 3)
        return MetricReport(
            t_ns=reader.end_ns or 0,
            processor=self.name,
            metrics=metrics,
            params={"step_length_m": self.config.step_length_m},
        )

    def _phone(
        self, name: str, ph: _Phone, writer: LogWriter, metrics: dict[str, float | int | str | None]
    ) -> tuple[int, float, bool]:
        t_ns = np.asarray(ph.t_ns, np.int64)
        order = np.argsort(t_ns, kind="stable")
        t_ns = t_ns[order]
        acc = np.asarray(ph.acc, float)[order]
        t_s = (t_ns - t_ns[0]) / 1e9
        res = detect_steps(t_s, acc, self.config.steps)
        secs = float(t_s[-1]) if len(t_s) else 0.0
        metrics[f"steps/{name}"] = res.steps
        metrics[f"duration_s/{name}"] = round(secs, 3)
        rate = 1.0 / float(np.median(np.diff(t_s))) if len(t_s) > 1 else 0.0
        metrics[f"imu_rate_hz/{name}"] = round(rate, 2)
        metrics[f"bad_samples/{name}"] = res.bad_samples
        walking = res.cadence_hz > 0
        dt = 1.0 / res.rate_hz if res.rate_hz else 0.0  # the analysis grid's step
        metrics[f"walking_s/{name}"] = round(float(walking.sum() * dt), 3)
        metrics[f"cadence_hz/{name}"] = (
            round(float(np.median(res.cadence_hz[walking])), 3) if walking.any() else None
        )
        if res.steps == 0:
            metrics[f"distance_m/{name}"] = 0.0
            return 0, secs, True
        step_t = res.step_times_s
        # t_s and step times start at the first good sample; its offset from the first sample
        first_good = float(t_s[np.flatnonzero(np.linalg.norm(acc, axis=1) > 1.0)[0]])
        heading, known = _heading(t_s, np.asarray(ph.yaw)[order], np.asarray(ph.gyro_up)[order])
        at = step_t + first_good
        yaw = np.interp(at, t_s, heading) if known else np.zeros(len(at))
        cadence = np.interp(step_t, res.t_s, res.cadence_hz)
        length = self.config.step_length_m
        xy = np.cumsum(np.column_stack([np.cos(yaw), np.sin(yaw)]) * length, axis=0)
        stamps = t_ns[0] + np.round(at * 1e9).astype(np.int64)
        frame = f"pdr/{name}"
        path = PosesInFrame(frame_id=frame)
        for k in range(len(at)):
            t = int(stamps[k])
            writer.write(
                steps_topic(name),
                Step(
                    t_ns=t,
                    phone=name,
                    index=k + 1,
                    cadence_hz=round(float(cadence[k]), 4),
                    speed_mps=round(float(cadence[k] * length), 4),
                    position_m=Vec3(float(xy[k, 0]), float(xy[k, 1]), 0.0),
                    heading_rad=round(float(yaw[k]), 5) if known else None,
                ),
                t,
            )
            pose = pose_in_frame(t, float(xy[k, 0]), float(xy[k, 1]), float(yaw[k]), frame)
            writer.write(f"/pdr/{name}/pose", pose, t)
            path.poses.append(pose.pose)
        path.timestamp.FromNanoseconds(int(stamps[-1]))
        writer.write(f"/pdr/{name}/path", path, int(stamps[-1]))
        metrics[f"distance_m/{name}"] = round(res.steps * length, 3)
        return res.steps, secs, known


def _heading(t_s: np.ndarray, yaw: np.ndarray, gyro_up: np.ndarray) -> tuple[np.ndarray, bool]:
    """Heading at every sample: orientation yaw where given, else the integrated vertical gyro;
    (zeros, False) when neither exists."""
    if np.isfinite(yaw).any():
        good = np.isfinite(yaw)
        unwrapped = np.unwrap(yaw[good])
        return np.interp(t_s, t_s[good], unwrapped), True
    if np.isfinite(gyro_up).any():
        w = np.nan_to_num(gyro_up)
        return np.concatenate(([0.0], np.cumsum(np.diff(t_s) * w[1:]))), True
    return np.zeros(len(t_s)), False


PDR_PROCESSOR = ProcessorInfo(
    name="pdr",
    description="Pedestrian dead reckoning per phone: steps, cadence, speed, heading, path",
    factory=PdrProcessor,
)
"""Registry entry (entry point ``trackctl.processors``)."""
