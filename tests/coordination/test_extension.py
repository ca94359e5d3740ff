"""qpcoord.coordination.extensions: Def. 5.2 (rigid), Defs. 5.3/5.4 (soft, prioritised), Prop. 5.1,
Thm 5.1."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import qpcoord as qc
from qpcoord.coordination.extensions import RigidExtension, SoftExtension
from qpcoord.coordination.periodicity import closure_errors
from qpcoord.coordination.potentials import FunctionPotential, JointCentring
from qpcoord.kinematics.paths import Path

ARM3 = qc.robots.load("planar_3r")
ARM5 = qc.robots.load("spatial_5r")
ARM6 = qc.robots.load("planar_nr", n=6)
CIRCLE = qc.paths.Circle()
LISSAJOUS = qc.paths.LissajousSphere()
Q0 = np.array([0.0, np.pi / 3, -np.pi / 3])  # thesis Fig. 5.9 start, tip at (2, 0)


class Fixed(Path):
    """A constant end-effector reference (Prop. 5.1)."""

    dim = 2

    def __init__(self, point):
        self.point = np.asarray(point, dtype=float)

    def _eval(self, t):
        n = t.shape[0]
        return np.tile(self.point, (n, 1)), np.zeros((n, 2)), np.zeros((n, 2))


def test_one_potential_is_def_5_3():
    """q̇ = J⁺Ẏ + (I − J⁺J)(−∇gᵀ g) with the plain pseudo-inverse."""
    g = JointCentring(np.pi / 2, 1.3, joints=[0])
    q = np.array([0.2, 0.9, -0.4])
    t = 0.3
    J = ARM3.jacobian(q)
    Jp = np.linalg.pinv(J)
    val, grad = g.evaluate(q)
    expected = Jp @ CIRCLE.velocity(t) + (np.eye(3) - Jp @ J) @ (-grad * val)
    for method in ("nullspace", "hierarchical"):
        got = SoftExtension(ARM3, g, method=method).velocity(q, t, CIRCLE)
        np.testing.assert_allclose(got, expected, atol=1e-12, err_msg=method)


def _stack_cases():
    rng = np.random.default_rng(7)
    pots5 = [JointCentring(0.3, 1.0, joints=[3]), JointCentring(-0.2, 2.0, joints=[4])]
    pots6 = [
        JointCentring(0.5, 1.0, joints=[1]),
        JointCentring(0.0, 1.0, joints=[2, 3]),
        JointCentring(0.2, 0.5),
    ]
    circle6 = qc.paths.Circle(center=(3.0, 0.5), radius=0.8, period=5.0)
    return rng, [(ARM5, pots5, LISSAJOUS), (ARM6, pots6, circle6)]


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_projection_formula_and_strict_qp_agree_on_equality_stacks(seed):
    """Def. 5.4's nested projections = the lexicographic QP when no inequality is active."""
    rng = np.random.default_rng(seed)
    _, cases = _stack_cases()
    for arm, pots, path in cases:
        q = rng.uniform(-1.2, 1.2, arm.nq)
        t = float(rng.uniform(0, 5))
        a = SoftExtension(arm, pots, method="nullspace", gain=3.0).velocity(q, t, path)
        S = SoftExtension(arm, pots, method="hierarchical", gain=3.0)
        b = S.velocity(q, t, path)
        np.testing.assert_allclose(b, a, atol=1e-9 * max(1.0, np.abs(a).max()))


def test_lower_levels_never_disturb_higher_ones():
    """Def. 5.4: adding g₃ changes neither Ẏ nor the rates of g₁, g₂."""
    _, cases = _stack_cases()
    arm, pots, path = cases[1]
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = rng.uniform(-1.2, 1.2, arm.nq)
        J = arm.jacobian(q)
        two = SoftExtension(arm, pots[:2], method="nullspace").velocity(q, 1.0, path)
        three_s = SoftExtension(arm, pots, method="nullspace")
        three = three_s.velocity(q, 1.0, path)
        np.testing.assert_allclose(J @ three, path.velocity(1.0), atol=1e-12)
        np.testing.assert_allclose(J @ three, J @ two, atol=1e-12)
        for g in pots[:2]:
            grad = g.gradient(q)
            assert grad @ three == pytest.approx(grad @ two, abs=1e-11)
        assert three_s.info["free_dofs"].tolist() == [4, 3, 2]
        assert not np.allclose(three, two)  # the third level does act


def test_only_the_qp_keeps_limits_hard():
    """The formula exceeds a speed limit; the strict QP keeps it and still tracks Ẏ."""
    g = JointCentring(np.pi / 2, 1.0, joints=[0])
    formula = SoftExtension(ARM3, g, method="nullspace").velocity(Q0, 0.0, CIRCLE)
    assert np.abs(formula).max() > 3.0  # (3.25, −2.25, −2.25) rad/s
    limits = [qc.VelocityLimits(ARM3, 2.0)]
    S = SoftExtension(ARM3, g, method="hierarchical", limits=limits)
    qdot = S.velocity(Q0, 0.0, CIRCLE)
    assert np.abs(qdot).max() <= 2.0 + 1e-9
    np.testing.assert_allclose(ARM3.jacobian(Q0) @ qdot, CIRCLE.velocity(0.0), atol=1e-8)
    assert S.last.level_residuals[0] < 1e-8
    assert S.last.level_residuals[1] > 1e-3  # g's rate is cut by the limit
    with pytest.raises(ValueError, match="nullspace.*limits"):
        SoftExtension(ARM3, g, method="nullspace", limits=limits)


def test_a_level_without_freedom_is_reported_not_faked():
    pots = [JointCentring(0.0, 1.0, joints=[0]), JointCentring(0.0, 1.0, joints=[1])]
    S = SoftExtension(ARM3, pots, method="nullspace")
    qdot = S.velocity(np.array([0.2, 0.9, -0.4]), 0.0, CIRCLE)
    assert np.all(np.isfinite(qdot))
    assert S.info["achievable"].tolist() == [True, False]
    assert S.info["free_dofs"].tolist() == [1, 0]


def test_bad_input():
    g = JointCentring(0.0, 1.0)
    with pytest.raises(ValueError, match="no redundancy"):
        SoftExtension(qc.robots.load("planar_nr", n=2), g)
    with pytest.raises(ValueError, match="method"):
        SoftExtension(ARM3, g, method="weighted")
    with pytest.raises(ValueError, match=r"potentials\[0\]"):
        SoftExtension(ARM3, [lambda q: q])
    with pytest.raises(ValueError, match="scale"):
        SoftExtension(ARM3, g, scale=-1.0)
    nan = FunctionPotential(lambda q: 1.0, lambda q: q * np.nan, name="nan potential")
    with pytest.raises(ValueError, match="nan potential"):
        SoftExtension(ARM3, nan).velocity(Q0, 0.0, CIRCLE)


def test_prop_5_1_self_motion_converges_to_a_fixed_point():
    """Fixed end effector, convex g: V = g decreases and q stops where ∇g ⟂ the fibre."""
    g = JointCentring([0.4, 0.4, 0.4], 1.0)
    q0 = np.array([0.0, np.pi / 3, -np.pi / 3])
    target = Fixed(ARM3.position(q0))
    S = SoftExtension(ARM3, g, method="nullspace", gain=5.0)
    tr = qc.simulate(ARM3, S, target, q0, duration=15.0, dt=0.02, start="q0")
    V = np.array([g.value(q) for q in tr.q])
    assert np.max(np.diff(V)) <= 1e-12
    q_end = tr.q[-1]
    n = qc.task_manifold.self_motion_direction(ARM3, q_end)
    assert abs(g.gradient(q_end) @ n) < 1e-6  # stationary on the fibre
    assert np.linalg.norm(tr.qdot[-1]) < 1e-6
    assert tr.max_error < 1e-6


def test_thm_5_1_converges_to_a_limit_cycle_and_j_plus_does_not():
    T = CIRCLE.period
    g = JointCentring(np.pi / 2, 3.0, joints=[0])
    S = SoftExtension(ARM3, g, method="nullspace", gain=10.0)
    tr = qc.simulate(ARM3, S, CIRCLE, Q0, duration=7 * T, dt=T / 100, start="q0")
    e = closure_errors(tr, T)
    assert e[0] > 0.1  # not periodic at first
    assert np.all(e[4:] < 1e-6)  # measured: < 1e-6 from the 5th period
    free = qc.simulate(
        ARM3, qc.schemes.PseudoInverse(ARM3, gain=10.0), CIRCLE, Q0, 3 * T, T / 100, start="q0"
    )
    assert np.all(closure_errors(free, T) > 1e-3)  # Remark 5.2: J⁺ drifts


def test_hard_joint_limits_hold_over_a_run_while_the_potential_pushes_past_them():
    """Thm 5.1's g pulls q₁ toward π/2; a hard upper limit q₁ ≤ 0.5 holds on every step."""
    g = JointCentring(np.pi / 2, 1.0, joints=[0])
    dt = CIRCLE.period / 400
    upper = np.array([0.5, np.inf, np.inf])
    limits = [qc.JointLimits(ARM3, lower=-np.inf, upper=upper)]
    S = SoftExtension(ARM3, g, gain=10.0, limits=limits, dt=dt)
    tr = qc.simulate(ARM3, S, CIRCLE, Q0, 2 * CIRCLE.period, dt, integrator="euler", start="q0")
    assert tr.q[:, 0].max() <= 0.5 + 1e-9
    assert tr.q[:, 0].max() > 0.5 - 1e-3  # the limit is reached: it binds
    free = SoftExtension(ARM3, g, gain=10.0, method="nullspace")
    tr_free = qc.simulate(
        ARM3, free, CIRCLE, Q0, 2 * CIRCLE.period, dt, integrator="euler", start="q0"
    )
    assert tr_free.q[:, 0].max() > 1.0  # without the limit the potential takes q₁ past it
    assert tr.max_error < 0.01  # measured 5.9e-3 m (Euler, 400 steps per period)


def test_rigid_extension_reports_an_algorithmic_singularity():
    """[J; e₁] is singular where links 2 and 3 align although J has full rank."""
    R = RigidExtension(ARM3, [[1.0, 0.0, 0.0]])
    ok = R.velocity(Q0, 0.0, CIRCLE)
    np.testing.assert_allclose(ARM3.jacobian(Q0) @ ok, CIRCLE.velocity(0.0), atol=1e-10)
    assert ok[0] == pytest.approx(0.0, abs=1e-12)
    q_sing = np.array([0.0, 0.5, 0.5])
    assert np.linalg.matrix_rank(ARM3.jacobian(q_sing)) == 2
    with pytest.raises(qc.AlgorithmicSingularity) as err:
        R.velocity(q_sing, 1.25, CIRCLE)
    np.testing.assert_array_equal(err.value.q, q_sing)
    assert err.value.t == 1.25 and err.value.sigma < 1e-6
    assert "q = [0.0, 0.5, 0.5]" in str(err.value)
    with pytest.raises(ValueError, match="square"):
        RigidExtension(ARM3, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def test_rigid_extension_response_is_periodic():
    """Def. 5.2: a unique solution, so a closed path gives closed joint paths."""
    T = CIRCLE.period
    R = RigidExtension(ARM3, [[0.0, 1.0, 1.0]], gain=10.0)
    tr = qc.simulate(ARM3, R, CIRCLE, Q0, duration=3 * T, dt=T / 100, start="q0")
    assert np.all(closure_errors(tr, T)[1:] < 1e-9)
    assert R.sigma_min > 1e-3
