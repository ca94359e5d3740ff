"""qpcoord.coordination.periodicity: Poincaré sections, closure errors, period detection."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc
from qpcoord.coordination.periodicity import closure_errors, detect_period, poincare_section


def _traj(fn, dfn, T_end: float, dt: float) -> qc.Trajectory:
    t = np.arange(int(round(T_end / dt)) + 1) * dt
    q = fn(t)
    return qc.Trajectory(t=t, q=q, qdot=dfn(t), y=q[:, :1], y_ref=q[:, :1])


def _harmonic(period_multiple: float, T: float = 2.0, drift: float = 0.0):
    w = 2 * np.pi / (period_multiple * T)
    # phase 0.3: the stroboscopic samples of an m·T-periodic signal differ within a cycle
    fn = lambda t: np.stack(  # noqa: E731
        [np.sin(w * t + 0.3) + drift * t, np.cos(2 * w * t + 0.3)], axis=1
    )
    dfn = lambda t: np.stack(  # noqa: E731
        [w * np.cos(w * t + 0.3) + drift, -2 * w * np.sin(2 * w * t + 0.3)], axis=1
    )
    return fn, dfn


@pytest.mark.parametrize("m", [1, 2, 3])
def test_detects_the_period_multiple(m):
    fn, dfn = _harmonic(m)
    traj = _traj(fn, dfn, 2.0 * 10 * m, 0.01)
    res = detect_period(traj, 2.0)
    assert res.periodic and res.multiple == m and res.settled_after == 0
    assert f"period {m}·T" in str(res)


def test_drift_is_not_periodic_and_closure_errors_measure_it():
    fn, dfn = _harmonic(1, drift=1e-3)
    traj = _traj(fn, dfn, 20.0, 0.01)
    errs = closure_errors(traj, 2.0)
    np.testing.assert_allclose(errs, 2e-3, rtol=1e-9)  # drift × T per period
    res = detect_period(traj, 2.0)
    assert not res.periodic and "not periodic within 10 periods" in str(res)


def test_off_grid_period_uses_hermite_interpolation():
    fn, dfn = _harmonic(1, T=np.pi)  # π s is no whole number of 0.01 s steps
    traj = _traj(fn, dfn, 10 * np.pi, 0.01)
    p = poincare_section(traj, np.pi, t0=0.005)
    np.testing.assert_allclose(p, fn(0.005 + np.pi * np.arange(len(p))), atol=1e-8)
    assert closure_errors(traj, np.pi).max() < 1e-8


def test_settling_is_reported():
    T = 2.0
    fn0, dfn0 = _harmonic(1, T)

    def fn(t):  # a decaying offset: a limit cycle reached after a few periods
        return fn0(t) + np.exp(-t)[:, None]

    def dfn(t):
        return dfn0(t) - np.exp(-t)[:, None]

    traj = _traj(fn, dfn, 40.0, 0.01)
    res = detect_period(traj, T, tol=1e-6)
    assert res.periodic and res.multiple == 1
    # gap √2·e^{-2j}(1 − e^{-2}) (two joints) ≤ 1e-6 from j = 8 on (1.01e-6 at j = 7)
    assert res.settled_after == 8


def test_5r_thesis_schemes_pinv_drifts_and_thm42_closes():
    arm = qc.robots.load("spatial_5r")
    path = qc.paths.LissajousSphere()
    omega = np.array([[1.0, 0, 0, 0, 1.0], [0, 1.0, 0, 1.0, 0]])
    dt = path.period / 400
    runs = {}
    for name, cons in (("pinv", None), ("thm42", [qc.OneFormTask(arm, omega)])):
        ik = qc.IK(arm, [qc.PositionTask(arm, gain=10.0)], dt=dt, constraints=cons)
        runs[name] = qc.simulate(arm, ik, path, qc.robots.spatial_5r.Q0_THESIS, 3 * path.period, dt)
    pinv = closure_errors(runs["pinv"], path.period)
    thm = closure_errors(runs["thm42"], path.period)
    assert pinv.min() > 0.05  # measured 0.069–0.074 rad per period
    # first period: the tracking error of the run (1.1e-6 rad at dt = T/400); then exact
    assert thm[0] < 1e-5 and thm[1:].max() < 1e-9
    assert detect_period(runs["thm42"], path.period, min_repeats=2).multiple == 1
    assert not detect_period(runs["pinv"], path.period).periodic


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"period": 0.0}, "period must be > 0"),
        ({"period": True}, "period must be a number"),
        ({"period": 100.0}, "does not contain one period"),
        ({"t0": -1.0}, "outside the trajectory"),
    ],
)
def test_bad_arguments(kwargs, match):
    fn, dfn = _harmonic(1)
    traj = _traj(fn, dfn, 10.0, 0.01)
    args = {"period": 2.0}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        poincare_section(traj, **args)


def test_not_a_trajectory():
    with pytest.raises(ValueError, match="Trajectory"):
        closure_errors(np.zeros((10, 2)), 1.0)


def test_periods_to_closure():
    from qpcoord.coordination.periodicity import periods_to_closure

    assert periods_to_closure([1e-9, 1e-9]) == 1
    assert periods_to_closure([0.1, 1e-3, 1e-8, 1e-9]) == 3
    assert periods_to_closure([0.1, 1e-8, 1e-3]) is None
    assert periods_to_closure([0.1, 1e-8, np.nan]) is None
    with pytest.raises(ValueError, match="empty"):
        periods_to_closure([])


def test_joint_path_lengths_of_a_uniform_rotation():
    from qpcoord.coordination.periodicity import joint_path_lengths
    from qpcoord.kinematics.simulation import Trajectory

    t = np.linspace(0, 4.0, 401)
    q = np.column_stack((0.5 * t, np.zeros_like(t)))
    qd = np.tile([0.5, 0.0], (t.size, 1))
    tr = Trajectory(t=t, q=q, qdot=qd, y=q, y_ref=q)
    np.testing.assert_allclose(joint_path_lengths(tr, 1.0), [0.5] * 4, atol=1e-12)
    with pytest.raises(ValueError, match="whole number"):
        joint_path_lengths(tr, 1.005)
