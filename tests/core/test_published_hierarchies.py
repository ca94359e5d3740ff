"""Published hierarchical least-squares problems (LexLS, soth, hdaqp; ``tests/data/hlsp``)
on every backend with the default options, judged against the exact lexicographic
reference (:mod:`support.oracle`) and, for the humanoid, LexLS's published solution.

Every level value must match the reference to ``REL`` of its value (a floor of ``FLOOR``
of the level's scale for levels whose optimum is 0), or the solution must say
``"inaccurate"`` — which fails here too: these problems are expected to be certified.
Uncertified: the humanoid's last level 4.9e-4 above the optimum (regularisation 1e-9)
on every backend and 12 % above on HiGHS; soth's 30-variable stack letting level-0 joint
limits slip by up to 9e-6 to improve level 2. Each is pinned below.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog, lsq_linear
from support.campaign import level_scales
from support.hlsp import NAMES, load
from support.oracle import level_residuals, lexicographic

import qpcoord as qc
from qpcoord.core import native

#: Backends fast enough for the normal suite; osqp and scs (seconds on the humanoid) are slow.
FAST = [s for s in ("daqp", "quadprog", "proxqp", "piqp", "clarabel", "highs")
        if s in qc.available_solvers()]  # fmt: skip
SLOW = [s for s in ("osqp", "scs") if s in qc.available_solvers()]
BACKENDS = [pytest.param(s) for s in FAST] + [pytest.param(s, marks=pytest.mark.slow) for s in SLOW]
#: Relative agreement of a level value with the reference.
REL = 1e-6
#: Floor (relative to the level's scale) for levels whose optimum is 0.
FLOOR = 1e-9
#: A higher level may not be worse than the reference by more than this of its squared scale.
WORSEN = 1e-9

_REF: dict = {}


def _case(name: str, as_bounds: bool):
    key = (name, as_bounds)
    if key not in _REF:
        P = load(name, simple_as_bounds=as_bounds)
        _REF[key] = (P, lexicographic(P.levels, P.bounds, polish=True))
    return _REF[key]


def _solve(P, solver: str):
    """Default options. scs (first-order, run to 1e-10) may hit the 10 s time limit on the
    88-variable humanoid: that is a clear error in bounded time, reported as xfail."""
    try:
        return P.stack().solve(solver=solver)
    except qc.SolverError as exc:
        if solver == "scs" and "time limit" in str(exc):
            pytest.xfail(f"scs: {str(exc)[:80]}")
        raise


CASES = [(name, False) for name in NAMES] + [("lexls_test01_humanoid", True)]
IDS = [f"{n}{'-box' if b else ''}" for n, b in CASES]


def _dual_gap(A, b, E, u, lo, up, x) -> tuple[float, float, float]:
    """Level value at ``x``, a lower bound on the optimum of
    ``min ‖A x − b‖ s.t. E x = u, lo ≤ x ≤ up`` (finite box) by Lagrangian duality, and the
    rounding of that bound's square. ``g(y, μ) = −½‖y‖² − yᵀb − μᵀu + Σ min(cᵢ loᵢ, cᵢ upᵢ)``,
    ``c = Aᵀy + Eᵀμ``, is a lower bound on ``½‖A x − b‖²`` for *any* ``(y, μ)``.
    ``y = A x − b``; ``μ`` maximises ``g`` (an LP: concave piecewise linear), so an inexact LP
    only loosens the bound.

    The bound is exact for the ``(y, μ)`` used, but its evaluation is not: ``g`` is a small
    difference of large terms (soth_sot: ``μᵀu`` and the box term are ±3.2e3, ``g`` is 1.9e-3,
    a cancellation of 1.7e6), so ``lower`` may exceed the optimum by the rounding of ``g``.
    Each dot product of length ``k`` errs by at most ``k·eps`` times the dot product of the
    absolute values (Higham, Accuracy and Stability, §3.1), ``c`` likewise, and each box term
    ``min(cᵢ loᵢ, cᵢ upᵢ)`` by ``max(|loᵢ|, |upᵢ|)·|δcᵢ|`` plus its own rounding; so with
    ``K = rows(A) + rows(E) + n + 4`` (the longest chain of additions)
    ``|δg| ≤ K·eps·(|y|ᵀ|y| + |y|ᵀ|b| + |μ|ᵀ|u| + 2·wᵀ(|A|ᵀ|y| + |E|ᵀ|μ|))``, ``w = max(|lo|,
    |up|)``, to first order. The third value returned is ``2·|δg|``, the rounding of
    ``lower²``."""
    y = A @ x - b
    c0 = A.T @ y
    m, n = E.shape
    # variables (μ, t): minimise uᵀμ − Σt  s.t.  t_i ≤ c_i lo_i,  t_i ≤ c_i up_i
    G = np.block([[-lo[:, None] * E.T, np.eye(n)], [-up[:, None] * E.T, np.eye(n)]])
    h = np.concatenate([lo * c0, up * c0])
    lp = linprog(
        np.concatenate([u, -np.ones(n)]), A_ub=G, b_ub=h, bounds=(None, None), method="highs"
    )
    assert lp.status == 0, lp.message
    mu = lp.x[:m]
    c = c0 + E.T @ mu
    g = -0.5 * y @ y - y @ b - mu @ u + float(np.sum(np.minimum(c * lo, c * up)))
    ay, amu = np.abs(y), np.abs(mu)
    w = np.maximum(np.abs(lo), np.abs(up))
    mag = (
        ay @ ay
        + ay @ np.abs(b)
        + amu @ np.abs(u)
        + 2.0 * w @ (np.abs(A).T @ ay + np.abs(E).T @ amu)
    )
    dg = (A.shape[0] + m + n + 4) * np.finfo(float).eps * float(mag)
    return float(np.linalg.norm(y)), float(np.sqrt(max(2.0 * g, 0.0))), 2.0 * dg


@pytest.mark.parametrize("solver", BACKENDS)
@pytest.mark.parametrize(("name", "as_bounds"), CASES, ids=IDS)
def test_level_values_match_the_reference(name, as_bounds, solver):
    P, ref = _case(name, as_bounds)
    sol = _solve(P, solver)
    assert sol.status == "optimal", f"{name}/{solver}: {sol.status} {sol.info.get('inaccurate')}"
    ours, theirs = sol.level_residuals, ref.level_optima
    scale = level_scales(P.levels, ref.x)
    tol = np.maximum(REL * theirs, FLOOR * scale)
    for k in range(len(ours)):
        assert abs(ours[k] - theirs[k]) <= tol[k], (
            f"{name}/{solver} level {k}: {ours[k]!r} vs reference {theirs[k]!r} "
            f"({(ours[k] - theirs[k]) / max(theirs[k], 1e-300):.2e} relative)"
        )
    # no higher level worsened to improve a lower one
    worse2 = (ours**2 - theirs**2) / scale**2
    for k in range(len(ours)):
        assert not (worse2[k] > WORSEN and (worse2[k + 1 :] < -WORSEN).any()), (name, k)
    # hard rows never slip
    if P.bounds is not None:
        lb, ub = P.bounds.resolve(P.n)
        assert np.all(sol.x >= lb) and np.all(sol.x <= ub)


@pytest.mark.parametrize("solver", BACKENDS)
def test_humanoid_last_level_is_exact_and_matches_lexls(solver):
    """LexLS test_01 (88 variables, 5 levels). Uncertified, the last level came out 4.9e-4
    relative above the optimum with the default regularisation on every backend, 12 % on
    HiGHS. It must now match the exact reference and LexLS's published solution to 1e-6."""
    for as_bounds in (False, True):
        P, ref = _case("lexls_test01_humanoid", as_bounds)
        sol = _solve(P, solver)
        assert sol.status == "optimal"
        published = level_residuals(P.levels, P.solution)
        last = sol.level_residuals[-1]
        assert last == pytest.approx(ref.level_optima[-1], rel=REL)
        assert last == pytest.approx(published[-1], rel=REL)
        # the levels above are met (published and reference: ~1e-13; values, not slack)
        assert np.all(sol.level_residuals[:-1] <= 1e-9)


@pytest.mark.parametrize("solver", ["piqp", "proxqp", "clarabel", "highs"])
@pytest.mark.parametrize("as_bounds", [False, True], ids=["rows", "box"])
def test_humanoid_minimum_norm_x_is_the_native_engines(solver, as_bounds):
    """The minimum-norm step decides ``x`` (every level value matched while it was wrong):
    from the interior-point backends' points, pulled back into a row, the active-set
    continuation stopped 0.11 (rows) / 0.42 (box) from the exact ``x``, HiGHS (box) 8.9,
    and was returned as "optimal" unchecked. The step is strictly convex, so ``x`` is
    unique: both engines' ``x`` agree to their tolerances relative to ``‖x‖∞`` (1e-9; 5e-11
    measured, ``‖x‖∞`` ~ 2e2)."""
    if solver not in qc.available_solvers() or not native.available():
        pytest.skip(f"{solver} or the native engine not installed")
    P, _ = _case("lexls_test01_humanoid", as_bounds)
    sol = P.stack().solve(solver=solver, engine="python")
    ref = P.stack().solve(engine="native")
    assert sol.status == "optimal" and ref.status == "optimal"
    assert np.abs(sol.x - ref.x).max() <= 1e-9 * float(np.abs(ref.x).max())


@pytest.mark.parametrize("solver", BACKENDS)
def test_soth_sot_joint_limits_never_slip(solver):
    """soth ``sot.txt`` (30 variables, 5 levels, level 0 = joint limits as rows).
    Uncertified, several backends let the level-0 limits slip by up to 9e-6 to improve level 2."""
    P, _ = _case("soth_sot", False)
    lim = P.levels[0]
    sol = _solve(P, solver)
    cx = lim.C @ sol.x
    slip = np.maximum(np.maximum(lim.lower - cx, cx - lim.upper), 0.0)
    assert slip.max() <= 1e-12, f"{solver}: joint limits slip by {slip.max():.2e}"


def test_soth_sot_plain_reference_is_off_at_level_1():
    """soth_sot: level 1 (3 equality rows under the joint-limit box) is a bounded least-
    squares problem, solved exactly by scipy's BVLS. The library's ``A₁x`` equals BVLS's to
    rounding; the plain (conic, unpolished) reference's misses it by ~2.5e-11 and its
    level 1 is ~2e-11 above the optimum — which buys it a level 2 better than the true
    lexicographic optimum by ~2e-5 relative. Hence the tests use ``polish=True``."""
    P, _ = _case("soth_sot", False)
    ref = lexicographic(P.levels, P.bounds)
    lim, t1 = P.levels[0], P.levels[1]
    assert np.allclose(lim.C, np.eye(P.n))
    bv = lsq_linear(t1.A, t1.b, bounds=(lim.lower, lim.upper), method="bvls", tol=1e-15)
    u = t1.A @ bv.x
    sol = P.stack().solve(solver="daqp")
    # A₁x is unique on level 1's optimal set; an exact solve gets it to the rounding of the
    # fitted values of a least-squares problem on the free columns F (BVLS's active mask):
    # (n + 1)·eps·(‖|A₁||x|‖ + κ(A₁_F)·‖r₁‖), here 31·eps·(3.0 + 23·0.0047) = 2.1e-14, twice
    # for two solves (measured: 4.6e-16)
    free = bv.active_mask == 0
    r1 = np.linalg.norm(u - t1.b)
    rounding = (
        2.0
        * (P.n + 1)
        * np.finfo(float).eps
        * (np.linalg.norm(np.abs(t1.A) @ np.abs(bv.x)) + np.linalg.cond(t1.A[:, free]) * r1)
    )
    assert np.linalg.norm(t1.A @ sol.x - u) <= rounding
    assert np.linalg.norm(t1.A @ ref.x - u) > 10.0 * rounding  # 2.5e-11: not rounding
    assert ref.level_optima[1] > r1 + 10.0 * rounding  # 2e-11 above the optimum


@pytest.mark.parametrize("solver", BACKENDS)
def test_soth_sot_level_2_meets_its_dual_bound(solver):
    """Level 2 of soth_sot judged without the reference: pinned to level 1's exact values
    (BVLS) inside the joint-limit box, the library's level-2 value is within 1e-6 relative
    of a Lagrangian lower bound on the optimum (so it is optimal to 1e-6). The lower bound,
    ``value`` and the library's level value are each exact only to their rounding, bounded
    from the magnitudes of the terms that make them up (``_dual_gap``)."""
    P, _ = _case("soth_sot", False)
    lim, t1, t2 = P.levels[0], P.levels[1], P.levels[2]
    bv = lsq_linear(t1.A, t1.b, bounds=(lim.lower, lim.upper), method="bvls", tol=1e-15)
    sol = _solve(P, solver)
    value, lower, rounding2 = _dual_gap(t2.A, t2.b, t1.A, t1.A @ bv.x, lim.lower, lim.upper, sol.x)
    # the level value computed here and by the library: each ‖A x − b‖ errs by at most
    # (n + 1)·eps·‖|A||x| + |b|‖ (a dot product of length n, then the subtraction);
    # here ‖|A||x| + |b|‖ = 11 against a value of 0.061: 2.6e-12 relative for both together
    agree = (
        2.0
        * (P.n + 2)
        * np.finfo(float).eps
        * np.linalg.norm(np.abs(t2.A) @ np.abs(sol.x) + np.abs(t2.b))
    )
    assert abs(value - sol.level_residuals[2]) <= agree
    # a lower bound, up to the rounding of its evaluation (_dual_gap): lower ≤ value·(1 + ρ),
    # ρ = rounding2 / (2·value²), 3.6e-8 on soth_sot, well inside the 1e-6 gap allowed below
    assert lower**2 <= value**2 + rounding2, (lower, value, rounding2)
    assert rounding2 / (2.0 * value**2) <= 0.1 * REL  # the allowance does not hide the gap
    assert value - lower <= REL * value, f"{solver}: gap {(value - lower) / value:.2e}"


def test_loader_maps_rows_and_simple_bounds():
    """Rows with lower == upper are equalities, the others inequalities; the humanoid's
    level-0 simple bounds become the box only on request, and both forms have the same
    lexicographic optimum (the box is consistent, so level 0's optimal set is the box)."""
    P = load("lexls_test01_humanoid")
    Pb = load("lexls_test01_humanoid", simple_as_bounds=True)
    assert len(P.levels) == 5 and len(Pb.levels) == 4 and Pb.bounds is not None
    eqs = [t for t in P.levels[4:] if isinstance(t, qc.Equality)]
    assert eqs and eqs[0].A.shape == (97, 88)
    r, rb = _case("lexls_test01_humanoid", False)[1], _case("lexls_test01_humanoid", True)[1]
    assert r.level_optima[-1] == pytest.approx(rb.level_optima[-1], rel=1e-9)
    with pytest.raises(ValueError, match="simple_as_bounds"):
        load("soth_sot", simple_as_bounds=True)
    with pytest.raises(ValueError, match="name"):
        load("nope")
