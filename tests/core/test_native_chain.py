"""The native active set's start after a missed warm trial (issue 24, ``Hierarchy.grow_seed``).

A stage without slack rows (a level of equality rows only, the minimum-norm step) whose
stored working set misses is seeded today by a ratio test from z = 0 towards the stored set's
point: the working set keeps the stored rows tight at both ends only, and every other row of
the new optimum enters by an iteration of its own. With ``grow_seed`` (off by default: fewer
iterations on chain30 but not fewer instructions, benchmarks/README.md) the stored set is
grown first by the rows its point violates and the point moved to the grown set's optimum, a
few rounds, and the active set starts there when that point meets every row. The optimum is
the same: here the level values equal the switch-off path's and the Python engine's
(``LEVEL_TOL`` relative), x (unique: the minimum-norm completion) the same, on changing data,
with ties in the ratio test (duplicated rows: dependent working rows), equal bounds, no
freedom left and inherited inequality rows; the path was taken (``grown_seeds``).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_native import needs_native, switch_check, switch_pair
from test_native_iter import _vertex_stack, no_freedom_stack

import qpcoord as qc


def _pair(stack: qc.Stack):
    """(P, new, plain): two native solvers of ``stack``, grow_seed on and off."""
    return switch_pair(stack, "grow_seed", default=False)


def _iterations(info: dict) -> int:
    """Active-set iterations of one call (hard phase, levels, minimum-norm stage)."""
    return int(
        sum(info["active_set_iterations"]) + info["hard_iterations"] + info["min_norm_iterations"]
    )


def _check(stack: qc.Stack, P, new, plain, warm: bool = True) -> tuple[int, int, int]:
    """Solve with both (warm unless told) and with the Python engine: the same level values,
    the same x (unique). Returns (stages ``new`` started from a grown set, its iterations,
    those of ``plain``)."""
    grown, infon, infop, _ = switch_check(stack, P, new, plain, "grown_seeds", warm=warm)
    return grown, _iterations(infon), _iterations(infop)


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
    """chain30 moved as the benchmark moves it, warm from step to step: the same level values
    and x as the switch-off path and the Python engine at every step; grown sets were
    started from, and the whole run took fewer active-set iterations than the seed alone."""
    st, move = _chain30()
    P, new, plain = _pair(st)
    grown = it_new = it_plain = 0
    for step in range(0, 120, 3):
        move(step)
        g, i_n, i_p = _check(st, P, new, plain)
        grown += g
        it_new += i_n
        it_plain += i_p
    assert grown > 0
    assert it_new < it_plain, (it_new, it_plain)


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_vertex_stack_large_moves(seed):
    """A first level that ends on a vertex of the box, moved far between calls (stored sets
    miss): the same as the switch-off path and the Python engine at every step."""
    st, move = _vertex_stack(seed)
    P, new, plain = _pair(st)
    for step in range(10):
        move(3 * step)
        _check(st, P, new, plain)


@needs_native
@pytest.mark.parametrize(
    ("equal", "duplicate", "inequality"),
    [(3, False, False), (0, True, False), (2, True, False), (0, False, True), (2, True, True)],
    ids=["equal bounds", "ties and dependent rows", "both", "inherited rows", "all"],
)
def test_degenerate_cases(equal, duplicate, inequality):
    """Equal bounds (equality rows of every working set), hard rows duplicating bounds (exact
    ties in the ratio test, dependent rows in a grown set), an inequality level whose rows
    are inherited by the equality levels below: the same as the switch-off path and the
    Python engine, warm over large moves."""
    for seed in (5, 6, 7):
        st, move = _vertex_stack(
            seed, equal_bounds=equal, duplicate=duplicate, inequality_level=inequality
        )
        P, new, plain = _pair(st)
        for step in range(6):
            move(4 * step)
            _check(st, P, new, plain)


@needs_native
def test_degenerate_cases_take_the_path():
    """Across the degenerate stacks above, some stage started from a grown set."""
    grown = 0
    for seed in (5, 6, 7):
        for equal, duplicate, inequality in ((3, False, False), (2, True, True)):
            st, move = _vertex_stack(
                seed, equal_bounds=equal, duplicate=duplicate, inequality_level=inequality
            )
            P, new, plain = _pair(st)
            for step in range(6):
                move(4 * step)
                grown += _check(st, P, new, plain)[0]
    assert grown > 0


@needs_native
def test_no_freedom_left():
    """Levels that fix every variable (the null space empty after the second level) on top of
    a first level that ends on bounds: the same as the switch-off path and the Python
    engine, cold then warm over moving targets."""
    st, e1, A1 = no_freedom_stack()
    n = A1.shape[1]
    P, new, plain = _pair(st)
    for step in range(5):
        e1.update(b=A1 @ np.full(n, 0.5 - 0.3 * step))
        _check(st, P, new, plain, warm=step > 0)


@needs_native
def test_counter_reset_and_default_off():
    """The switch is off by default; its counter is reset at every call (a call whose stored
    sets all hit reports 0 after one that grew a set)."""
    from qpcoord.core.native import NativeHierarchy

    st, move = _chain30()
    P = st._compiled
    assert NativeHierarchy(P, st.damping)._solver.grow_seed is False
    _, new, _ = _pair(st)
    seen = False
    for step in range(0, 60, 3):
        move(step)
        new.solve(P, warm=True)
        if new._solver.grown_seeds > 0:
            seen = True
            new.solve(P, warm=True)  # the same data: every stored working set hits
            assert new._solver.grown_seeds == 0
            break
    assert seen
