"""qpcoord.coordination.geometry: brackets, involutivity, dual fields (thesis §3.6, chapter 4)."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc
from qpcoord import geometry as g

OMEGA_45 = np.array([[1.0, 0, 0, 0, 1.0], [0, 1.0, 0, 1.0, 0]])  # Ex 4.4


def _lemma41_jacobian(q):
    """Submersion of Lemma 4.1: x₁ = q₁, x₂ = q₂ + q₁q₃."""
    return np.array([[1.0, 0.0, 0.0], [q[2], 1.0, q[0]]])


def _pinv_field(e):
    def f(q):
        J = _lemma41_jacobian(q)
        return J.T @ np.linalg.solve(J @ J.T, e)

    return f


def test_bracket_of_linear_fields_is_the_commutator():
    A = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    B = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    q = np.array([0.3, -0.2, 0.5])
    # [Ax, Bx] = (BA − AB) x
    np.testing.assert_allclose(
        g.lie_bracket(lambda x: A @ x, lambda x: B @ x, q), (B @ A - A @ B) @ q, atol=1e-14
    )


def test_jacobian_paths_agree():
    """Complex step (numpy field) vs 4th-order differences (a field that casts to float)."""
    f = _pinv_field([1.0, 0.0])
    q = np.array([0.3, -0.7, 1.1])
    cs = g.field_jacobian(f, q)
    fd = g.field_jacobian(lambda x: f(np.real(x).astype(float)), q)
    np.testing.assert_allclose(cs, fd, atol=1e-9)


@pytest.mark.parametrize("seed", range(5))
def test_lemma_4_1_pulled_back_fields_are_not_involutive(seed):
    q = np.random.default_rng(seed).uniform(-2, 2, 3)
    f1, f2 = _pinv_field([1.0, 0.0]), _pinv_field([0.0, 1.0])
    assert abs(g.bracket_determinant(f1, f2, q)) > 1e-3
    assert not g.is_involutive([f1, f2], q)


@pytest.mark.parametrize("seed", range(5))
def test_lemma_4_1_printed_fields_give_the_printed_determinant_up_to_sign(seed):
    """The thesis's f₁, f₂ with its det[f₁, f₂, [f₁, f₂]] = −(1 + q₁²)²: our bracket has
    the opposite sign convention, so +(1 + q₁²)²."""
    q = np.random.default_rng(seed).uniform(-2, 2, 3)

    def t1(q):
        return np.array([1 + q[2] ** 2, q[2], q[0] * q[2]])

    def t2(q):
        s = 1 + q[0] ** 2 + q[2] ** 2
        return np.array([q[2] * (2 + q[0] ** 2 + q[2] ** 2), s, q[0] * s])

    np.testing.assert_allclose(g.bracket_determinant(t1, t2, q), (1 + q[0] ** 2) ** 2, rtol=1e-10)


def test_example_4_3_planar_3r_pinv_fields():
    """Ex 4.3: J⁺ pulls the trivially involutive (1, 0), (0, 1) back to non-involutive
    fields. Eq. 4.6's first two components match J⁺e₁; its third has the opposite sign
    (a typo: ours is the exact pseudo-inverse, J f₁ = e₁)."""
    arm = qc.robots.load("planar_3r")
    F1 = g.PseudoInverseField(arm, [1.0, 0.0])
    F2 = g.PseudoInverseField(arm, [0.0, 1.0])
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(-np.pi, np.pi, 3)
        np.testing.assert_allclose(arm.jacobian(q) @ F1(q), [1.0, 0.0], atol=1e-12)
        assert abs(g.bracket_determinant(F1, F2, q)) > 1e-6
        q1, q2, q3 = q
        alpha = -3 + np.cos(2 * q1 - 2 * q2) + np.cos(2 * q1 - 2 * q3) + np.cos(2 * q2 - 2 * q3)
        eq46 = (
            np.array(
                [
                    2 * np.sin(q1) + np.sin(q1 - 2 * q2) + np.sin(q1 - 2 * q3),
                    -np.sin(2 * q1 - q2) + 2 * np.sin(q2) + np.sin(q2 - 2 * q3),
                    np.sin(2 * q1 - q3) + np.sin(2 * q2 - q3) - 2 * np.sin(q3),
                ]
            )
            / alpha
        )
        np.testing.assert_allclose(F1(q)[:2], eq46[:2], atol=1e-12)
        np.testing.assert_allclose(F1(q)[2], -eq46[2], atol=1e-12)


def test_pseudo_inverse_field_jacobian_is_analytic_and_right():
    arm = qc.robots.load("spatial_5r")
    F = g.PseudoInverseField(arm, [0.1, -0.2, 0.3])
    q = qc.robots.spatial_5r.Q0_THESIS
    fd = g.field_jacobian(lambda x: F(np.real(x).astype(float)), q)
    np.testing.assert_allclose(F.jacobian(q), fd, atol=1e-8)


def test_theorem_4_2_dual_fields_are_involutive_and_span_the_stack_solutions():
    """Ex 4.4 on the 5R: f₁, f₂ dual to (ω₁, ω₄, ω₅) are involutive, and every velocity of
    the Thm 4.2 stack (sphere task + ω₄, ω₅ hard) lies in their span."""
    arm = qc.robots.load("spatial_5r")
    path = qc.paths.LissajousSphere()
    c = path.center
    forms = qc.schemes.sphere_forms(arm, c, OMEGA_45)

    q0 = qc.inverse_kinematics(arm, path.position(0.0), qc.robots.spatial_5r.Q0_THESIS)
    # the fields as functions of q (orientation carried from a reference basis)
    ref = g.dual_fields(forms, q0)
    f1 = lambda q: g.dual_fields(forms, q, previous=ref)[:, 0]  # noqa: E731
    f2 = lambda q: g.dual_fields(forms, q, previous=ref)[:, 1]  # noqa: E731
    assert g.involutivity_defect([f1, f2], q0) < 1e-7
    ik = qc.IK(
        arm, [qc.PositionTask(arm, gain=10.0)], 0.01, constraints=[qc.OneFormTask(arm, OMEGA_45)]
    )
    traj = qc.simulate(arm, ik, path, q0, duration=3.0, dt=0.01)
    for k in (0, 100, 300):
        basis = g.dual_fields(forms, traj.q[k])
        qdot = traj.qdot[k]
        # on the sphere (tracking error ~1e-9 m) ω₁ q̇ = 0, so q̇ ∈ span{f₁, f₂}
        resid = qdot - basis @ (basis.T @ qdot)
        assert np.linalg.norm(resid) < 1e-7 * max(1.0, np.linalg.norm(qdot))


def test_dual_fields_keep_their_orientation_along_a_path():
    W = lambda q: np.array([[np.cos(q[0]), np.sin(q[0]), 0.0]])  # noqa: E731
    prev = g.dual_fields(W, [0.0, 0.0, 0.0])
    for a in np.linspace(0.0, 3.0, 60):
        N = g.dual_fields(W, [a, 0.0, 0.0], previous=prev)
        assert np.linalg.norm(N - prev) < 0.1  # no flips between close points
        np.testing.assert_allclose(W([a, 0, 0]) @ N, 0.0, atol=1e-12)
        prev = N


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="dependent"):
        g.dual_fields(np.array([[1.0, 0, 0], [2.0, 0, 0]]), [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="columns"):
        g.dual_fields(np.ones((1, 2)), [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="returned 2 values"):
        g.lie_bracket(lambda q: q[:2], lambda q: q, [0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="dependent"):
        g.involutivity_defect([lambda q: q, lambda q: 2 * q], [0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="3-D"):
        g.bracket_determinant(lambda q: q, lambda q: q, [0.1, 0.2])
    with pytest.raises(ValueError, match="singular"):
        g.PseudoInverseField(qc.robots.load("planar_3r"), [1.0, 0.0])(np.zeros(3))
