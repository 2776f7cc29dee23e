"""The S-Mirror run as events over the log: node frames, wheel odometry, ground-truth samples.

:class:`Localizer` holds the state of the nodes, the link and the robot's pose filter, and handles
one message at a time in log order:

* a node frame: the node senses its foreground and, when robots request images, encodes and sends
  them (unicast or broadcast); our robot detects its LEDs in the crops it receives and queues the
  fix for the time it arrives (communication and processing delay);
* wheel odometry: the robot dead-reckons and applies the fixes that have arrived;
* a ground-truth sample: scored (metrics only) once the estimate has reached its time.

The centralized baseline (vision only) runs LED detection on whole frames instead.
"""

from __future__ import annotations

import math
import time

import cv2
import numpy as np

from trackctl.geometry.odometry import increment
from trackctl.logs import topics
from trackctl.logs.foxglove import pose_in_frame
from trackctl.logs.messages import GroundTruth, MirrorTransmission, WheelOdometry
from trackctl.logs.reader import LogMessage
from trackctl.logs.writer import LogWriter
from trackctl.smirror.config import Mode, SmirrorConfig, SmirrorResult, pose_topic, sent_topic
from trackctl.smirror.link import Delivery, NodeLink
from trackctl.smirror.node import CastMode, ForegroundPayload, beacon_bytes, decide_cast
from trackctl.smirror.robot import LedFix, PoseFilter, locate_robot
from trackctl.smirror.site import Site

__all__ = ["Localizer", "decode_frame"]


def decode_frame(data: bytes, flags: int = cv2.IMREAD_COLOR) -> np.ndarray | None:
    """A JPEG/PNG frame as pixels, or None when it does not decode."""
    try:
        img = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    except cv2.error:
        return None
    return img


class Localizer:
    """State and message handlers of one S-Mirror run.

    Args:
        site: the log's site (cameras, robot, LEDs, wheels, coverage).
        cfg: the run's configuration.
        writer: where poses and transmissions go (None: figures only).
    """

    def __init__(self, site: Site, cfg: SmirrorConfig, writer: LogWriter | None) -> None:
        self.site, self.cfg, self.writer = site, cfg, writer
        self.res = SmirrorResult(requesters=site.requesters, robot=site.robot)
        self.rng = np.random.default_rng(cfg.seed)
        self.links = {n: NodeLink(cfg.link, self.rng) for n in sorted(site.models)}
        self.pose_out = pose_topic(site.robot)
        self.beacon_sizes = {n: beacon_bytes(m) for n, m in site.models.items()}
        self.next_beacon_ns = 0
        self.beacon_ns = int(cfg.beacon_period_s * 1e9)
        self.frame_period_ns: dict[str, int] = {}
        self.last_frame_ns: dict[str, int] = {}
        self.filt: PoseFilter | None = None
        self.last_odo: WheelOdometry | None = None
        self.pending: list[tuple[int, LedFix, float, float]] = []  # arrival, fix, sigmas
        self.central: list[tuple[int, LedFix]] = []  # centralized fixes by availability time
        self.central_pose: LedFix | None = None
        self.last_answer: tuple[int, float] | None = None  # (frame t_ns, delay ms) of our last
        self.central_ms = 0.0
        self.dr_ms: list[float] = []
        self.gt_wait: list[tuple[int, float, float]] = []
        self.last_gt_xy: tuple[float, float] | None = None
        self.path_m = 0.0
        self.t_first: int | None = None
        self.t_last: int | None = None

    def wanted_topics(self) -> list[str]:
        """Node images, odometry (mirror+odom) and ground truth (for the metrics)."""
        wanted = self.site.image_topics + ([self.site.odom_topic] if self.site.use_odom else [])
        return wanted + [topics.GROUND_TRUTH]

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
        elif msg.topic == self.site.odom_topic:
            self._on_odometry(t_ns, msg.message)
        else:
            self._on_frame(msg.topic.split("/")[1], t_ns, bytes(msg.message.data))

    def finish(self) -> SmirrorResult:
        """Score what is still waiting for the estimate; the run's figures."""
        for t_ns, gx, gy in self.gt_wait:
            self._score(t_ns, gx, gy)
        if self.t_first is not None and self.t_last is not None:
            self.res.duration_s = (self.t_last - self.t_first) / 1e9
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
            if ent.entity_id != self.site.robot:
                continue
            gx, gy = ent.position_m.x, ent.position_m.y
            if self.last_gt_xy is not None:
                self.path_m += math.hypot(gx - self.last_gt_xy[0], gy - self.last_gt_xy[1])
            self.last_gt_xy = (gx, gy)
            if self.site.use_odom and (self.filt is None or self.filt.t_ns < t_ns):
                self.gt_wait.append((t_ns, gx, gy))  # scored once odometry reaches it
            else:
                self._score(t_ns, gx, gy)

    def _estimate(self, t_ns: int) -> tuple[float, float, float] | None:
        if self.site.use_odom:
            return None if self.filt is None or not self.filt.localized else self.filt.pose
        while self.central and self.central[0][0] <= t_ns:
            self.central_pose = self.central.pop(0)[1]
        if self.central_pose is None:
            return None
        return self.central_pose.x_m, self.central_pose.y_m, self.central_pose.yaw_rad

    def _score(self, t_ns: int, gx: float, gy: float) -> None:
        est = self._estimate(t_ns)
        if est is None:
            self.res.unlocalized_samples += 1
            return
        res, cfg = self.res, self.cfg
        cov = self.site.cover.covering((gx, gy))
        res.t_s.append(t_ns / 1e9)
        res.error_m.append(math.hypot(est[0] - gx, est[1] - gy))
        res.in_coverage.append(cov is not None)
        res.range_m.append(math.nan if cov is None else cov[1])
        res.path_m.append(self.path_m)
        if not self.site.use_odom:
            res.delay_ms.append(cfg.sensing_ms + self.central_ms)
            return
        answer = self.last_answer
        fresh = (
            answer is not None
            and t_ns - answer[0] <= 1.5 * max(self.frame_period_ns.values() or [0]) + 3e8
        )
        dr = float(np.median(self.dr_ms[-50:])) if self.dr_ms else 0.0
        res.delay_ms.append(answer[1] if fresh and answer is not None else cfg.sensing_ms + dr)

    # -- odometry -------------------------------------------------------------------------------
    def _on_odometry(self, t_ns: int, odo: WheelOdometry) -> None:
        started = time.perf_counter()
        if self.filt is None:
            # a known start (a dock) or none: dead reckoning from a placeholder until a fix
            known = self.site.start is not None
            x, y, yaw = self.site.start or (0.0, 0.0, 0.0)
            self.filt = PoseFilter(x, y, yaw, t_ns, self.cfg.filter, localized=known)
        else:
            was = self.filt.localized
            dt = (t_ns - self.filt.t_ns) / 1e9
            self._dead_reckon(self.filt, t_ns, odo)
            self.res.odometry_s += dt
            self.res.localized_s += dt if was else 0.0
        self.dr_ms.append((time.perf_counter() - started) * 1e3)
        self.last_odo = odo
        if self.filt.localized and self.res.first_fix_s is None and self.t_first is not None:
            self.res.first_fix_s = (t_ns - self.t_first) / 1e9
        if self.writer is not None and self.filt.localized:
            x, y, yaw = self.filt.pose
            self.writer.write(self.pose_out, pose_in_frame(t_ns, x, y, yaw), t_ns)
        while self.gt_wait and self.gt_wait[0][0] <= t_ns:
            self._score(*self.gt_wait.pop(0))

    def _dead_reckon(self, filt: PoseFilter, t_ns: int, odo: WheelOdometry) -> None:
        """Apply the fixes that have arrived, then the wheel motion since the last sample."""
        while self.pending and self.pending[0][0] <= t_ns:
            _, ready, sp, sy = self.pending.pop(0)
            filt.last_nis = None
            self.res.fixes_used += filt.apply_fix(ready, sp, sy)
            if filt.last_nis is not None:
                self.res.nis.append(filt.last_nis)
        last = self.last_odo
        assert last is not None
        # encoder ticks, or v/omega held over the interval, or the robot's own poses
        ds, dyaw = increment(last, odo, self.site.drive) or (0.0, 0.0)
        filt.step(t_ns, ds, dyaw)

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
        res, cfg, led = self.res, self.cfg, self.site.led
        started = time.perf_counter()
        last = self.central_pose
        near = None if last is None else (last.x_m, last.y_m)
        fix = locate_robot([(0, 0, frame)], self.site.cams[name], led, t_ns, near)
        self.central_ms = (time.perf_counter() - started) * 1e3
        res.robot_ms.append(self.central_ms)
        res.fix_attempts += 1
        if fix is None:
            return
        res.fixes += 1
        avail = t_ns + int((cfg.sensing_ms + cfg.processing_ms) * 1e6)
        self.central.append((avail, fix))
        self.central.sort(key=lambda c: c[0])
        if self.writer is not None:
            pose = pose_in_frame(t_ns, fix.x_m, fix.y_m, fix.yaw_rad)
            self.writer.write(self.pose_out, pose, t_ns)

    def _mirror(self, name: str, t_ns: int, frame: np.ndarray) -> None:
        """A node senses; when robots request images it encodes and sends its foreground."""
        node, res, cfg = self.site.nodes[name], self.res, self.cfg
        mask = node.sense(frame)
        ours = False
        if self.filt is not None and not self.filt.localized:
            ours = True  # lost: the robot asks every node until one shows its LEDs
        elif self.filt is not None:
            x, y, _ = self.filt.pose
            cov = self.site.cover.covering((x, y))
            ours = cov is not None and cov[0] == name
        requests = (1 if ours else 0) + (self.site.requesters - 1)
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
        delivery = self.links[name].send(t_ns / 1e6, size, requests, broadcast, ours)
        res.queue_ms.append(delivery.queue_ms)
        if delivery.dropped:
            res.answers_dropped += 1
            if ours:
                res.ours_requested += 1
            return
        sent = size if broadcast else size * requests
        res.cast_modes.add(cast.value)
        res.image_messages += 1
        res.images_new += is_new
        res.images_old += not is_new
        res.foreground_bytes += size
        res.full_frame_bytes += full
        res.events.append((t_ns / 1e9, sent, size * requests, size if ours else 0))
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
        if ours and self.filt is not None:
            self._receive(name, t_ns, payload, delivery, node_ms, self.filt)

    def _receive(
        self,
        name: str,
        t_ns: int,
        payload: ForegroundPayload,
        delivery: Delivery,
        node_ms: float,
        filt: PoseFilter,
    ) -> None:
        """Our robot: the transfer, then LED detection on the received crops; the fix is queued
        for the time it arrives."""
        res, cfg, led = self.res, self.cfg, self.site.led
        res.ours_requested += 1
        if delivery.comm_ms is None:
            res.broadcast_lost += delivery.lost
            return
        comm_ms = delivery.comm_ms
        started = time.perf_counter()
        near = (filt.pose[0], filt.pose[1]) if filt.localized else None
        fix = locate_robot(payload.crops(), self.site.cams[name], led, payload.t_ns, near)
        robot_ms = (time.perf_counter() - started) * 1e3
        res.robot_ms.append(robot_ms)
        res.fix_attempts += 1
        self.last_answer = (t_ns, cfg.sensing_ms + node_ms + comm_ms + robot_ms)
        if fix is None:
            return
        res.fixes += 1
        sp, sy = filt.fix_sigma(fix, self.site.cams[name], led.led_height_m)
        arrival = t_ns + int((comm_ms + cfg.processing_ms) * 1e6)
        self.pending.append((arrival, fix, sp, sy))
        self.pending.sort(key=lambda p: p[0])
