"""The native active set on conflicting, degenerate and ill-conditioned levels equals the
Python engine.

- The least-squares step by the slack structure: a level's least squares runs in
  ``y = (z, w)``, one slack per inequality row; a slack whose row is outside the working set
  is taken to zero in closed form and the rest of the step is the minimum-norm solution of a
  small system (``Stats.slack_steps``).
- The exact finish of an ill-conditioned level (a second active set from the first's end):
  bit for bit the same with every cached factorisation dropped.
- The cold start at a degenerate point: a level solved after another that left x on a vertex
  of the bounds (or of inherited inequality rows) adds at once every row that blocks a step at
  length zero (``Stats.batch_rows``), with the same optimum.
- Steps of rounding at a large point end the active set.

Every step equals the Python engine (level values ``LEVEL_TOL`` relative, x where unique).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from support.hlsp import load
from support.native_engine import LEVEL_TOL, X_TOL, native_solver, needs_native, path_check
from support.published import published_module
from support.stacks import hard_random_stack, inequality_shifts, no_freedom_stack, vertex_stack

import qpcoord as qc


def _slack_check(stack, P, h, unique_x: bool = True) -> tuple[int, int]:
    """Solve natively and with the Python engine; compare; return (slack steps,
    iterations)."""
    xn, rn, info = h.solve(P)
    steps = h.counters.slack_steps
    sp = stack.solve(engine="python")
    ref = sp.level_residuals
    assert np.all(np.abs(rn - ref) <= LEVEL_TOL * np.maximum(1.0, ref)), (rn, ref)
    scale = max(1.0, float(np.max(np.abs(sp.x))))
    if unique_x:
        assert np.max(np.abs(xn - sp.x)) <= X_TOL * scale
    return steps, int(np.sum(info["active_set_iterations"]))


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_conflicting_rows_many_iterations_equal_python(seed):
    """Levels of conflicting unit inequality rows beside a few equality rows, warm over
    moving bounds (misses, seeded starts, rows entering and leaving): the slack step is
    taken at many iterations and every step equals the Python engine."""
    st = hard_random_stack(seed, n=30, levels=6)
    P, h = native_solver(st)
    move = inequality_shifts(st)
    total = iters = 0
    for step in range(8):
        move(step)
        s, it = _slack_check(st, P, h)
        total += s
        iters += it
    assert iters >= 20  # the active set works (not only warm hits)
    assert total >= 10


@needs_native
@pytest.mark.parametrize("seed", [0, 1])
def test_degenerate_rows_and_zero_weights(seed):
    """Degenerate working sets: duplicated and opposite rows (dependent rows of G_w: the
    general path), row weights from 1e-8 to 1e4 (slack columns of very different scale), a
    level whose equality rows are rank-deficient, tight boxes: equal to the Python engine,
    and the slack step still taken where it applies."""
    rng = np.random.default_rng(seed)
    n = 12
    C = rng.standard_normal((8, n))
    C = np.vstack([C, C[:3], -C[3:5]])  # duplicates and opposite rows
    C /= np.linalg.norm(C, axis=1)[:, None]
    lo = rng.uniform(0.3, 0.8, C.shape[0])
    w = np.ones(C.shape[0])
    w[[1, 9]] = 1e-8  # the row may be violated almost at no cost
    w[[2, 6]] = 1e4
    rank2 = rng.standard_normal((5, 2)) @ rng.standard_normal((2, n))
    ineq = qc.Inequality(C, lo, np.full(C.shape[0], np.inf), weight=w)
    eq = qc.Equality(rank2, rng.standard_normal(5))
    low = qc.Inequality(rng.standard_normal((6, n)), -np.ones(6) * 0.2, np.ones(6) * 0.2)
    st = qc.Stack([[ineq, eq], low], bounds=qc.Bounds(-0.6 * np.ones(n), 0.6 * np.ones(n)))
    P, h = native_solver(st)
    lo0 = lo.copy()
    total = 0
    for step in range(8):
        ineq.update(lower=lo0 + 0.2 * np.sin(0.9 * step + np.arange(lo0.size)))
        s, _ = _slack_check(st, P, h, unique_x=False)
        total += s
    assert total > 0


@needs_native
@pytest.mark.parametrize("case", ["humanoid", "ill_conditioned"])
def test_exact_finish_of_an_ill_conditioned_level_equals_python(case):
    """An ill-conditioned level is finished to rounding (a second active set right after the
    first ended optimal, started from that end's factorisation and last step): the Python
    engine's level values, and the same numbers, bit for bit, when every cached
    factorisation is dropped before the call. Cases: the moving humanoid (its level 4:
    sigma_min / |A| ~ 5e-5) and a random ill-conditioned equality level under conflicting
    inequality rows."""
    from qpcoord.core.native import NativeHierarchy

    if case == "humanoid":
        hp = published_module()
        prob = load("lexls_test01_humanoid")
        st = qc.Stack(prob.levels, bounds=prob.bounds)
        mover = hp._mover(prob.levels)
    else:
        rng = np.random.default_rng(5)
        n = 20
        U, _ = np.linalg.qr(rng.standard_normal((30, n)))
        V, _ = np.linalg.qr(rng.standard_normal((n, n)))
        A = U @ np.diag(np.logspace(0, -5, n)) @ V.T  # sigma_min / sigma_max = 1e-5
        C = rng.standard_normal((12, n))
        C /= np.linalg.norm(C, axis=1)[:, None]
        ineq = qc.Inequality(C, rng.uniform(0.2, 0.6, 12), np.full(12, np.inf))
        eq = qc.Equality(A, rng.standard_normal(30))
        st = qc.Stack([ineq, eq], bounds=qc.Bounds(-np.ones(n), np.ones(n)))
        lo0 = ineq.lower.copy()

        def mover(step: int) -> None:
            ineq.update(lower=lo0 + 0.1 * np.sin(0.6 * step + np.arange(12)))

    P = st._compiled
    new = NativeHierarchy(P, st.damping)
    plain = NativeHierarchy(P, st.damping)
    for step in range(5):
        mover(step)
        xn, rn, _ = new.solve(P)
        plain._solver.invalidate_caches()
        xp, rp, _ = plain.solve(P)
        assert np.array_equal(xn, xp) and np.array_equal(rn, rp)
        ref = st.solve(engine="python").level_residuals
        assert np.all(np.abs(rn - ref) <= LEVEL_TOL * np.maximum(1.0, ref)), (rn, ref)


_DATA = Path(__file__).resolve().parents[1] / "data"


def _batch_check(stack: qc.Stack, P, h, warm: bool) -> int:
    """Solve natively (cold unless ``warm``) and with the Python engine: the same level
    values, the same x (unique). Returns the rows batched."""
    return path_check(stack, P, h, "batch_rows", warm=warm)[0]


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_cold_start_at_a_vertex_batches_blocking_rows(seed):
    """Cold solves of a stack whose first level ends on a vertex of the box: the same level
    values and x as the Python engine at every step; rows were batched."""
    st, move = vertex_stack(seed)
    P, h = native_solver(st)
    batched = 0
    for step in range(5):
        move(step)
        batched += _batch_check(st, P, h, warm=False)
    assert batched > 0


@needs_native
@pytest.mark.parametrize("seed", [0, 3])
def test_warm_steps_after_a_batched_cold_start(seed):
    """Warm from step to step (the stored working sets of a batched first call): the same
    values and x as the Python engine."""
    st, move = vertex_stack(seed)
    P, h = native_solver(st)
    for step in range(8):
        move(step)
        _batch_check(st, P, h, warm=True)


@needs_native
@pytest.mark.parametrize(
    ("equal", "duplicate", "inequality"),
    [(3, False, False), (0, True, False), (2, True, False), (0, False, True), (2, True, True)],
    ids=["equal bounds", "ties and dependent rows", "both", "inherited rows", "all"],
)
def test_cold_start_at_equal_bounds_ties_and_inherited_rows(equal, duplicate, inequality):
    """Equal bounds (equality rows of the working set from the start), hard rows duplicating
    bounds (exact ties in the ratio test; the second of each pair is dependent on the
    first in the working set), an inequality level whose rows are inherited: the same as the
    Python engine, cold and warm."""
    batched = 0
    for seed in (5, 6, 7):
        st, move = vertex_stack(
            seed, equal_bounds=equal, duplicate=duplicate, inequality_level=inequality
        )
        P, h = native_solver(st)
        for step in range(3):
            move(step)
            batched += _batch_check(st, P, h, warm=False)
            _batch_check(st, P, h, warm=True)
    assert batched > 0


@needs_native
def test_cold_start_with_no_freedom_left():
    """Levels that fix every variable (the null space empty after the second level) on top
    of a first level that ends on bounds: the same as the Python engine."""
    st, e1, A1 = no_freedom_stack()
    n = A1.shape[1]
    P, h = native_solver(st)
    for step in range(3):
        e1.update(b=A1 @ np.full(n, 0.5 + 0.1 * step))
        _batch_check(st, P, h, warm=False)
        _batch_check(st, P, h, warm=True)


@needs_native
def test_batched_rows_are_counted_per_call():
    """The counter is reset at every call (a warm call after a batched cold one reports its
    own count)."""
    st, move = vertex_stack(0)
    P, h = native_solver(st)
    move(0)
    h.solve(P, warm=False)
    assert h.counters.batch_rows > 0
    h.solve(P, warm=True)  # the same data: every stored working set hits
    assert h.counters.batch_rows == 0


@needs_native
def test_steps_of_rounding_at_a_large_point_end_the_active_set():
    """A stationary point far from the origin ends the level: level 0, 5
    inequality rows of rank 3 in 8 variables, leaves level 1 (6 equality rows, satisfiable)
    a point at |y| ~ 650 after a drop; the least-squares steps there are rounding of
    Q y - c (relative to |Q| |y|, not to |Q y| ~ |c|: 1e-10 long, gaining 1e-26 each),
    which the stationarity floor, relative to |c| only, took for progress: "the active set of
    level 1 did not converge" until the iteration cap (found by a random stack,
    seed 4857; the Python engine solved it). It ends, with the Python
    engine's level values."""
    d = np.load(_DATA / "native_rounding_steps_4857.npz")
    tasks = [qc.Inequality(d["C0"], upper=d["u0"])]
    tasks += [qc.Equality(d[f"A{i}"], d[f"b{i}"]) for i in range(1, 5)]
    stack = qc.Stack(tasks)
    native = stack.solve(engine="native")
    python = stack.solve(engine="python")
    assert native.status == python.status == "optimal"
    ref = python.level_residuals
    np.testing.assert_allclose(
        native.level_residuals, ref, rtol=LEVEL_TOL, atol=LEVEL_TOL * max(1.0, np.abs(ref).max())
    )
