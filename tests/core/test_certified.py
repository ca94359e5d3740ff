"""The certified hierarchy: every level's KKT conditions
are checked on the returned point; where they fail the level is made exact (active-set
continuation, fallback backends) or the solution says ``status="inaccurate"``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import lsq_linear
from support.stacks import retry_leak_case

import qpcoord as qc
import qpcoord.core.methods.hierarchical as hier
from qpcoord.core.polish import KKT_FEAS_TOL, KKT_TOL, active_set_ls, kkt_residual

SOLVERS = qc.available_solvers()
FAST = [s for s in ("daqp", "quadprog", "piqp", "clarabel", "highs", "osqp") if s in SOLVERS]

# one equality level, two active bounds, condition 5e3
A1 = np.array(
    [
        [0.3, 1e3, -10, 700, -0.01],
        [0.5, -500, 100, 600, 1e-3],
        [-0.6, -200, -100, -300, -3e-3],
        [-0.4, 500, -40, -50, -0.1],
    ]
)
B1, W1 = np.array([4.0, 7, 0.6, 3]), np.array([7.0, 2, 2, 8])
LO1 = [-np.inf, -np.inf, -0.02, -np.inf, -np.inf]
UP1 = [np.inf, np.inf, np.inf, 0.006, np.inf]


@pytest.mark.parametrize("solver", FAST)
def test_one_level_two_active_bounds_is_exact(solver):
    """Was 33.36 on every backend (the regularisation, one scalar for columns from 0.1 to
    1e3, pulled x5 from -57 to -25); bvls finds 19.32."""
    sol = qc.Stack([qc.Equality(A1, B1, weight=W1)], bounds=qc.Bounds(LO1, UP1)).solve(
        solver=solver
    )
    sw = np.sqrt(W1)
    ref = lsq_linear(sw[:, None] * A1, sw * B1, bounds=(LO1, UP1), method="bvls", tol=1e-14)
    value = sol.level_residuals[0] ** 2
    ref_value = float(np.sum((sw * (A1 @ ref.x - B1)) ** 2))
    assert ref_value == pytest.approx(19.32, abs=5e-3)
    assert value == pytest.approx(ref_value, rel=1e-9)
    assert sol.status == "optimal"
    assert sol.x[2] == pytest.approx(-0.02, abs=1e-9) and sol.x[3] <= 0.006
    assert sol.info["kkt"][0] <= 1e-7


def test_uncertified_level_is_inaccurate_and_strict_raises(monkeypatch):
    """A level whose certificate cannot be met is reported, never silently returned."""
    monkeypatch.setattr(hier, "KKT_TOL", -1.0)  # nothing can be certified
    stack = qc.Stack([qc.Equality(A1, B1, weight=W1)], bounds=qc.Bounds(LO1, UP1), fallback=False)
    sol = stack.solve(solver="quadprog")
    assert sol.status == "inaccurate"
    assert sol.info["inaccurate"]["level"] == 0
    assert np.isfinite(sol.info["inaccurate"]["kkt_residual"])
    assert sol.info["inaccurate"]["reason"].startswith("level 0: its optimality conditions")
    with pytest.raises(qc.SolverError, match="level 0"):
        stack.solve(solver="quadprog", strict=True)
    with pytest.raises(ValueError, match="strict"):
        stack.solve(strict="yes")


def test_strict_solve_returns_certified_answers():
    sol = qc.Stack([qc.Equality(A1, B1, weight=W1)], bounds=qc.Bounds(LO1, UP1)).solve(strict=True)
    assert sol.status == "optimal" and not sol.info["uncertified"]


def test_closed_form_levels_stay_inside_their_box():
    """A closed-form candidate accepted to FEAS_TOL is snapped into the bounds (the IK's
    0.125 rad/s bound was exceeded by 2.7e-10)."""
    ub = 0.125
    A = np.array([[1.0, 1.0, 1.0]])
    b = np.array([3 * ub * (1 + 5e-10)])
    sol = qc.Stack([qc.Equality(A, b)], bounds=qc.Bounds(-ub, ub)).solve()
    assert np.all(sol.x <= ub)


def test_kkt_residual_sees_a_wrong_active_set():
    """Independent of the library's method: at the regularised point of the 1-level case
    the certificate fails; at bvls's optimum it holds."""
    sw = np.sqrt(W1)
    Q, c = sw[:, None] * A1, sw * B1
    G = np.eye(5)[[2, 3]]
    lo, hi = np.array([-0.02, -np.inf]), np.array([np.inf, 0.006])
    ref = lsq_linear(Q, c, bounds=(LO1, UP1), method="bvls", tol=1e-14).x
    st, inf = kkt_residual(Q, c, G, lo, hi, ref)
    assert st < 1e-7 and inf == 0.0
    biased = np.array([-2.84646682, 1.62352538e-04, 1.84091980e-02, 6e-3, -25.3437253])
    assert kkt_residual(Q, c, G, lo, hi, biased)[0] > 1e-3
    y, ok = active_set_ls(Q, c, G, lo, hi, biased)
    assert ok
    np.testing.assert_allclose(y, ref, rtol=1e-8, atol=1e-10)


def test_fallback_on_a_point_outside_its_rows(monkeypatch):
    """A backend point outside its QP's rows by more than CHECK_TOL goes to the fallback
    chain (daqp 4.9e-6 outside gave SolverError at every step without it)."""
    import qpcoord.core.elimination as elim

    real = elim.solve_dense_qp

    def bad_daqp(solver, H, f, G, lo, hi, lb, ub, y0):
        res = real(solver, H, f, G, lo, hi, lb, ub, y0)
        if solver == "daqp":
            res.y = res.y + 1.0  # far outside
        return res

    monkeypatch.setattr(elim, "solve_dense_qp", bad_daqp)
    stack = qc.Stack([qc.Equality(A1, B1, weight=W1)], bounds=qc.Bounds(LO1, UP1))
    sol = stack.solve(solver="daqp")
    assert sol.info["fallbacks"] and sol.status == "optimal"
    assert sol.level_residuals[0] ** 2 == pytest.approx(19.3248, rel=1e-4)


@pytest.mark.parametrize("solver", ["daqp", "quadprog", "proxqp"])
def test_a_level_met_exactly_with_zero_targets_is_certified(solver):
    """An inequality level with lower == upper met to rounding (slack objective: c = 0 and
    Q y ≈ 0, so the level's own scale is ~1e-16) is certified by its value on the library's
    max(1, scale) rule. Found at the merge: every backend returned "inaccurate" (KKT 0.79 on
    level 0) and proxqp spent 3 s in fallbacks on this 5-variable stack."""
    head, extra, options = retry_leak_case()
    sol = qc.solve_stack([*head, extra], solver=solver, **options)
    assert sol.status == "optimal", sol.info
    assert sol.info["fallbacks"] == []
    # met to the rounding of C x against its bounds: (n + 1)·eps·‖|C||x| + |bounds|‖, 7e-15
    # (measured: 3e-16)
    C, lo = head[0][0].C, head[0][0].lower
    rounding = (C.shape[1] + 1) * np.finfo(float).eps
    assert sol.level_residuals[0] <= rounding * np.linalg.norm(
        np.abs(C) @ np.abs(sol.x) + np.abs(lo)
    )


def test_certificate_skips_the_nnls_when_the_gradient_is_zero(monkeypatch):
    """Certification cost: μ = 0 certifies a point whose gradient is already
    under the tolerance, so no NNLS runs, active rows or not; a level met exactly needs
    neither the column scaling nor the NNLS. Same verdicts with the rows prepared once."""
    import scipy.optimize

    from qpcoord.core.polish import prepare

    def no_nnls(*a, **k):
        raise AssertionError("NNLS called")

    monkeypatch.setattr(scipy.optimize, "nnls", no_nnls)
    Q = np.array([[1.0, 0.0], [1.0, 0.0]])
    c = np.array([1.0, -1.0])  # residual (−1, 1) at y = 0, gradient Qᵀr = 0
    G = np.array([[0.0, 1.0]])
    lo, hi = np.array([-np.inf]), np.array([0.0])  # active at y = 0
    y = np.zeros(2)
    st, inf = kkt_residual(Q, c, G, lo, hi, y)
    assert st == 0.0 and inf == 0.0
    assert kkt_residual(Q, c, G, lo, hi, y, prepare(Q, G, lo, hi)) == (st, inf)
    # met exactly (value 0) with the row active
    c0 = np.zeros(2)
    assert kkt_residual(Q, c0, G, lo, hi, y, prepare(Q, G, lo, hi)) == (0.0, 0.0)


def test_prepared_rows_give_the_same_certificate():
    rng = np.random.default_rng(3)
    for _ in range(20):
        Q = rng.normal(size=(4, 5))
        c = rng.normal(size=4)
        G = rng.normal(size=(6, 5)) * 10.0 ** rng.uniform(-3, 3, (6, 1))
        G[2] = 0.0  # a zero row is dropped
        y = rng.normal(size=5)
        gy = G @ y
        lo = gy - rng.uniform(0, 1, 6) * (rng.uniform(size=6) < 0.5)
        hi = gy + rng.uniform(0, 1, 6)
        from qpcoord.core.polish import prepare

        a = kkt_residual(Q, c, G, lo, hi, y)
        b = kkt_residual(Q, c, G, lo, hi, y, prepare(Q, G, lo, hi))
        assert a == pytest.approx(b, rel=1e-12, abs=1e-15)


_MN_LEVELS = [qc.Equality([[1.0, 1.0, 0.0]], [2.0])]
_MN_BOUNDS = qc.Bounds([-1.0, -1.0, 0.5], [2.0, 2.0, 2.0])
_MN_OPTIMUM = np.array([1.0, 1.0, 0.5])


def _bad_minimum_norm_qp(monkeypatch, dx, stuck):
    """Make the minimum-norm step's QP return its optimum moved by ``dx`` (in ``x``), and,
    with ``stuck``, the active-set continuation after it return its start (the levels above
    solve unpatched)."""
    import qpcoord.core.elimination as elim

    real, real_continuation = elim.Reduced.solve_qp, hier.active_set_ls

    def solve_qp(self, H, f, *args, where="", **kwargs):
        y = real(self, H, f, *args, where=where, **kwargs)
        if where != "minimum-norm step":
            monkeypatch.setattr(hier, "active_set_ls", real_continuation)
            return y
        if stuck:
            monkeypatch.setattr(
                hier, "active_set_ls", lambda Q, c, G, lo, hi, y0, **kw: (y0, False)
            )
        return y + self.project(np.asarray(dx))

    monkeypatch.setattr(elim.Reduced, "solve_qp", solve_qp)


def test_minimum_norm_point_rejected_by_its_exact_finish_is_certified(monkeypatch):
    """The QP's point of the minimum-norm step, within its rows but 0.17 from the optimum,
    after its exact finish on the active rows is rejected: it was kept unchecked and the
    solution said "optimal"; it is now checked, fails, and the continuation from it finds
    the optimum."""
    _bad_minimum_norm_qp(monkeypatch, [0.1, -0.1, 0.1], stuck=False)
    monkeypatch.setattr(hier, "_exact_on_active_rows", lambda *args: None)
    sol = qc.Stack(_MN_LEVELS, bounds=_MN_BOUNDS).solve(engine="python", solver="daqp")
    assert sol.status == "optimal" and not sol.info["uncertified"]
    # the continuation solves the step exactly on its working set: a 3-variable system of
    # condition 1 with entries ~1, to a few ε
    np.testing.assert_allclose(sol.x, _MN_OPTIMUM, atol=1e-12)


@pytest.mark.parametrize(
    "dx",
    [[0.1, -0.1, 0.1], [1.2, -1.2, 0.1]],
    ids=["within-the-rows", "pulled-back"],
)
def test_uncertified_minimum_norm_step_is_inaccurate_and_strict_raises(monkeypatch, dx):
    """A minimum-norm step whose every path ends on a point away from its optimum (the
    QP's point within the rows, 0.17 from it, or one through the upper bound of x0 pulled
    back into it, 1.4 from it; and a continuation that stops where it started) is
    reported as the level after the last one, never returned as "optimal"."""
    _bad_minimum_norm_qp(monkeypatch, dx, stuck=True)
    stack = qc.Stack(_MN_LEVELS, bounds=_MN_BOUNDS, fallback=False)
    sol = stack.solve(engine="python", solver="daqp")
    assert np.abs(sol.x - _MN_OPTIMUM).max() > 0.01  # the injected point is what was kept
    assert sol.status == "inaccurate"
    assert sol.info["inaccurate"]["level"] == len(_MN_LEVELS)
    assert sol.info["inaccurate"]["kkt_residual"] > KKT_TOL
    assert "the minimum-norm step" in sol.info["inaccurate"]["reason"]
    with pytest.raises(qc.SolverError, match=rf"level {len(_MN_LEVELS)} \(the minimum-norm step\)"):
        stack.solve(engine="python", solver="daqp", strict=True)


def test_a_row_short_of_its_bound_carries_its_gap():
    """A row within KKT_FEAS_TOL of its bound counts as active, but a multiplier ``μ`` on a
    row ``s`` short of it is an objective gap ``μ·s`` the cone does not see. Two rows
    ``δ`` from parallel bound a wedge whose edge is met to the tolerance for a long way:
    10 along it from the unique optimum the gradient lies in their cone (``μ ~ 10/δ``,
    right signs), and the point is feasible, 50 above the optimum's value. It was
    certified by stationarity alone (0); with ``gap=True`` (the minimum-norm step's check)
    the gap ``μ·s`` = 150 is part of the residual."""
    C = 1e6  # the rows' bounds: their tolerance is KKT_FEAS_TOL·C
    delta = 0.5 * KKT_FEAS_TOL * C / 15.0  # 15 along the edge, row 2 is half of it short
    G = np.array([[1.0, 0.0], [1.0, delta]])
    lo, hi = np.array([C, -np.inf]), np.array([np.inf, C])
    Q, c = np.eye(2), np.array([C - 1.0, -5.0])
    # strictly convex: the KKT point is the optimum (row 1 at its bound, μ = 1; row 2
    # 5δ short of its bound, no multiplier)
    optimum = np.array([C, -5.0])
    held = np.array([C, -15.0])
    st, infeas = kkt_residual(Q, c, G, lo, hi, optimum, gap=True)
    assert st <= KKT_TOL and infeas == 0.0
    # the held point is feasible and its gradient lies in the rows' cone, right signs
    g = held - c
    a2 = G[1] / np.linalg.norm(G[1])
    mu2 = -g[1] / a2[1]
    mu1 = g[0] + mu2 * a2[0]
    assert mu1 > 0 and mu2 > 0
    # the identity holds to the rounding of μ₂·a₂ (ε·μ₂ per entry)
    eps = np.finfo(float).eps
    assert np.abs(mu1 * G[0] - mu2 * a2 - g).max() <= 4.0 * eps * mu2
    st, infeas = kkt_residual(Q, c, G, lo, hi, held, gap=True)
    assert infeas == 0.0
    assert st > KKT_TOL, st
    # a level's check (no gap term) sees stationarity only
    assert kkt_residual(Q, c, G, lo, hi, held)[0] <= KKT_TOL


_HUMANOID_STEP = Path(__file__).resolve().parents[1] / "data" / "humanoid_min_norm_step.npz"


def test_humanoid_minimum_norm_step_held_on_rows_dependent_to_rounding_is_not_certified():
    """The LexLS humanoid's (rows form) minimum-norm step: 8 free directions, 20 rows. Its
    optimum meets 11 rows whose normals are dependent to rounding (smallest singular value
    5e-14): they are met to ~1e-13 along a segment 8.7 long. Finishing the step on the
    rows its QP point met to ACTIVE_TOL held it at the segment's far end (``held``): its
    gradient lay in the rows' cone with multipliers of 1e14 on rows 1e-13 past their
    bounds, and the certificate (stationarity 0) accepted a point 8.7 from the optimum
    whose value is 38 above it. The data: the step's rows, ``p`` (``min ½‖z + p‖²``),
    the optimum (the native engine's within 9e-11) and the held point."""
    d = np.load(_HUMANOID_STEP)
    G, lo, hi, p = d["G"], d["lo"], d["hi"], d["p"]
    optimum, held = d["optimum"], d["held"]
    Q = np.eye(p.size)
    st, infeas = kkt_residual(Q, -p, G, lo, hi, optimum, gap=True)
    assert st <= KKT_TOL and infeas <= KKT_FEAS_TOL
    st_held, infeas_held = kkt_residual(Q, -p, G, lo, hi, held, gap=True)
    # the held point is as feasible as the optimum, so is the segment between them (each
    # row's violation is convex along it): the held point is not the minimum on a
    # segment of points feasible to the tolerance; the step is strictly convex
    assert infeas_held <= KKT_FEAS_TOL
    assert np.linalg.norm(held - optimum) > 8.0
    value = 0.5 * np.sum((held + p) ** 2) - 0.5 * np.sum((optimum + p) ** 2)
    assert value > 30.0
    assert st_held > KKT_TOL, st_held
