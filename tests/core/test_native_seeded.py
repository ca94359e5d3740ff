"""The native active set's start after a missed warm trial, over large moves.

A stage without slack rows (a level of equality rows only, the minimum-norm step) whose
stored working set misses is seeded by a ratio test from z = 0 towards the stored set's
point: the working set keeps the stored rows tight at both ends, and every other row of the
new optimum enters by an iteration of its own. The optimum does not depend on the start:
here the level values equal the Python engine's (``LEVEL_TOL`` relative) and x (unique: the
minimum-norm completion) too, on changing data, with ties in the ratio test (duplicated
rows: dependent working rows), equal bounds, no freedom left and inherited inequality rows;
the seeded start was taken (``warm_start_seeded``).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_native import native_solver, needs_native, path_check
from test_native_iter import _vertex_stack, no_freedom_stack

import qpcoord as qc


def _check(stack: qc.Stack, P, h, warm: bool = True) -> int:
    """Solve natively (warm unless told) and with the Python engine: the same level values,
    the same x (unique). Returns the stages seeded from a missed stored set."""
    return path_check(stack, P, h, "batch_rows", warm=warm)[1]["warm_start_seeded"]


def _chain30():
    """hierarchy_bench's chain30 scenario (30 variables, joint-limit bounds, 3/3/6/6
    equality rows) and its move(step)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    try:
        import hierarchy_bench as hb
    finally:
        sys.path.pop(0)
    sc = hb._scenario(hb.chain30, np.random.default_rng(0))
    return sc["stack"], sc["move"]


@needs_native
def test_chain30_moving():
    """chain30 moved as the benchmark moves it, every third step, warm from step to step:
    the same level values and x as the Python engine at every step; seeded starts taken."""
    st, move = _chain30()
    P, h = native_solver(st)
    seeded = 0
    for step in range(0, 120, 3):
        move(step)
        seeded += _check(st, P, h)
    assert seeded > 0


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_vertex_stack_large_moves(seed):
    """A first level that ends on a vertex of the box, moved far between calls (stored sets
    miss): the same as the Python engine at every step."""
    st, move = _vertex_stack(seed)
    P, h = native_solver(st)
    for step in range(10):
        move(3 * step)
        _check(st, P, h)


@needs_native
@pytest.mark.parametrize(
    ("equal", "duplicate", "inequality"),
    [(3, False, False), (0, True, False), (2, True, False), (0, False, True), (2, True, True)],
    ids=["equal bounds", "ties and dependent rows", "both", "inherited rows", "all"],
)
def test_degenerate_cases(equal, duplicate, inequality):
    """Equal bounds (equality rows of every working set), hard rows duplicating bounds (exact
    ties in the ratio test, dependent rows in a seeded set), an inequality level whose rows
    are inherited by the equality levels below: the same as the Python engine, warm over
    large moves."""
    for seed in (5, 6, 7):
        st, move = _vertex_stack(
            seed, equal_bounds=equal, duplicate=duplicate, inequality_level=inequality
        )
        P, h = native_solver(st)
        for step in range(6):
            move(4 * step)
            _check(st, P, h)


@needs_native
def test_no_freedom_left():
    """Levels that fix every variable (the null space empty after the second level) on top of
    a first level that ends on bounds: the same as the Python engine, cold then warm over
    moving targets."""
    st, e1, A1 = no_freedom_stack()
    n = A1.shape[1]
    P, h = native_solver(st)
    for step in range(5):
        e1.update(b=A1 @ np.full(n, 0.5 - 0.3 * step))
        _check(st, P, h, warm=step > 0)
