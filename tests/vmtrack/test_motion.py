"""Phone motion: a change of carry (the phone moved to another pocket or the hand) is found."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from trackctl.logs.messages import Imu, Quat, Vec3
from trackctl.vmtrack.motion import G, PhoneMotion

S = 1_000_000_000


def _walk(
    attitudes: list[tuple[float, Rotation]],
    hz: float = 50.0,
    cadence: float = 1.8,
    level: Callable[[float], tuple[float, float]] | None = None,
) -> PhoneMotion:
    """A phone walked at ``cadence`` steps/s for each (seconds, device-to-world rotation) in
    turn, heading east; the world specific force (gravity + step bounce, and the one-leg stride
    at half the step rate, with ``level(t)``'s horizontal acceleration of the body) seen in the
    device frame."""
    phone = PhoneMotion("m1")
    t0 = 0.0
    for secs, rot in attitudes:
        for k in range(int(secs * hz)):
            t = t0 + k / hz
            ph = 2 * math.pi * cadence * t
            ax, ay = level(t) if level is not None else (0.0, 0.0)
            world = np.array([ax, ay, G + 2.0 * math.sin(ph) + 0.8 * math.sin(ph / 2)])
            a = rot.inv().apply(world)
            x, y, z, w = rot.as_quat()
            phone.add(
                Imu(
                    t_ns=int(round(t * S)),
                    frame_id="phone/m1",
                    accel_mps2=Vec3(*map(float, a)),
                    orientation=Quat(float(x), float(y), float(z), float(w)),
                )
            )
        t0 += secs
    phone.finish()
    return phone


def test_a_phone_moved_from_the_hand_to_a_pocket_changes_carry_once() -> None:
    hand = Rotation.from_euler("x", 35, degrees=True)  # tilted towards the face
    pocket = Rotation.from_euler("zx", [90, 90], degrees=True)  # upright, screen sideways
    phone = _walk([(30.0, hand), (30.0, pocket)])
    changes = phone.carry_changes / S
    assert len(changes) == 1
    assert abs(changes[0] - 30.0) < 1.0


def test_a_phone_kept_in_one_carry_does_not_change() -> None:
    phone = _walk([(60.0, Rotation.from_euler("x", 35, degrees=True))])
    assert len(phone.carry_changes) == 0
    assert np.median(phone.speed) > 1.0  # it walked: 1.8 steps/s x 0.7 m


def test_real_walks_in_one_carry_are_not_cut_up() -> None:
    # the Oxford step-counter walks: ~3 minutes each with the phone in one place (hand, pockets,
    # bag, armband, neck pouch), put there at the start and taken out at the end
    import pandas as pd

    from tests.conftest import SHARED_DATA, shared_file

    shared_file("phones", "README.md")
    middle = []
    for path in sorted((SHARED_DATA / "phones").glob("*.csv")):
        d = pd.read_csv(path, header=None).to_numpy()
        phone = PhoneMotion(path.stem)
        for row in d:
            phone.add(
                Imu(
                    t_ns=int(row[0] - d[0, 0]),
                    frame_id="phone/x",
                    accel_mps2=Vec3(float(row[1]), float(row[2]), float(row[3])),
                )
            )
        phone.finish()
        span = (d[-1, 0] - d[0, 0]) / S
        middle += [t for t in phone.carry_changes / S if 10 < t < span - 10]
    assert len(middle) <= 1  # one adjustment (the armband at 56 s) in 20 minutes of walking


POCKET = Rotation.from_euler("zx", [90, 90], degrees=True)


def test_a_jogger_s_cadence_is_read_where_the_phone_s_rate_resolves_it() -> None:
    # 3 steps/s (a jog): read at 16 Hz; at the paper's 5 Hz it is beyond Nyquist (2.5 Hz), so
    # the search stops below it rather than reading an alias as a cadence it cannot tell apart
    fast = _walk([(30.0, POCKET)], hz=16.0, cadence=3.0)
    assert np.median(fast.speed) / fast.config.step_length_m == pytest.approx(3.0, abs=0.05)
    slow_rate = _walk([(30.0, POCKET)], hz=5.0, cadence=3.0)
    assert np.median(slow_rate.speed) / slow_rate.config.step_length_m < 2.45
    walker = _walk([(30.0, POCKET)], hz=16.0, cadence=1.6)
    assert np.median(walker.speed) / walker.config.step_length_m == pytest.approx(1.6, abs=0.05)


def test_without_an_orientation_the_step_is_read_on_the_vertical_not_the_norm() -> None:
    # a pocket phone without a rotation vector: a soft 1.7 Hz step bounce, and the forward push
    # and brake of each step, strong: the norm of the specific force, G + v + h^2 / 2G, peaks at
    # twice the step rate (3.4 Hz, a jog's cadence); its part along the mean "up" at the step
    phone = PhoneMotion("m1")
    hz, cadence = 50.0, 1.7
    for k in range(int(30 * hz)):
        t = k / hz
        ph = 2 * math.pi * cadence * t
        world = np.array([6.0 * math.sin(ph), 0.0, G + 0.6 * math.sin(ph)])
        a = POCKET.inv().apply(world)
        phone.add(Imu(t_ns=int(round(t * S)), frame_id="phone/m1", accel_mps2=Vec3(*map(float, a))))
    phone.finish()
    assert np.median(phone.speed) / phone.config.step_length_m == pytest.approx(cadence, abs=0.05)


def _turned(deg: float) -> Rotation:
    """The pocket attitude turned by ``deg`` about the world's vertical."""
    return Rotation.from_euler("z", deg, degrees=True) * POCKET


@pytest.mark.parametrize(
    "deg",
    [
        160.0,  # put back in its pocket the other way round
        100.0,  # moved from a back pocket to a front one: a quarter turn and a bit
    ],
)
def test_a_phone_turned_in_its_pocket_changes_carry(deg: float) -> None:
    # the same attitude before and after ("up" unchanged): only the heading tells, turning by
    # ``deg`` from one sample to the next, faster than any walker's body turns
    for hz in (5.0, 16.0, 50.0):
        phone = _walk([(30.0, POCKET), (30.0, _turned(deg))], hz=hz)
        changes = phone.carry_changes / S
        assert len(changes) == 1
        assert abs(changes[0] - 30.0) < 0.5


def test_a_walker_turning_a_sharp_corner_does_not_change_carry() -> None:
    # a 90 deg corner in half a second (180 deg/s, a walker's sharpest), the phone kept in its
    # pocket, with no help from the body's swing (no ``level`` force): the turn is too slow
    for hz in (5.0, 16.0, 50.0):
        n = max(1, round(0.5 * hz))
        corner = [(1.0 / hz, _turned(90.0 * (i + 1) / n)) for i in range(n)]
        phone = _walk([(30.0, POCKET), *corner, (30.0, _turned(90.0))], hz=hz)
        assert len(phone.carry_changes) == 0


def test_a_walker_who_turns_back_at_once_does_not_change_carry() -> None:
    # a path reversed at once (as simulated paths reverse; no walker does), the phone turning
    # with it: the body's velocity swings from +1.26 to -1.26 m/s east, which the accelerometer
    # feels (-12.6 m/s^2 for 0.2 s), so the heading's turn is the walk's, not the phone's
    def back(t: float) -> tuple[float, float]:
        return (-12.6, 0.0) if 30.0 <= t < 30.2 else (0.0, 0.0)

    for hz in (5.0, 50.0):
        phone = _walk([(30.0, POCKET), (30.0, _turned(180.0))], hz=hz, level=back)
        assert len(phone.carry_changes) == 0
        # without the body's swing, the same turn is the phone's
        alone = _walk([(30.0, POCKET), (30.0, _turned(180.0))], hz=hz)
        assert len(alone.carry_changes) == 1


def test_a_walker_turning_round_does_not_change_carry() -> None:
    # an about-turn while walking: 180 deg over 1.5 s (120 deg/s), the phone kept in its pocket
    turn = [(0.1, _turned(12.0 * (i + 1))) for i in range(15)]
    for hz in (5.0, 50.0):
        phone = _walk([(30.0, POCKET), *turn, (30.0, _turned(180.0))], hz=hz)
        assert len(phone.carry_changes) == 0
