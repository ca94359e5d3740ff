"""The native active set's start after a missed warm trial gives the cold answer.

A stage whose stored working set misses is seeded: the stored set made feasible (a level with
slack rows), a ratio test from ``z = 0`` towards the stored set's point (a stage without slack
rows: equality levels, the minimum-norm step), the set's point with each slack the row's
violation there (the hard phase). Over small and large moves, on degenerate vertices and with
no freedom left, the seeded start ends on a cold solve's x and the Python engine's, and it is
used (``warm_start_seeded``).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from support.native_engine import X_TOL, native_solver, needs_native, path_check
from support.stacks import (
    hard_random_stack,
    hard_row_stack,
    inequality_shifts,
    no_freedom_stack,
    vertex_stack,
)

import qpcoord as qc


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_missed_working_set_seeds_the_next_start(seed):
    """Moving targets make stored working sets miss; the seeded start (the stored set made
    feasible) ends on the same level values as the Python engine and as a cold solve, and
    it is used."""
    from qpcoord.core.native import NativeHierarchy

    s = hard_random_stack(seed, n=30, levels=6)
    P = s._compiled
    seeded = NativeHierarchy(P, s.damping)
    cold = NativeHierarchy(P, s.damping)
    move = inequality_shifts(s)
    used = 0
    for step in range(12):
        move(step)
        xs, rs, info = seeded.solve(P)
        xc, rc, _ = cold.solve(P, warm=False)
        ref = s.solve(engine="python").level_residuals
        np.testing.assert_allclose(rs, ref, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(rc, ref, rtol=1e-9, atol=1e-10)
        used += info["warm_start_seeded"]
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
def test_a_missed_hard_phase_set_seeds_its_start():
    """Hard inequality rows that x = 0 breaks: the least-violation phase runs at every call.
    As the rows move its stored working set misses; the seeded start (the set's point, each
    slack the row's violation there) ends on a cold solve's x and the Python engine's, and
    it is used."""
    from qpcoord.core.native import NativeHierarchy

    s, hard, move = hard_row_stack(np.random.default_rng(1))
    C = hard.C
    P = s._compiled
    seeded = NativeHierarchy(P, s.damping)
    cold = NativeHierarchy(P, s.damping)
    used = 0
    for step in range(20):
        xt = move(step)  # xt stays feasible
        xs_, rs, info = seeded.solve(P)
        xc, rc, cinfo = cold.solve(P, warm=False)
        sp = s.solve(engine="python")
        np.testing.assert_allclose(rs, sp.level_residuals, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(xs_, xc, rtol=0, atol=1e-9)
        np.testing.assert_allclose(xs_, sp.x, rtol=0, atol=X_TOL)
        assert np.all(C @ xs_ >= C @ xt - 0.05 - 1e-9)
        used += info["warm_start_seeded"]
    assert used > 0


def _check(stack: qc.Stack, P, h, warm: bool = True) -> int:
    """Solve natively (warm unless told) and with the Python engine: the same level values,
    the same x (unique). Returns the stages seeded from a missed stored set."""
    return path_check(stack, P, h, "batch_rows", warm=warm)[1]["warm_start_seeded"]


def _chain30():
    """hierarchy_bench's chain30 scenario (30 variables, joint-limit bounds, 3/3/6/6
    equality rows) and its move(step)."""

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    try:
        import hierarchy_bench as hb
    finally:
        sys.path.pop(0)
    sc = hb._scenario(hb.chain30, np.random.default_rng(0))
    return sc["stack"], sc["move"]


@needs_native
def test_the_moving_chain30_is_seeded():
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
def test_large_moves_from_a_vertex_of_the_box(seed):
    """A first level that ends on a vertex of the box, moved far between calls (stored sets
    miss): the same as the Python engine at every step."""
    st, move = vertex_stack(seed)
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
def test_seeded_starts_at_equal_bounds_ties_and_inherited_rows(equal, duplicate, inequality):
    """Equal bounds (equality rows of every working set), hard rows duplicating bounds (exact
    ties in the ratio test, dependent rows in a seeded set), an inequality level whose rows
    are inherited by the equality levels below: the same as the Python engine, warm over
    large moves."""
    for seed in (5, 6, 7):
        st, move = vertex_stack(
            seed, equal_bounds=equal, duplicate=duplicate, inequality_level=inequality
        )
        P, h = native_solver(st)
        for step in range(6):
            move(4 * step)
            _check(st, P, h)


@needs_native
def test_seeded_start_with_no_freedom_left():
    """Levels that fix every variable (the null space empty after the second level) on top of
    a first level that ends on bounds: the same as the Python engine, cold then warm over
    moving targets."""
    st, e1, A1 = no_freedom_stack()
    n = A1.shape[1]
    P, h = native_solver(st)
    for step in range(5):
        e1.update(b=A1 @ np.full(n, 0.5 - 0.3 * step))
        _check(st, P, h, warm=step > 0)
