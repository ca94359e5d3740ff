"""Near-degenerate levels: rows that cancel to within rounding decide the levels below.

A level whose rows nearly cancel (two rows parallel to 3.4e-10 of their norms, targets 0.86
apart) has a direction along which its value changes by ~1e-8 of itself over the whole box:
the point kept along it is set by gradients under ``KKT_TOL``, and the levels below depend on
it (the regression problem: level 1 at 5 089 on the native engine, 8 424 on the Python engine,
24.57 when that direction is left to the lower levels). The rank rule of both engines
(``MOVABLE_TOL``: a combination of a level's rows whose projection is within 1e-9 of the rows
it combines is dependent, rounding of the freeze) leaves such a direction to the lower levels
(``_independent_rank`` and the native ``Hierarchy::independent_rank``).

Tolerance of a level value against a reference (both are lexicographic optima up to that
rank decision): leaving a direction with ``s ≤ MOVABLE_TOL·Σ|uⱼ|‖Aⱼ‖ ≤ MOVABLE_TOL·‖A‖_F``
to the lower levels moves the level's residual vector by at most ``δ = MOVABLE_TOL·‖A‖_F·
‖x‖`` (plus the certificate's ``KKT_TOL`` of its scale), so its squared value by
``2·√value·δ + δ²``, with ``δ = 2e-9·scale``, ``scale = ‖b‖ + ‖A‖_F·‖x‖`` (weighted rows;
inequality rows: their finite bounds and ``‖C‖_F``), the level's scale of the native end check.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from support.native_engine import needs_native
from support.oracle import OracleError, level_residuals, lexicographic

import qpcoord as qc
from qpcoord.core import native
from qpcoord.core.linalg import numerical_rank, svd
from qpcoord.core.methods.hierarchical import MOVABLE_TOL, _independent_rank

DATA = Path(__file__).resolve().parents[1] / "data" / "regressions" / "near_parallel_level1.json"
#: ``δ = REL·scale`` (module docstring): the rank decision (MOVABLE_TOL) and the certificate.
REL = 2.0 * MOVABLE_TOL


def _task(t):
    if t[0] == "eq":
        w = np.asarray(t[3], dtype=float) if isinstance(t[3], list) else float(t[3])
        return qc.Equality(np.array(t[1], dtype=float), np.array(t[2], dtype=float), w)
    lo = np.array([-np.inf if v is None else v for v in t[2]], dtype=float)
    hi = np.array([np.inf if v is None else v for v in t[3]], dtype=float)
    return qc.Inequality(np.array(t[1], dtype=float), lo, hi)


def load_regression(path: Path = DATA):
    """``(levels, bounds, hard, reference)`` of a regression problem file
    (``tests/data/regressions/README.md``); ``reference``: the soft levels' optimal values
    (squared residuals), the hard level's dropped."""
    d = json.loads(path.read_text())
    levels = [[_task(t) for t in lv] for lv in d["levels"]]
    hard = [_task(t) for t in d["hard"]]
    bounds = qc.Bounds(np.array(d["lower"], dtype=float), np.array(d["upper"], dtype=float))
    ref = np.array(d["reference_level_values"], dtype=float)
    if d["reference_has_hard_level"]:
        ref = ref[1:]
    return levels, bounds, hard, ref


def level_scales(levels, x) -> np.ndarray:
    """Each level's scale ``‖b‖ + ‖A‖_F·‖x‖`` (weighted rows; inequality rows: their finite
    bounds for ``b``, ``C`` for ``A``)."""
    nx = float(np.linalg.norm(x))
    out = []
    for lv in levels:
        total = 0.0
        for t in lv if isinstance(lv, list) else [lv]:
            sw = np.sqrt(np.broadcast_to(np.asarray(t.weight, dtype=float), (t.shape[0],)))
            if isinstance(t, qc.Equality):
                total += np.linalg.norm(sw * t.b) + np.linalg.norm(sw[:, None] * t.A) * nx
            else:
                bnd = np.maximum(
                    np.where(np.isfinite(t.lower), np.abs(t.lower), 0.0),
                    np.where(np.isfinite(t.upper), np.abs(t.upper), 0.0),
                )
                total += np.linalg.norm(sw * bnd) + np.linalg.norm(sw[:, None] * t.C) * nx
        out.append(total)
    return np.array(out)


def value_tol(ref: np.ndarray, scales: np.ndarray) -> np.ndarray:
    """``2·√value·δ + δ²`` with ``δ = REL·scale`` (module docstring)."""
    delta = REL * scales
    return 2.0 * np.sqrt(np.maximum(ref, 0.0)) * delta + delta * delta


def _stack(levels, bounds, hard):
    return qc.Stack(levels, bounds=bounds, constraints=hard)


def _check(sol, levels, ref):
    """The solution reaches ``ref`` on every level, or says ``"inaccurate"`` naming a level
    at or above the first one that misses. Returns whether it reached it."""
    values = sol.level_residuals**2
    tol = value_tol(ref, level_scales(levels, sol.x))
    off = np.abs(values - ref) > tol
    if sol.status == "optimal":
        assert not off.any(), (values, ref, tol)
        return True
    assert sol.status == "inaccurate"
    k = sol.info["inaccurate"]["level"]
    assert sol.info["inaccurate"]["reason"].startswith(f"level {k}: ")
    assert not off.any() or k <= int(np.argmax(off)), (k, values, ref)
    return not off.any()


def test_the_rows_of_level_0_are_parallel_to_within_the_rank_rule():
    """The regression problem's level 0, projected on the hard equalities' null space: its
    smallest singular value (2.8e-9, two rows parallel to 3.4e-10) is a combination of rows
    within MOVABLE_TOL of their norms, not of the combined row — the direction the rule leaves
    to the lower levels (fails with the combined row's norm as the measure)."""
    levels, _bounds, hard, _ref = load_regression()
    E = hard[1].A  # the hard equalities (unit weight): one row, three times
    _u, se, Vte = svd(E, full=True)
    Z = Vte[numerical_rank(se, E.shape) :].T
    t = levels[0][0]
    A = np.sqrt(np.asarray(t.weight))[:, None] * t.A
    U, s, _Vt = svd(A @ Z, full=False)
    rank = numerical_rank(s, (A @ Z).shape, float(np.linalg.norm(A)))
    assert rank == 17
    assert s[16] > MOVABLE_TOL * float(np.linalg.norm(A.T @ U[:, 16]))  # the combined row
    assert _independent_rank(A, U, s, rank, float(np.linalg.norm(A))) == 16


@pytest.mark.parametrize("solver", qc.available_solvers())
def test_python_engine_reaches_the_lexicographic_optimum(solver):
    levels, bounds, hard, ref = load_regression()
    sol = _stack(levels, bounds, hard).solve(engine="python", solver=solver)
    assert sol.status == "optimal"
    assert _check(sol, levels, ref)


@needs_native
def test_native_engine_reaches_the_lexicographic_optimum():
    """Cold, then warm from the stored working sets: the native rank rule leaves the
    cancelling direction of level 0 to the lower levels (its ``dependent_drops`` counter)."""
    levels, bounds, hard, ref = load_regression()
    stack = _stack(levels, bounds, hard)
    for _ in range(2):
        sol = stack.solve(engine="native")
        assert sol.status == "optimal"
        assert _check(sol, levels, ref)


@needs_native
def test_the_engines_never_give_two_different_optimal_answers():
    levels, bounds, hard, _ref = load_regression()
    stack = _stack(levels, bounds, hard)
    py = stack.solve(engine="python")
    nat = stack.solve(engine="native")
    if py.status == nat.status == "optimal":
        vp, vn = py.level_residuals**2, nat.level_residuals**2
        tol = value_tol(vp, level_scales(levels, py.x))
        assert np.all(np.abs(vn - vp) <= tol), (vn, vp)


# ---- the family: near-parallel rows after a rank-deficient level ---------------------------


def near_parallel_stack(seed: int):
    """A seeded stack of the regression problem's family, and its rounded twin.

    ``n`` in 6…14 variables, a box that the levels reach, optionally hard equalities made of
    one row repeated (redundant); level 0 rank-deficient (a row repeated) or not; one level
    (0 or 1) holds a pair of rows parallel to ``10^U(-12, -9.5)`` of their norms with targets
    apart (the pair cannot both be met: only the near-parallel direction could); 1–3 more
    levels, one of them sometimes with inequality rows. Returns ``(levels, bounds, hard,
    rounded)``: ``rounded`` is ``levels`` with the pair made exactly parallel (the rank
    decision the library makes), whose reference is the lexicographic optimum to compare to.
    """
    rng = np.random.default_rng(seed)
    n = int(rng.integers(6, 15))
    hard = []
    if rng.uniform() < 0.5:
        row = rng.normal(size=n)
        E = np.vstack([row, row, 2.0 * row])
        e = E @ rng.uniform(-0.3, 0.3, n)
        hard.append(qc.Equality(E, e))
    pair_level = int(rng.integers(0, 2))
    nlev = int(rng.integers(2, 5))
    levels, rounded = [], []
    for k in range(nlev):
        m = int(rng.integers(2, max(3, n // 2) + 1))
        A = rng.normal(size=(m, n))
        if k == 0 and rng.uniform() < 0.6:
            A = np.vstack([A, A[0]])  # rank-deficient level
        A_exact = A.copy()
        b = A @ rng.uniform(-3.0, 3.0, n) + rng.normal(size=A.shape[0])
        if k == pair_level:
            c = rng.uniform(0.5, 2.0)
            g = rng.normal(size=n)
            A_exact = np.vstack([A, c * A[0]])
            eps = 10.0 ** rng.uniform(-12.0, -9.5) * c * np.linalg.norm(A[0])
            A = np.vstack([A, c * A[0] + eps * g / np.linalg.norm(g)])
            b = np.concatenate([b, [c * b[0] + rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 2.0)]])
        w = rng.uniform(0.5, 8.0, A.shape[0]) if rng.uniform() < 0.5 else 1.0
        tasks = [qc.Equality(A, b, w)]
        tasks_r = [qc.Equality(A_exact, b, w)]
        if k == nlev - 1 and rng.uniform() < 0.4:
            C = rng.normal(size=(int(rng.integers(1, 4)), n))
            cx = C @ rng.uniform(-1.0, 1.0, n)
            ineq = qc.Inequality(C, cx - 0.2, cx + 0.2)
            tasks.append(ineq)
            tasks_r.append(ineq)
        levels.append(tasks)
        rounded.append(tasks_r)
    half = rng.uniform(0.5, 2.0, n)
    bounds = qc.Bounds(-half, half)
    return levels, bounds, hard, rounded


def family_outcome(seed: int, engine: str, solver: str | None = None) -> str:
    """``"reached"``, ``"flagged"`` (``"inaccurate"``), ``"silent"`` (``"optimal"`` and a level
    off the reference), ``"error"`` (a ``SolverError``) or ``"skipped"`` (the reference could
    not be computed) for one seeded stack."""
    levels, bounds, hard, rounded = near_parallel_stack(seed)
    try:
        ref_x = lexicographic(rounded, bounds, hard or None, polish=True).x
    except OracleError:
        return "skipped"
    ref = level_residuals(levels, ref_x) ** 2
    try:
        sol = _stack(levels, bounds, hard or None).solve(engine=engine, solver=solver)
    except qc.SolverError:
        return "error"
    values = sol.level_residuals**2
    tol = value_tol(ref, np.maximum(level_scales(levels, sol.x), level_scales(levels, ref_x)))
    off = np.abs(values - ref) > tol
    if sol.status == "inaccurate":
        return "flagged"
    return "silent" if off.any() else "reached"


#: Seeds of the fast test (~35 ms each per engine, the reference the most of it; with the
#: combined row as the rank measure 10 of them are silently wrong on every engine).
FAST_SEEDS = range(40)


def _engines():
    out = [("python", "daqp"), ("python", "quadprog")]
    if native.available():
        out.append(("native", None))
    return out


@pytest.mark.parametrize(("engine", "solver"), _engines())
def test_near_parallel_family_is_never_silently_wrong(engine, solver):
    outcomes = [family_outcome(seed, engine, solver) for seed in FAST_SEEDS]
    assert "silent" not in outcomes, outcomes
    assert "error" not in outcomes, outcomes
    assert outcomes.count("reached") == len(FAST_SEEDS) - outcomes.count("skipped"), outcomes


#: The campaign, seeds 1000–1999 (30–100 s per engine on the project's 2-core machine,
#: ``pytest -m slow tests/core/test_near_degenerate.py``): with the combined row as the rank
#: measure 247 stacks were silently wrong on python/daqp and python/quadprog, 249 on the
#: native engine; with the rows' norms, 0 on each (1 000 reached).
@pytest.mark.slow
@pytest.mark.parametrize(("engine", "solver"), _engines())
def test_near_parallel_family_campaign(engine, solver):
    outcomes = [family_outcome(seed, engine, solver) for seed in range(1000, 2000)]
    assert "silent" not in outcomes, {o: outcomes.count(o) for o in set(outcomes)}
    assert "error" not in outcomes, {o: outcomes.count(o) for o in set(outcomes)}
