"""The RTS smoother against filterpy's on a linear model, in blocks, and across restarts."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from trackctl.bridgeloc.smooth import RtsSmoother

S = 1_000_000_000


def _run(n: int, seed: int, smoother: RtsSmoother | None, restart_at: int | None = None):  # noqa: ANN202
    """A linear 4-state model (constant velocity in x, heading walks slowly) measured in x and
    heading every step; x Jacobian-linear, so filterpy's smoother is exact for it."""
    rng = np.random.default_rng(seed)
    kf = KalmanFilter(dim_x=4, dim_z=2)
    kf.F = np.array([[1, 0, 0, 0.1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    kf.H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    kf.Q = np.diag([1e-3, 1e-3, 1e-4, 1e-3])
    kf.R = np.diag([0.05, 0.01])
    kf.x = np.zeros((4, 1))
    kf.P = np.eye(4)
    truth = np.zeros(4)
    xs, ps = [], []
    for k in range(n):
        if k:
            if smoother is not None:
                smoother.close(kf.x, kf.P)
            kf.predict()
            if smoother is not None:
                smoother.predicted(kf.F)
            truth = kf.F @ truth + rng.normal(0, np.sqrt(np.diag(kf.Q)))
        if restart_at is not None and k == restart_at:
            if smoother is not None:
                smoother.close(kf.x, kf.P)
                smoother.restart()
            kf.x, kf.P = np.zeros((4, 1)), np.eye(4)
        z = kf.H @ truth + rng.normal(0, np.sqrt(np.diag(kf.R)))
        if smoother is not None:
            smoother.open(k * S, kf.x, kf.P)
        if k % 7 != 3:  # some steps without a measurement
            kf.update(z[:, None])
        if smoother is not None:
            smoother.output(k * S, kf.x, kf.P)
        xs.append(kf.x.copy())
        ps.append(kf.P.copy())
    if smoother is not None:
        smoother.finish(kf.x, kf.P)
    return kf, np.array(xs), np.array(ps)


def test_matches_filterpy_on_a_linear_model() -> None:
    got: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    sm = RtsSmoother(lambda t, x, p: got.__setitem__(t, (x, p)), lag_s=1e9)
    kf, xs, ps = _run(80, 1, sm)
    want_x, want_p, _, _ = kf.rts_smoother(xs, ps)
    assert sorted(got) == [k * S for k in range(80)]
    for k in range(80):
        np.testing.assert_allclose(got[k * S][0], want_x[k], atol=1e-9)
        np.testing.assert_allclose(got[k * S][1], want_p[k], atol=1e-9)
    # smoothing helps: the smoothed variance is never above the filtered one
    assert all(got[k * S][1][0, 0] <= ps[k][0, 0] + 1e-12 for k in range(80))


def test_blocks_emit_in_order_and_agree_with_the_whole_run() -> None:
    whole: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    _run(300, 2, RtsSmoother(lambda t, x, p: whole.__setitem__(t, (x, p)), lag_s=1e9))
    order: list[int] = []
    blocks: dict[int, np.ndarray] = {}

    def emit(t: int, x: np.ndarray, p: np.ndarray) -> None:
        order.append(t)
        blocks[t] = x

    sm = RtsSmoother(emit, lag_s=40.0)
    _run(300, 2, sm)
    assert order == sorted(order) and len(order) == 300
    assert len(sm.nodes) == 0
    for t, (x, p) in whole.items():  # 40 s of the future: within a tenth of a std of all of it
        assert np.all(np.abs(blocks[t] - x)[:, 0] <= 0.1 * np.sqrt(np.diag(p)))


def test_nothing_is_smoothed_across_a_restart() -> None:
    got: dict[int, np.ndarray] = {}
    _, xs, _ = _run(60, 3, RtsSmoother(lambda t, x, p: got.__setitem__(t, x), lag_s=1e9), 30)
    # the last node before the restart keeps its filtered state
    np.testing.assert_allclose(got[29 * S], xs[29], atol=1e-12)
    assert not np.allclose(got[28 * S], xs[28])


@pytest.mark.parametrize("lag", [5.0, 1e9])
def test_singular_prior_does_not_raise(lag: float) -> None:
    sm = RtsSmoother(lambda t, x, p: None, lag_s=lag)
    sm.open(0, np.zeros((4, 1)), np.zeros((4, 4)))
    sm.output(0, np.zeros((4, 1)), np.zeros((4, 4)))
    sm.close(np.zeros((4, 1)), np.zeros((4, 4)))
    sm.predicted(np.eye(4))
    sm.output(S, np.zeros((4, 1)), np.zeros((4, 4)))
    sm.finish(np.zeros((4, 1)), np.zeros((4, 4)))
    assert not sm.nodes


def test_a_gap_between_fixes_is_closed_from_both_ends() -> None:
    """The robot drives 8 m with biased wheels and position fixes only for its first and last
    2 m: the filter drifts through the gap and jumps at its end; the smoothed poses also
    use the fixes after the gap."""
    import math

    from trackctl.bridgeloc.ekf import RobotEkf

    got: dict[int, np.ndarray] = {}
    ekf = RobotEkf(smoother=RtsSmoother(lambda t, x, p: got.__setitem__(t, x)))
    causal: dict[int, np.ndarray] = {}
    truth: dict[int, tuple[float, float]] = {}
    rng = np.random.default_rng(0)
    x = y = yaw = 0.0
    ds, curve = 0.02, 0.01  # 2 cm steps on a gentle curve; the odometry reads it 0.03 rad/m off
    for k in range(400):
        t = k * S // 10
        if k:
            yaw += curve
            x += ds * math.cos(yaw)
            y += ds * math.sin(yaw)
            ekf.predict(ds, curve - 0.03 * ds)
        truth[t] = (x, y)
        ekf.t_ns = t
        if k < 100 or k >= 300:
            fix = np.array([x, y]) + rng.normal(0, 0.02, 2)
            cov = np.eye(2) * 0.02**2
            if not ekf.initialized:
                ekf.init((fix[0], fix[1], yaw), np.diag([4e-4, 4e-4, 1e-2]))
            else:
                ekf.update_position(fix, cov)
        ekf.output(t)
        causal[t] = ekf.kf.x.copy()
    ekf.finish()
    gap = [k * S // 10 for k in range(200, 300)]
    err_c = [math.dist(causal[t][:2, 0], truth[t]) for t in gap]
    err_s = [math.dist(got[t][:2, 0], truth[t]) for t in gap]
    assert sorted(got) == sorted(causal)
    assert max(err_c) > 0.05  # the filter did drift
    assert float(np.mean(err_s)) < 0.5 * float(np.mean(err_c))
