"""qpcoord.coordination.potentials: values, analytic gradients and Hessians, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import qpcoord as qc
from qpcoord import potentials as P

ARM3 = qc.robots.load("planar_3r")
ARM5 = qc.robots.load("spatial_5r")


def fd_gradient(pot, q, h=1e-6):
    out = np.empty(q.size)
    for i in range(q.size):
        e = np.zeros(q.size)
        e[i] = h
        out[i] = (pot.value(q + e) - pot.value(q - e)) / (2 * h)
    return out


def fd_hessian(pot, q, h=1e-5):
    H = np.empty((q.size, q.size))
    for i in range(q.size):
        e = np.zeros(q.size)
        e[i] = h
        H[:, i] = (pot.gradient(q + e) - pot.gradient(q - e)) / (2 * h)
    return H


def potentials_3r():
    lower, upper = np.full(3, -2.0), np.full(3, 2.5)
    return [
        P.JointCentring(np.pi / 2, 3.0, joints=[0]),
        P.JointCentring([0.1, -0.2, 0.3], 0.5),
        P.JointLimitAvoidance(lower, upper, alpha=2.0),
        P.PointDistance(ARM3, [1.5, 0.0], radius=0.5),
        P.ObstacleDistance(ARM3.with_frame("link2"), [0.5, 1.5], influence=3.0, alpha=0.7),
        P.Manipulability(ARM3, alpha=0.3),
        2.0 * P.JointCentring(0.0, 1.0) + P.Manipulability(ARM3),
    ]


configs = st.lists(st.floats(-1.5, 1.5), min_size=3, max_size=3).map(np.array)


@settings(max_examples=25, deadline=None)
@given(q=configs)
def test_gradients_match_finite_differences(q):
    for pot in potentials_3r():
        try:
            g = pot.gradient(q)
        except ValueError:  # singular configuration for Manipulability: skip that one
            continue
        scale = max(1.0, float(np.abs(g).max()))
        # near a singular configuration (distance d = σ_min/σ_max of J) the manipulability
        # potential varies on the scale d: a central difference needs h ≪ d (its error is
        # ~ (h/d)², 2 % at q = (0, 0, 1e-5) with h = 1e-6, found by hypothesis), and below
        # d ≈ 1e-4 no step resolves it in float64 (round-off ~ eps·f/h): not checkable by FD
        h = 1e-6
        if "manipulability" in pot.name:
            s = np.linalg.svd(ARM3.jacobian(q), compute_uv=False)
            if s[-1] < 1e-4 * s[0]:
                continue
            h = min(1e-6, 1e-3 * s[-1] / s[0])
        np.testing.assert_allclose(g, fd_gradient(pot, q, h=h), atol=2e-6 * scale, err_msg=pot.name)


@settings(max_examples=20, deadline=None)
@given(q=configs)
def test_analytic_hessians_match_finite_differences(q):
    for pot in potentials_3r()[:4]:  # the ones with an analytic Hessian
        H = pot.hessian(q)
        np.testing.assert_allclose(H, H.T, atol=1e-12)
        scale = max(1.0, float(np.abs(H).max()))
        np.testing.assert_allclose(H, fd_hessian(pot, q), atol=1e-5 * scale, err_msg=pot.name)


def test_circle_task_hessian_on_the_5r_sphere_matches_finite_differences():
    """Eq. 5.16 for the Lissajous sphere task of the 5R."""
    path = qc.paths.LissajousSphere()
    h = P.PointDistance(ARM5, path.center, path.radius)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(-1.5, 1.5, 5)
        np.testing.assert_allclose(h.hessian(q), fd_hessian(h, q), atol=1e-6)
        np.testing.assert_allclose(h.gradient(q), fd_gradient(h, q), atol=1e-7)


def test_thesis_potential_values():
    g = P.JointCentring(np.pi / 2, 2.0, joints=[0])
    q = np.array([0.0, 1.0, -1.0])
    assert g.value(q) == pytest.approx(2.0 * (np.pi / 2) ** 2)
    np.testing.assert_allclose(g.gradient(q), [-2 * 2.0 * np.pi / 2, 0, 0])
    h = P.PointDistance(ARM3, [1.5, 0.0], 0.5)
    assert h.value([0.0, np.pi / 3, -np.pi / 3]) == pytest.approx(0.0, abs=1e-14)
    lim = P.JointLimitAvoidance([-1, -1], [1, 3])
    assert lim.value([0.0, 1.0]) == pytest.approx(0.0, abs=1e-15)  # mid-range
    assert lim.value([0.5, 1.0]) > 0


def test_sum_and_scale():
    a, b = P.JointCentring(0.0, 1.0), P.JointCentring(1.0, 2.0)
    s = a + 3.0 * b
    q = np.array([0.3, -0.2, 0.9])
    assert s.value(q) == pytest.approx(a.value(q) + 3 * b.value(q))
    np.testing.assert_allclose(s.hessian(q), a.hessian(q) + 3 * b.hessian(q))
    assert len((s + a).terms) == 3  # sums flatten


def test_evaluate_names_a_bad_user_potential():
    nan = P.FunctionPotential(lambda q: 1.0, lambda q: np.full(q.size, np.nan), name="broken")
    with pytest.raises(ValueError, match="broken.*not finite"):
        nan.evaluate([0.0, 0.0, 0.0])
    short = P.FunctionPotential(lambda q: 1.0, lambda q: np.zeros(2), name="short")
    with pytest.raises(ValueError, match="short.*3 entries"):
        short.evaluate([0.0, 0.0, 0.0])
    vec = P.FunctionPotential(lambda q: q, lambda q: q, name="vector")
    with pytest.raises(ValueError, match="vector.*value"):
        vec.evaluate([0.0, 1.0, 2.0])


@pytest.mark.parametrize("alpha", [0.0, -1.0, np.nan, np.inf, "1"])
def test_alpha_must_be_positive(alpha):
    with pytest.raises(ValueError, match="alpha"):
        P.JointCentring(0.0, alpha)


def test_bad_arguments():
    with pytest.raises(ValueError, match="joints"):
        P.JointCentring(0.0, 1.0, joints=[0, 0])
    with pytest.raises(ValueError, match="one per joint"):
        P.JointCentring([0.0, 1.0, 2.0], 1.0, joints=[0, 1])
    with pytest.raises(ValueError, match="out of range"):
        P.JointCentring(0.0, 1.0, joints=[5]).value([0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="no joint has finite"):
        P.JointLimitAvoidance([-np.inf], [np.inf])
    with pytest.raises(ValueError, match="not below"):
        P.JointLimitAvoidance([1.0], [0.0])
    with pytest.raises(ValueError, match=r"q\[1\].*outside"):
        P.JointLimitAvoidance([-1, -1], [1, 1]).value([0.0, 1.0])
    with pytest.raises(ValueError, match="radius"):
        P.PointDistance(ARM3, [0, 0], radius=-1)
    with pytest.raises(ValueError, match="on the obstacle"):
        P.ObstacleDistance(ARM3, [3.0, 0.0], influence=1.0).value([0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="singular"):
        P.Manipulability(ARM3).value([0.0, 0.0, 0.0])


def test_obstacle_potential_vanishes_outside_its_influence():
    pot = P.ObstacleDistance(ARM3, [10.0, 0.0], influence=1.0)
    q = np.array([0.2, 0.1, -0.1])
    assert pot.value(q) == 0.0
    np.testing.assert_array_equal(pot.gradient(q), np.zeros(3))
