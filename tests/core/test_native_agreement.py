"""The native engine (``Stack.solve(engine="native")``) gives the Python engine's answer and
the oracle's.

The Python engine is the oracle of the native one: on every solver-comparison case and on
hypothesis-generated stacks (equalities, inequalities, bounds, hard constraints, conflicts,
duplicated rows) both give the same level values to ``LEVEL_TOL`` relative (of
``max(1, value)``) and the same ``x`` (unique after the minimum-norm step); on the published
LexLS humanoid, moved as ``benchmarks/hierarchy_published.py`` moves it, the same level values
at every step while each of the engine's paths on that problem is taken; infeasible stacks
raise the same error in both engines.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from support.families import CASES, build, reference, stack
from support.families import case_ids as _ids
from support.native_engine import assert_same, native_solver, needs_native, path_check
from support.published import published_stack
from support.stacks import hard_random_stack
from support.strategies import stacks

import qpcoord as qc
from qpcoord.core import native


@needs_native
@pytest.mark.parametrize("name,seed", CASES, ids=_ids(CASES))
def test_native_matches_python(name, seed):
    spec = build(name, seed)
    sp = stack(spec).solve(engine="python")
    sn = stack(spec).solve(engine="native")
    assert sn.solver == "native" and sn.method == "hierarchical" and sn.status == "optimal"
    assert len(sn.info["active_set_iterations"]) == len(sp.level_residuals)
    assert_same(sp, sn)


@needs_native
@pytest.mark.parametrize("name,seed", CASES, ids=_ids(CASES))
def test_native_matches_oracle(name, seed):
    ref = reference(name, seed)
    spec = build(name, seed)
    sn = stack(spec).solve(engine="native")
    r = sn.level_residuals
    assert np.all(np.abs(r - ref.level_residuals) <= 1e-6 * np.maximum(1.0, ref.level_residuals))
    assert np.max(np.abs(sn.x - ref.x)) <= 1e-5 * max(1.0, float(np.max(np.abs(ref.x))))


@needs_native
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(stacks())
def test_native_matches_python_on_random_stacks(spec):
    sp = stack(spec).solve(engine="python")
    assume(sp.status == "optimal")  # the Python engine certified every level
    s = stack(spec)
    sn = s.solve(engine="native")
    assert_same(sp, sn)
    again = s.solve(engine="native")  # warm: the same data, the stored working sets
    assert_same(sp, again)


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
        assert_same(sp, sn)
        assert sn.info["hard_iterations"] == 0
        assert np.all(sn.x >= lb) and np.all(sn.x <= ub)


@needs_native
def test_level_values_are_computed_natively():
    """The level values the native call returns are each level's residual at x."""
    s = hard_random_stack(1)
    sol = s.solve(engine="native")
    ref = np.array([L.residual(sol.x) for L in s._compiled.levels])
    np.testing.assert_allclose(sol.level_residuals, ref, rtol=1e-12, atol=1e-14)
    assert sol.status == "optimal" and not sol.info["uncertified"]
    assert s.solve(engine="native", strict=True).status == "optimal"


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


#: The ``Stats`` counters of the paths the moving humanoid takes.
HUMANOID_PATHS = (
    "null_space_freezes",
    "wy_applications",
    "rz_factors",
    "k_qr_reuses",
    "slack_steps",
)


@needs_native
@pytest.mark.parametrize(
    ("box", "unit"),
    [(False, False), (True, False), (False, True), (True, True)],
    ids=["rows", "box form", "unit rows", "box + unit rows"],
)
def test_moving_humanoid_equals_python_on_every_path(box, unit):
    """The LexLS humanoid (88 variables, 5 levels) moved as hierarchy_published's re-solve
    table, warm, its caches dropped before each call: the level values equal the Python
    engine's at every step (x is the ill-conditioned minimum-norm point: not compared), and
    each of the engine's paths on it is taken:

    - its 97-row level of rank 52 in 60 (box form: 54 in 62) is frozen by the null space of
      its QR at every step;
    - its wide level of 21 rows changes Z (and, rows form, the 72 inherited rows'
      projection) in the WY form at every step on the FMA build, never on the baseline;
    - its last level's rank-deficient M (60-62 columns, rank 52-54) and K (rank 50-51 of
      51-53) go by RZ at every step, and K's QR is reused (after full steps, and by the exact
      finish after a warm hit; the unit-row copy's warm trials hit less often there);
    - level 0's 72 inequality rows take the slack step (the box form's level-0 rows are
      bounds: no slack reaches its active sets)."""
    st, move = published_stack("lexls_test01_humanoid", box, unit)
    P, h = native_solver(st)
    total = dict.fromkeys(HUMANOID_PATHS, 0)
    for step in range(6):
        move(step)
        path_check(st, P, h, HUMANOID_PATHS[0], unique_x=False)
        for name in HUMANOID_PATHS:
            total[name] += getattr(h.counters, name)
    assert total["null_space_freezes"] >= 4, total
    if not unit:
        fma = native.load().ISA == "x86-64-v3"
        assert (total["wy_applications"] >= 4) if fma else (total["wy_applications"] == 0), total
        assert (total["slack_steps"] == 0) if box else (total["slack_steps"] > 0), total
    if not (box and unit):
        assert total["rz_factors"] >= 4, total
        assert total["k_qr_reuses"] >= (1 if unit else 5), total
