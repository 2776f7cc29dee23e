"""Phone motion: a change of carry (the phone moved to another pocket or the hand) is found."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from trackctl.logs.messages import Imu, Quat, Vec3
from trackctl.vmtrack.motion import G, PhoneMotion

S = 1_000_000_000


def _walk(attitudes: list[tuple[float, Rotation]], hz: float = 50.0) -> PhoneMotion:
    """A phone walked at 1.8 steps/s for each (seconds, device-to-world rotation) in turn,
    heading east; the world specific force (gravity + step bounce) seen in the device frame."""
    phone = PhoneMotion("m1")
    t0 = 0.0
    for secs, rot in attitudes:
        for k in range(int(secs * hz)):
            t = t0 + k / hz
            world = np.array([0.0, 0.0, G + 2.0 * math.sin(2 * math.pi * 1.8 * t)])
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
