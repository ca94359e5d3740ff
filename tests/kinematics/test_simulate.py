"""qc.simulate on the thesis tracking tasks, and its argument checks."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc

# thesis Fig. 5.9: 3R arm, circle c = (1.5, 0), R = 0.5, T = π, q0 = (0, π/3, −π/3)
Q0_3R = np.array([0.0, np.pi / 3, -np.pi / 3])


@pytest.fixture(scope="module")
def arm3():
    return qc.robots.load("planar_3r")


def test_thesis_q0_starts_on_the_circle(arm3):
    np.testing.assert_allclose(arm3.position(Q0_3R), qc.paths.Circle().position(0.0), atol=1e-15)


@pytest.mark.parametrize("method", ["hierarchical", "nullspace", "weighted"])
def test_3r_tracks_the_circle_within_1e6_of_its_length(arm3, method):
    circle = qc.paths.Circle()
    traj = qc.simulate(
        arm3,
        [qc.PositionTask(arm3, gain=10.0)],
        circle,
        Q0_3R,
        duration=circle.period,
        dt=0.01,
        method=method,
    )
    assert traj.t.shape == (315,) and traj.q.shape == (315, 3) and traj.y.shape == (315, 2)
    assert traj.max_error < 1e-6 * circle.length()  # measured 4.9e-8 m (length π m)
    np.testing.assert_allclose(traj.y_ref, circle.position(traj.t))
    # the recorded qdot is the scheme's output: J q̇ = ẏ_ref + K e at every sample
    for k in (0, 100, 314):
        J = arm3.jacobian(traj.q[k])
        e = traj.y_ref[k] - traj.y[k]
        np.testing.assert_allclose(
            J @ traj.qdot[k], circle.velocity(traj.t[k]) + 10.0 * e, atol=1e-10
        )


def test_euler_is_a_plain_control_loop(arm3):
    circle = qc.paths.Circle()
    ee = qc.PositionTask(arm3, gain=10.0)
    traj = qc.simulate(arm3, [ee], circle, Q0_3R, 1.0, 0.01, integrator="euler")
    # one step of q ← q + dt q̇ between samples
    np.testing.assert_allclose(traj.q[1:], traj.q[:-1] + 0.01 * traj.qdot[:-1], atol=1e-15)
    rk4 = qc.simulate(arm3, [ee], circle, Q0_3R, 1.0, 0.01)
    assert rk4.max_error < traj.max_error  # Euler lags by O(dt)


def test_start_ik_moves_q0_onto_the_path(arm3):
    circle = qc.paths.Circle(phase=np.pi / 2)  # start at (1.5, 0.5), not where q0 is
    traj = qc.simulate(arm3, [qc.PositionTask(arm3)], circle, Q0_3R, 0.1, 0.01)
    np.testing.assert_allclose(traj.y[0], circle.position(0.0), atol=1e-12)
    np.testing.assert_allclose(traj.info["q0"], Q0_3R)
    assert np.linalg.norm(traj.info["q_start"] - Q0_3R) < 1.0
    raw = qc.simulate(arm3, [qc.PositionTask(arm3)], circle, Q0_3R, 0.1, 0.01, start="q0")
    np.testing.assert_allclose(raw.q[0], Q0_3R)


def test_a_scheme_object_is_accepted(arm3):
    class Still:
        def velocity(self, q, t, reference):
            return np.zeros(3)

    traj = qc.simulate(arm3, Still(), qc.paths.Circle(), Q0_3R, 0.05, 0.01, start="q0")
    np.testing.assert_allclose(traj.q, np.tile(Q0_3R, (6, 1)))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"robot": "arm"}, "robot must be"),
        ({"target": [2.0, 0.0]}, "target must be"),
        ({"target": qc.paths.LissajousSphere()}, "3-D but the robot has 2"),
        ({"q0": [0.0, 0.0]}, "q0 must have 3 entries"),
        ({"q0": [0.0, np.nan, 0.0]}, r"q0\[1\] is nan"),
        ({"duration": 0.0}, "duration"),
        ({"dt": -0.01}, "dt must be > 0"),
        ({"integrator": "rk45"}, "integrator"),
        ({"start": "home"}, "start must be"),
        ({"scheme": object()}, "velocity"),
    ],
)
def test_bad_arguments_are_named(arm3, kwargs, match):
    args = {
        "robot": arm3,
        "scheme": [qc.PositionTask(arm3)],
        "target": qc.paths.Circle(),
        "q0": Q0_3R,
        "duration": 0.1,
        "dt": 0.01,
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        qc.simulate(**args)


def test_scheme_returning_nan_is_reported(arm3):
    class Broken:
        def velocity(self, q, t, reference):
            return np.full(3, np.nan)

    with pytest.raises(ValueError, match="invalid velocity at t = 0"):
        qc.simulate(arm3, Broken(), qc.paths.Circle(), Q0_3R, 0.1, 0.01, start="q0")


# ---- 5R arm on the thesis Lissajous (Eq. 3.3, Example 4.1) --------------------------------
Q0_5R = np.array([0.298, 0.165, 0.260, 1.24, 4.37])  # thesis Example 4.1, rad
OMEGA_45 = np.array([[1.0, 0.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0, 0.0]])  # Ex 4.4


@pytest.fixture(scope="module")
def arm5():
    return qc.robots.load("spatial_5r")


@pytest.mark.parametrize("with_forms", [False, True], ids=["pseudo-inverse", "thm-4.2"])
def test_5r_tracks_the_lissajous_within_1e6_of_its_length(arm5, with_forms):
    path = qc.paths.LissajousSphere()
    constraints = [qc.OneFormTask(arm5, OMEGA_45, name="ω4, ω5")] if with_forms else None
    ik = qc.IK(arm5, [qc.PositionTask(arm5, gain=10.0)], dt=0.01, constraints=constraints)
    traj = qc.simulate(arm5, ik, path, Q0_5R, duration=path.period, dt=0.01)
    assert traj.max_error < 1e-6 * path.length()  # measured 8e-9 / 1.2e-8 m (length 7.9 m)
    if with_forms:
        # the motion stays on the leaf q1 + q5 = const, q2 + q4 = const ...
        sums = traj.q @ OMEGA_45.T
        np.testing.assert_allclose(sums, np.tile(sums[0], (len(sums), 1)), atol=1e-9)
        # ... and the hypothesis of Thm 4.2 holds along it: [J; ω4; ω5] stays invertible
        smin = min(
            np.linalg.svd(np.vstack((arm5.jacobian(q), OMEGA_45)), compute_uv=False)[-1]
            for q in traj.q[::10]
        )
        assert smin > 0.05  # measured 0.182
