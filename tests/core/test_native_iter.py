"""The native active set's cold start at a degenerate point.

A level solved after another that left x on a vertex of the bounds (or of inherited
inequality rows) starts its active set at a point where many rows are tight. Started cold
(no stored working set: the first call, ``warm=False``), its first steps are blocked at
length zero one row at a time: each blocking row enters by an iteration of its own (a
least-squares step and a ratio test that move nothing). Instead, a step blocked at length
zero adds every row that blocks it at length zero at once (y does not move). The optimum is
the same: here the level values equal the Python engine's (``LEVEL_TOL`` relative), x
(unique: the minimum-norm completion) the same,
on changing data, cold and warm, with ties in the ratio test (duplicated rows: dependent
working rows), equal bounds, no freedom left and inherited inequality rows; the path was
taken (``Stats.batch_rows``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_native import LEVEL_TOL, native_solver, needs_native, path_check

import qpcoord as qc

_DATA = Path(__file__).resolve().parents[1] / "data"


def _check(stack: qc.Stack, P, h, warm: bool) -> int:
    """Solve natively (cold unless ``warm``) and with the Python engine: the same level
    values, the same x (unique). Returns the rows batched."""
    return path_check(stack, P, h, "batch_rows", warm=warm)[0]


def _vertex_stack(
    seed: int,
    n: int = 12,
    equal_bounds: int = 0,
    duplicate: bool = False,
    inequality_level: bool = False,
):
    """Bounds |x_j| <= 0.3, a first level of 4 equality rows far out of reach (its optimum
    rests on many bounds: a vertex of the box in most directions), then equality levels of 3
    and 2 rows that start there. ``equal_bounds`` variables get lb = ub; ``duplicate`` adds
    hard inequality rows equal to the first bounds (rows tied with the bounds in every
    ratio test: dependent working rows); ``inequality_level`` puts first an inequality level
    whose rows end tight (inherited by the levels below). Returns (stack, move(step))."""
    rng = np.random.default_rng(seed)
    lb = np.full(n, -0.3)
    ub = np.full(n, 0.3)
    for j in range(equal_bounds):
        lb[j] = ub[j] = rng.uniform(-0.2, 0.2)
    A1 = rng.standard_normal((4, n))
    b1 = 5.0 * rng.standard_normal(4)
    e1 = qc.Equality(A1, b1)
    A2 = rng.standard_normal((3, n))
    e2 = qc.Equality(A2, rng.standard_normal(3))
    A3 = rng.standard_normal((2, n))
    e3 = qc.Equality(A3, rng.standard_normal(2))
    levels: list = [e1, e2, e3]
    if inequality_level:
        C = rng.standard_normal((3, n))
        C /= np.linalg.norm(C, axis=1)[:, None]
        ineq = qc.Inequality(C, np.full(3, 0.05), np.full(3, np.inf))
        levels.insert(0, ineq)
    cons = None
    if duplicate:
        D = np.eye(n)[:4]
        cons = [qc.Inequality(D, lb[:4].copy(), ub[:4].copy())]
    st = qc.Stack(levels, bounds=qc.Bounds(lb, ub), constraints=cons)
    d1 = rng.standard_normal(4)

    def move(step: int) -> None:
        e1.update(b=b1 + 0.3 * np.sin(0.7 * step) * d1)

    return st, move


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_cold_solves_on_changing_data(seed):
    """Cold solves of a stack whose first level ends on a vertex of the box: the same level
    values and x as the Python engine at every step; rows were batched."""
    st, move = _vertex_stack(seed)
    P, h = native_solver(st)
    batched = 0
    for step in range(5):
        move(step)
        batched += _check(st, P, h, warm=False)
    assert batched > 0


@needs_native
@pytest.mark.parametrize("seed", [0, 3])
def test_warm_steps_after_a_cold_first_call(seed):
    """Warm from step to step (the stored working sets of a batched first call): the same
    values and x as the Python engine."""
    st, move = _vertex_stack(seed)
    P, h = native_solver(st)
    for step in range(8):
        move(step)
        _check(st, P, h, warm=True)


@needs_native
@pytest.mark.parametrize(
    ("equal", "duplicate", "inequality"),
    [(3, False, False), (0, True, False), (2, True, False), (0, False, True), (2, True, True)],
    ids=["equal bounds", "ties and dependent rows", "both", "inherited rows", "all"],
)
def test_degenerate_cases(equal, duplicate, inequality):
    """Equal bounds (equality rows of the working set from the start), hard rows duplicating
    bounds (exact ties in the ratio test; the second of each pair is dependent on the
    first in the working set), an inequality level whose rows are inherited: the same as the
    Python engine, cold and warm."""
    batched = 0
    for seed in (5, 6, 7):
        st, move = _vertex_stack(
            seed, equal_bounds=equal, duplicate=duplicate, inequality_level=inequality
        )
        P, h = native_solver(st)
        for step in range(3):
            move(step)
            batched += _check(st, P, h, warm=False)
            _check(st, P, h, warm=True)
    assert batched > 0


def no_freedom_stack() -> tuple[qc.Stack, qc.Equality, np.ndarray]:
    """``(stack, e1, A1)``: 6 variables in a box of ±0.2, a 3-row level far outside it (ends on
    bounds), then a square level that fixes every variable (no freedom left below it); move
    the first level's target with ``e1.update(b=A1 @ ...)`` (also test_native_seeded)."""
    rng = np.random.default_rng(11)
    n = 6
    A1 = rng.standard_normal((3, n))
    A2 = rng.standard_normal((n, n))
    e1 = qc.Equality(A1, 4.0 * rng.standard_normal(3))
    e2 = qc.Equality(A2, 0.1 * rng.standard_normal(n))
    st = qc.Stack([e1, e2], bounds=qc.Bounds(np.full(n, -0.2), np.full(n, 0.2)))
    return st, e1, A1


@needs_native
def test_no_freedom_left():
    """Levels that fix every variable (the null space empty after the second level) on top
    of a first level that ends on bounds: the same as the Python engine."""
    st, e1, A1 = no_freedom_stack()
    n = A1.shape[1]
    P, h = native_solver(st)
    for step in range(3):
        e1.update(b=A1 @ np.full(n, 0.5 + 0.1 * step))
        _check(st, P, h, warm=False)
        _check(st, P, h, warm=True)


@needs_native
def test_batch_counter_is_per_call():
    """The counter is reset at every call (a warm call after a batched cold one reports its
    own count)."""
    st, move = _vertex_stack(0)
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
    level 1 did not converge" until the iteration cap (found by test_native_memo's generator,
    seed 4857; the Python engine solved it). Now it ends, with the Python engine's level
    values."""
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
