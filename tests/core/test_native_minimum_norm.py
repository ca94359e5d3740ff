"""The native engine's minimum-norm stage as a least-distance problem.

After the last level, the native engine finds the minimum-norm x = xbar + Z y over the
last optimal set: min |xbar + Z y| over the bounds and the inherited rows, Z an orthonormal
basis of the freedom left. Z^T Z = I, so the objective is |y + Z^T xbar|^2 + const: an
identity Hessian (strictly convex in y, so the point y, and x, is unique). On a working set
with null space N (the last columns of its rows' QR) the least-squares step
min |Z (y + N s) + xbar| is s = -N^T g, g = Z^T (Z y + xbar): K = Z N has orthonormal
columns, so the general path's QR of K (and the projected objective Z Qf) is not needed.
Here equal to the Python engine's and the cvxpy oracle's on changing data and on the degenerate
cases (bounds active at the start, equal bounds, no freedom left, inherited inequality rows), and
the path was taken (``Stats.least_distance_steps``).
"""

from __future__ import annotations

import numpy as np
import pytest
from support.native_engine import X_TOL, native_solver, needs_native, path_check

import qpcoord as qc

#: the cvxpy oracle's minimum-norm point (Clarabel, tolerances 1e-11-1e-12) against ours
ORACLE_X_TOL = 1e-6


def _check(stack: qc.Stack, P, h, oracle: tuple | None = None) -> int:
    """Solve natively, with the Python engine (and the oracle on ``oracle`` = (levels,
    bounds, constraints), the stack's arguments); the minimum-norm x is unique: compare it.
    Returns the least-distance steps."""
    taken, _, sp = path_check(stack, P, h, "least_distance_steps")
    if oracle is not None:
        from support.oracle import lexicographic

        xn = h.x
        scale = max(1.0, float(np.max(np.abs(sp.x))))
        ox = lexicographic(*oracle).x
        assert np.max(np.abs(xn - ox)) <= ORACLE_X_TOL * scale, np.max(np.abs(xn - ox))
    return taken


def _feasible_stack(seed: int, n: int = 14, equal_bounds: int = 0, hard: bool = False):
    """Consistent levels (an inequality level, then equality levels of 3 and 2 rows) under
    bounds that keep x away from 0 in some variables: the last optimal set leaves freedom
    (n - 5 or n - 6 directions) and its minimum-norm point rests on bounds and on the
    inequality level's rows (inherited), so the minimum-norm stage runs its active set.
    ``equal_bounds`` variables have lb = ub; ``hard`` adds a hard equality row.
    Returns (stack, move(step), the stack's arguments)."""
    rng = np.random.default_rng(seed)
    lb = -np.ones(n)
    ub = np.ones(n)
    lb[:4] = rng.uniform(0.1, 0.3, 4)  # x_j >= lb_j > 0: x = 0 leaves these bounds
    ub[4:6] = rng.uniform(-0.3, -0.1, 2)
    lb[4:6] = -1.0
    for j in range(6, 6 + equal_bounds):
        lb[j] = ub[j] = rng.uniform(-0.2, 0.2)
    C = rng.standard_normal((4, n))
    C /= np.linalg.norm(C, axis=1)[:, None]
    x0 = 0.5 * (lb + ub)  # inside the box: the rows and equalities are consistent there
    lo0 = C @ x0 - rng.uniform(0.0, 0.05, 4)  # some rows tight at the minimum-norm point
    ineq = qc.Inequality(C, lo0, np.full(4, np.inf))
    A1 = rng.standard_normal((3, n))
    A2 = rng.standard_normal((2, n))
    e1 = qc.Equality(A1, A1 @ x0)
    e2 = qc.Equality(A2, A2 @ x0)
    cons = None
    if hard:
        h = rng.standard_normal((1, n))
        cons = [qc.Equality(h, h @ x0)]
    args = ([ineq, e1, e2], qc.Bounds(lb, ub), cons)
    st = qc.Stack(args[0], bounds=args[1], constraints=cons)
    d1, d2 = rng.standard_normal(3), rng.standard_normal(4)

    def move(step: int) -> None:
        e1.update(b=A1 @ x0 + 0.02 * np.sin(0.7 * step) * d1)
        ineq.update(lower=lo0 + 0.02 * np.cos(0.5 * step) * d2)

    return st, move, args


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_moving_stack_same_point_as_python_and_oracle(seed):
    """Consistent levels under bounds, moving: the minimum-norm point rests on bounds and
    inherited inequality rows; equal to the Python engine's and the oracle's at every step (warm
    from step to step), and the least-distance path ran."""
    st, move, args = _feasible_stack(seed)
    P, h = native_solver(st)
    total = 0
    for step in range(6):
        move(step)
        total += _check(st, P, h, oracle=args if step % 2 == 0 else None)
    assert total > 0


@needs_native
@pytest.mark.parametrize(
    ("equal", "hard"), [(3, False), (0, True), (2, True)], ids=["equal bounds", "hard", "both"]
)
def test_equal_bounds_and_hard_rows(equal, hard):
    """Variables with lb = ub (equality rows of the working set from the start) and a hard
    equality row (Z is not the identity from the start): same point as the Python engine
    and the oracle."""
    st, move, args = _feasible_stack(5, equal_bounds=equal, hard=hard)
    P, h = native_solver(st)
    total = 0
    for step in range(4):
        move(step)
        total += _check(st, P, h, oracle=args if step == 0 else None)
    assert total > 0


@needs_native
def test_bounds_active_at_the_start():
    """The point the levels leave already sits on bounds (one-sided, lb = x exactly after
    the levels' closed form is clipped by the box): the minimum-norm stage starts with
    those rows tight (zero-length steps, then drops) and ends at the oracle's point."""
    n = 8
    rng = np.random.default_rng(21)
    A = rng.standard_normal((3, n))
    lb = np.full(n, -1.0)
    ub = np.full(n, 1.0)
    lb[:3] = 0.4
    x0 = np.clip(rng.uniform(-0.5, 0.5, n), lb, ub)
    x0[:3] = 0.4  # on the lower bounds
    e = qc.Equality(A, A @ x0)
    st = qc.Stack([e], bounds=qc.Bounds(lb, ub))
    P, h = native_solver(st)
    total = 0
    for step in range(4):
        e.update(b=A @ x0 + 0.05 * step * rng.standard_normal(3))
        total += _check(st, P, h, oracle=([e], qc.Bounds(lb, ub), None))
    assert total > 0


@needs_native
def test_no_freedom_left_takes_no_step():
    """Levels that fix every variable (the null space is empty): no least-distance step,
    and the Python engine's x."""
    rng = np.random.default_rng(3)
    n = 6
    st = qc.Stack(
        [
            qc.Equality(rng.standard_normal((4, n)), rng.standard_normal(4)),
            qc.Equality(rng.standard_normal((2, n)), rng.standard_normal(2)),
        ],
        bounds=qc.Bounds(-10 * np.ones(n), 10 * np.ones(n)),
    )
    P, h = native_solver(st)
    assert _check(st, P, h) == 0


@needs_native
def test_unconstrained_minimum_norm_is_the_closed_form():
    """A minimum-norm point inside the box is the closed form xbar - Z Z^T xbar: the active
    set does not run (no step); the Python engine's x."""
    rng = np.random.default_rng(4)
    n = 10
    st = qc.Stack(
        [qc.Equality(rng.standard_normal((3, n)), 0.1 * rng.standard_normal(3))],
        bounds=qc.Bounds(-10 * np.ones(n), 10 * np.ones(n)),
    )
    P, h = native_solver(st)
    xn, _, info = h.solve(P)
    assert h.counters.least_distance_steps == 0 and info["min_norm_iterations"] == 0
    xbar = st.solve(engine="python").x
    assert np.max(np.abs(xn - xbar)) <= X_TOL * max(1.0, float(np.max(np.abs(xbar))))


@needs_native
def test_chain30_moving_equals_python():
    """hierarchy_bench's chain30 (30 variables, joint-limit bounds, 3/3/6/6 equality rows),
    moved as the benchmark moves it: the minimum-norm stage's least-distance steps give the
    Python engine's x (unique) at every step."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    try:
        import hierarchy_bench as hb
    finally:
        sys.path.pop(0)
    sc = hb._scenario(hb.chain30, np.random.default_rng(0))
    st = sc["stack"]
    P, h = native_solver(st)
    total = 0
    for step in range(12):
        sc["move"](step)
        total += _check(st, P, h)
    assert total > 0
