"""The native weighted QP (``Stack.solve(method="weighted")``, :class:`PersistentQP`) against the
Python engine and the cvxpy oracle.

The weighted QP's optimum is unique (its Hessian is positive definite once ``ε`` is added where
the levels leave it singular, by the same rule in both engines): the native ``x`` must equal the
Python engine's to ``X_TOL`` relative and the cvxpy oracle's to ``ORACLE_TOL``, on every
solver-comparison case and on hypothesis-generated stacks. Without the extension these tests
skip (``QPCOORD_REQUIRE_NATIVE=1`` makes that a failure).
"""

from __future__ import annotations

import math
import warnings

import cvxpy as cp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from support.arrays import force_write as _force_write
from support.families import CASES, build, stack
from support.families import case_ids as _ids
from support.native_engine import needs_native_weighted
from support.stacks import clipped_stack, hard_random_stack, region_problem
from support.strategies import stacks as random_stacks
from support.weighted import X_TOL, assert_same_weighted, condition, epsilon, objective, relative_dx

import qpcoord as qc
from qpcoord.core import native
from qpcoord.core.persistent import PersistentQP

#: x against the cvxpy oracle (Clarabel's tolerances).
ORACLE_TOL = 1e-6


def weighted_oracle(s: qc.Stack, eps: float) -> np.ndarray:
    """The same weighted QP posed in cvxpy (Clarabel, tight tolerances)."""
    P = s._compiled
    P.refresh()
    x = cp.Variable(P.n)
    cost, cons, beta = 0.5 * eps * cp.sum_squares(x), [], 1.0
    for L in P.levels:
        if L.m_eq:
            cost += 0.5 * beta * cp.sum_squares(L.Ae @ x - L.be)
        if L.m_in:
            w = cp.Variable(L.m_in)
            cost += 0.5 * beta * cp.sum_squares(cp.multiply(L.sw, w))
            fin_lo, fin_hi = np.isfinite(L.lo), np.isfinite(L.hi)
            if fin_lo.any():
                cons.append((L.C @ x - w)[fin_lo] >= L.lo[fin_lo])
            if fin_hi.any():
                cons.append((L.C @ x - w)[fin_hi] <= L.hi[fin_hi])
        beta *= s.weight_ratio
    H = P.hard
    if H.m_eq:
        cons.append(H.Ae @ x == H.be)
    if H.m_in:
        lo, hi = H.lo, H.hi
        if np.isfinite(lo).any():
            cons.append((H.C @ x)[np.isfinite(lo)] >= lo[np.isfinite(lo)])
        if np.isfinite(hi).any():
            cons.append((H.C @ x)[np.isfinite(hi)] <= hi[np.isfinite(hi)])
    if P.lb is not None:
        fl, fu = np.isfinite(P.lb), np.isfinite(P.ub)
        cons += [x[fl] >= P.lb[fl], x[fu] <= P.ub[fu]]
    cp.Problem(cp.Minimize(cost), cons).solve(
        solver="CLARABEL", tol_gap_abs=1e-12, tol_gap_rel=1e-12, tol_feas=1e-12
    )
    return x.value


# ---------------------------------------------------------------------------------------
# engine rule
# ---------------------------------------------------------------------------------------


@needs_native_weighted
def test_weighted_default_is_native_where_built():
    s = clipped_stack()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert s.solve(method="weighted").solver == "native"
    assert s.solve(method="weighted", engine="python").solver != "native"
    assert s.solve(method="weighted", solver="daqp").solver == "daqp"
    with pytest.raises(ValueError, match="solver='daqp' is not supported"):
        s.solve(method="weighted", solver="daqp", engine="native")
    with pytest.raises(ValueError, match="unknown engine 'fast'"):
        s.solve(method="weighted", engine="fast")


def test_weighted_falls_back_to_python_without_the_extension(missing_extension):
    s = clipped_stack()
    with pytest.warns(RuntimeWarning, match="native engine is not built"):
        sol = s.solve(method="weighted")
    assert sol.solver != "native"
    with pytest.raises(native.NativeUnavailableError):
        s.solve(method="weighted", engine="native")
    assert PersistentQP(s).engine == "python"


# ---------------------------------------------------------------------------------------
# native vs Python and the oracle
# ---------------------------------------------------------------------------------------


@needs_native_weighted
@pytest.mark.parametrize("name,seed", CASES, ids=_ids(CASES))
def test_native_weighted_matches_python(name, seed):
    spec = build(name, seed)
    s = stack(spec)
    sp = s.solve(method="weighted", engine="python")
    sn = stack(spec).solve(method="weighted")
    assert_same_weighted(s, sp, sn)


@needs_native_weighted
@pytest.mark.parametrize("name,seed", CASES, ids=_ids(CASES))
def test_native_weighted_matches_oracle(name, seed):
    s = stack(build(name, seed))
    sn = s.solve(method="weighted")
    eps = epsilon(s, sn)
    ref = weighted_oracle(s, eps)
    if sn.info["regularized"] or condition(s) > 1e8:
        # x is (nearly) undetermined along the Hessian's null space: the same cost, the
        # native one no higher than the oracle's (it solves the QP exactly)
        fo, fn = objective(s, ref, eps), objective(s, sn.x, eps)
        assert fn <= fo + 1e-9 * max(1.0, abs(fo)), (fo, fn)
        assert abs(fn - fo) <= 1e-7 * max(1.0, abs(fo)), (fo, fn)
    else:
        assert relative_dx(sn.x, ref) <= ORACLE_TOL


@needs_native_weighted
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(random_stacks())
def test_native_weighted_matches_python_on_random_stacks(spec):
    s = stack(spec)
    sp = s.solve(method="weighted", engine="python")
    sn = s.solve(method="weighted")
    assert_same_weighted(s, sp, sn)
    again = s.solve(method="weighted")  # warm: the same data, the stored working set
    assert_same_weighted(s, sp, again)
    assert again.info["iterations"] == 0 and not again.info["refactored"]


# ---------------------------------------------------------------------------------------
# warm start, refactoring, errors
# ---------------------------------------------------------------------------------------


@needs_native_weighted
def test_warm_start_gives_the_cold_answer():
    """A moving target over 40 steps: each warm solve equals a cold one (a fresh stack, and
    the same stack after ``forget``) and the Python engine's; the stored set is hit."""
    spec = build("mixed_levels", 1)
    warm = stack(spec)
    eq = spec["levels"][2]
    rng = np.random.default_rng(3)
    hits = 0
    for _ in range(40):
        eq.update(b=np.clip(eq.b + 0.02 * rng.standard_normal(eq.b.shape[0]), -1, 1))
        sw = warm.solve(method="weighted")
        sc = stack(spec).solve(method="weighted")
        assert sc.info["warm_start_hit"] is False
        np.testing.assert_allclose(sw.x, sc.x, rtol=0, atol=1e-10)
        assert_same_weighted(warm, stack(spec).solve(method="weighted", engine="python"), sw)
        hits += sw.info["warm_start_hit"]
    assert hits > 10


@needs_native_weighted
def test_changed_matrix_is_refactored():
    spec = build("weighted_mixed", 0)
    s = stack(spec)
    s.solve(method="weighted")
    assert not s.solve(method="weighted").info["refactored"]
    t = spec["levels"][0][0] if isinstance(spec["levels"][0], list) else spec["levels"][0]
    t.update(A=1.5 * t.A)
    sn = s.solve(method="weighted")
    assert sn.info["refactored"]
    assert_same_weighted(s, s.solve(method="weighted", engine="python"), sn)


@needs_native_weighted
@pytest.mark.parametrize("engine", ["python", "native"])
def test_inconsistent_hard_equalities(engine):
    hard = qc.Equality(np.array([[1.0, 0.0], [1.0, 0.0]]), [0.0, 1.0], name="pin")
    s = qc.Stack([qc.Equality(np.eye(2), [0.0, 0.0])], constraints=[hard])
    msg = r"hard equality constraints are inconsistent \(Equality 'pin'\): least-squares"
    with pytest.raises(qc.InfeasibleError, match=msg):
        s.solve(method="weighted", engine=engine)


@needs_native_weighted
@pytest.mark.parametrize("engine", ["python", "native"])
def test_hard_inequalities_outside_the_box(engine):
    hard = qc.Inequality(np.array([[1.0, 1.0]]), lower=3.0)
    s = qc.Stack(
        [qc.Equality(np.eye(2), [0.0, 0.0])], bounds=qc.Bounds(-1.0, 1.0), constraints=[hard]
    )
    with pytest.raises(
        qc.InfeasibleError, match="constraints: bounds and hard constraints are inconsistent"
    ):
        s.solve(method="weighted", engine=engine)
    # a set one rounding wide is not infeasible
    thin = qc.Inequality(np.array([[1.0, 1.0]]), lower=2.0 + 1e-13)
    s2 = qc.Stack(
        [qc.Equality(np.eye(2), [0.0, 0.0])], bounds=qc.Bounds(-1.0, 1.0), constraints=[thin]
    )
    np.testing.assert_allclose(s2.solve(method="weighted", engine=engine).x, [1.0, 1.0])


@needs_native_weighted
@pytest.mark.parametrize("engine", ["python", "native"])
def test_hard_equalities_fix_x_outside_the_box(engine):
    s = qc.Stack(
        [qc.Equality(np.ones((1, 2)), [0.0])],
        bounds=qc.Bounds(-1.0, 1.0),
        constraints=[qc.Equality(np.eye(2), [2.0, 0.0])],
    )
    with pytest.raises(qc.InfeasibleError, match="the hard equalities fix x completely"):
        s.solve(method="weighted", engine=engine)


@needs_native_weighted
@pytest.mark.parametrize("engine", ["python", "native"])
def test_nan_in_a_task_names_it(engine):
    t = qc.Inequality(np.eye(2), lower=[0.0, 0.0], name="fence")
    s = qc.Stack([t, qc.Equality(np.eye(2), [1.0, 1.0])], bounds=qc.Bounds(-2.0, 2.0))
    s.solve(method="weighted", engine=engine)
    _force_write(t.C, (0, 0), np.nan)  # reached the array without update()
    with pytest.raises(ValueError, match=r"Inequality 'fence': C contains nan.*found at solve"):
        s.solve(method="weighted", engine=engine)


@needs_native_weighted
def test_nan_in_a_right_hand_side_names_it():
    e = qc.Equality(np.eye(2), [1.0, 1.0], name="track")
    s = qc.Stack([e], bounds=qc.Bounds(-2.0, 2.0))
    s.solve(method="weighted")
    _force_write(e.b, (1,), np.nan)
    with pytest.raises(ValueError, match=r"Equality 'track': b contains nan.*found at solve"):
        s.solve(method="weighted")


@needs_native_weighted
def test_time_limit_gives_the_python_engines_error():
    s = hard_random_stack(0)
    with pytest.raises(qc.SolverError, match=r"time limit of 1e-09 s reached.*native engine"):
        s.solve(method="weighted", time_limit=1e-9)
    sn = s.solve(method="weighted", time_limit=math.inf)  # not poisoned
    assert_same_weighted(s, s.solve(method="weighted", engine="python"), sn)


@needs_native_weighted
def test_level_values_are_each_levels_residual():
    s = hard_random_stack(1)
    sol = s.solve(method="weighted")
    ref = np.array([L.residual(sol.x) for L in s._compiled.levels])
    np.testing.assert_allclose(sol.level_residuals, ref, rtol=1e-12, atol=1e-14)


@needs_native_weighted
def test_regularisation_only_where_singular():
    """ε is added exactly where the Python rule adds it: a rank-deficient stack gets the
    minimum-norm answer (to ε), a full-rank one the exact weighted least squares."""
    sing = qc.Stack([qc.Equality([[1.0, 1.0]], [2.0])])
    sn = sing.solve(method="weighted")
    assert sn.info["regularized"]
    np.testing.assert_allclose(sn.x, [1.0, 1.0], atol=1e-8)
    full = qc.Stack([qc.Equality(np.eye(2), [2.0, -1.0])])
    sf = full.solve(method="weighted")
    assert not sf.info["regularized"]
    np.testing.assert_allclose(sf.x, [2.0, -1.0], rtol=0, atol=1e-15)


# ---------------------------------------------------------------------------------------
# PersistentQP on the native weighted QP
# ---------------------------------------------------------------------------------------


def _mpc_like(seed: int):
    """A fixed-matrix stack (tracking, soft band, effort; hard row; box): only b and limits
    move per step."""
    rng = np.random.default_rng(seed)
    n = 12
    track = qc.Equality(rng.standard_normal((6, n)), np.zeros(6), weight=2.0, name="track")
    soft = qc.Inequality(rng.standard_normal((4, n)), -0.3, 0.3, name="band")
    effort = qc.Equality(np.eye(n), np.zeros(n), name="effort")
    hard_in = qc.Inequality(rng.standard_normal((2, n)), -1.0, 1.0, name="hard")
    box = qc.Bounds(-np.ones(n), np.ones(n))
    s = qc.Stack([track, soft, effort], bounds=box, constraints=[hard_in], weight_ratio=1e-2)
    return s, track, soft, effort, rng


@needs_native_weighted
def test_persistent_native_matches_daqp_over_500_steps():
    s, track, soft, effort, rng = _mpc_like(0)
    pn = PersistentQP(s)
    pd = PersistentQP(s, engine="python")
    assert pn.engine == "native" and pd.engine == "python"
    worst, hits = 0.0, 0
    for k in range(500):
        track.update(b=2.0 * np.sin(0.05 * k + np.arange(6)))
        effort.update(b=0.1 * rng.standard_normal(12))
        if k % 50 == 25:
            soft.update(lower=-0.3 - 0.1 * rng.random(4), upper=0.3 + 0.1 * rng.random(4))
        a, b = pn.solve(), pd.solve()
        assert a.info["persistent"] and a.solver == "native" and b.solver == "daqp"
        worst = max(worst, relative_dx(a.x, b.x))
        hits += a.info["iterations"] == 0
        np.testing.assert_allclose(a.level_residuals, b.level_residuals, rtol=1e-6, atol=1e-9)
    assert worst < 1e-8, worst
    assert pn.setups == 1 and pn.fallbacks == 0
    assert hits > 100  # consecutive steps: the stored working set is often optimal


@needs_native_weighted
def test_persistent_native_is_the_general_weighted_answer():
    """The native workspace answers ``stack.solve(method="weighted")`` exactly (one rule
    for ε), also with a hard equality."""
    s, track, *_ = _mpc_like(1)
    s2 = qc.Stack(
        [s.levels[0], s.levels[1], s.levels[2]],
        bounds=qc.Bounds(-np.ones(12), np.ones(12)),
        constraints=[qc.Equality(np.ones((1, 12)), [0.5], name="sum")],
        weight_ratio=1e-2,
    )
    pq = PersistentQP(s2)
    for k in range(20):
        track.update(b=np.cos(0.2 * k + np.arange(6)))
        a = pq.solve()
        b = s2.solve(method="weighted", engine="python")
        assert relative_dx(a.x, b.x) <= X_TOL
        assert abs(a.x.sum() - 0.5) <= 1e-12


@needs_native_weighted
def test_persistent_native_falls_back_on_infeasible_steps():
    s, track, soft, effort, rng = _mpc_like(2)
    pq = PersistentQP(s)
    pq.solve()
    hard = s._compiled.hard.ineqs[0]
    hard.update(lower=[50.0, -1.0], upper=[60.0, 1.0])  # far outside the box: infeasible
    with pytest.raises(qc.InfeasibleError, match="bounds and hard constraints are inconsistent"):
        pq.solve()
    assert pq.fallbacks == 1
    hard.update(lower=[-1.0, -1.0], upper=[1.0, 1.0])
    sol = pq.solve()
    assert sol.info["persistent"]
    assert_same_weighted(s, s.solve(method="weighted", engine="python"), s.solve(method="weighted"))


@needs_native_weighted
@pytest.mark.parametrize("seed", [0, 1])
def test_persistent_native_regions_match_daqp(seed):
    """The parametric path (critical-region cache, then the QP) on the native workspace:
    the same answers as on the daqp workspace, most steps from the cache."""
    pn = region_problem(seed, engine="native")[1]
    pd = region_problem(seed, engine="python")[1]
    assert pn.engine == "native" and pd.engine == "python"
    direction = np.random.default_rng(seed + 10).normal(size=3)
    worst = 0.0
    for k in range(300):
        theta = 3.0 * np.sin(0.02 * k) * direction + 0.3 * np.sin(0.11 * k)
        worst = max(worst, relative_dx(pn.solve_theta(theta), pd.solve_theta(theta)))
    assert worst < 1e-8, worst
    assert pn.region_steps > 150 and pn.qp_steps > 0 and pn.fallbacks == 0
