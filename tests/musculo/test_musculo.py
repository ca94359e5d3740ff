"""Muscle-force sharing (appendix A): the Stack against a cvxpy reference on every backend,
against the thesis's two-step method, invariants (hypothesis) and bad input.

Reference: cvxpy + Clarabel on the thesis problem written directly, in activations
``a = F / F_max`` (with one muscle stress σ, ``Σ (F/PCSA)² = σ² Σ a²``):

- Q within reach: ``min Σ a²`` s.t. ``W diag(F_max) a = Q``, ``0 ≤ a ≤ 1``;
- Q out of reach: first ``min ‖W diag(F_max) a − Q‖²`` s.t. ``0 ≤ a ≤ 1``, giving the
  closest producible ``Q*`` (unique: the objective is strictly convex in ``W F``), then the
  first problem with ``Q*``.

Tolerance: ``|F − F_ref| ≤ 1e-6 · F_max`` per muscle (Clarabel at 1e-11 is far inside it).
"""

from __future__ import annotations

import functools

import cvxpy as cp
import numpy as np
import pytest
from conftest import SOLVERS
from hypothesis import given, settings
from hypothesis import strategies as st

import qpcoord as qc
from qpcoord import musculo
from qpcoord.core import native
from qpcoord.robots import shoulder

F_TOL = 1e-6  # × F_max
CLARABEL = dict(tol_gap_abs=1e-11, tol_gap_rel=1e-11, tol_feas=1e-11, max_iter=400)

MODEL = qc.robots.load("shoulder")


def _case(k: int):
    """Seeded posture and load. k < 6: Q = W F0 with F0 admissible (within reach; k ≥ 3
    have muscles at F_max in F0, so bounds are active at the optimum); k ≥ 6: far beyond
    what the muscles can produce."""
    rng = np.random.default_rng(1000 + k)
    q = MODEL.lower + rng.uniform(0.05, 0.95, 3) * (MODEL.upper - MODEL.lower)
    W = MODEL.moment_arms(q)
    a0 = rng.uniform(0.0, 1.0, 11) ** 2
    if k >= 3:
        a0[rng.choice(11, 3, replace=False)] = 1.0
    Q = W @ (a0 * MODEL.f_max)
    if k >= 6:
        Q = 3.0 * Q + rng.normal(0.0, 40.0, 3)
    return q, Q


CASES = list(range(8))


@functools.cache
def _reference(k: int) -> np.ndarray:
    q, Q = _case(k)
    A = MODEL.moment_arms(q) * MODEL.f_max  # N·m per unit activation
    a = cp.Variable(11)
    box = [a >= 0, a <= 1]
    target = Q
    if k >= 6:
        p = cp.Problem(cp.Minimize(cp.sum_squares(A @ a - Q) / 100.0), box)
        p.solve(solver=cp.CLARABEL, **CLARABEL)
        assert p.status == cp.OPTIMAL
        target = A @ a.value
    p = cp.Problem(cp.Minimize(cp.sum_squares(a)), [A @ a == target, *box])
    p.solve(solver=cp.CLARABEL, **CLARABEL)
    assert p.status == cp.OPTIMAL
    return a.value * MODEL.f_max


def _check_forces(F, F_ref):
    err = np.abs(F - F_ref) / MODEL.f_max
    assert err.max() <= F_TOL, f"max |F − F_ref|/F_max = {err.max():.2e}"


@pytest.mark.parametrize("solver", SOLVERS)
def test_stack_matches_cvxpy(solver):
    for k in CASES:
        q, Q = _case(k)
        d = musculo.distribute(MODEL, q, Q, solver=solver)
        _check_forces(d.forces, _reference(k))
        _check_forces(d.solution.x, _reference(k))  # the stack's own point, before polish
        assert d.bound_violation <= 1e-9 * MODEL.f_max.max()
        if k < 6:
            assert d.feasible and d.relative_residual <= 1e-9, (k, d.relative_residual)
        else:  # best effort: the top level is not met and the result says so
            assert not d.feasible
            assert d.solution.level_residuals[0] == pytest.approx(d.residual, rel=1e-6)
            assert d.residual > 1.0  # N·m
            assert d.saturated.any()


@pytest.mark.parametrize("solver", SOLVERS)
def test_two_step_gives_the_stack_forces(solver):
    ks = [0, 3, 4] if solver == "scs" else CASES[:6]  # scs: ~1 s per null-space QP
    for k in ks:
        q, Q = _case(k)
        two = musculo.two_step(MODEL, q, Q, solver=solver)
        one = musculo.distribute(MODEL, q, Q, solver="quadprog")
        _check_forces(two.forces, one.forces)
        _check_forces(two.forces, _reference(k))
        assert two.relative_residual <= 1e-9 and two.bound_violation <= 1e-9 * 1739.0


def test_two_step_reports_its_steps():
    q, Q = _case(4)
    two = musculo.two_step(MODEL, q, Q)
    assert two.info["qp"]  # the pseudo-inverse left the bounds (case with saturation)
    F_eff = two.info["F_eff"]
    assert (F_eff < 0).any() or (F_eff > MODEL.f_max).any()
    W = MODEL.moment_arms(q)
    assert np.allclose(W @ F_eff, Q, rtol=1e-12, atol=1e-12 * np.abs(Q).max())
    # the null-space QP of Eq. A.28 needs no linear term: Nᵀ E F_eff = 0
    import scipy.linalg

    N = scipy.linalg.null_space(W)
    e = 1.0 / MODEL.pcsa**2
    g = N.T @ (e * F_eff)
    assert np.abs(g).max() <= 1e-12 * np.abs(e * F_eff).max()


#: A posture where E⁻¹Wᵀλ > 0 for some λ (rare: 2 of 2000 random postures/λ, seed 0;
#: for almost every load the pseudo-inverse of Eq. A.22 asks some muscle to push).
Q_POS = np.radians([14.0, 65.3, -81.3])
LAMBDA_POS = np.array([0.844, -0.102, -0.35])


def test_inside_the_bounds_the_answer_is_the_weighted_pseudo_inverse(monkeypatch):
    # the counts of QP calls below are about the Python engine's method (Eq. A.22's closed
    # form accepted up to s = 1 inclusive); the native engine gives the same forces but at
    # s = 1 exactly (a muscle at F_max) its top level's closed-form candidate breaks the
    # bound and its active set runs (qp_calls 1): pin the Python engine for this test
    monkeypatch.setattr(native, "DEFAULT_ENGINE", "python")
    W = MODEL.moment_arms(Q_POS)
    E_inv = MODEL.pcsa**2
    F_dir = E_inv * (W.T @ LAMBDA_POS)
    assert (F_dir > 0).all()
    F_dir *= 1.0 / np.max(F_dir / MODEL.f_max)  # s = 1: first muscle reaches F_max
    beyond = 0
    for s in np.linspace(0.0, 2.0, 9):
        Q = W @ (s * F_dir)
        d = musculo.distribute(MODEL, Q_POS, Q)
        assert d.bound_violation == 0.0
        if not d.feasible:
            assert s > 1.0
            with pytest.raises(qc.InfeasibleError):
                musculo.two_step(MODEL, Q_POS, Q)
            continue
        two = musculo.two_step(MODEL, Q_POS, Q)
        _check_forces(two.forces, d.forces)
        if s <= 1.0:  # Eq. A.22 within the bounds: closed form, no QP, linear in Q
            np.testing.assert_allclose(d.forces, s * F_dir, rtol=1e-12, atol=1e-10)
            assert d.solution.info["qp_calls"] == 0 and not two.info["qp"]
        else:  # beyond: a bound is active and the null-space QP runs
            assert d.saturated.any() and two.info["qp"]
            assert d.solution.info["qp_calls"] > 0
            beyond += 1
    assert beyond >= 1


def test_out_of_reach_two_step_raises_and_stack_is_best_effort():
    q, Q = _case(6)
    with pytest.raises(qc.InfeasibleError, match="beyond what the muscles can produce"):
        musculo.two_step(MODEL, q, Q)
    d = musculo.distribute(MODEL, q, Q)
    assert not d.feasible and d.relative_residual > 1e-3
    # moving W F towards Q from the best effort is impossible within the bounds: the
    # residual direction is blocked (checked by the reference's first stage)
    _check_forces(d.forces, _reference(6))


def test_just_out_of_reach_is_reported_as_best_effort():
    """A load a hair beyond the muscles' capacity: small top-level miss, still reported
    as not feasible (the polish cannot turn it into an exact answer)."""
    q = np.radians([-90.0, 0.0, 0.0])
    z = np.zeros(3)

    def Q_for(mass):  # a weight in the hand, 0.62 m from the GH centre
        return MODEL.generalised_forces(q, z, z, MODEL.point_load_moment(q, mass, 0.62))

    share = musculo.MuscleSharing(MODEL)
    lo, hi = 0.0, 30.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if share.solve(q, Q_for(mid)).feasible else (lo, mid)
    assert 10.0 < lo < 20.0  # kg; measured 13.75 (element lines; 14.53 lumped)
    d = share.solve(q, Q_for(hi * 1.0001))
    assert not d.feasible and 0.0 < d.relative_residual < 1e-3
    assert d.bound_violation == 0.0 and d.saturated.any()
    with pytest.raises(qc.InfeasibleError):
        musculo.two_step(MODEL, q, Q_for(hi * 1.0001))
    assert share.solve(q, Q_for(lo)).feasible


def test_activations_are_eq_A31():
    q, Q = _case(3)
    d = musculo.distribute(MODEL, q, Q)
    assert np.allclose(d.activations, d.forces / MODEL.f_max)
    assert np.allclose(musculo.activations(MODEL, d.forces), d.activations)
    assert np.allclose(d.stresses, d.activations * MODEL.stress)
    assert np.all((d.activations >= 0) & (d.activations <= 1 + 1e-12))
    assert np.array_equal(d.saturated, d.activations >= 1 - 1e-9)


def test_one_stack_for_a_motion_equals_fresh_solves():
    share = musculo.MuscleSharing(MODEL)
    for k in range(6):
        q, Q = _case(k)
        a = share.solve(q, Q)
        b = musculo.distribute(MODEL, q, Q)
        _check_forces(a.forces, b.forces)


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3),
    st.lists(st.floats(0.0, 1.0), min_size=11, max_size=11),
)
def test_producible_loads_are_produced_with_no_more_stress(u, a0):
    """Invariants: Q = W F0 with F0 admissible ⇒ W F = Q to 1e-9, bounds hold, and the
    stress cost is no more than F0's (F0 is admissible, F optimal)."""
    q = MODEL.lower + np.asarray(u) * (MODEL.upper - MODEL.lower)
    F0 = np.asarray(a0) * MODEL.f_max
    Q = MODEL.moment_arms(q) @ F0
    d = musculo.distribute(MODEL, q, Q)
    assert d.feasible and d.relative_residual <= 1e-9
    assert d.bound_violation == 0.0
    cost = np.sum(d.stresses**2)
    assert cost <= np.sum((F0 / MODEL.pcsa) ** 2) * (1 + 1e-9) + 1e-6


# ---------------------------------------------------------------- bad input
def test_bad_input_is_named():
    q = np.zeros(3)
    with pytest.raises(ValueError, match=r"Q\[1\] is nan"):
        musculo.distribute(MODEL, q, [1.0, np.nan, 0.0])
    with pytest.raises(ValueError, match=r"Q\[1\] is nan"):
        musculo.two_step(MODEL, q, [1.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="Q must have shape"):
        musculo.distribute(MODEL, q, [1.0, 2.0])
    with pytest.raises(ValueError, match=r"q\[1\] \(phi\) = 2.0 rad"):
        musculo.distribute(MODEL, [0.0, 2.0, 0.0], np.zeros(3))
    with pytest.raises(ValueError, match="method"):
        musculo.distribute(MODEL, q, np.zeros(3), method="magic")
    with pytest.raises(ValueError, match="solver"):
        musculo.distribute(MODEL, q, np.ones(3), solver="nope")
    bad = shoulder.build()
    bad.f_max = bad.f_max.copy()
    bad.f_max[4] = -1432.0
    with pytest.raises(ValueError, match=r"f_max\[4\] \('infraspinatus'\) = -1432.0 N"):
        musculo.distribute(bad, q, np.zeros(3))
    with pytest.raises(ValueError, match="forces"):
        musculo.activations(MODEL, np.full(11, np.inf))
