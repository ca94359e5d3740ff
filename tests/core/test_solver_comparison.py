"""Cross-check of ``Stack.solve`` against an independent reference, on every QP backend.

The reference is :mod:`support.oracle` (cvxpy + Clarabel, one conic solve per level, then the
minimum-norm step). It is first validated on closed forms (``pinv``, the projected
two-level formula, clipping) and against a second, differently formulated reference
(objective-value constraints).

The stacks are the seeded families of :mod:`support.families`: Gaussian entries and targets
of order 1, ``n ≤ 12``, singular values (also of the projected levels) above ~1e-4·s₀ and
inequality violations at an optimum either 0 or ≥ ~1e-3.

Tolerances
----------
``RES_TOL`` (1e-6): ``|r − r_ref| ≤ 1e-6·max(1, r_ref)``. The data are O(1), so residuals
below 1 are compared absolutely (a zero residual has no relative scale), larger ones
relatively. The reference itself is accurate to ~1e-9 (its self-check and the closed-form
tests below), so the whole budget is the library's.

``X_TOL`` (1e-5): ``‖x − x_ref‖∞ ≤ 1e-5·max(1, ‖x_ref‖∞)``. After the minimum-norm step the
solution is unique and Lipschitz in the levels' optimal values, with the inverse of the
smallest singular value of the active (pinned) rows as constant. In the families solved
by QPs (where the backends matter) those rows have σ_min ≳ 0.1, so x is allowed 10× the
residual budget (measured worst ratio: 8, highs on ``ill_conditioned_bounded-1``, 2.1e-7 →
1.7e-6). The equality-only families, even at cond 1e4, are solved in closed form and agree
to ~1e-10.

Known failures
--------------
``KNOWN_FAILURES`` lists the (test, backend, case) combinations that fail because of a
library bug or a backend's accuracy limit, as ``xfail(strict=True)``: once fixed they
XPASS, which fails the run, and the entry must be removed. Nothing is loosened instead.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import SOLVERS
from support.families import (
    CASES,
    EQ_CASES,
    FEASIBLE_CASES,
    INEQ_CASES,
    build,
    case_ids,
    reference,
    stack,
)
from support.oracle import OracleError, level_residuals, lexicographic

import qpcoord as qc

RES_TOL = 1e-6
X_TOL = 1e-5


def _res_close(r, r_ref, tol=RES_TOL) -> np.ndarray:
    """Per-level pass/fail of ``|r − r_ref| ≤ tol·max(1, r_ref)``."""
    return np.abs(np.asarray(r) - r_ref) <= tol * np.maximum(1.0, r_ref)


def _x_err(x, x_ref) -> float:
    return float(np.max(np.abs(np.asarray(x) - x_ref)) / max(1.0, np.max(np.abs(x_ref))))


def _report(sol_r, ref_r) -> str:
    return (
        f"\n  library   {np.array2string(np.asarray(sol_r), precision=10)}"
        f"\n  reference {np.array2string(np.asarray(ref_r), precision=10)}"
        f"\n  |diff|    {np.array2string(np.abs(np.asarray(sol_r) - ref_r), precision=2)}"
    )


# ---------------------------------------------------------------------------------------
# The reference itself
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("m,n,rank", [(3, 8, 3), (8, 5, 5), (6, 9, 4), (5, 5, 2)])
def test_oracle_single_equality_is_pinv(rng, m, n, rank):
    """One equality level alone: the minimum-norm least-squares solution ``A⁺b`` (also for
    rank-deficient, wide and tall A)."""
    A = rng.standard_normal((m, rank)) @ rng.standard_normal((rank, n))
    b = rng.standard_normal(m)
    ref = lexicographic([qc.Equality(A, b)])
    x = np.linalg.pinv(A) @ b
    assert _x_err(ref.x, x) < 1e-9
    assert ref.level_residuals[0] == pytest.approx(np.linalg.norm(A @ x - b), abs=1e-9)


@pytest.mark.parametrize("m1,m2,n", [(3, 7, 8), (2, 3, 8), (4, 4, 6)])
def test_oracle_two_levels_projected_formula(rng, m1, m2, n):
    """``x = A₁⁺b₁ + (A₂N₁)⁺(b₂ − A₂A₁⁺b₁)`` with ``N₁ = I − A₁⁺A₁``; weights included."""
    A1, b1 = rng.standard_normal((m1, n)), rng.standard_normal(m1)
    A2, b2 = rng.standard_normal((m2, n)), rng.standard_normal(m2)
    w2 = rng.uniform(0.1, 10.0, m2)
    ref = lexicographic([qc.Equality(A1, b1), qc.Equality(A2, b2, weight=w2)])
    S = np.sqrt(w2)[:, None]
    P1 = np.linalg.pinv(A1)
    x1 = P1 @ b1
    N1 = np.eye(n) - P1 @ A1
    x = x1 + np.linalg.pinv(S * A2 @ N1) @ (S[:, 0] * (b2 - A2 @ x1))
    assert _x_err(ref.x, x) < 1e-9
    expected = [np.linalg.norm(A1 @ x - b1), np.linalg.norm(S[:, 0] * (A2 @ x - b2))]
    np.testing.assert_allclose(ref.level_residuals, expected, atol=1e-9, rtol=1e-9)


def test_oracle_inequalities_closed_form():
    """Decoupled inequality levels under bounds have closed forms: level 0 asks ``x ≥ lo``
    (beyond the bounds for coordinates 1 and 3: violated, pinned at 1), level 1 asks
    ``x₀, x₁ ≤ −2``, impossible since level 0 keeps ``x₀ ≥ 0.5`` and pinned ``x₁ = 1``
    (both violated); the min-norm step puts every coordinate as close to 0 as allowed."""
    n = 6
    ub = np.full(n, 1.0)
    lo = np.array([0.5, 2.0, -3.0, 1.5, 0.2, -0.4])  # 2 and 5 are satisfied by 0
    hi = np.full(n, -2.0)
    ref = lexicographic(
        [qc.Inequality(np.eye(n), lower=lo), qc.Inequality(np.eye(n)[[0, 1]], upper=hi[:2])],
        bounds=qc.Bounds(-ub, ub),
    )
    x = np.clip(np.maximum(lo, 0.0), -ub, ub)
    assert _x_err(ref.x, x) < 1e-9
    r0 = np.linalg.norm(np.maximum(lo - x, 0.0))
    r1 = np.linalg.norm(x[:2] - hi[:2])
    np.testing.assert_allclose(ref.level_residuals, [r0, r1], atol=1e-9)
    assert [len(v) for v in ref.info["violated_rows"]] == [2, 2]


def test_oracle_hard_constraints_closed_form(rng):
    """With hard equalities ``Hx = h`` and one level ``x ≈ t``: ``x = t + H⁺(h − Ht)``."""
    n = 7
    H, h, t = rng.standard_normal((3, n)), rng.standard_normal(3), rng.standard_normal(n)
    ref = lexicographic([qc.Equality(np.eye(n), t)], constraints=[qc.Equality(H, h)])
    x = t + np.linalg.pinv(H) @ (h - H @ t)
    assert _x_err(ref.x, x) < 1e-9


@pytest.mark.parametrize("name,seed", INEQ_CASES, ids=case_ids(INEQ_CASES))
def test_oracle_pin_agrees_with_epigraph(name, seed):
    """The default formulation (pinned optimal values, classification of violated rows)
    agrees with objective-value constraints ``r_j ≤ r_j* + τ(1 + r_j*)``, which need no
    classification of rows.

    Those constraints touch the optimal set tangentially: Clarabel cannot always finish
    with ``τ = 1e-9`` (InsufficientProgress), so ``τ = 1e-8`` is the fallback. Their
    square-root sensitivity lets x move by ~√(2τ r*)/σ ≈ 1e-3 for r* ≈ 10 and lets the
    lower levels gain up to ~5e-4 (measured worst: 2.6e-3 and 4.3e-4): tolerances 1e-2 for
    x and 1e-3 for residuals. That still catches a misclassified row (an O(0.1–1) error).
    """
    spec = build(name, seed)
    ref = reference(name, seed)
    for tau in (1e-9, 1e-8):
        try:
            epi = lexicographic(
                spec["levels"], spec["bounds"], spec["constraints"], mode="epigraph", epi_tol=tau
            )
            break
        except OracleError:
            continue
    else:
        pytest.fail("the epigraph formulation failed with τ = 1e-9 and 1e-8")
    assert _res_close(epi.level_residuals, ref.level_residuals, 1e-3).all(), _report(
        epi.level_residuals, ref.level_residuals
    )
    assert _x_err(epi.x, ref.x) < 1e-2


@pytest.mark.parametrize("name,seed", CASES, ids=case_ids(CASES))
def test_oracle_residual_definition(name, seed):
    """The oracle's residuals reproduce the optima of its own level solves, and its
    residual function (tasks' public attributes only) is ``Solution.level_residuals``."""
    spec = build(name, seed)
    ref = reference(name, seed)
    np.testing.assert_allclose(ref.level_residuals, ref.level_optima, rtol=1e-8, atol=1e-8)
    st = stack(spec)
    for solver in SOLVERS:  # any point will do; the first backend that solves the case
        try:
            sol = st.solve(solver=solver)
        except (qc.SolverError, qc.InfeasibleError):
            continue
        np.testing.assert_allclose(
            level_residuals(spec["levels"], sol.x), sol.level_residuals, rtol=1e-12, atol=1e-14
        )
        return
    pytest.skip("no backend solves this case (see test_hierarchical_matches_oracle)")


# ---------------------------------------------------------------------------------------
# Known failures: library bugs and backend limits, as xfail(strict=True)
# ---------------------------------------------------------------------------------------

#: Short reasons of known failures; the details (repro, numbers) go in comments. Empty:
#: the seven causes found when this suite was written (nullspace rank from a projector's
#: round-off, slack classification at 1e-9, daqp conditioning and tolerances, Clarabel
#: AlmostSolved, proxqp infeasibility thresholds, the hard phase, and level-QP accuracy)
#: are fixed in the library (active-set refinement of every level QP, see hierarchical.py).
BUGS: dict[str, str] = {}

_HM = "hierarchical_matches_oracle"
_WB = "weighted_never_beats_strict_level0"
_WC = "weighted_close_on_feasible_hierarchy"
_NS = "nullspace_matches_hierarchical"
_HARD = ("hard_mixed-0", "hard_mixed-1", "hard_mixed-2")

#: (test, backend or None, case) -> BUGS key (versions matter: measured with daqp 0.11.0,
#: quadprog 0.1.14, proxsuite 0.8.0, piqp 0.7.0, clarabel 0.11.1, highspy 1.15.1,
#: osqp 1.1.3, scs 3.3.1).
KNOWN_FAILURES: dict[tuple, str] = {}


def _params(test: str, cases, solvers=(None,)):
    """pytest params, ids ``solver-family-seed``, with the known failures as strict xfails."""
    out = []
    for solver in solvers:
        for name, seed in cases:
            case = f"{name}-{seed}"
            bug = KNOWN_FAILURES.get((test, solver, case))
            marks = [pytest.mark.xfail(reason=f"[{bug}] {BUGS[bug]}", strict=True)] if bug else []
            args = (name, seed) if solver is None else (name, seed, solver)
            pid = case if solver is None else f"{solver}-{case}"
            out.append(pytest.param(*args, marks=marks, id=pid))
    return out


# ---------------------------------------------------------------------------------------
# Library vs reference
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("name,seed,solver", _params(_HM, CASES, SOLVERS))
def test_hierarchical_matches_oracle(name, seed, solver):
    """Per-level residuals to RES_TOL and the (unique, minimum-norm) x to X_TOL."""
    spec = build(name, seed)
    ref = reference(name, seed)
    sol = stack(spec).solve(solver=solver, method="hierarchical")
    assert sol.status == "optimal"
    ok = _res_close(sol.level_residuals, ref.level_residuals)
    assert ok.all(), f"levels {np.flatnonzero(~ok)} differ:" + _report(
        sol.level_residuals, ref.level_residuals
    )
    err = _x_err(sol.x, ref.x)
    assert err <= X_TOL, f"x differs from the reference by {err:.2e} (relative)"


@pytest.mark.parametrize("name,seed", _params(_NS, EQ_CASES))
def test_nullspace_matches_hierarchical(name, seed):
    """Equality-only stacks: the recursive projection formula equals the strict hierarchy
    (both are closed forms here; 1e-9 relative allows for cond ≤ 1e4 times round-off)."""
    spec = build(name, seed)
    st = stack(spec)
    hier = st.solve(method="hierarchical")
    ns = st.solve(method="nullspace")
    assert _res_close(ns.level_residuals, hier.level_residuals, 1e-9).all(), _report(
        ns.level_residuals, hier.level_residuals
    )
    assert _x_err(ns.x, hier.x) < 1e-9
    ref = reference(name, seed)
    assert _res_close(ns.level_residuals, ref.level_residuals).all()
    assert _x_err(ns.x, ref.x) <= X_TOL


@pytest.mark.parametrize("name,seed,solver", _params(_WB, CASES, SOLVERS))
def test_weighted_never_beats_strict_level0(name, seed, solver):
    """The strict hierarchy is optimal for level 0: the weighted QP cannot do better
    (beyond RES_TOL). (It may do much worse: lower levels leak into level 0 by about
    ``weight_ratio`` times their row weights, e.g. +0.44 on ``weighted_mixed-2`` whose
    level-1 weights reach 1e2, so there is no useful upper bound in general.)"""
    spec = build(name, seed)
    w = stack(spec).solve(solver=solver, method="weighted")
    r0 = reference(name, seed).level_residuals[0]
    assert w.level_residuals[0] >= r0 - RES_TOL * max(1.0, r0), _report(w.level_residuals[:1], [r0])


@pytest.mark.parametrize("name,seed,solver", _params(_WC, FEASIBLE_CASES, SOLVERS))
def test_weighted_close_on_feasible_hierarchy(name, seed, solver):
    """Every level can be met (all reference residuals 0). The weighted QP minimises
    ``Σ_k β_k f_k(x) + ε‖x‖²`` with ``β_k = weight_ratio^k`` and ``ε = regularization``
    (no hard constraints here and 0 inside the bounds, so its variable is x itself). The
    reference x* is feasible with ``f_k(x*) = 0``, so at the weighted optimum
    ``β_k f_k ≤ ε‖x*‖²``, i.e. ``r_k ≤ √(ε/β_k)·‖x*‖``: 3e-5‖x*‖ at level 0, 3e-2‖x*‖ at
    level 2 with the defaults. Plus RES_TOL for the backend. (This is sharp for the
    ill-conditioned family, where ε outweighs β_k σ² and r_2 reaches ~40.)"""
    spec = build(name, seed)
    st = stack(spec)
    assert spec["constraints"] is None
    ref = reference(name, seed)
    assert np.all(ref.level_residuals < 1e-8)  # the premise: a feasible hierarchy
    w = st.solve(solver=solver, method="weighted")
    beta = st.weight_ratio ** np.arange(st.num_levels)
    bound = np.sqrt(st.regularization / beta) * np.linalg.norm(ref.x) + RES_TOL
    assert np.all(w.level_residuals <= bound), (
        f"\n  weighted {w.level_residuals}\n  bound    {bound}"
    )
