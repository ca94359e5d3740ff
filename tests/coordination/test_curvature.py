"""qpcoord.coordination.curvature: §5.4 Hessian direction and §5.5 complementary form;
task_manifold."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc
from qpcoord.coordination.curvature import ComplementaryForm, HessianDirection, task_function
from qpcoord.coordination.extensions import RigidExtension
from qpcoord.coordination.periodicity import closure_errors
from qpcoord.coordination.task_manifold import fibre, fibre_point, self_motion_direction

ARM3 = qc.robots.load("planar_3r")
CIRCLE = qc.paths.Circle()
T = CIRCLE.period
Q0 = np.array([0.0, np.pi / 3, -np.pi / 3])


def test_task_function_is_eq_5_14_to_5_16():
    q = np.array([0.3, 1.1, -0.7])
    c = CIRCLE.center
    h, omega, H = task_function(ARM3, q, c, 0.5)
    y = ARM3.position(q)
    assert h == pytest.approx(np.sum((y - c) ** 2) - 0.25, abs=1e-14)
    np.testing.assert_allclose(omega, 2 * (y - c) @ ARM3.jacobian(q), atol=1e-14)
    Hf = np.empty((3, 3))
    for i in range(3):
        e = np.zeros(3)
        e[i] = 1e-6
        Hf[:, i] = (
            task_function(ARM3, q + e, c, 0.5, False)[1]
            - task_function(ARM3, q - e, c, 0.5, False)[1]
        ) / 2e-6
    np.testing.assert_allclose(H, Hf, atol=1e-8)


def test_hessian_direction_is_the_largest_curvature_in_ker_omega_h():
    rng = np.random.default_rng(2)
    S = HessianDirection(ARM3)
    for _ in range(5):
        t = float(rng.uniform(0, T))
        q = qc.inverse_kinematics(ARM3, CIRCLE.position(t), Q0 + rng.normal(0, 0.2, 3))
        _, omega, H = task_function(ARM3, q, CIRCLE.center, CIRCLE.radius)
        f1 = S.direction(q, t, CIRCLE)
        assert abs(omega @ f1) < 1e-12 * np.linalg.norm(omega)
        # brute force over the unit circle of ker ω_h
        k = np.linalg.svd(omega[None, :])[2][1:].T
        angles = np.linspace(0, np.pi, 20001)
        dirs = k @ np.vstack((np.cos(angles), np.sin(angles)))
        curv = np.abs(np.einsum("ia,ij,ja->a", dirs, H, dirs))
        assert abs(f1 @ H @ f1) == pytest.approx(curv.max(), rel=1e-6)
        qdot = S.velocity(q, t, CIRCLE)
        np.testing.assert_allclose(ARM3.jacobian(q) @ qdot, CIRCLE.velocity(t), atol=1e-10)


def test_hessian_direction_raises_on_a_vanishing_task_speed():
    S = HessianDirection(ARM3, tol=0.999)  # every J f₁ counts as vanishing
    with pytest.raises(qc.AlgorithmicSingularity, match="pure self-motion") as err:
        S.velocity(Q0, 0.0, CIRCLE)
    np.testing.assert_array_equal(err.value.q, Q0)


@pytest.mark.parametrize(
    "gain, steps, first, tol", [(0.0, 400, 1e-8, 1e-8), (10.0, 200, 1e-6, 1e-12)]
)
def test_complementary_form_is_periodic_from_the_first_period(gain, steps, first, tol):
    """§5.5 / Fig. 5.9 parameters: the joints close every period.

    Open loop (the thesis), closure is the integrator's error (measured 7e-10 to 3e-9 rad
    per period at 400 RK4 steps); with CLIK (8e-8 over the first period at 200 steps, the
    integration error being corrected) it is rounding after the first period.
    """
    results = []
    for s in (0.0, 0.6):
        q_bar = fibre_point(ARM3, Q0, s)
        C = ComplementaryForm(ARM3, q_bar, gain=gain)
        tr = qc.simulate(ARM3, C, CIRCLE, q_bar, duration=2 * T, dt=T / steps, start="q0")
        e = closure_errors(tr, T)
        assert e[0] < first and e[-1] < tol, e
        plane = (tr.q - q_bar) @ C.omega_c.T
        assert np.abs(plane).max() < 1e-12  # the joints stay in ω_c (q − q̄) = 0
        assert tr.max_error < 1e-6  # measured ≤ 2.5e-7 m
        results.append(tr.q)
    # a different q̄, a different periodic response (Fig. 5.8 A)
    assert np.abs(results[0] - results[1]).max() > 0.1


def test_complementary_form_equals_the_rigid_extension_on_the_path():
    q_bar = fibre_point(ARM3, Q0, 0.3)
    C = ComplementaryForm(ARM3, q_bar)
    R = RigidExtension(ARM3, C.omega_c)
    tr = qc.simulate(ARM3, C, CIRCLE, q_bar, duration=T, dt=T / 400, start="q0")
    for k in range(0, 400, 57):
        q, t = tr.q[k], tr.t[k]
        np.testing.assert_allclose(C.velocity(q, t, CIRCLE), R.velocity(q, t, CIRCLE), atol=1e-6)


def test_complementary_form_bad_q_bar():
    with pytest.raises(ValueError, match="singular"):
        ComplementaryForm(ARM3, [0.0, 0.0, 0.0])  # stretched arm
    with pytest.raises(ValueError, match="q_bar"):
        ComplementaryForm(ARM3, [0.0, np.nan, 0.0])


def test_no_centre_is_a_clear_error():
    class NoCentre(qc.paths.Path):
        dim = 2

        def _eval(self, t):
            z = np.zeros((t.shape[0], 2))
            return z + 2.0, z, z

    with pytest.raises(ValueError, match="centre"):
        HessianDirection(ARM3).velocity(Q0, 0.0, NoCentre())


def test_fibre_closes_on_the_end_effector_point():
    pts, length = fibre(ARM3, Q0, step=0.02)
    y0 = ARM3.position(Q0)
    err = max(np.linalg.norm(ARM3.position(p) - y0) for p in pts)
    assert err < 1e-10
    assert 9.0 < length < 10.5  # measured 9.62 rad
    steps = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    assert steps.max() < 0.021


def test_fibre_point_round_trip_and_direction():
    q1 = fibre_point(ARM3, Q0, 0.5)
    np.testing.assert_allclose(ARM3.position(q1), ARM3.position(Q0), atol=1e-11)
    np.testing.assert_allclose(fibre_point(ARM3, q1, -0.5), Q0, atol=1e-9)
    n = self_motion_direction(ARM3, Q0)
    assert abs(n @ (fibre_point(ARM3, Q0, 1e-3) - Q0) - 1e-3) < 1e-8
    np.testing.assert_allclose(ARM3.jacobian(Q0) @ n, 0, atol=1e-14)


def test_fibres_need_one_degree_of_redundancy():
    with pytest.raises(ValueError, match="one degree of redundancy"):
        fibre(qc.robots.load("spatial_5r"), np.zeros(5))
    with pytest.raises(ValueError, match="step"):
        fibre(ARM3, Q0, step=0.0)
