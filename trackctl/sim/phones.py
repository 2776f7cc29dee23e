"""Phones carried by walking people: the IMU a real phone reports (the ``realistic`` preset).

Every model, its parameter and its source (docs/vmtrack.md, "Simulator"):

* **Carry** per person, drawn from ``carries`` (hand 30 %, front pocket 30 %, back pocket 15 %,
  bag 25 %), and changed when the phone is taken out and put back (a Poisson process of
  ``carry_changes_per_min``, 0.2: once in five minutes, more often than the 47-76 pickups a
  day of phone-use studies (Deloitte 2017, dscout 2016) spread over waking hours). Each
  carry has an attitude (measured: the gravity direction in the
  device frame of the Oxford step-counter traces in ``shared/data/phones``: hand tilted ~35 deg
  towards the face, pockets upright with the device y axis up, bag on its side with x up), a
  yaw between the device and the walking direction (hand: N(0, 10 deg); pockets and bag:
  uniform, a new draw at each change), a yaw sway at the stride frequency (hand 3 deg,
  pockets 20, bag 8) and a vertical bounce amplitude at normal speed (measured on the same
  traces: magnitude std 2.2 m/s^2 in the hand, 4.7 in the pockets, 3.8 in the bag; a sinusoid
  of amplitude std * sqrt(2)); pockets add the stride (one leg) at half the step rate.
* **Heading** is the Android rotation vector's: the device attitude in a frame whose north is
  ``site_yaw_deg`` away from the site's x axis (uniform per log: the site frame is not magnetic
  north), disturbed indoors by a smooth magnetic field (``magnetic_deg`` amplitude over
  ``magnetic_wavelength_m``; steel and wiring deflect indoor compasses by 10-20 deg, Li et al.,
  IPIN 2012) and a slow random walk (``heading_drift_deg_per_sqrt_s``).
* **Gait** per person: step length uniform in ``step_length_m`` (0.55-0.85 m; adult step
  lengths, Grieve & Gear 1966), growing with speed (0.75 + 0.25 v / 1.3 of it: cadence and
  length both rise with speed).
* **Always on**: phones report for the whole log. Outside the cameras' view their carriers
  stand or walk (alternating 5-30 s bouts) where no camera sees them: towards where they come
  into view before, away from where they left after (headings within +-45 deg of the ones
  they had there): a person out of view cannot walk back through the view unseen, as random
  headings from the moment they left would have them do.
* **Clock**: each phone's clock is off by uniform +-``clock_offset_s`` and drifts by
  +-``clock_drift_ppm`` (phones without NTP sync; quartz clocks drift 10-50 ppm).
* **Sampling**: each phone reports at one of ``imu_rates_hz`` (Android's SENSOR_DELAY_NORMAL,
  UI and GAME: 5, 16, 50 Hz), with ``jitter_ms`` timestamp jitter and ``drop`` of the samples
  lost. Accelerometer noise 0.15 m/s^2, gyro noise 0.02 rad/s and bias 0.01 rad/s (MEMS
  datasheets, e.g. Bosch BMI160).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from trackctl.logs.messages import Imu, Quat, Vec3
from trackctl.sim.walkers import Trajectory

__all__ = ["PhoneRealism", "PhoneTruth", "CARRIES", "realistic_imu"]

G = 9.80665
S = 1_000_000_000


@dataclass(frozen=True, slots=True)
class _Carry:
    attitude: tuple[str, float]
    """Device tilt from level: (axis, degrees) of a rotation applied before the yaw."""
    yaw_sigma_deg: float | None
    """Device-to-walk yaw: N(0, sigma), or uniform on the circle when None."""
    sway_deg: float
    bounce_mps2: float
    stride: float
    """Amplitude of the one-leg stride component, as a share of the bounce."""


CARRIES: dict[str, _Carry] = {
    "hand": _Carry(("x", 35.0), 10.0, 3.0, 3.2, 0.0),
    "front_pocket": _Carry(("x", 90.0), None, 20.0, 6.6, 0.3),
    "back_pocket": _Carry(("x", 90.0), None, 20.0, 6.8, 0.4),
    "bag": _Carry(("y", -90.0), None, 8.0, 5.3, 0.1),
}


@dataclass(frozen=True, slots=True)
class PhoneRealism:
    """Knobs of the phone models above (see the module docstring for sources)."""

    carries: tuple[tuple[str, float], ...] = (
        ("hand", 0.3),
        ("front_pocket", 0.3),
        ("back_pocket", 0.15),
        ("bag", 0.25),
    )
    carry_changes_per_min: float = 0.2
    site_yaw_deg: float | None = None
    """Rotation of magnetic north from the site's x axis; None: uniform per log."""
    magnetic_deg: float = 10.0
    magnetic_wavelength_m: float = 6.0
    heading_drift_deg_per_sqrt_s: float = 1.0
    step_length_m: tuple[float, float] = (0.55, 0.85)
    always_on: bool = True
    clock_offset_s: float = 2.0
    clock_drift_ppm: float = 50.0
    imu_rates_hz: tuple[float, ...] = (5.0, 16.0, 50.0)
    jitter_ms: float = 3.0
    drop: float = 0.02
    carry_yaw_deg: float | None = None
    """Every phone's device-to-walk yaw fixed to this (tests: 0, 45, 90, 180); None: per carry."""


@dataclass(frozen=True, slots=True)
class PhoneTruth:
    """What the simulator chose for one phone (scenario metadata; read by metrics only)."""

    carry: str
    yaw_offset_deg: float
    """First carry's device-to-walk yaw plus the site rotation (what a tracker must estimate)."""
    clock_offset_s: float
    clock_drift_ppm: float
    step_length_m: float
    imu_hz: float


def _walk_velocity(
    traj: Trajectory, duration: float, dt: float, rng: np.random.Generator, always_on: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The carrier's true time grid, velocity and position (NaN out of view) over the log.

    Inside the trajectory, its velocity; outside (always-on phones), bouts of standing and of
    walking (5-30 s each, 0.8-1.4 m/s) where no camera sees them: before coming into view the
    carrier walks towards where they enter, after leaving away from where they left (the
    heading they had there, wandering within +-45 deg), so the walk never crosses the
    cameras' view unseen; the bout next to the view is a walk (people walk in and out)."""
    t = np.arange(0.0, duration + dt, dt)
    xy = traj.at(t)
    inside = ~np.isnan(xy).any(axis=1)
    vel = np.zeros((len(t), 2))
    if inside.any():
        filled = xy.copy()
        idx = np.flatnonzero(inside)
        for j in range(2):
            filled[:, j] = np.interp(np.arange(len(t)), idx, xy[idx, j])
        vel = np.gradient(filled, dt, axis=0)
    if not always_on:
        vel[~inside] = np.nan
        return t, vel, xy
    if not inside.any():
        _outside_bouts(vel, np.arange(len(t)), rng.uniform(-math.pi, math.pi), dt, rng, 180.0)
        return t, vel, xy
    i0, i1 = int(idx[0]), int(idx[-1])
    near = max(int(2.0 / dt), 1)
    h_in = _heading(filled[min(i0 + near, i1)] - filled[i0], rng)
    h_out = _heading(filled[i1] - filled[max(i1 - near, i0)], rng)
    _outside_bouts(vel, np.arange(i0 - 1, -1, -1), h_in, dt, rng, 45.0)
    _outside_bouts(vel, np.arange(i1 + 1, len(t)), h_out, dt, rng, 45.0)
    return t, vel, xy


def _heading(move: np.ndarray, rng: np.random.Generator) -> float:
    """Direction of ``move`` (rad); a random one when it is under 0.1 m (standing)."""
    if np.hypot(*move) > 0.1:
        return math.atan2(move[1], move[0])
    return float(rng.uniform(-math.pi, math.pi))


def _outside_bouts(
    vel: np.ndarray,
    order: np.ndarray,
    heading: float,
    dt: float,
    rng: np.random.Generator,
    spread_deg: float,
) -> None:
    """Fill ``vel`` at the samples ``order`` (walked away from the view: the first is next to
    it) with alternating bouts of walking and standing; walking heads along ``heading``,
    wandering slowly (4 deg per sqrt(s)) within +-``spread_deg``."""
    k, walking, wander = 0, True, 0.0
    lim = math.radians(spread_deg)
    while k < len(order):
        n = max(int(rng.uniform(5.0, 30.0) / dt), 1)
        seg = order[k : k + n]
        if walking:
            steps = rng.normal(0, math.radians(4.0) * math.sqrt(dt), len(seg))
            turn = np.clip(wander + np.cumsum(steps), -lim, lim)
            wander = float(turn[-1])
            speed = rng.uniform(0.8, 1.4)
            vel[seg] = np.column_stack([np.cos(heading + turn), np.sin(heading + turn)]) * speed
        else:
            vel[seg] = 0.0
        walking = not walking
        k += n


def _magnetic(xy: np.ndarray, rng: np.random.Generator, cfg: PhoneRealism) -> np.ndarray:
    """Heading disturbance (rad) of the indoor magnetic field at positions ``xy`` (NaN: out of
    view, where a slow random walk of the same size stands in)."""
    lam = cfg.magnetic_wavelength_m
    p = rng.uniform(0, 2 * math.pi, 4)
    amp = math.radians(cfg.magnetic_deg)
    x, y = np.nan_to_num(xy[:, 0]), np.nan_to_num(xy[:, 1])
    field = (
        amp
        * 0.5
        * (
            np.sin(2 * math.pi * x / lam + p[0]) * np.cos(2 * math.pi * y / lam + p[1])
            + np.sin(2 * math.pi * (x + y) / (1.7 * lam) + p[2])
        )
    )
    out = np.isnan(xy).any(axis=1)
    if out.any():
        walk = np.cumsum(rng.normal(0, amp * 0.05, len(xy)))
        field[out] = np.clip(walk[out], -amp, amp)
    return field


def _carry_yaw(carry: _Carry, rng: np.random.Generator, cfg: PhoneRealism) -> float:
    if cfg.carry_yaw_deg is not None:
        return math.radians(cfg.carry_yaw_deg)
    if carry.yaw_sigma_deg is None:
        return float(rng.uniform(-math.pi, math.pi))
    return float(rng.normal(0, math.radians(carry.yaw_sigma_deg)))


@dataclass(frozen=True, slots=True)
class _Gait:
    """The carrier's walk on the true time grid: speed, heading (held while standing), step
    length, stride phase and horizontal acceleration."""

    speed: np.ndarray
    heading: np.ndarray
    step_len: float
    phase: np.ndarray
    acc: np.ndarray


def _gait(vel: np.ndarray, dt: float, rng: np.random.Generator, cfg: PhoneRealism) -> _Gait:
    """Speed, heading, stride phase and acceleration of the walk ``vel``; draws the step length."""
    speed = np.linalg.norm(np.nan_to_num(vel), axis=1)
    heading = np.arctan2(np.nan_to_num(vel[:, 1]), np.nan_to_num(vel[:, 0]))
    for k in range(1, len(heading)):  # keep the last heading while standing
        if speed[k] < 0.1:
            heading[k] = heading[k - 1]
    heading = np.unwrap(heading)
    step_len = float(rng.uniform(*cfg.step_length_m))
    cadence = speed / (step_len * (0.75 + 0.25 * np.minimum(speed, 2.0) / 1.3))
    phase = 2 * math.pi * np.cumsum(cadence) * dt
    acc = np.gradient(np.nan_to_num(vel), dt, axis=0)
    return _Gait(speed, heading, step_len, phase, acc)


@dataclass(frozen=True, slots=True)
class _CarryPlan:
    """Where the phone is carried over the log: a segment per Poisson change."""

    names: list[str]
    """The carries of ``cfg.carries``; ``idx`` indexes this list."""
    first: str
    first_yaw: float
    idx: np.ndarray
    """Carry index per time-grid sample."""
    yaw_off: np.ndarray
    """Device-to-walk yaw per time-grid sample (rad)."""


def _carry_plan(t: np.ndarray, rng: np.random.Generator, cfg: PhoneRealism) -> _CarryPlan:
    """The first carry and its yaw, then a new carry (and yaw) at each Poisson change."""
    names = [c for c, _ in cfg.carries]
    probs = np.array([p for _, p in cfg.carries], float)
    probs /= probs.sum()
    n = len(t)
    carry_idx = np.zeros(n, int)
    yaw_off = np.zeros(n)
    first = str(rng.choice(names, p=probs))
    cur, cur_yaw = first, _carry_yaw(CARRIES[first], rng, cfg)
    first_yaw = cur_yaw
    rate = cfg.carry_changes_per_min / 60.0
    next_change = rng.exponential(1 / rate) if rate > 0 else math.inf
    for k in range(n):
        if t[k] >= next_change:
            cur = str(rng.choice(names, p=probs))
            cur_yaw = _carry_yaw(CARRIES[cur], rng, cfg)
            next_change += rng.exponential(1 / rate)
        carry_idx[k] = names.index(cur)
        yaw_off[k] = cur_yaw
    return _CarryPlan(names, first, first_yaw, carry_idx, yaw_off)


@dataclass(frozen=True, slots=True)
class _DeviceMotion:
    """The device's yaw in the rotation-vector frame, its rate, and the vertical specific force."""

    yaw: np.ndarray
    yaw_rate: np.ndarray
    vert: np.ndarray


def _device_motion(
    gait: _Gait,
    plan: _CarryPlan,
    xy: np.ndarray,
    site_yaw: float,
    dt: float,
    rng: np.random.Generator,
    cfg: PhoneRealism,
) -> _DeviceMotion:
    """Heading plus carry yaw, sway, site rotation, magnetic disturbance and drift; bounce."""
    carries = [CARRIES[name] for name in plan.names]
    sway = np.radians([c.sway_deg for c in carries])[plan.idx] * np.sin(gait.phase / 2)
    bounce = np.array([c.bounce_mps2 for c in carries])[plan.idx]
    bounce_amp = bounce * np.minimum(gait.speed / 1.3, 1.5) ** 1.5
    stride = np.array([c.stride for c in carries])[plan.idx]
    drift_sigma = math.radians(cfg.heading_drift_deg_per_sqrt_s) * math.sqrt(dt)
    drift = np.cumsum(rng.normal(0, drift_sigma, len(plan.idx)))
    yaw_dev = gait.heading + plan.yaw_off + sway + site_yaw + _magnetic(xy, rng, cfg) + drift
    yaw_rate = np.gradient(np.unwrap(yaw_dev), dt)
    vert = G + bounce_amp * (np.sin(gait.phase) + stride * np.sin(gait.phase / 2))
    return _DeviceMotion(yaw_dev, yaw_rate, vert)


@dataclass(frozen=True, slots=True)
class _PhoneClock:
    """The phone's sampling: rate, clock offset and drift, its stamps and their true times."""

    hz: float
    offset: float
    drift_ppm: float
    stamps: np.ndarray
    """Sample stamps on the phone's clock (s)."""
    true_t: np.ndarray
    """True (log) time of each stamp, jittered (s)."""
    keep: np.ndarray
    """Samples inside the log and not dropped."""


def _phone_clock(
    duration: float, t_end: float, rng: np.random.Generator, cfg: PhoneRealism
) -> _PhoneClock:
    """True sample times of this phone's clock, jittered, some dropped."""
    hz = float(rng.choice(cfg.imu_rates_hz))
    offset = float(rng.uniform(-cfg.clock_offset_s, cfg.clock_offset_s))
    drift_ppm = float(rng.uniform(-cfg.clock_drift_ppm, cfg.clock_drift_ppm))
    stamps = np.arange(0.0, duration, 1.0 / hz)
    true_t = (stamps - offset) / (1 + drift_ppm * 1e-6)
    true_t = true_t + rng.normal(0, cfg.jitter_ms / 1000.0, len(true_t))
    keep = (true_t >= 0) & (true_t <= t_end) & (rng.random(len(true_t)) >= cfg.drop)
    return _PhoneClock(hz, offset, drift_ppm, stamps, true_t, keep)


def _device_rotations(plan: _CarryPlan, ks: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Device -> world matrices (len(ks), 3, 3) at grid samples ``ks``: the carry's tilt, then
    the yaw about world z (vectorised by carry)."""
    rot_m = np.empty((len(ks), 3, 3))
    for i, name in enumerate(plan.names):
        axis, deg = CARRIES[name].attitude
        tilt = Rotation.from_euler(axis, deg, degrees=True)
        m = plan.idx[ks] == i
        if m.any():
            rot_m[m] = (Rotation.from_euler("z", yaw[ks[m]][:, None]) * tilt).as_matrix()
    return rot_m


def _imu_messages(
    frame: str,
    gait: _Gait,
    plan: _CarryPlan,
    motion: _DeviceMotion,
    clock: _PhoneClock,
    dt: float,
    rng: np.random.Generator,
) -> list[Imu]:
    """The kept samples as device-frame IMU messages (noise and gyro bias drawn here)."""
    n = len(plan.idx)
    gyro_bias = rng.normal(0, 0.01, 3)
    noise_a = rng.normal(0, 0.15, (len(clock.stamps), 3))
    noise_g = rng.normal(0, 0.02, (len(clock.stamps), 3))
    sel = np.flatnonzero(clock.keep)
    ks = np.minimum(np.round(clock.true_t[sel] / dt).astype(int), n - 1)
    rot_m = _device_rotations(plan, ks, motion.yaw)
    f_world = np.column_stack([gait.acc[ks, 0], gait.acc[ks, 1], motion.vert[ks]])
    w_world = np.column_stack([np.zeros(len(ks)), np.zeros(len(ks)), motion.yaw_rate[ks]])
    f_dev = np.einsum("kji,kj->ki", rot_m, f_world) + noise_a[sel]
    gyro = np.einsum("kji,kj->ki", rot_m, w_world) + gyro_bias + noise_g[sel]
    quats = Rotation.from_matrix(rot_m).as_quat() if len(sel) else np.zeros((0, 4))
    return [
        Imu(
            int(round(clock.stamps[j] * S)),
            frame,
            Vec3(*map(float, f_dev[r])),
            Vec3(*map(float, gyro[r])),
            Quat(*map(float, quats[r])),
        )
        for r, j in enumerate(sel)
    ]


def realistic_imu(
    traj: Trajectory,
    mac: str,
    duration: float,
    rng: np.random.Generator,
    cfg: PhoneRealism,
    site_yaw: float,
) -> tuple[list[Imu], PhoneTruth, np.ndarray]:
    """The IMU samples (phone clock stamps) of the phone carried along ``traj``, its truth,
    and its carrier's whereabouts in view and out of it (:func:`_whereabouts`)."""
    dt = 0.02
    t, vel, xy = _walk_velocity(traj, duration, dt, rng, cfg.always_on)
    gait = _gait(vel, dt, rng, cfg)
    plan = _carry_plan(t, rng, cfg)
    motion = _device_motion(gait, plan, xy, site_yaw, dt, rng, cfg)
    clock = _phone_clock(duration, float(t[-1]), rng, cfg)
    out = _imu_messages(f"phone/{mac}", gait, plan, motion, clock, dt, rng)
    yaw_offset = math.remainder(plan.first_yaw + site_yaw, 2 * math.pi)
    truth = PhoneTruth(
        carry=plan.first,
        yaw_offset_deg=round(math.degrees(yaw_offset), 2),
        clock_offset_s=round(clock.offset, 4),
        clock_drift_ppm=round(clock.drift_ppm, 2),
        step_length_m=round(gait.step_len, 3),
        imu_hz=clock.hz,
    )
    return out, truth, _whereabouts(t, vel, xy)


def _whereabouts(t: np.ndarray, vel: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(n, 3) time (s), x, y of the carrier over the log: in view where they are seen, out of
    view walked from where they came in or left by their out-of-view walk (the APs hear the
    phone there); NaN for a carrier never in view (somewhere else in the building)."""
    inside = ~np.isnan(xy).any(axis=1)
    out = np.column_stack([t, xy])
    if not inside.any():
        return out
    dt = float(t[1] - t[0]) if len(t) > 1 else 1.0
    step = np.nan_to_num(vel) * dt
    i0, i1 = (int(i) for i in np.flatnonzero(inside)[[0, -1]])
    if i0 > 0:  # walked back from where they came in: k < i0 is there less the steps since
        out[i0 - 1 :: -1, 1:] = xy[i0] - np.cumsum(step[i0:0:-1], axis=0)
    after = np.cumsum(step[i1 + 1 :], axis=0)
    out[i1 + 1 :, 1:] = xy[i1] + after
    return out
