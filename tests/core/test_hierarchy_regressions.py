"""Regression tests for strict-hierarchy corner cases found while building the core.

Each case has a closed-form answer and runs on every installed backend.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support.dumps import spec_from_npz

import qpcoord as qc
import qpcoord.core.methods.hierarchical as hierarchical
from qpcoord.core import native
from qpcoord.core.linalg import numerical_rank
from qpcoord.core.polish import active_rank

SOLVERS = qc.available_solvers()


@pytest.mark.parametrize("solver", SOLVERS)
def test_lower_row_with_no_freedom_left_is_reported_not_rejected(solver):
    """Level 0 uses all freedom under active bounds; level 1's row cannot be met and must
    be reported as its residual, not raise 'breaks an inequality a higher level had
    satisfied'."""
    sol = qc.solve_stack(
        [qc.Equality(np.eye(2), [1.0, 2.0]), qc.Inequality([[1.0, 1.0]], upper=0.5)],
        bounds=qc.Bounds(-1.0, 1.0),
        solver=solver,
    )
    np.testing.assert_allclose(sol.x, [1.0, 1.0], atol=1e-7)
    np.testing.assert_allclose(sol.level_residuals, [1.0, 1.5], atol=1e-6)


@pytest.mark.parametrize("solver", SOLVERS)
def test_small_scale_rows_are_not_frozen_as_violated(solver):
    """A limit row scaled by dt = 0.01 is satisfiable; the posture below must still get
    x₂ = 1 (it got 0.0999 when the regularisation outweighed the row's slack cost)."""
    sol = qc.Stack(
        [
            qc.Equality([[1.0, 0.0]], [0.0]),
            qc.Inequality([[0.0, 0.01]], lower=0.001),
            qc.Equality([[0.0, 1.0]], [1.0]),
        ]
    ).solve(solver=solver)
    np.testing.assert_allclose(sol.x, [0.0, 1.0], atol=1e-7)


@pytest.mark.parametrize("solver", SOLVERS)
def test_hard_phase_starts_outside_the_hard_inequalities(solver):
    """The min-norm point of the hard equalities violates a hard inequality by O(1)."""
    sol = qc.Stack(
        [qc.Equality(np.eye(2), [0.0, 0.0])],
        constraints=[qc.Equality([[1.0, 1.0]], [0.0]), qc.Inequality([[1.0, 0.0]], lower=1.0)],
    ).solve(solver=solver)
    np.testing.assert_allclose(sol.x, [1.0, -1.0], atol=1e-7)


@pytest.mark.parametrize("solver", SOLVERS)
def test_satisfiable_mixed_level_row_is_not_frozen(solver):
    """Level 0 = {x₀ = 1, x₁ ≥ 1}: satisfiable, so level 1 (x₁ = 5) is met exactly."""
    sol = qc.Stack(
        [
            [qc.Equality([1.0, 0.0, 0.0], 1.0), qc.Inequality([0.0, 1.0, 0.0], lower=1.0)],
            qc.Equality([0.0, 1.0, 0.0], 5.0),
        ]
    ).solve(solver=solver)
    np.testing.assert_allclose(sol.x, [1.0, 5.0, 0.0], atol=1e-7)
    np.testing.assert_allclose(sol.level_residuals, [0.0, 0.0], atol=1e-7)


def test_nullspace_keeps_higher_levels_exact():
    """Projector round-off once counted as rank and broke level 0 (1.85 instead of 7e-15)."""
    rng = np.random.default_rng(0)
    A1, b1 = rng.standard_normal((3, 4)), rng.standard_normal(3)
    A2, b2 = rng.standard_normal((2, 4)), rng.standard_normal(2)
    stack = qc.Stack([qc.Equality(A1, b1), qc.Equality(A2, b2)])
    ns = stack.solve(method="nullspace")
    hi = stack.solve(method="hierarchical")
    # level 0 is met exactly: its residual is the rounding of forming A₁x − b₁ from a
    # backward-stable solve, c·eps·(‖A₁‖‖x‖ + ‖b₁‖) with c = 10·(n + 1): 6.8e-13 (measured
    # 4.4e-15; the defect gave 1.85)
    rounding = (
        50
        * np.finfo(float).eps
        * (np.linalg.norm(A1, 2) * np.linalg.norm(ns.x) + np.linalg.norm(b1))
    )
    assert ns.level_residuals[0] < rounding
    np.testing.assert_allclose(ns.x, hi.x, atol=1e-10)


@pytest.mark.parametrize("name", ["regularization", "damping", "weight_ratio"])
@pytest.mark.parametrize("value", [True, float("nan"), "1e-9", -1.0])
def test_stack_options_are_validated(name, value):
    with pytest.raises(ValueError, match=name):
        qc.Stack([qc.Equality([[1.0, 0.0]], [0.0])], **{name: value})


@pytest.mark.parametrize("solver", SOLVERS)
def test_pointed_cone_of_pinned_speed_bounds(solver):
    """A Panda IK step (position above posture, |q̇| ≤ 0.45 rad/s) where four joints sit
    on their bound after level 0 and their cone in level 1's null space is pointed.

    daqp 0.11 reported the (feasible by construction) level-1 QP infeasible with every
    setting; the stack now falls back to another backend and says so in ``info``. Exact
    answer: level 1 cannot move the four pinned joints (residual 26.515922); inexact
    backends may gain ~2e-4 from their 1e-8 opening of the bounds.
    """
    d = np.load(Path(__file__).parents[1] / "data" / "panda_pinned_cone.npz")
    stack = qc.Stack(
        [qc.Equality(d["A0"], d["b0"]), qc.Equality(d["A1"], d["b1"])],
        bounds=qc.Bounds(d["lb"], d["ub"]),
    )
    sol = stack.solve(solver=solver)
    assert np.all(sol.x >= d["lb"] - 1e-9) and np.all(sol.x <= d["ub"] + 1e-9)
    # level 0 to the stack's stated tolerance; level 1 depends on how far a backend's
    # tolerance lets level 0 move (osqp: 2e-7 at level 0 buys 4e-4 at level 1)
    np.testing.assert_allclose(sol.level_residuals[0], 1.917008445, rtol=1e-6)
    exact = solver in ("daqp", "quadprog")
    np.testing.assert_allclose(sol.level_residuals[1], 26.515922, rtol=1e-7 if exact else 1e-3)
    if solver == "daqp":
        assert sol.info["fallbacks"] == ["level 1: quadprog"]


SHOULDER_W = np.array(
    [
        [0.021745, -0.018582, 0.018375, 0.014491, -0.008618, 0.019016, 0.050926, -0.020842,
         -0.011098, 0.03162, 0.045009],
        [-0.033134, -0.018138, 0.017773, 0.030366, 0.009947, -0.000527, -0.039637, 0.009819,
         -0.003534, -0.0207, 0.038764],
        [-0.006101, -0.003409, 0.004618, -0.000658, -0.016366, -0.017279, 0.011166, 0.003368,
         0.022027, 0.014794, 0.018701],
    ]
)  # fmt: skip


@pytest.mark.parametrize("solver", SOLVERS)
def test_exactly_met_level_over_a_nearly_singular_hessian_is_refined(solver):
    """Muscle sharing (appendix A): W F = Q is met exactly by many F in the box; the level's
    Hessian is WᵀW plus the 1e-9 regularisation. Interior-point points used to keep a
    5.6e-8 residual (their active set is only a guess there); the truncated refinement of
    ``polish`` brings piqp and clarabel to 1.6e-15 like the active-set backends. osqp (ADMM)
    keeps 5e-8: its point is not polished at the next level either."""
    Q = np.array([-4.787660, 3.156755, 0.026878])
    fmax = np.array([1063.0, 1739, 505, 463, 1432, 497, 608, 621, 1431, 562, 1188])
    stack = qc.Stack(
        [qc.Equality(SHOULDER_W, Q), qc.Equality(np.diag(fmax.mean() / fmax), np.zeros(11))],
        bounds=qc.Bounds(np.zeros(11), fmax),
    )
    sol = stack.solve(solver=solver)
    tol = 1e-6 if solver == "osqp" else 1e-12
    assert sol.level_residuals[0] < tol * np.linalg.norm(Q)
    assert np.all(sol.x >= 0) and np.all(sol.x <= fmax)


def _stack_from_npz(path: Path, fallback: bool = True) -> qc.Stack:
    """A stack stored level by level as ``L{k}_{j}_eq_{A,b,w}`` / ``L{k}_{j}_in_{C,lo,hi,w}``,
    with optional bounds ``bounds_{lb,ub}`` and hard constraints ``H{j}_eq_{A,b}`` /
    ``H{j}_in_{C,lo,hi}``."""
    return qc.Stack(**spec_from_npz(path), fallback=fallback)


_DAQP_ONLY = Path(__file__).resolve().parents[1] / "data" / "python_engine_level_qp_infeasible.npz"


def test_level_qp_with_a_regularisation_only_z_block_is_solved_with_fallbacks():
    """The stack below, with the default fallback chain: daqp's own last attempt solves
    level 3 (a fallback backend did before), with quadprog's answer."""
    sol = _stack_from_npz(_DAQP_ONLY).solve(engine="python")
    assert sol.status == "optimal" and sol.info["fallbacks"] == []
    ref = _stack_from_npz(_DAQP_ONLY).solve(engine="python", solver="quadprog")
    _same_solution(sol, ref)


def test_level_qp_with_a_regularisation_only_z_block_is_solved_by_daqp_alone():
    """daqp alone (``fallback=False``) declared level 3 infeasible although ``z = 0`` with its
    slack meets every row (see :func:`test_daqp_reproducer`); its last attempt, a proximal
    term of the Hessian's scale (``backends._DAQP_SETTINGS``), solves it: no fallback, the
    quadprog answer."""
    sol = _stack_from_npz(_DAQP_ONLY, fallback=False).solve(engine="python")
    assert sol.status == "optimal" and sol.info["fallbacks"] == []
    ref = _stack_from_npz(_DAQP_ONLY).solve(engine="python", solver="quadprog")
    _same_solution(sol, ref)


_DATA = Path(__file__).resolve().parents[1] / "data"
#: Random stacks (tests/support/strategies.py, 4 of 40 000 seeds) on which daqp alone called a
#: level QP infeasible that is feasible by construction (z = 0 with its slacks).
_DAQP_FALSE_INFEASIBLE = sorted(_DATA.glob("daqp_false_infeasible_[0-9]*.npz"))
#: The one of them the proximal attempt does not solve: its level QP (f ~5e4, rows at 1e5)
#: ends at daqp's iteration limit for every eps_prox from 1e-2 to 10 (measured).
_DAQP_STILL_FAILS = "daqp_false_infeasible_24866"


def _same_solution(sol: qc.Solution, ref: qc.Solution, x=None) -> None:
    """Level residuals to 1e-9 relative, ``x`` (``sol.x`` unless given) to 1e-9 of ``|x|∞``."""
    rs, rr = sol.level_residuals, ref.level_residuals
    assert np.all(np.abs(rs - rr) <= 1e-9 * np.maximum(1.0, rr)), (rs, rr)
    x = sol.x if x is None else x
    assert np.max(np.abs(x - ref.x)) <= 1e-9 * max(1.0, float(np.max(np.abs(ref.x))))


@pytest.mark.parametrize(
    "path",
    [
        pytest.param(
            p,
            marks=pytest.mark.xfail(
                strict=True,
                raises=qc.SolverError,
                reason="daqp alone: level 2 still 'infeasible' (the proximal attempt stops at "
                "its iteration limit); with fallbacks quadprog solves it",
            ),
        )
        if p.stem == _DAQP_STILL_FAILS
        else p
        for p in _DAQP_FALSE_INFEASIBLE
    ],
    ids=lambda p: p.stem,
)
def test_stacks_daqp_alone_called_infeasible_are_solved_without_fallbacks(path):
    """Each stack: daqp alone, no fallback; the quadprog answer and the native engine's."""
    sol = _stack_from_npz(path, fallback=False).solve(engine="python", solver="daqp")
    assert sol.status == "optimal" and sol.info["fallbacks"] == []
    ref = _stack_from_npz(path).solve(engine="python", solver="quadprog")
    _same_solution(sol, ref)
    if native.available():
        _same_solution(_stack_from_npz(path).solve(engine="native"), sol)


def test_daqp_reproducer():
    """The minimal reproducer (level 3 of the stack above, 3 variables ``y = (z, w)``, 6 rows):
    ``H = diag(1e-9, 1e-9, 1)``, ``f = 0``; one level row ``D z − w`` and five inherited rows,
    three of them opened by 1e-12 round ``z = 0`` (a wedge of two nearly parallel rows and a
    third through its tip). ``z = 0`` with its slack is feasible; daqp 0.11 (every setting of
    ``_DAQP_SETTINGS`` but the last) reports infeasible (exit flag -1).

    Cause (measured): daqp recovers the primal iterate from the dual one through
    ``(H + eps_prox·I)⁻¹`` (~1e6 with ``eps_prox = 1e-6``) times multipliers O(1) (the slack's
    curvature is 1): its iterate is 2e-9 off the exact vertex and violates the third row by
    1.6e-9 > ``primal_tol`` (1e-10), which the exact optimum meets with a 3e-10 margin; the
    row is added, the working set is singular, and the singular step, finding no blocking
    multiplier, declares infeasibility. With ``eps_prox ≥ 1e-2`` (the iterate's error
    ~1e-15) daqp solves it (and 17 of the 19 level QPs daqp failed on in 40 000 random stacks).
    """
    import daqp

    from qpcoord.core.backends import _DAQP_SETTINGS, OK, _solve_daqp, _solve_quadprog

    with np.load(_DATA / "daqp_false_infeasible_qp.npz") as d:
        H, f, G, lo, hi = (d[k] for k in ("H", "f", "G", "lo", "hi"))
    y_safe = np.array([0.0, 0.0, -lo[0]])  # z = 0, w meeting the level row exactly
    g = G @ y_safe
    assert np.all(g >= lo) and np.all(g <= hi)
    exact = _solve_quadprog(H, f, G, lo, hi, None, None, None)
    assert exact.code == OK
    sense = np.zeros(G.shape[0], dtype=np.int32)
    bu, bl = np.minimum(hi, 1e30), np.maximum(lo, -1e30)
    for tries in _DAQP_SETTINGS[:-1]:
        assert daqp.solve(H, f, G, bu, bl, sense, **tries)[2] == -1  # "infeasible"
    y, _, flag, _ = daqp.solve(H, f, G, bu, bl, sense, eps_prox=1e-2, eta_prox=1e-12,
                               primal_tol=1e-10)  # fmt: skip
    assert flag == 1
    np.testing.assert_allclose(y, exact.y, atol=1e-9)
    res = _solve_daqp(H, f, G, lo, hi, None, None, None)  # the last attempt solves it
    assert res.code == OK
    np.testing.assert_allclose(res.y, exact.y, atol=1e-9)


def _rotated(spec: dict, Q: np.ndarray) -> dict:
    """The stack in the variables ``u = Qᵀ x`` (``x = Q u``): every row ``a`` becomes ``Qᵀ a``;
    bounds stay bounds only for a signed permutation ``Q``."""

    def task(t):
        if isinstance(t, qc.Equality):
            return qc.Equality(t.A @ Q, t.b, weight=t.weight)
        return qc.Inequality(t.C @ Q, t.lower, t.upper, weight=t.weight)

    bounds = None
    if spec["bounds"] is not None:
        P = np.abs(Q).T  # Q = P·S: u_i = s_i x_{p(i)}
        s = np.sign(Q.sum(axis=0))
        lb, ub = P @ spec["bounds"].lower, P @ spec["bounds"].upper
        bounds = qc.Bounds(np.where(s > 0, lb, -ub), np.where(s > 0, ub, -lb))
    hard = spec["constraints"]
    return dict(
        levels=[[task(t) for t in lv] for lv in spec["levels"]],
        bounds=bounds,
        constraints=None if hard is None else [task(t) for t in hard],
    )


@settings(max_examples=60, deadline=None)
@given(
    case=st.sampled_from(
        [_DAQP_ONLY, *(p for p in _DAQP_FALSE_INFEASIBLE if p.stem != _DAQP_STILL_FAILS)]
    ),
    seed=st.integers(0, 2**32 - 1),
)
def test_daqp_alone_solves_the_false_infeasible_stacks_in_any_coordinates(case, seed):
    """The stacks daqp alone called infeasible, in random orthonormal coordinates (a signed
    permutation when there are bounds): daqp alone (``fallback=False``) solves each with the
    same level residuals, and ``Q u`` is the answer in the original coordinates."""
    spec = spec_from_npz(case)
    t0 = spec["levels"][0][0]
    n = (t0.A if isinstance(t0, qc.Equality) else t0.C).shape[1]
    rng = np.random.default_rng(seed)
    if spec["bounds"] is None:
        Q = np.linalg.qr(rng.standard_normal((n, n)))[0]
    else:
        Q = np.eye(n)[rng.permutation(n)] * rng.choice([-1.0, 1.0], n)
    ref = qc.Stack(**spec).solve(engine="python", solver="daqp")
    sol = qc.Stack(**_rotated(spec, Q), fallback=False).solve(engine="python", solver="daqp")
    assert sol.status == "optimal"
    _same_solution(sol, ref, Q @ sol.x)  # level residuals do not depend on the coordinates


_PARALLEL_EDGES = Path(__file__).resolve().parents[1] / "data" / "talos_polygon_parallel_edges.npz"


@pytest.mark.parametrize("solver", ["daqp", "quadprog"])
def test_nearly_parallel_active_rows_do_not_send_the_refinement_far(solver):
    """Talos, feet fixed (level 0), support polygon (level 1), CoM pulled forward (level 2),
    joint-velocity damping (level 3), step 9 of
    ``test_support_polygon_holds_the_com_with_feet_fixed``: the CoM reaches the polygon's
    front edge, where two hull edges are parallel to 4e-10 and both active. The Python
    engine's exact refinement of level 2 made both rows exactly tight: a step of 1e7 along
    their difference, on level 2's optimal set (its value unchanged, certified), which
    froze level 3 at 7.1e6 instead of 0.478; "optimal", no warning, and the robot's next
    configuration was garbage. Now those rows count as one at the activity tolerance."""
    from support.oracle import lexicographic

    spec = spec_from_npz(_PARALLEL_EDGES)
    sol = qc.Stack(**spec).solve(engine="python", solver=solver)
    assert sol.status == "optimal"
    ref = lexicographic(spec["levels"])
    # Clarabel's accuracy (the oracle's): ~1e-9 on the values, x unique (level 3 = I)
    np.testing.assert_allclose(sol.level_residuals, ref.level_residuals, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(sol.x, ref.x, atol=1e-6)
    if native.available():
        _same_solution(sol, qc.Stack(**spec_from_npz(_PARALLEL_EDGES)).solve(engine="native"))


def test_nearly_parallel_active_rows_count_as_one_at_the_activity_tolerance(monkeypatch):
    """The decision behind the test above, which only some rounding paths turn into a far
    step (on others the two-row step is rejected later): at level 2's refinement the two
    active hull edges have singular values 0.59 and 2.3e-10, one constraint at the activity
    tolerance (``active_rank``), two at rounding (``numerical_rank``, which the refinement
    used before: a step of 1e7 along their difference). 2.3e-10 is 260 times under the
    activity threshold (1e-7 of 0.59) and 7e4 times over the rounding one (26·eps·0.59), so
    the decision is the same on every rounding path."""
    decisions = []

    def spy(s, shape, tol):
        rank = active_rank(s, shape, tol)
        decisions.append((s.copy(), shape, rank))
        return rank

    monkeypatch.setattr(hierarchical, "active_rank", spy)
    qc.Stack(**spec_from_npz(_PARALLEL_EDGES)).solve(engine="python", solver="daqp")
    wedges = [(s, shape, rank) for s, shape, rank in decisions if s[-1] < 1e-6 * s[0]]
    assert wedges
    for s, shape, rank in wedges:
        assert shape[0] == 2 and s[-1] < 1e-9 * s[0], s
        assert rank == 1
        assert numerical_rank(s, shape) == 2  # rounding alone tells the two apart


_EXTREME_FEET = sorted(_DATA.glob("talos_extreme_feet_*.npz"))


def _level_scale(task_levels, x) -> np.ndarray:
    """Each level's scale ``‖b‖ + ‖A‖_F·‖x‖`` (inequality rows: their finite bounds)."""
    out = []
    for lv in task_levels:
        sc = 0.0
        for t in lv:
            M, v = (t.A, t.b) if isinstance(t, qc.Equality) else (t.C, t.upper)
            sc += float(np.linalg.norm(np.where(np.isfinite(v), v, 0.0)))
            sc += float(np.linalg.norm(M)) * float(np.linalg.norm(x))
        out.append(sc)
    return np.array(out)


@pytest.mark.parametrize("path", _EXTREME_FEET, ids=lambda p: p.stem)
def test_rows_dependent_on_the_frozen_rows_to_rounding_are_not_stepped_along(path):
    """Talos, feet (level 0), support polygon (1), CoM (2), posture damping ``x = 0`` (3),
    steps 10 and 11 of a closed loop after a bad step: feet targets ~1e5, level 0's condition
    number 3e6. The polygon rows lie in the span of the feet and CoM rows (to 1e-11), so with
    the feet frozen their 6 projections have rank 2 plus singular values ~1e-13: rounding of
    the freeze. The native level-1 active set stepped along them to ``y`` = 1e17 and level 2
    "did not converge" (SolverError); both engines froze 2 such directions at the CoM level
    and the posture level ended 1.6 % (Python, step 10) to 23 % (native) above its optimum.

    Reference: the polygon pins the CoM (its violated rows are frozen), so level 3 is the
    minimum-norm ``x`` with the feet and the CoM at the solution's values, a least-squares
    problem (checked: the polygon's satisfied row stays satisfied there). The cvxpy oracle
    cannot certify this scale (step 10: Clarabel "infeasible" at level 1; step 11: its
    self-check fails at 4e-6 on level 0, its level 3 is 2e-8 from this reference).
    Both engines say "optimal": the native end check compares level 0's value (7.6e-8,
    rounding at ``‖b‖`` 1e5) with the frozen one relative to ``max(1, value, scale)``
    (relative to ``max(1, value)`` it would say "inaccurate"),
    the level's ``‖b‖ + ‖A‖_F·‖x‖`` (the size of its value's rounding)."""
    spec = spec_from_npz(path)
    sol = {e: qc.Stack(**spec_from_npz(path)).solve(engine=e) for e in ("python", "native")}
    if not native.available():
        del sol["native"]
    lv = spec["levels"]
    A0 = np.vstack([t.A for t in lv[0]])
    b0 = np.concatenate([t.b for t in lv[0]])
    A2 = lv[2][0].A
    poly = lv[1][0]
    B = np.vstack([A0, A2])
    sv = np.linalg.svd(B, compute_uv=False)
    for eng, s in sol.items():
        assert s.status == "optimal", (eng, s.status, s.info.get("inaccurate"))
        rhs = np.concatenate([b0, A2 @ s.x])
        x3 = np.linalg.lstsq(B, rhs, rcond=None)[0]
        cx = poly.C @ x3
        sat = poly.C @ s.x <= poly.upper
        assert np.all(cx[sat] <= poly.upper[sat]), eng
        # a minimum-norm solution of a consistent system is exact to its forward error,
        # eps·κ(B)·(1 + ‖rhs‖ / (‖B‖·‖x‖)) relative (κ = 5e6 and 8e6 here: ~2e-9), for the
        # reference and for the engine alike: 4 times that (the bugs: 1.6 % to 23 %)
        rel = 4 * np.finfo(float).eps * sv[0] / sv[-1]
        rel *= 1.0 + np.linalg.norm(rhs) / (sv[0] * np.linalg.norm(x3))
        np.testing.assert_allclose(s.level_residuals[3], np.linalg.norm(x3), rtol=rel, err_msg=eng)
    if "native" in sol:
        p, n = sol["python"], sol["native"]
        scale = _level_scale(lv, p.x)
        assert np.all(np.abs(p.level_residuals - n.level_residuals) <= 1e-9 * scale), (
            p.level_residuals,
            n.level_residuals,
        )
        # x is unique (level 3 is x = 0 with unit weights)
        assert np.max(np.abs(p.x - n.x)) <= 1e-9 * float(np.max(np.abs(p.x)))


_NEARLY_PINNED = Path(__file__).resolve().parents[1] / "data" / "panda_nearly_pinned_face.npz"


def _nearly_pinned_reference() -> tuple[dict, np.ndarray, float, np.ndarray, float]:
    """The stack, its exact answer (the vertex of the level-0 rows and the four speed bounds
    level 1 pushes against, a 7×7 solve of condition number ~8), the rounding bound of that
    solve, the face's near-null direction and how far along it an active set may stop."""
    d = dict(np.load(_NEARLY_PINNED))
    A0, b0, A1, b1, lb, ub = (d[k] for k in ("A0", "b0", "A1", "b1", "lb", "ub"))
    eye = np.eye(A0.shape[1])
    V = np.vstack((A0, eye[[0, 2, 5, 6]]))
    x = np.linalg.solve(V, np.concatenate((b0, [ub[0], lb[2], lb[5], ub[6]])))
    eps = np.finfo(float).eps
    # backward-stable solve: ε·κ(V)·‖x‖, with a factor for the two solves compared
    x_tol = 16.0 * eps * np.linalg.cond(V) * float(np.abs(x).max())
    # the face of level 0 with joints 1, 6, 7 on their bounds is a line, along which level
    # 1's row is 1.9e-10 of its norm: level 1 gains g per unit along it; an active set
    # calls a working set solved where a step gains under 1e-15 of the objective f
    face = np.linalg.svd(np.vstack((A0, eye[[0, 5, 6]])))[2][-1]
    res = A1 @ x - b1
    f = float(res @ res)
    g = abs(2.0 * float(res @ (A1 @ face)))
    return d, x, x_tol, face, 1e-15 * f / g


def _nearly_pinned_stack(d: dict) -> qc.Stack:
    return qc.Stack(
        [qc.Equality(d["A0"], d["b0"]), qc.Equality(d["A1"], d["b1"])],
        bounds=qc.Bounds(d["lb"], d["ub"]),
        damping=1e-4,
    )


@pytest.mark.parametrize("solver", SOLVERS)
def test_minimum_norm_step_does_not_slide_through_the_bounds_opening(solver):
    """A Panda IK step (hand position, then a posture asking 240 rad/s² of rate it cannot
    get, the speed limits as bounds; ``examples/ch5_hierarchy.py``'s second step) whose
    level 1 ends on a vertex: joints 1, 3, 6, 7 on their speed bounds. Level 1 froze, the
    minimum-norm step keeps 3 directions in which the three bounds of joints 1, 6, 7 are
    nearly dependent (smallest singular value 1.9e-10 with the frozen rows): the Python
    engine's minimum-norm QP went 3e-12 past them (the backends' opening of the rows)
    and bought 0.017 rad/s along the face (joint 3 at −2.169 instead of −2.175), leaving
    level 0 at 1.2e-12 and level 1 1.8e-11 above its optimum, while the native engine,
    exact on the bounds, stayed on the vertex. The step is now finished exactly on the
    rows the QP's point meets to the opening (daqp and quadprog failed without it)."""
    d, x_ref, x_tol, face, face_tol = _nearly_pinned_reference()
    sol = _nearly_pinned_stack(d).solve(engine="python", solver=solver)
    assert sol.status == "optimal", sol.info
    # exact across the face; along it (level 1's row is 1.9e-10 of its norm there) the
    # certified step may stop where the native active set may: piqp's and clarabel's level 1
    # leave a row ~6e-16 short of its bound, which moves the step's optimum ~1e-6 along it
    # (the fallback's point, certified); the slide through the opening was 0.017
    dx = sol.x - x_ref
    along = float(dx @ face)
    assert abs(along) <= face_tol, along
    assert np.abs(dx - along * face).max() <= x_tol, (sol.x, x_ref)
    # level 0 is met exactly by the vertex: its residual is the rounding of A0 x − b0
    eps = np.finfo(float).eps
    scale = np.linalg.norm(d["A0"]) * np.linalg.norm(x_ref) + np.linalg.norm(d["b0"])
    assert sol.level_residuals[0] <= 8.0 * eps * scale
    if native.available():
        sn = _nearly_pinned_stack(d).solve(engine="native")
        dx = sn.x - x_ref
        along = float(dx @ face)
        # the native active set may stop short of joint 3's bound along the face (a step
        # gaining under 1e-15 of level 1's objective), exact across it
        assert abs(along) <= face_tol, along
        assert np.abs(dx - along * face).max() <= x_tol
        assert abs(sn.level_residuals[1] - sol.level_residuals[1]) <= 8.0 * eps * (
            abs(float(d["b1"][0])) + np.linalg.norm(d["A1"]) * np.linalg.norm(x_ref)
        )
