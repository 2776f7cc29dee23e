"""The S-Mirror run as events over the log: node frames, wheel odometry, ground-truth samples.

:class:`Localizer` holds the state of the nodes, the links and every localized robot's pose filter
(:class:`RobotRun`), and handles one message at a time in log order:

* a node frame: the node senses its foreground and, when robots request images (the log's robots
  that ask this node, plus other requesters that are traffic only), encodes and sends them
  (unicast or broadcast); each of our robots that asked detects its own LEDs (its colours, near
  its predicted position) in the crops it receives and queues the fix for the time its copy
  arrives (communication and processing delay);
* wheel odometry of a robot: it dead-reckons and applies the fixes that have arrived;
* a ground-truth sample: scored (metrics only) once the estimate has reached its time.

The centralized baseline (vision only) runs LED detection on whole frames instead.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from trackctl.geometry.odometry import increment, integrate_step
from trackctl.logs import topics
from trackctl.logs.foxglove import (
    map_base_transform,
    map_odom_transform,
    odom_base_transform,
    pose_in_frame,
)
from trackctl.logs.messages import GroundTruth, MirrorTransmission, WheelOdometry
from trackctl.logs.reader import LogMessage
from trackctl.logs.writer import LogWriter
from trackctl.smirror.config import Mode, SmirrorConfig, SmirrorResult, pose_topic, sent_topic
from trackctl.smirror.link import NodeLink
from trackctl.smirror.node import CastMode, ForegroundPayload, beacon_bytes, decide_cast
from trackctl.smirror.robot import LedFix, PoseFilter, locate_robot
from trackctl.smirror.site import Coverage, RobotSite, Site

__all__ = ["Localizer", "RobotRun", "decode_frame", "merge_robots"]


def decode_frame(data: bytes, flags: int = cv2.IMREAD_COLOR) -> np.ndarray | None:
    """A JPEG/PNG frame as pixels, or None when it does not decode."""
    try:
        img = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    except cv2.error:
        return None
    return img


@dataclass(eq=False)
class RobotRun:
    """One localized robot: its pose filter, the fixes on their way to it, its figures."""

    site: RobotSite
    res: SmirrorResult
    pose_out: str
    filt: PoseFilter | None = None
    last_odo: WheelOdometry | None = None
    pending: list[tuple[int, LedFix, float, float]] = field(default_factory=list)
    """Fixes by arrival time, with their position and heading sigmas."""
    central: list[tuple[int, LedFix]] = field(default_factory=list)
    """Centralized fixes by availability time."""
    central_pose: LedFix | None = None
    central_ms: float = 0.0
    last_answer: tuple[int, float] | None = None
    """(frame t_ns, delay ms) of the last answer that reached this robot."""
    dr_ms: list[float] = field(default_factory=list)
    gt_wait: list[tuple[int, float, float]] = field(default_factory=list)
    last_gt_xy: tuple[float, float] | None = None
    path_m: float = 0.0
    odom_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """The wheels alone, from the first odometry sample (the ``NAME/odom`` frame's origin)."""
    _covering: tuple[tuple[float, float], str | None] | None = None
    """The node covering the last pose asked about (the nodes' frames of one instant ask alike)."""

    @property
    def name(self) -> str:
        return self.site.name

    @property
    def tf_out(self) -> str:
        """The robot's frame tree: ``/smirror/NAME/tf`` (foxglove.FrameTransform)."""
        return topics.transforms(f"/smirror/{self.name}")

    def requests(self, node: str, cover: Coverage) -> bool:
        """Whether this robot asks ``node`` for its image: lost, it asks every node until one
        shows its LEDs; localized, it asks the node that covers its pose."""
        if self.filt is None:
            return False
        if not self.filt.localized:
            return True
        x, y, _ = self.filt.pose
        if self._covering is None or self._covering[0] != (x, y):
            cov = cover.covering((x, y))
            self._covering = ((x, y), None if cov is None else cov[0])
        return self._covering[1] == node


class Localizer:
    """State and message handlers of one S-Mirror run.

    Args:
        site: the log's site (cameras, robots, LEDs, wheels, coverage).
        cfg: the run's configuration.
        writer: where poses and transmissions go (None: figures only).
    """

    def __init__(self, site: Site, cfg: SmirrorConfig, writer: LogWriter | None) -> None:
        self.site, self.cfg, self.writer = site, cfg, writer
        names = [r.name for r in site.robots]
        self.res = SmirrorResult(requesters=site.requesters, robot=",".join(names))
        self.robots = [
            RobotRun(r, SmirrorResult(requesters=site.requesters, robot=r.name), pose_topic(r.name))
            for r in site.robots
        ]
        self.by_odom = {r.site.odom_topic: r for r in self.robots}
        self.by_name = {r.name: r for r in self.robots}
        self.rng = np.random.default_rng(cfg.seed)
        self.links = {n: NodeLink(cfg.link, self.rng) for n in sorted(site.models)}
        self.beacon_sizes = {n: beacon_bytes(m) for n, m in site.models.items()}
        self.next_beacon_ns = 0
        self.beacon_ns = int(cfg.beacon_period_s * 1e9)
        self.frame_period_ns: dict[str, int] = {}
        self.last_frame_ns: dict[str, int] = {}
        self.t_first: int | None = None
        self.t_last: int | None = None

    def wanted_topics(self) -> list[str]:
        """Node images, odometry (mirror+odom) and ground truth (for the metrics)."""
        return list(self.expected_schemas())

    def expected_schemas(self) -> dict[str, str]:
        """The schema each wanted topic must have (a topic whose schema lies is skipped)."""
        odom = [r.site.odom_topic for r in self.robots] if self.site.use_odom else []
        return {
            **{t: "foxglove.CompressedImage" for t in self.site.image_topics},
            **{t: WheelOdometry.SCHEMA for t in odom},
            topics.GROUND_TRUTH: GroundTruth.SCHEMA,
        }

    # -- dispatch -------------------------------------------------------------------------------
    def on_message(self, msg: LogMessage) -> None:
        """Handle one message of the log, in log-time order."""
        t_ns = msg.log_time_ns
        self.t_first = t_ns if self.t_first is None else self.t_first
        self.t_last = t_ns
        if self.cfg.mode is not Mode.CENTRALIZED:
            self._flush_beacons(t_ns)
        if msg.topic == topics.GROUND_TRUTH:
            self._on_truth(t_ns, msg.message)
        elif msg.topic in self.by_odom:
            self._on_odometry(self.by_odom[msg.topic], t_ns, msg.message)
        else:
            self._on_frame(msg.topic.split("/")[1], t_ns, bytes(msg.message.data))

    def finish(self) -> SmirrorResult:
        """Score what is still waiting for the estimate; the run's figures (all robots' samples
        together, in time order) and each robot's in ``per_robot``."""
        duration = 0.0
        if self.t_first is not None and self.t_last is not None:
            duration = (self.t_last - self.t_first) / 1e9
        for robot in self.robots:
            for t_ns, gx, gy in robot.gt_wait:
                self._score(robot, t_ns, gx, gy)
            robot.gt_wait.clear()
            robot.res.duration_s = duration
        self.res.duration_s = duration
        merge_robots(self.res, [r.res for r in self.robots])
        return self.res

    # -- beacons --------------------------------------------------------------------------------
    def _flush_beacons(self, t_ns: int) -> None:
        while self.next_beacon_ns <= t_ns:
            for name in sorted(self.site.models):
                size = self.beacon_sizes[name]
                self.res.beacons += 1
                self.res.events.append((self.next_beacon_ns / 1e9, size, size, 0))
                if self.writer is not None:
                    self.writer.write(
                        sent_topic(name),
                        MirrorTransmission(
                            self.next_beacon_ns,
                            name,
                            "beacon",
                            CastMode.BROADCAST.value,
                            0,
                            size,
                            size,
                        ),
                        self.next_beacon_ns,
                    )
            self.next_beacon_ns += self.beacon_ns

    # -- ground truth (metrics only) --------------------------------------------------------------
    def _on_truth(self, t_ns: int, truth: GroundTruth) -> None:
        for ent in truth.entities:
            robot = self.by_name.get(ent.entity_id)
            if robot is None:
                continue
            gx, gy = ent.position_m.x, ent.position_m.y
            if robot.last_gt_xy is not None:
                robot.path_m += math.hypot(gx - robot.last_gt_xy[0], gy - robot.last_gt_xy[1])
            robot.last_gt_xy = (gx, gy)
            if self.site.use_odom and (robot.filt is None or robot.filt.t_ns < t_ns):
                robot.gt_wait.append((t_ns, gx, gy))  # scored once odometry reaches it
            else:
                self._score(robot, t_ns, gx, gy)

    def _estimate(self, robot: RobotRun, t_ns: int) -> tuple[float, float, float] | None:
        if self.site.use_odom:
            filt = robot.filt
            return None if filt is None or not filt.localized else filt.pose
        while robot.central and robot.central[0][0] <= t_ns:
            robot.central_pose = robot.central.pop(0)[1]
        if robot.central_pose is None:
            return None
        pose = robot.central_pose
        return pose.x_m, pose.y_m, pose.yaw_rad

    def _score(self, robot: RobotRun, t_ns: int, gx: float, gy: float) -> None:
        est = self._estimate(robot, t_ns)
        res, cfg = robot.res, self.cfg
        if est is None:
            res.unlocalized_samples += 1
            return
        cov = self.site.cover.covering((gx, gy))
        res.t_s.append(t_ns / 1e9)
        res.error_m.append(math.hypot(est[0] - gx, est[1] - gy))
        res.in_coverage.append(cov is not None)
        res.range_m.append(math.nan if cov is None else cov[1])
        res.path_m.append(robot.path_m)
        if not self.site.use_odom:
            res.delay_ms.append(cfg.sensing_ms + robot.central_ms)
            return
        answer = robot.last_answer
        fresh = (
            answer is not None
            and t_ns - answer[0] <= 1.5 * max(self.frame_period_ns.values() or [0]) + 3e8
        )
        dr = float(np.median(robot.dr_ms[-50:])) if robot.dr_ms else 0.0
        res.delay_ms.append(answer[1] if fresh and answer is not None else cfg.sensing_ms + dr)

    # -- odometry -------------------------------------------------------------------------------
    def _on_odometry(self, robot: RobotRun, t_ns: int, odo: WheelOdometry) -> None:
        started = time.perf_counter()
        res = robot.res
        if robot.filt is None:
            # a known start (a dock) or none: dead reckoning from a placeholder until a fix
            known = self.site.start is not None
            x, y, yaw = self.site.start or (0.0, 0.0, 0.0)
            robot.filt = PoseFilter(x, y, yaw, t_ns, self.cfg.filter, localized=known)
        else:
            was = robot.filt.localized
            dt = (t_ns - robot.filt.t_ns) / 1e9
            ds, dyaw = self._dead_reckon(robot, robot.filt, t_ns, odo)
            robot.odom_pose = integrate_step(*robot.odom_pose, ds, dyaw)
            res.odometry_s += dt
            res.localized_s += dt if was else 0.0
        robot.dr_ms.append((time.perf_counter() - started) * 1e3)
        robot.last_odo = odo
        filt = robot.filt
        if filt.localized and res.first_fix_s is None and self.t_first is not None:
            res.first_fix_s = (t_ns - self.t_first) / 1e9
        if self.writer is not None:
            self._write_frames(robot, t_ns)
        if self.writer is not None and filt.localized:
            x, y, yaw = filt.pose
            self.writer.write(robot.pose_out, pose_in_frame(t_ns, x, y, yaw), t_ns)
        while robot.gt_wait and robot.gt_wait[0][0] <= t_ns:
            self._score(robot, *robot.gt_wait.pop(0))

    def _write_frames(self, robot: RobotRun, t_ns: int) -> None:
        """The robot's frame tree at an odometry sample: ``NAME/odom -> NAME/base_link`` (the
        wheels alone) and, once localized, ``map -> NAME/odom`` (the estimate's correction)."""
        assert self.writer is not None and robot.filt is not None
        odom = robot.odom_pose
        self.writer.write(robot.tf_out, odom_base_transform(t_ns, robot.name, *odom), t_ns)
        if robot.filt.localized:
            tf = map_odom_transform(t_ns, robot.name, robot.filt.pose, odom)
            self.writer.write(robot.tf_out, tf, t_ns)

    def _dead_reckon(
        self, robot: RobotRun, filt: PoseFilter, t_ns: int, odo: WheelOdometry
    ) -> tuple[float, float]:
        """Apply the fixes that have arrived, then the wheel motion since the last sample;
        returns that motion (distance m, heading change rad)."""
        while robot.pending and robot.pending[0][0] <= t_ns:
            _, ready, sp, sy = robot.pending.pop(0)
            filt.last_nis = None
            robot.res.fixes_used += filt.apply_fix(ready, sp, sy)
            if filt.last_nis is not None:
                robot.res.nis.append(filt.last_nis)
        last = robot.last_odo
        assert last is not None
        # encoder ticks, or v/omega held over the interval, or the robot's own poses
        ds, dyaw = increment(last, odo, robot.site.drive) or (0.0, 0.0)
        filt.step(t_ns, ds, dyaw)
        return ds, dyaw

    # -- node frames ----------------------------------------------------------------------------
    def _on_frame(self, name: str, t_ns: int, data: bytes) -> None:
        if name in self.last_frame_ns:
            self.frame_period_ns[name] = t_ns - self.last_frame_ns[name]
        self.last_frame_ns[name] = t_ns
        frame = decode_frame(data)
        if frame is None:
            self.res.decode_failures += 1
            return
        if self.cfg.mode is Mode.CENTRALIZED:
            self._centralized(name, t_ns, frame)
        else:
            self._mirror(name, t_ns, frame)

    def _centralized(self, name: str, t_ns: int, frame: np.ndarray) -> None:
        """The vision-only baseline: LED detection on the whole frame, at the server."""
        cfg = self.cfg
        for robot in self.robots:
            res = robot.res
            started = time.perf_counter()
            last = robot.central_pose
            near = None if last is None else (last.x_m, last.y_m)
            fix = locate_robot([(0, 0, frame)], self.site.cams[name], robot.site.led, t_ns, near)
            robot.central_ms = (time.perf_counter() - started) * 1e3
            res.robot_ms.append(robot.central_ms)
            res.fix_attempts += 1
            if fix is None:
                continue
            res.fixes += 1
            avail = t_ns + int((cfg.sensing_ms + cfg.processing_ms) * 1e6)
            robot.central.append((avail, fix))
            robot.central.sort(key=lambda c: c[0])
            if self.writer is not None:
                pose = pose_in_frame(t_ns, fix.x_m, fix.y_m, fix.yaw_rad)
                self.writer.write(robot.pose_out, pose, t_ns)
                # vision only: no odometry frame between the map and the robot
                tf = map_base_transform(t_ns, robot.name, fix.x_m, fix.y_m, fix.yaw_rad)
                self.writer.write(robot.tf_out, tf, t_ns)

    def _mirror(self, name: str, t_ns: int, frame: np.ndarray) -> None:
        """A node senses; when robots request images it encodes and sends its foreground."""
        node, res, cfg = self.site.nodes[name], self.res, self.cfg
        mask = node.sense(frame)
        ours = [r for r in self.robots if r.requests(name, self.site.cover)]
        requests = len(ours) + (self.site.requesters - len(self.robots))
        if requests == 0:
            return
        started = time.perf_counter()
        payload, is_new = node.encode(t_ns, frame, mask)
        node_ms = node.last_sense_ms + (time.perf_counter() - started) * 1e3
        res.node_ms.append(node_ms)
        full = node.full_frame_bytes(frame)
        cast = decide_cast(requests, cfg.broadcast_threshold)
        size = payload.size_bytes
        broadcast = cast is CastMode.BROADCAST
        delivery = self.links[name].send(t_ns / 1e6, size, requests, broadcast, len(ours))
        res.queue_ms.append(delivery.queue_ms)
        if delivery.dropped:
            res.answers_dropped += 1
            for robot in ours:
                robot.res.ours_requested += 1
            return
        sent = size if broadcast else size * requests
        res.cast_modes.add(cast.value)
        res.image_messages += 1
        res.images_new += is_new
        res.images_old += not is_new
        res.foreground_bytes += size
        res.full_frame_bytes += full
        res.events.append((t_ns / 1e9, sent, size * requests, size * len(ours)))
        if self.writer is not None:
            self.writer.write(
                sent_topic(name),
                MirrorTransmission(
                    t_ns,
                    name,
                    "image",
                    cast.value,
                    requests,
                    size,
                    sent,
                    "new" if is_new else "old",
                    len(payload.regions),
                    full,
                    round(node_ms, 3),
                ),
                t_ns,
            )
        for robot, comm_ms in zip(ours, delivery.arrivals, strict=True):
            self._receive(robot, name, t_ns, payload, comm_ms, node_ms)

    def _receive(
        self,
        robot: RobotRun,
        name: str,
        t_ns: int,
        payload: ForegroundPayload,
        comm_ms: float | None,
        node_ms: float,
    ) -> None:
        """One robot: the transfer, then LED detection on the received crops; the fix is queued
        for the time it arrives."""
        res, cfg, led, filt = robot.res, self.cfg, robot.site.led, robot.filt
        assert filt is not None
        res.ours_requested += 1
        if comm_ms is None:
            res.broadcast_lost += 1
            return
        started = time.perf_counter()
        near = (filt.pose[0], filt.pose[1]) if filt.localized else None
        fix = locate_robot(payload.crops(), self.site.cams[name], led, payload.t_ns, near)
        robot_ms = (time.perf_counter() - started) * 1e3
        res.robot_ms.append(robot_ms)
        res.fix_attempts += 1
        robot.last_answer = (t_ns, cfg.sensing_ms + node_ms + comm_ms + robot_ms)
        if fix is None:
            return
        res.fixes += 1
        sp, sy = filt.fix_sigma(fix, self.site.cams[name], led.led_height_m)
        arrival = t_ns + int((comm_ms + cfg.processing_ms) * 1e6)
        robot.pending.append((arrival, fix, sp, sy))
        robot.pending.sort(key=lambda p: p[0])


ROBOT_COUNTS = (
    "ours_requested",
    "fix_attempts",
    "fixes",
    "fixes_used",
    "broadcast_lost",
    "localized_s",
    "odometry_s",
    "unlocalized_samples",
)


def merge_robots(total: SmirrorResult, robots: list[SmirrorResult]) -> None:
    """Put the robots' figures into the run's: counts summed, samples merged by time (stable,
    so one robot's samples stay exactly its own), the first fix the earliest."""
    order = np.argsort(np.concatenate([np.asarray(r.t_s, float) for r in robots]), kind="stable")
    for name in ("t_s", "error_m", "in_coverage", "range_m", "delay_ms", "path_m"):
        joined = [v for r in robots for v in getattr(r, name)]
        setattr(total, name, [joined[i] for i in order])
    for name in ("robot_ms", "nis"):
        setattr(total, name, [v for r in robots for v in getattr(r, name)])
    for name in ROBOT_COUNTS:
        setattr(total, name, sum(getattr(r, name) for r in robots))
    firsts = [r.first_fix_s for r in robots if r.first_fix_s is not None]
    total.first_fix_s = min(firsts) if firsts else None
    total.per_robot = {r.robot: r for r in robots}
