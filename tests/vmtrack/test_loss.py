"""Loss detection judges a binding by the track's detections, not by its phone-fed state."""

from __future__ import annotations

import numpy as np

from trackctl.vmtrack.align import Alignment, lag_grid
from trackctl.vmtrack.binder import IdentityBinder
from trackctl.vmtrack.config import VmTrackConfig
from trackctl.vmtrack.motion import PhoneMotion
from trackctl.vmtrack.tracker import GroundTrack, TrackerConfig

S = 1_000_000_000


def _phone(speed: float) -> PhoneMotion:
    p = PhoneMotion("m1")
    p.t_ns = np.arange(0, 30 * S, S // 5, dtype=np.int64)
    p.v = np.tile([speed, 0.0], (len(p.t_ns), 1))
    p.speed = np.full(len(p.t_ns), speed)
    p.heading = np.zeros(len(p.t_ns))
    return p


def _run(track_speed: float) -> IdentityBinder:
    cfg = VmTrackConfig()
    binder = IdentityBinder({"m1": _phone(1.0)}, cfg.binding, cfg.align)
    trk = GroundTrack.start("v1", np.zeros(2), 0, TrackerConfig())
    # bound with a known alignment: the phone's heading is the walk's, its clock the cameras'
    zero = int(np.argmin(np.abs(lag_grid(cfg.align))))
    binder._bind_track("m1", trk, 0, al=Alignment(1 + 0j, 0.0, zero))
    rng = np.random.default_rng(0)
    for k in range(1, 40):  # 3 fps for 13 s
        t = k * S // 3
        v = binder.velocity("m1", t)
        trk.advance(t, TrackerConfig(), v)  # the phone's velocity enters the filter state
        xy = np.array([track_speed * t / S, 0.0]) + rng.normal(0, 0.2, 2)
        trk.correct(xy)
        trk.last_hit_ns = t
        binder._detect_losses(t)
    return binder


def test_a_phone_walking_away_from_a_standing_person_is_a_loss() -> None:
    binder = _run(track_speed=0.0)
    assert "m1" not in binder.bound
    assert binder.stats.losses == 1


def test_a_track_walking_with_its_phone_keeps_it() -> None:
    binder = _run(track_speed=1.0)
    assert "m1" in binder.bound
    assert binder.stats.losses == 0


def test_visual_velocity_is_the_slope_of_the_detections() -> None:
    trk = GroundTrack.start("v1", np.zeros(2), 0, TrackerConfig())
    assert trk.visual_velocity() is None
    for k in range(1, 10):
        trk.advance(k * S // 2, TrackerConfig(), None)
        trk.correct(np.array([0.5 * k * 0.5, -0.25 * k * 0.5]))
    v, times = trk.visual_velocity()  # type: ignore[misc]
    assert np.allclose(v, [0.5, -0.25])
    assert times[-1] == 9 * S // 2 and len(times) == 6  # the last 2.5 s
