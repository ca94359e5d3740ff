"""qpcoord.coordination.schemes (chapter 4): what each scheme computes, checked against its
formula."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc
from qpcoord import geometry as g
from qpcoord import schemes as S

OMEGA_45 = np.array([[1.0, 0, 0, 0, 1.0], [0, 1.0, 0, 1.0, 0]])


@pytest.fixture(scope="module")
def arm():
    return qc.robots.load("spatial_5r")


@pytest.fixture(scope="module")
def path():
    return qc.paths.LissajousSphere()


@pytest.fixture(scope="module")
def q_on_path(arm, path):
    return qc.inverse_kinematics(arm, path.position(0.0), qc.robots.spatial_5r.Q0_THESIS)


def test_pseudo_inverse_is_eq_4_1(arm, path, q_on_path):
    qdot = S.PseudoInverse(arm).velocity(q_on_path, 0.0, path)
    expected = np.linalg.pinv(arm.jacobian(q_on_path)) @ path.velocity(0.0)
    np.testing.assert_allclose(qdot, expected, atol=1e-12)


def test_output_manifold_basis_equals_the_pseudo_inverse_on_the_sphere(arm, path, q_on_path):
    """Eq. 4.3 is J⁺ of a tangent Ẏ written in (v₁, v₂): by linearity it is J⁺Ẏ."""
    a = S.OutputManifoldBasis(arm, path.center).velocity(q_on_path, 0.0, path)
    b = S.PseudoInverse(arm).velocity(q_on_path, 0.0, path)
    np.testing.assert_allclose(a, b, atol=1e-12)


def test_sphere_basis_is_tangent_and_involutive(path):
    c = path.center
    for t in np.linspace(0.0, path.period, 7):
        y = path.position(t)
        v1, v2 = S.sphere_basis(y, c)
        np.testing.assert_allclose([v1 @ (y - c), v2 @ (y - c)], 0.0, atol=1e-14)
    # as fields on R³: [v₁, v₂] lies in their span away from x = c_x
    f1 = lambda y: S.sphere_basis(y, c)[0]  # noqa: E731
    f2 = lambda y: S.sphere_basis(y, c)[1]  # noqa: E731
    assert g.is_involutive([f1, f2], path.position(1.0))


def test_involutive_basis_is_the_theorem_4_2_construction(arm, path, q_on_path):
    """q̇ of the constrained stack = α f₁ + β f₂ with f dual to (ω₁, ω₄, ω₅) and
    Ẏ = α J f₁ + β J f₂."""
    q = q_on_path
    qdot = S.InvolutiveBasis(arm, OMEGA_45).velocity(q, 0.0, path)
    F = g.dual_fields(S.sphere_forms(arm, path.center, OMEGA_45), q)  # 5 × 2
    V = arm.jacobian(q) @ F  # v₁, v₂ = J f₁, J f₂ (a basis of the sphere's tangent plane)
    ab = np.linalg.lstsq(V, path.velocity(0.0), rcond=None)[0]
    np.testing.assert_allclose(V @ ab, path.velocity(0.0), atol=1e-12)  # Ẏ ∈ span{v}
    np.testing.assert_allclose(qdot, F @ ab, atol=1e-12)
    np.testing.assert_allclose(OMEGA_45 @ qdot, 0.0, atol=1e-14)


def test_output_basis_degenerates_on_the_equator_line(arm):
    center = arm.position(np.zeros(5)) - np.array([0.0, 1.0, 0.0])  # x = c_x at q = 0
    sch = S.OutputManifoldBasis(arm, center)
    with pytest.raises(ValueError, match="degenerates"):
        sch.velocity(np.zeros(5), 0.0, qc.paths.LissajousSphere())


def test_sphere_forms_checks_sizes(arm):
    with pytest.raises(ValueError, match="center must have 3 entries"):
        S.sphere_forms(arm, [0.0, 0.0], OMEGA_45)


def test_schemes_reject_bad_robots():
    with pytest.raises(ValueError, match="qpcoord.Robot"):
        S.PseudoInverse("arm")
    with pytest.raises(ValueError, match="3 task rows"):
        S.OutputManifoldBasis(qc.robots.load("planar_3r"), [0.0, 0.0, 0.0])


def test_lemma_4_2_self_motion_changes_the_leaf_and_the_new_leaf_is_periodic(arm, path, q_on_path):
    """A self-motion R (J R = 0) is not tangent to a leaf: [J; ω₄; ω₅] R ≠ 0."""
    J = arm.jacobian(q_on_path)
    R = np.linalg.svd(J)[2][3:].T  # self-motion basis (5 × 2)
    assert np.linalg.svd(OMEGA_45 @ R, compute_uv=False)[-1] > 0.1
    q_leaf = qc.inverse_kinematics(arm, path.position(0.0), q_on_path + 0.3 * R[:, 0])
    assert np.abs(OMEGA_45 @ (q_leaf - q_on_path)).max() > 0.01  # another leaf
    dt = path.period / 200
    traj = qc.simulate(
        arm,
        S.InvolutiveBasis(arm, OMEGA_45, gain=10.0),
        path,
        q_leaf,
        2 * path.period,
        dt,
        start="q0",
    )
    leaf = traj.q @ OMEGA_45.T
    np.testing.assert_allclose(leaf, np.tile(leaf[0], (len(leaf), 1)), atol=1e-12)
    assert qc.analysis.closure_errors(traj, path.period)[1] < 1e-9
