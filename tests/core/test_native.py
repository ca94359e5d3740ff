"""The native engine (``Stack.solve(engine="native")``) against the Python engine and the oracle.

The Python engine is the oracle of the native one: on every solver-comparison case and on
hypothesis-generated stacks (equalities, inequalities, bounds, hard constraints, conflicts,
duplicated rows) both must give the same level values to ``LEVEL_TOL`` relative (of
``max(1, value)``) and the same ``x`` (unique after the minimum-norm step).

Without the extension these tests skip, with the reason; ``QPCOORD_REQUIRE_NATIVE=1`` (set by
``.ci/run``) makes a missing extension a failure instead. The fallback tests run everywhere:
they simulate a missing extension.
"""

from __future__ import annotations

import importlib.util
import math
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from support.arrays import force_write as _force_write
from support.families import CASES, build, reference, stack
from support.families import case_ids as _ids
from support.hlsp import load

import qpcoord as qc
from qpcoord.core import native

#: Level values: |r_native − r_python| ≤ LEVEL_TOL·max(1, r_python).
LEVEL_TOL = 1e-9
#: x (unique): ‖x_native − x_python‖∞ ≤ X_TOL·max(1, ‖x_python‖∞).
X_TOL = 1e-7

BUILT = native.available()
if not BUILT and os.environ.get("QPCOORD_REQUIRE_NATIVE") == "1":
    raise RuntimeError(
        "QPCOORD_REQUIRE_NATIVE=1 but the native engine is not built: " + str(native._load_error)
    )
needs_native = pytest.mark.skipif(
    not BUILT, reason=f"the native engine (qpcoord._native) is not built: {native._load_error}"
)


def native_solver(stack: qc.Stack):
    """``(P, h)``: the compiled stack and a native solver of it (``h.counters``: the
    counters of its last call)."""
    from qpcoord.core.native import NativeHierarchy

    P = stack._compiled
    return P, NativeHierarchy(P, stack.damping)


def path_check(stack: qc.Stack, P, h, counter: str, unique_x: bool = True, warm: bool = True):
    """Solve with the native solver ``h`` (``warm``: from its stored working sets, else cold;
    its caches dropped first, so that the counters count the factorisations and freezes
    computed, not restored: test_native_memo tests the caches) and with the Python engine:
    the same level values (``LEVEL_TOL`` relative) and, ``unique_x``, the same x
    (``X_TOL``). ``counter``: the ``Stats`` field of the path under test. Returns ``(its
    count, the native info, the Python Solution)``."""
    h._solver.invalidate_caches()
    xn, rn, infon = h.solve(P, warm=warm)
    taken = getattr(h.counters, counter)
    sp = stack.solve(engine="python")
    ref = sp.level_residuals
    assert np.all(np.abs(rn - ref) <= LEVEL_TOL * np.maximum(1.0, ref)), (rn, ref)
    if unique_x:
        scale = max(1.0, float(np.max(np.abs(sp.x))))
        assert np.max(np.abs(xn - sp.x)) <= X_TOL * scale, np.max(np.abs(xn - sp.x))
    return taken, infon, sp


def benchmark_module(name: str):
    """The script ``benchmarks/<name>.py`` imported as a module."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.pop(0)


def published_module():
    """``benchmarks/hierarchy_published.py`` imported (the LexLS humanoid and its moves)."""
    return benchmark_module("hierarchy_published")


def published_stack(stem: str, box: bool = False, unit: bool = False):
    """``(stack, move(step))`` of a published problem (``tests/data/hlsp``), moved as
    ``hierarchy_published.py``'s re-solve table does (``box``: simple rows as bounds;
    ``unit``: its unit-row copy)."""
    hp = published_module()
    prob = load(stem, simple_as_bounds=box)
    levels = hp.unit_rows(prob.levels) if unit else prob.levels
    return qc.Stack(levels, bounds=prob.bounds), hp._mover(levels)


def _same(sp: qc.Solution, sn: qc.Solution) -> None:
    rp, rn = sp.level_residuals, sn.level_residuals
    assert np.all(np.abs(rn - rp) <= LEVEL_TOL * np.maximum(1.0, rp)), (rp, rn)
    dx = np.max(np.abs(sn.x - sp.x)) / max(1.0, float(np.max(np.abs(sp.x))))
    assert dx <= X_TOL, (dx, sp.x, sn.x)


# ---------------------------------------------------------------------------------------
# engine selection and the fallback (no extension needed)
# ---------------------------------------------------------------------------------------


def _small_stack() -> qc.Stack:
    return qc.Stack([qc.Equality(np.eye(3), [1.0, 2.0, 3.0])], bounds=qc.Bounds(-1.0, 1.0))


def test_default_falls_back_with_one_warning(missing_extension, monkeypatch):
    monkeypatch.setattr(native, "DEFAULT_ENGINE", "native")
    s = _small_stack()
    with pytest.warns(RuntimeWarning, match="native engine is not built") as rec:
        sol = s.solve()
    assert len(rec) == 1
    assert rec[0].filename == __file__  # stacklevel: the user's call
    assert sol.solver != "native"
    np.testing.assert_allclose(sol.x, [1.0, 1.0, 1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert s.solve().solver != "native"  # once per process


def test_explicit_native_without_extension_raises(missing_extension):
    with pytest.raises(native.NativeUnavailableError, match="not built"):
        _small_stack().solve(engine="native")
    with pytest.raises(ImportError):
        _small_stack().solve(engine="native")


def test_python_default_never_warns(missing_extension, monkeypatch):
    monkeypatch.setattr(native, "DEFAULT_ENGINE", "python")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _small_stack().solve().solver != "native"
        assert _small_stack().solve(engine="python").solver != "native"


@needs_native
def test_default_is_native_where_built():
    """``engine=None`` on a hierarchical stack without ``solver=`` is the native engine."""
    assert native.DEFAULT_ENGINE == "native"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _small_stack().solve().solver == "native"
        assert qc.solve_stack([qc.Equality(np.eye(2), [1.0, 2.0])]).solver == "native"
    assert _small_stack().solve(engine="python").solver != "native"


def test_engine_argument_errors():
    s = _small_stack()
    with pytest.raises(ValueError, match="unknown engine 'fast'"):
        s.solve(engine="fast")
    with pytest.raises(ValueError, match="method='nullspace'"):
        s.solve(method="nullspace", engine="native")
    with pytest.raises(ValueError, match="solver='daqp'"):
        s.solve(solver="daqp", engine="native")


def test_default_uses_python_for_other_methods(monkeypatch):
    monkeypatch.setattr(native, "DEFAULT_ENGINE", "native")
    s = _small_stack()
    assert (
        qc.Stack([qc.Equality(np.eye(2), [1.0, 2.0])]).solve(method="nullspace").solver != "native"
    )
    assert s.solve(solver="daqp").solver == "daqp"


# ---------------------------------------------------------------------------------------
# native vs Python on the solver-comparison cases and the oracle
# ---------------------------------------------------------------------------------------


@needs_native
@pytest.mark.parametrize("name,seed", CASES, ids=_ids(CASES))
def test_native_matches_python(name, seed):
    spec = build(name, seed)
    sp = stack(spec).solve(engine="python")
    sn = stack(spec).solve(engine="native")
    assert sn.solver == "native" and sn.method == "hierarchical" and sn.status == "optimal"
    assert len(sn.info["active_set_iterations"]) == len(sp.level_residuals)
    _same(sp, sn)


@needs_native
@pytest.mark.parametrize("name,seed", CASES, ids=_ids(CASES))
def test_native_matches_oracle(name, seed):
    ref = reference(name, seed)
    spec = build(name, seed)
    sn = stack(spec).solve(engine="native")
    r = sn.level_residuals
    assert np.all(np.abs(r - ref.level_residuals) <= 1e-6 * np.maximum(1.0, ref.level_residuals))
    assert np.max(np.abs(sn.x - ref.x)) <= 1e-5 * max(1.0, float(np.max(np.abs(ref.x))))


# ---------------------------------------------------------------------------------------
# hypothesis-generated stacks
# ---------------------------------------------------------------------------------------


@st.composite
def stacks(draw):
    """Random stacks: n ≤ 8, 1–4 levels of equality and inequality rows (duplicated rows for
    rank deficiency, conflicting targets), optional bounds around 0, optional hard
    equalities (consistent) and hard inequalities (met by a known point inside the box)."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    n = draw(st.integers(2, 8))
    levels = []
    for _ in range(draw(st.integers(1, 4))):
        tasks = []
        me = draw(st.integers(0, 4))
        mi = draw(st.integers(0 if me else 1, 3))
        if me:
            A = rng.standard_normal((me, n))
            if me > 1 and draw(st.booleans()):
                A[-1] = A[0]  # duplicated row (a conflict if the targets differ)
            w = rng.uniform(0.1, 10.0, me) if draw(st.booleans()) else 1.0
            tasks.append(qc.Equality(A, 2.0 * rng.standard_normal(me), weight=w))
        if mi:
            C = rng.standard_normal((mi, n))
            lo = rng.uniform(-2.0, 1.0, mi)
            hi = lo + rng.uniform(0.0, 2.0, mi)
            lo[rng.random(mi) < 0.3] = -np.inf
            tasks.append(qc.Inequality(C, lo, hi, weight=rng.uniform(0.5, 4.0, mi)))
        levels.append(tasks)
    bounds = None
    x0 = rng.uniform(-0.5, 0.5, n)
    if draw(st.booleans()):
        bounds = qc.Bounds(-rng.uniform(0.6, 2.0, n), rng.uniform(0.6, 2.0, n))
    constraints = []
    if draw(st.booleans()):
        A = rng.standard_normal((draw(st.integers(1, max(1, n - 2))), n))
        constraints.append(qc.Equality(A, A @ x0))
    if draw(st.booleans()):
        C = rng.standard_normal((2, n))
        constraints.append(qc.Inequality(C, C @ x0 - 0.2, C @ x0 + rng.uniform(0.0, 0.5, 2)))
    return dict(levels=levels, bounds=bounds, constraints=constraints or None)


@needs_native
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(stacks())
def test_native_matches_python_on_random_stacks(spec):
    sp = stack(spec).solve(engine="python")
    assume(sp.status == "optimal")  # the Python engine certified every level
    s = stack(spec)
    sn = s.solve(engine="native")
    _same(sp, sn)
    again = s.solve(engine="native")  # warm: the same data, the stored working sets
    _same(sp, again)


# ---------------------------------------------------------------------------------------
# infeasible stacks, warm start, bad input
# ---------------------------------------------------------------------------------------


@needs_native
@pytest.mark.parametrize("engine", ["python", "native"])
def test_inconsistent_hard_equalities(engine):
    hard = qc.Equality(np.array([[1.0, 0.0], [1.0, 0.0]]), [0.0, 1.0], name="pin")
    s = qc.Stack([qc.Equality(np.eye(2), [0.0, 0.0])], constraints=[hard])
    msg = r"hard equality constraints are inconsistent \(.*pin"
    with pytest.raises(qc.InfeasibleError, match=msg):
        s.solve(engine=engine)


@needs_native
@pytest.mark.parametrize("engine", ["python", "native"])
def test_hard_inequalities_outside_the_box(engine):
    hard = qc.Inequality(np.array([[1.0, 1.0]]), lower=3.0)
    s = qc.Stack(
        [qc.Equality(np.eye(2), [0.0, 0.0])], bounds=qc.Bounds(-1.0, 1.0), constraints=[hard]
    )
    with pytest.raises(qc.InfeasibleError, match="bounds and hard constraints are inconsistent"):
        s.solve(engine=engine)


@needs_native
@pytest.mark.parametrize("engine", ["python", "native"])
def test_hard_equalities_fix_x_outside_the_box(engine):
    s = qc.Stack(
        [qc.Equality(np.ones((1, 2)), [0.0])],
        bounds=qc.Bounds(-1.0, 1.0),
        constraints=[qc.Equality(np.eye(2), [2.0, 0.0])],
    )
    with pytest.raises(qc.InfeasibleError):
        s.solve(engine=engine)


@needs_native
@pytest.mark.parametrize("seed", range(4))
def test_a_box_away_from_zero_starts_at_its_nearest_point(seed):
    """Bounds only (no hard rows), x = 0 outside the box: the hard phase starts the levels
    from the box's point nearest 0 (no active set: ``hard_iterations == 0``); the answer is
    the Python engine's, cold and warm, as the targets move."""
    rng = np.random.default_rng(seed)
    n = 8
    lb = rng.uniform(0.2, 1.0, n) * rng.choice([-1.0, 1.0], n)
    lb[0] = 2.0  # 0 is outside the box
    ub = np.where(lb > 0, lb + rng.uniform(0.0, 1.0, n), lb * 0.3)  # ub < 0 where lb < 0
    ub[1] = lb[1]  # a fixed variable
    eq = qc.Equality(rng.standard_normal((3, n)), rng.standard_normal(3))
    ineq = qc.Inequality(rng.standard_normal((4, n)), -np.ones(4), np.ones(4))
    post = qc.Equality(np.eye(n), np.zeros(n))
    s = qc.Stack([eq, ineq, post], bounds=qc.Bounds(lb, ub))
    for step in range(4):
        eq.update(b=eq.b + 0.3 * np.sin(step + np.arange(3)))
        sp = s.solve(engine="python")
        sn = s.solve(engine="native")
        _same(sp, sn)
        assert sn.info["hard_iterations"] == 0
        assert np.all(sn.x >= lb) and np.all(sn.x <= ub)


@needs_native
def test_warm_start_gives_the_cold_answer():
    """A moving target over 30 steps: each warm re-solve equals a fresh (cold) stack's."""
    spec = build("mixed_levels", 1)
    warm = stack(spec)
    hits = 0
    rng = np.random.default_rng(3)
    eq = spec["levels"][2]
    for _ in range(30):
        eq.update(b=np.clip(eq.b + 0.02 * rng.standard_normal(eq.b.shape[0]), -1, 1))
        sw = warm.solve(engine="native")
        sc = stack(spec).solve(engine="native")
        sp = stack(spec).solve(engine="python")
        _same(sp, sw)
        _same(sc, sw)
        hits += sw.info["warm_start_hits"]
    assert hits > 0  # the stored working sets were optimal at least once


@needs_native
def test_repeated_solve_is_a_warm_hit():
    s = stack(build("inequality_levels", 0))
    first = s.solve(engine="native")
    second = s.solve(engine="native")
    assert first.info["warm_start_hits"] == 0
    assert second.info["warm_start_hits"] >= 1
    np.testing.assert_allclose(second.x, first.x, atol=1e-12)


@needs_native
@pytest.mark.parametrize("box", [True, False], ids=["box", "published"])
def test_unchanged_humanoid_is_a_warm_hit(box):
    """The LexLS humanoid solved again unchanged: every stage the active set solves is a
    warm hit (its stored working set kept the equality rows lo = hi of the stage, which the
    stored set does not list: without it the box form missed at two levels on every call),
    and x is the cold solve's and the Python engine's.

    (Before the active set took a step that gains under 1e-15 of a large objective but is no
    rounding, the cold call could stop its minimum-norm stage short, and the first warm call
    then reseeded that stage once: a8faed4 had relaxed this test to the third call; the fix
    (tested in tests/core/test_talos_joint_limit_oracle.py) restored it.)"""
    P = load("lexls_test01_humanoid", simple_as_bounds=box)
    s = qc.Stack(P.levels, bounds=P.bounds)
    cold = s.solve(engine="native")
    warm = s.solve(engine="native")
    info = warm.info
    assert cold.info["warm_start_hits"] == 0 and cold.info["qp_calls"] > 0
    assert info["warm_start_hits"] == info["qp_calls"] == cold.info["qp_calls"]
    assert info["warm_start_seeded"] == 0
    assert info["hard_iterations"] == 0 and info["min_norm_iterations"] == 0
    # the one level left with iterations is the exact finish of an ill-conditioned level
    # (run after a hit too): a refinement step, not a search
    assert sum(info["active_set_iterations"]) <= 2
    np.testing.assert_allclose(warm.x, cold.x, rtol=0, atol=1e-9)
    sp = s.solve(engine="python")
    scale = max(1.0, float(np.max(np.abs(sp.x))))
    np.testing.assert_allclose(warm.x, sp.x, rtol=0, atol=1e-9 * scale)
    ref = np.asarray(sp.level_residuals)
    gap = np.abs(np.asarray(warm.level_residuals) - ref) / np.maximum(1.0, ref)
    assert gap.max() <= 1e-9


@needs_native
@pytest.mark.parametrize("engine", ["python", "native"])
def test_nan_in_a_task_names_it(engine):
    t = qc.Inequality(np.eye(2), lower=[0.0, 0.0], name="fence")
    s = qc.Stack([t, qc.Equality(np.eye(2), [1.0, 1.0])], bounds=qc.Bounds(-2.0, 2.0))
    s.solve(engine=engine)
    _force_write(t.C, (0, 0), np.nan)  # reached the array without update()
    with pytest.raises(ValueError, match=r"Inequality 'fence': C contains nan.*found at solve"):
        s.solve(engine=engine)


@needs_native
def test_bad_warm_start_is_rejected():
    with pytest.raises(ValueError, match="warm_start"):
        _small_stack().solve(engine="native", warm_start=[1.0])


@needs_native
def test_solve_stack_engine():
    sol = qc.solve_stack([qc.Equality(np.eye(2), [3.0, -3.0])], engine="native")
    assert sol.solver == "native"
    np.testing.assert_allclose(sol.x, [3.0, -3.0])


@needs_native
@pytest.mark.parametrize("engine", ["python", "native"])
def test_wrong_sided_infinity_in_the_bounds_is_named(engine):
    s = qc.Stack([qc.Equality(np.eye(2), [1.0, 1.0])], bounds=qc.Bounds(-2.0, 2.0))
    s.solve(engine=engine)
    _force_write(s._compiled.lb, (0,), np.inf)  # reached the array without a setter
    with pytest.raises(ValueError, match="found at solve time"):
        s.solve(engine=engine)


def _hard_random_stack(seed: int, n: int = 40, levels: int = 8) -> qc.Stack:
    """Levels of unit inequality rows that conflict: many active-set iterations."""
    rng = np.random.default_rng(seed)
    tasks = []
    for _ in range(levels):
        C = rng.standard_normal((15, n))
        C /= np.linalg.norm(C, axis=1)[:, None]
        lo = rng.uniform(0.2, 1.0, 15)
        tasks.append(
            [
                qc.Equality(rng.standard_normal((4, n)), rng.standard_normal(4)),
                qc.Inequality(C, lo, lo + 0.1),
            ]
        )
    return qc.Stack(tasks, bounds=qc.Bounds(-np.ones(n), np.ones(n)))


@needs_native
def test_time_limit_gives_the_python_engines_error():
    """An expired deadline ends the native active set with the Python engine's message."""
    s = _hard_random_stack(0)
    with pytest.raises(qc.SolverError, match=r"time limit of 1e-09 s reached.*native engine"):
        s.solve(engine="native", time_limit=1e-9)
    sn = s.solve(engine="native", time_limit=math.inf)  # not poisoned: a cold solve
    _same(s.solve(engine="python"), sn)


@needs_native
def test_level_values_are_computed_natively():
    """The level values the native call returns are each level's residual at x."""
    s = _hard_random_stack(1)
    sol = s.solve(engine="native")
    ref = np.array([L.residual(sol.x) for L in s._compiled.levels])
    np.testing.assert_allclose(sol.level_residuals, ref, rtol=1e-12, atol=1e-14)
    assert sol.status == "optimal" and not sol.info["uncertified"]
    assert s.solve(engine="native", strict=True).status == "optimal"


@needs_native
def test_repeated_calls_reuse_the_buffers():
    """The per-step path writes the tasks' numbers straight into the compiled stack's stacked
    arrays, which the native solver is bound to: the same objects every step, and every
    level's buffers are views of them (no copy between refresh and the native call)."""
    s = _hard_random_stack(2)
    s.solve(engine="native")
    nh, P = s._native, s._compiled
    arrays = (P.Aeq, P.beq, P.C, P.clo, P.chi, P.csw, nh.x, nh.res, nh.stats, nh.detail)
    ids = [id(a) for a in arrays]
    for _ in range(5):
        s.solve(engine="native")
    assert s._native is nh
    assert [id(a) for a in arrays] == ids
    for L in P.levels:
        assert np.shares_memory(L.C, P.C) and np.shares_memory(L.lo, P.clo)


@needs_native
def test_engines_alternate_on_one_stack():
    """A Python solve lets a level read its task's arrays in place; the next native solve
    must still see every number (the stacked arrays are rewritten, the views restored),
    with weighted rows and a bounds update in between."""
    rng = np.random.default_rng(5)
    A = rng.standard_normal((3, 6))
    pos = qc.Equality(A, rng.standard_normal(3))
    post = qc.Equality(np.eye(6), rng.standard_normal(6), weight=np.linspace(0.5, 2.0, 6))
    lim = qc.Inequality(rng.standard_normal((2, 6)), -0.2, 0.3)
    box = qc.Bounds(-0.8 * np.ones(6), 0.8 * np.ones(6))
    s = qc.Stack([pos, [post, lim]], bounds=box)
    for step in range(6):
        pos.update(b=np.sin(0.3 * step + np.arange(3)))
        if step == 3:
            box.update(lower=-0.5 * np.ones(6))
        engine = ("python", "native")[step % 2]
        got = s.solve(engine=engine)
        fresh = qc.Stack([pos, [post, lim]], bounds=box).solve(engine="python")
        np.testing.assert_allclose(
            got.level_residuals, fresh.level_residuals, rtol=1e-9, atol=1e-12
        )
        assert (got.x >= -0.8 - 1e-12).all() and (got.x <= 0.8 + 1e-12).all()
        if step >= 3:
            assert (got.x >= -0.5 - 1e-12).all()


@needs_native
@pytest.mark.parametrize("engine", ["python", "native"])
def test_qp_calls_count_the_levels_that_needed_an_active_set(engine):
    """Both engines report ``qp_calls``: 0 when every level's closed form meets the bounds,
    > 0 when a bound is active (the native engine counts its active-set stages)."""
    inside = qc.Stack([qc.Equality(np.eye(3), [0.1, 0.2, 0.3])], bounds=qc.Bounds(-1.0, 1.0))
    assert inside.solve(engine=engine).info["qp_calls"] == 0
    outside = qc.Stack([qc.Equality(np.eye(3), [0.1, 2.0, 0.3])], bounds=qc.Bounds(-1.0, 1.0))
    sol = outside.solve(engine=engine)
    assert sol.info["qp_calls"] > 0
    np.testing.assert_allclose(sol.x, [0.1, 1.0, 0.3], atol=1e-12)


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_missed_working_set_seeds_the_next_start(seed):
    """Moving targets make stored working sets miss; the seeded start (the stored set made
    feasible) ends on the same level values as the Python engine and as a cold solve, and
    it is used."""
    from qpcoord.core.native import NativeHierarchy

    s = _hard_random_stack(seed, n=30, levels=6)
    P = s._compiled
    seeded = NativeHierarchy(P, s.damping)
    cold = NativeHierarchy(P, s.damping)
    eqs = [t for lev in s.levels for t in lev if isinstance(t, qc.Inequality)]
    used = 0
    for step in range(12):
        for j, t in enumerate(eqs):
            shift = 0.05 * np.sin(0.7 * step + j)
            t.update(lower=t.lower + shift, upper=t.upper + shift)
        xs, rs, info = seeded.solve(P)
        xc, rc, _ = cold.solve(P, warm=False)
        ref = s.solve(engine="python").level_residuals
        np.testing.assert_allclose(rs, ref, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(rc, ref, rtol=1e-9, atol=1e-10)
        used += info["warm_start_seeded"]
    assert used > 0


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_downdated_working_sets_give_the_cold_answer(seed):
    """Moving bounds make rows leave the working sets during warm solves; the QR of the
    working set is then downdated (Givens) instead of refactorised. Every step's answer
    equals the refactorising solver's, a cold solve's and the Python engine's (level values
    to 1e-9 relative, x to 1e-9), and downdates did happen."""
    from qpcoord.core.native import NativeHierarchy

    s = _hard_random_stack(seed, n=30, levels=6)
    P = s._compiled
    down = NativeHierarchy(P, s.damping)
    cold = NativeHierarchy(P, s.damping)
    ineqs = [t for lev in s.levels for t in lev if isinstance(t, qc.Inequality)]
    used = 0
    for step in range(12):
        for j, t in enumerate(ineqs):
            shift = 0.05 * np.sin(0.7 * step + j)
            t.update(lower=t.lower + shift, upper=t.upper + shift)
        xd, rd, _ = down.solve(P)
        used += down.counters.downdates
        xc, rc, _ = cold.solve(P, warm=False)
        ref = s.solve(engine="python")
        for r in (rd, rc):
            np.testing.assert_allclose(r, ref.level_residuals, rtol=1e-9, atol=1e-10)
        scale = max(1.0, float(np.max(np.abs(xc))))
        assert np.max(np.abs(xd - xc)) <= 1e-9 * scale
        assert np.max(np.abs(xd - ref.x)) <= X_TOL * scale
    assert used > 0


@needs_native
def test_a_missed_minimum_norm_set_seeds_its_start():
    """One level of inequality rows leaves freedom: the minimum-norm step runs an active set
    on the inherited rows and the box. As the rows move its stored working set misses; the
    seeded start ends on the cold start's x and the Python engine's, and it is used."""
    from qpcoord.core.native import NativeHierarchy

    rng = np.random.default_rng(0)
    n = 8
    C = rng.standard_normal((6, n))
    C /= np.linalg.norm(C, axis=1)[:, None]
    lo0 = rng.uniform(0.2, 0.8, 6)
    t = qc.Inequality(C, lo0.copy(), np.full(6, np.inf))
    s = qc.Stack([t], bounds=qc.Bounds(-np.ones(n), np.ones(n)))
    P = s._compiled
    seeded = NativeHierarchy(P, s.damping)
    cold = NativeHierarchy(P, s.damping)
    used = 0
    for step in range(20):
        t.update(lower=lo0 + 0.3 * np.sin(0.9 * step + np.arange(6)))
        xs, rs, info = seeded.solve(P)
        xc, rc, cinfo = cold.solve(P, warm=False)
        assert cinfo["warm_start_seeded"] == 0
        sp = s.solve(engine="python")
        np.testing.assert_allclose(rs, sp.level_residuals, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(xs, xc, rtol=0, atol=1e-9)
        np.testing.assert_allclose(xs, sp.x, rtol=0, atol=X_TOL)
        if info["active_set_iterations"] == [0] and info["min_norm_iterations"]:
            used += info["warm_start_seeded"]  # the level hit: the seed was the min-norm step's
    assert used > 0


@needs_native
@pytest.mark.parametrize("cond", [1e2, 1e5, 1e6, 3e6, 2e7, math.inf])
def test_closed_forms_by_qr_and_by_svd_agree_with_python(cond):
    """A level's closed form comes from a QR of its projected equalities when their smallest
    singular value is certainly above the damping threshold (4x), else from the damped SVD:
    well-conditioned (QR), just above the threshold (SVD, undamped), below it (SVD, damped:
    s = 5e-8 < 1e-7 s_ref) and exactly rank-deficient levels all give the Python engine's
    answer, with the box inactive and active. (Far below the threshold, s ~ 1e-8..1e-12, the
    next level's value differs between the engines, with the old build too: a known
    discrepancy, not covered here.)"""
    rng = np.random.default_rng(int(cond) % 97 if math.isfinite(cond) else 7)
    n = 7
    U, _ = np.linalg.qr(rng.standard_normal((4, 4)))
    V, _ = np.linalg.qr(rng.standard_normal((n, n)))
    s = np.array([1.0, 0.5, 1.0 / cond if math.isfinite(cond) else 0.0, 0.2])
    A = (U * s) @ V[:, :4].T  # 4 x 7, singular values s
    wide = qc.Equality(A, rng.standard_normal(4))
    tall = qc.Equality(rng.standard_normal((9, n)), rng.standard_normal(9))
    for box in (10.0, 0.3):
        st = qc.Stack([wide, tall], bounds=qc.Bounds(-box, box))
        _same(st.solve(engine="python"), st.solve(engine="native"))


def _rank_deficient_stack(rng, box: float) -> tuple[qc.Stack, list[qc.Equality]]:
    """Levels whose projected equalities are exactly rank-deficient: a tall level (9 rows of
    rank 3 on 8 variables), a wide one (3 rows of rank 2: one row a combination of the
    others), a conflicting inequality level, a tall level of rank 2 again; the box on top."""
    n = 8
    tall = qc.Equality(
        rng.standard_normal((9, 3)) @ rng.standard_normal((3, n)), rng.standard_normal(9)
    )
    W = rng.standard_normal((2, n))
    wide = qc.Equality(np.vstack([W, W[0] - 2.0 * W[1]]), rng.standard_normal(3))
    C = rng.standard_normal((4, n))
    ineq = qc.Inequality(C, rng.uniform(0.5, 1.0, 4), np.full(4, np.inf))
    low = qc.Equality(
        rng.standard_normal((6, 2)) @ rng.standard_normal((2, n)), rng.standard_normal(6)
    )
    st = qc.Stack([tall, wide, ineq, low], bounds=qc.Bounds(-box, box))
    return st, [tall, wide, low]


@needs_native
@pytest.mark.parametrize("box", [10.0, 0.4], ids=["box-inactive", "box-active"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rank_deficient_closed_form_by_qr_equals_the_svd(seed, box):
    """A rank-deficient level's closed form comes from the rank-revealing QR of its projected
    equalities (no SVD) when the QR shows a clear gap: tall and wide levels, accepted closed
    forms and closed forms followed by an active set (the freeze from the QR's row space),
    warm over moving right-hand sides. Every step equals the Python engine (level values
    1e-9 relative, x to 1e-7), and the QR path was taken for the tall and the wide level."""
    from qpcoord.core.native import NativeHierarchy

    rng = np.random.default_rng(seed)
    st, eqs = _rank_deficient_stack(rng, box)
    P = st._compiled
    by_qr = NativeHierarchy(P, st.damping)
    targets = [t.b.copy() for t in eqs]
    qr_forms = 0
    for step in range(6):
        for j, (t, b0) in enumerate(zip(eqs, targets, strict=True)):
            t.update(b=b0 + 0.2 * np.sin(0.8 * step + j + np.arange(b0.size)))
        xq, rq, _ = by_qr.solve(P)
        qr_forms += by_qr.counters.qr_closed_forms
        sp = st.solve(engine="python")
        np.testing.assert_allclose(rq, sp.level_residuals, rtol=1e-9, atol=1e-10)
        scale = max(1.0, float(np.max(np.abs(sp.x))))
        assert np.max(np.abs(xq - sp.x)) <= X_TOL * scale
    # the tall and the wide level at every step (the last level may have no freedom left)
    assert qr_forms >= 6 * 2


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compressed_and_wide_least_squares_equal_python(seed):
    """Conflicting inequality levels on few equality rows (a wide projected objective: its
    step from one QR of K^T) and a last level of many rank-deficient equality rows beside
    inequality rows (a tall level factorised by the QR: its least squares on the compressed
    objective R), warm over moving bounds and targets: every step equals the Python engine
    (level values 1e-9 relative, x to 1e-7)."""
    from qpcoord.core.native import NativeHierarchy

    rng = np.random.default_rng(seed)
    n = 40
    st = _hard_random_stack(seed, n=n, levels=1)
    C = rng.standard_normal((10, n))
    tall = qc.Equality(
        rng.standard_normal((40, 12)) @ rng.standard_normal((12, n)), rng.standard_normal(40)
    )
    last = qc.Inequality(C, rng.uniform(0.5, 1.0, 10), np.full(10, np.inf))
    st = qc.Stack([*st.levels, [tall, last]], bounds=qc.Bounds(-np.ones(n), np.ones(n)))
    P = st._compiled
    new = NativeHierarchy(P, st.damping)
    ineqs = [t for lev in st.levels for t in lev if isinstance(t, qc.Inequality)]
    b0 = tall.b.copy()
    for step in range(8):
        for j, t in enumerate(ineqs):
            shift = 0.05 * np.sin(0.7 * step + j)
            t.update(lower=t.lower + shift, upper=t.upper + shift)
        tall.update(b=b0 + 0.1 * np.sin(0.5 * step + np.arange(40)))
        xn, rn, info = new.solve(P)
        assert new.counters.qr_closed_forms == 2  # the wide first and the tall last level
        # the last level's least squares ran (later steps: warm trials on the same problem)
        assert step > 0 or info["active_set_iterations"][-1] > 0
        sp = st.solve(engine="python")
        np.testing.assert_allclose(rn, sp.level_residuals, rtol=1e-9, atol=1e-10)
        scale = max(1.0, float(np.max(np.abs(sp.x))))
        assert np.max(np.abs(xn - sp.x)) <= X_TOL * scale


@needs_native
def test_a_missed_hard_phase_set_seeds_its_start():
    """Hard inequality rows that x = 0 breaks: the least-violation phase runs at every call.
    As the rows move its stored working set misses; the seeded start (the set's point, each
    slack the row's violation there) ends on a cold solve's x and the Python engine's, and
    it is used."""
    from qpcoord.core.native import NativeHierarchy

    rng = np.random.default_rng(1)
    n = 8
    xs = rng.uniform(-0.5, 0.5, n)
    C = rng.standard_normal((5, n))
    C /= np.linalg.norm(C, axis=1)[:, None]
    C *= np.sign(C @ xs)[:, None]
    hard = qc.Inequality(C, C @ xs - 0.05, np.full(5, np.inf))
    lev = qc.Equality(rng.standard_normal((3, n)), rng.standard_normal(3))
    s = qc.Stack([lev], bounds=qc.Bounds(-np.ones(n), np.ones(n)), constraints=[hard])
    P = s._compiled
    seeded = NativeHierarchy(P, s.damping)
    cold = NativeHierarchy(P, s.damping)
    used = 0
    for step in range(20):
        xt = np.clip(xs + 0.4 * np.sin(0.7 * step + np.arange(n)), -0.9, 0.9)
        hard.update(lower=C @ xt - 0.05)  # xt stays feasible
        xs_, rs, info = seeded.solve(P)
        xc, rc, cinfo = cold.solve(P, warm=False)
        sp = s.solve(engine="python")
        np.testing.assert_allclose(rs, sp.level_residuals, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(xs_, xc, rtol=0, atol=1e-9)
        np.testing.assert_allclose(xs_, sp.x, rtol=0, atol=X_TOL)
        assert np.all(C @ xs_ >= C @ xt - 0.05 - 1e-9)
        used += info["warm_start_seeded"]
    assert used > 0


def _hard_row_scenario(rng) -> dict:
    """Hard rows that x = 0 breaks (the least-violation phase runs), one level, moving."""
    n = 8
    xs = rng.uniform(-0.5, 0.5, n)
    C = rng.standard_normal((5, n))
    C /= np.linalg.norm(C, axis=1)[:, None]
    C *= np.sign(C @ xs)[:, None]
    hard = qc.Inequality(C, C @ xs - 0.05, np.full(5, np.inf))
    lev = qc.Equality(rng.standard_normal((3, n)), rng.standard_normal(3))
    s = qc.Stack([lev], bounds=qc.Bounds(-np.ones(n), np.ones(n)), constraints=[hard])

    def move(step, x=None):
        xt = np.clip(xs + 0.4 * np.sin(0.7 * step + np.arange(n)), -0.9, 0.9)
        hard.update(lower=C @ xt - 0.05)

    return {"stack": s, "move": move, "daqp": None}


def _conflict_scenario(rng) -> dict:
    """Conflicting inequality levels with moving rows: misses, seeds, drops (downdates)."""
    s = _hard_random_stack(int(rng.integers(100)), n=30, levels=6)
    ineqs = [t for lev in s.levels for t in lev if isinstance(t, qc.Inequality)]

    def move(step, x=None):
        for j, t in enumerate(ineqs):
            shift = 0.05 * np.sin(0.7 * step + j)
            t.update(lower=t.lower + shift, upper=t.upper + shift)

    return {"stack": s, "move": move, "daqp": None}


def _small_damped_scenario(rng) -> dict:
    """Small levels (n = 10 < 16 columns: the size below which Eigen 3.4's BDCSVD built a
    local JacobiSVD per call) with near-singular equality rows under a large damping, so the
    closed form goes by the SVD, not the QR; a moving inequality level before them changes
    the free dimension r from call to call (the projected matrices change width)."""
    n = 10
    A1 = rng.standard_normal((3, n))
    A1[2] = A1[0] + 1e-4 * rng.standard_normal(n)  # a singular value below the damping
    A2 = rng.standard_normal((4, n))
    A2[3] = A2[1] - 1e-4 * rng.standard_normal(n)
    C0 = rng.standard_normal((4, n))
    eq1 = qc.Equality(A1, rng.standard_normal(3))
    ineq = qc.Inequality(C0, -0.3 * np.ones(4), 0.3 * np.ones(4))
    eq2 = qc.Equality(A2, rng.standard_normal(4))
    s = qc.Stack([[ineq], [eq1], [eq2]], bounds=qc.Bounds(-2.0, 2.0), damping=1e-2)
    b1, b2, lo = eq1.b.copy(), eq2.b.copy(), ineq.lower.copy()

    def move(step, x=None):
        eq1.update(b=b1 + 0.5 * np.sin(0.9 * step))
        eq2.update(b=b2 * (1.0 + 0.4 * np.cos(0.6 * step)))
        shift = 0.25 * np.sin(1.3 * step + np.arange(4))  # rows enter and leave the active set
        ineq.update(lower=lo + shift, upper=lo + shift + 0.6)

    return {"stack": s, "move": move, "daqp": None}


@pytest.mark.engine_independent
@needs_native
def test_the_native_call_allocates_nothing_after_the_first(tmp_path, hierarchy_driver):
    """The C++ driver (src/native/tools/driver.cpp; tools/count_allocations.hpp counts malloc,
    calloc, realloc and the aligned forms, where Eigen's storage allocates) replays moving
    stacks that exercise every stage — the hard phase, levels with misses, seeded starts, QR
    appends and downdates, the minimum-norm step, damped closed forms by the SVD on small
    levels whose width changes — warm and cold: no heap allocation in any call after the
    first pass, and every call succeeds."""
    root = Path(__file__).resolve().parents[2]
    tools = root / "src" / "native" / "tools"
    spec = importlib.util.spec_from_file_location("dump_problems", tools / "dump_problems.py")
    dp = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(dp)
    scenarios = {
        "hard": _hard_row_scenario,
        "conflict": _conflict_scenario,
        "small_damped": _small_damped_scenario,
    }
    for name, make in scenarios.items():
        dp.dump(name, make, 12, tmp_path)
    exe = hierarchy_driver
    for name in scenarios:
        for mode in ("warm", "cold"):
            out = subprocess.run(
                [str(exe), str(tmp_path / f"{name}.bin"), "3", mode],
                capture_output=True, text=True, timeout=120,
            )  # fmt: skip
            assert out.returncode == 0, (name, mode, out.stderr)
            assert "allocations after the first pass 0" in out.stdout, (name, mode, out.stdout)
