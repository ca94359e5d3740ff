"""The native engine's per-level bookkeeping of the inherited rows.

``Hierarchy::cin_norm``: an inherited row's norm |C_i| (the scale below which its projection
cannot bind) is computed once per call, on first use, not at every level's
``add_inherited_rows`` (soth_sot: 30 rows x 5 levels). The same numbers bit for bit (no
switch; the driver's x on the dumped problems is byte-identical, warm and cold,
baseline and x86-64-v3 builds).

The tests run moved stacks whose later levels inherit many rows (soth_sot's 30 joint
limits, 27-28 active; rows with infinite sides and a zero row) warm against the Python
engine (level values, x), and check that the stored working sets still hit: the warm trial
reads the same rows and norms as before.
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
def test_soth_sot_inherited_rows_warm():
    # level 0: 30 joint limits (27-28 stay active and are inherited), then 3/3/6/6 equality
    # rows: every level adds the 30 inherited rows with their kept norms
    stack, move = published_stack("soth_sot")
    steps = 12
    hits, levels = _run(stack, move, steps)
    # the driver on 50 moved steps: 5.98 of 6 stages hit per solve
    assert hits >= (steps - 1) * levels, (hits, steps, levels)


@needs_native
def test_bounds_only_warm():
    # 9 variables, bounds only (no inherited row), a 3-row then a 9-row equality level
    # pushing several bounds active
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
    # its projection never binds); the kept norms must match the Python engine on every
    # moved step
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
