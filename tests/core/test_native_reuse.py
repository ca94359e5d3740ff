"""The native engine's per-level bookkeeping of the inherited rows and the stored working
sets (issue 24, helper "reuse", session 13).

Two changes that keep every number bit for bit (no switch; the driver's x on the nine dumps
of session 12 is byte-identical, warm and cold, baseline and x86-64-v3 builds):

* ``Hierarchy::cin_norm``: an inherited row's norm |C_i| (the scale below which its
  projection cannot bind) is computed once per call, on first use, not at every level's
  ``add_inherited_rows`` (soth_sot: 30 rows x 5 levels).
* ``Hierarchy::map_working_set``: a stored working set's rows are found in the level's
  problem by a table of row ids when it has more than 4 rows among more than 16 rows of P
  (soth_sot's 27-28 of 30 inherited joint limits), else by the search per stored row (the
  Panda's 9 bound rows).

A wrong mapping would not give a wrong answer (the trial would miss and the active set
start cold) but would lose the warm start: the tests check the level values and x against
the Python engine and that the stored sets still hit.
"""

from __future__ import annotations

import numpy as np
from test_native import LEVEL_TOL, X_TOL, needs_native, published_stack

import qpcoord as qc
from qpcoord.core.native import NativeHierarchy


def _run(stack: qc.Stack, move, steps: int) -> tuple[int, int]:
    """Solve ``stack`` warm at ``steps`` moved steps with one native solver; every step equal
    to the Python engine (level values ``LEVEL_TOL`` relative, x ``X_TOL``). Returns (warm
    hits summed over the steps after the first, stages per solve)."""
    P = stack._compiled
    nat = NativeHierarchy(P, stack.damping)
    hits = 0
    stages = 0
    for step in range(steps):
        move(step)
        x, r, info = nat.solve(P, warm=step > 0)
        sp = stack.solve(engine="python")
        ref = sp.level_residuals
        assert np.all(np.abs(r - ref) <= LEVEL_TOL * np.maximum(1.0, ref)), (step, r, ref)
        scale = max(1.0, float(np.max(np.abs(sp.x))))
        assert np.max(np.abs(x - sp.x)) <= X_TOL * scale, (step, np.max(np.abs(x - sp.x)))
        if step > 0:
            hits += int(info["warm_start_hits"])
        stages = len(ref)
    return hits, stages


@needs_native
def test_soth_sot_stored_sets_mapped_by_the_id_table():
    # level 0: 30 joint limits (27-28 stay active and are inherited), then 3/3/6/6 equality
    # rows: every level's stored set (> 4 rows of P's 30) goes through the id table
    stack, move = published_stack("soth_sot")
    steps = 12
    hits, levels = _run(stack, move, steps)
    # the driver on 50 moved steps: 5.98 of 6 stages hit per solve; a broken mapping misses
    assert hits >= (steps - 1) * levels, (hits, steps, levels)


@needs_native
def test_bounds_only_sets_mapped_by_the_search():
    # 9 variables, bounds only (9 rows of P: the search per stored row), a 3-row then a
    # 9-row equality level pushing several bounds active
    rng = np.random.default_rng(7)
    A1 = rng.standard_normal((3, 9))
    A2 = rng.standard_normal((9, 9))
    b1 = 3.0 * rng.standard_normal(3)
    b2 = 3.0 * rng.standard_normal(9)
    t1, t2 = qc.Equality(A1, b1.copy()), qc.Equality(A2, b2.copy())
    stack = qc.Stack([t1, t2], bounds=qc.Bounds(-0.5, 0.5))

    def move(step: int) -> None:
        t1.update(b=b1 + 1e-3 * np.sin(0.1 * step + np.arange(3)))
        t2.update(b=b2 + 1e-3 * np.sin(0.1 * step + np.arange(9)))

    hits, levels = _run(stack, move, 10)
    assert hits > 0


@needs_native
def test_inherited_rows_with_infinite_sides_and_zero_rows():
    # inherited rows skipped by inherit (both sides infinite) and a zero row (its norm 0:
    # its projection never binds) keep the ids sparse; the table and the cached norms must
    # still match the Python engine on every moved step
    rng = np.random.default_rng(11)
    n = 24
    C = rng.standard_normal((20, n))
    C[3] = 0.0
    lo = -0.2 * np.ones(20)
    hi = 0.2 * np.ones(20)
    lo[5], hi[5] = -np.inf, np.inf
    lo[8] = -np.inf
    ineq = qc.Inequality(C, lo, hi)
    A1 = rng.standard_normal((4, n))
    A2 = rng.standard_normal((6, n))
    b1 = 4.0 * rng.standard_normal(4)
    b2 = 4.0 * rng.standard_normal(6)
    t1, t2 = qc.Equality(A1, b1.copy()), qc.Equality(A2, b2.copy())
    stack = qc.Stack([ineq, t1, t2])

    def move(step: int) -> None:
        t1.update(b=b1 + 1e-2 * np.sin(0.3 * step + np.arange(4)))
        t2.update(b=b2 + 1e-2 * np.sin(0.3 * step + np.arange(6)))

    hits, levels = _run(stack, move, 10)
    assert hits > 0
