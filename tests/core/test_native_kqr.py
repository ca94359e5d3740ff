"""The native engine's least squares with fewer factorisations: the QR of the projected
objective reused, and minimum-norm solutions of trapezoidal systems by an RZ factorisation.

A level's least-squares step factorises K = Q N, the objective projected on the null space
of the working set's rows (the LexLS humanoid's level 4: 60 x 51-53, rank 50-51). K depends
on the working set's QR alone, so its factorisation is kept while that QR does not change
and reused by the next step: after a full step (the working set unchanged: the step that
confirms stationarity), and by the exact finish of an ill-conditioned level whose warm trial
hit (the finish starts from the trial's working set, point and K). Every step here equals
the Python engine (level values 1e-9 relative, x where unique), and the reuse was taken
(``Stats.k_qr_reuses``).

A rank-deficient tall level's closed form (M P = Qm [R11 R12; 0 R22], R22 dropped), its row
space (the freeze) and a rank-deficient K's step solve [R11 R12] w = b in minimum norm: the
R12 block is folded into R11 by one Householder reflector per row (the RZ factorisation,
LAPACK's xTZRZF: about 4 rank^2 (cols - rank) flops; the humanoid's 60 x 52 and 53 x 51
blocks). Here equal to the Python engine's, and taken (``Stats.rz_factors``).

Until a hard equality row or a level's freeze changes it, the null-space basis Z is the
identity (every problem's first level when there are no hard equalities); its projections
A Z, C Z and Cin Z are then the rows themselves, copied instead of multiplied (the
humanoid's level 0: 72 x 88 by 88 x 88; ``Stats.identity_products``).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_native import native_solver, needs_native, path_check, published_stack

import qpcoord as qc


def _check(stack: qc.Stack, P, h, unique_x: bool, counter: str = "k_qr_reuses") -> int:
    """Solve natively and with the Python engine, compare; return the path's ``counter``."""
    return path_check(stack, P, h, counter, unique_x)[0]


@needs_native
@pytest.mark.parametrize(
    ("box", "unit", "least"),
    [(False, False, 5), (True, False, 5), (False, True, 1)],
    ids=["rows", "box form", "unit rows"],
)
def test_moving_humanoid_reuses_k_and_equals_python(box, unit, least):
    """The LexLS humanoid (88 variables, 5 levels) moved as hierarchy_published's re-solve
    table: its level 4's rank-deficient K is reused (after full steps, and by the exact
    finish after a warm hit), and the level values equal the Python engine's (x is the
    ill-conditioned minimum-norm point: not compared). The unit-row copy's warm trials hit less
    often on that level: fewer reuses."""
    st, move = published_stack("lexls_test01_humanoid", box, unit)
    P, h = native_solver(st)
    total = 0
    for step in range(5):
        move(step)
        total += _check(st, P, h, unique_x=False)
    assert total >= least


def _equality_under_bounds(seed: int, rank: int, cond: float):
    """A 30 x 20 equality level of the given rank (singular values 1 .. cond) under a
    unit-row inequality level and tight bounds: its closed form leaves the box, so its least
    squares runs the active set on the bound rows (no slack: the K path), warm from step to
    step as its target moves. Returns (stack, move(step))."""
    rng = np.random.default_rng(seed)
    n = 20
    U, _ = np.linalg.qr(rng.standard_normal((30, rank)))
    V, _ = np.linalg.qr(rng.standard_normal((n, rank)))
    A = U @ np.diag(np.logspace(0, np.log10(cond), rank)) @ V.T
    C = rng.standard_normal((6, n))
    C /= np.linalg.norm(C, axis=1)[:, None]
    ineq = qc.Inequality(C, rng.uniform(-0.2, 0.1, 6), np.full(6, np.inf))
    b0 = 2.0 * rng.standard_normal(30)
    eq = qc.Equality(A, b0)
    last = qc.Equality(rng.standard_normal((4, n)), rng.standard_normal(4))
    st = qc.Stack([ineq, eq, last], bounds=qc.Bounds(-0.3 * np.ones(n), 0.3 * np.ones(n)))
    d = rng.standard_normal(30)

    def move(step: int) -> None:
        eq.update(b=b0 + 0.05 * np.sin(0.5 * step) * d)

    return st, move


@needs_native
@pytest.mark.parametrize(
    ("seed", "rank", "cond", "unique"),
    [(0, 20, 1e-1, True), (1, 12, 1e-1, True), (2, 20, 1e-6, False), (4, 9, 1e-6, False)],
    ids=["full rank", "rank-deficient K", "ill-conditioned", "ill-conditioned, rank 9"],
)
def test_equality_level_on_the_bounds(seed, rank, cond, unique):
    """An equality level held by the bounds, moving: full-rank and rank-deficient K (the
    minimum-norm step through the QR of [R11 R12]^T, also reused), well- and
    ill-conditioned (sigma_min / sigma_max = 1e-6: the exact finish, started from the warm
    trial's K): equal to the Python engine at every step, x
    compared where the problem is well conditioned."""
    st, move = _equality_under_bounds(seed, rank, cond)
    P, h = native_solver(st)
    total = 0
    for step in range(8):
        move(step)
        total += _check(st, P, h, unique_x=unique)
    assert total > 0


@needs_native
@pytest.mark.parametrize(
    ("box", "unit"), [(False, False), (True, False), (False, True)], ids=["rows", "box", "unit"]
)
def test_moving_humanoid_rz_equals_python(box, unit):
    """The moving humanoid: its last level's rank-deficient M (60-62 columns, rank 52-54)
    and K (rank 50-51 of 51-53) go by RZ; level values equal the Python engine's (x: the
    ill-conditioned minimum-norm point, not compared)."""
    st, move = published_stack("lexls_test01_humanoid", box, unit)
    P, h = native_solver(st)
    total = 0
    for step in range(4):
        move(step)
        total += _check(st, P, h, unique_x=False, counter="rz_factors")
    assert total >= 4


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rank_deficient_tall_levels_closed_form_and_freeze(seed):
    """Tall equality levels of low rank (30 x 24 of rank 9, 20 x 24 of rank 6) with their
    closed forms feasible: the minimum-norm step and the row space frozen come from the RZ;
    the last level and the minimum-norm stage then see the same null space. x is unique:
    equal to the Python engine's, over changing targets."""
    rng = np.random.default_rng(seed)
    n = 24
    A1 = rng.standard_normal((30, 9)) @ rng.standard_normal((9, n))
    A2 = rng.standard_normal((20, 6)) @ rng.standard_normal((6, n))
    A3 = rng.standard_normal((5, n))
    b1, b2, b3 = (rng.standard_normal(m) for m in (30, 20, 5))
    t1, t2, t3 = qc.Equality(A1, b1), qc.Equality(A2, b2), qc.Equality(A3, b3)
    st = qc.Stack([t1, t2, t3])
    P, h = native_solver(st)
    total = 0
    for step in range(4):
        t1.update(b=b1 + 0.3 * step * rng.standard_normal(30))
        t2.update(b=b2 + 0.3 * np.cos(step) * rng.standard_normal(20))
        total += _check(st, P, h, unique_x=True, counter="rz_factors")
    assert total >= 8  # both rank-deficient levels at every step


@needs_native
@pytest.mark.parametrize(
    ("seed", "rank", "cond", "unique"),
    [(1, 12, 1e-1, True), (4, 9, 1e-6, False)],
    ids=["rank-deficient K", "ill-conditioned, rank 9"],
)
def test_rank_deficient_k_by_rz(seed, rank, cond, unique):
    """An equality level held by the bounds (its active set's K rank-deficient): the
    minimum-norm step by the RZ equals the Python engine's."""
    st, move = _equality_under_bounds(seed, rank, cond)
    P, h = native_solver(st)
    total = 0
    for step in range(8):
        move(step)
        total += _check(st, P, h, unique_x=unique, counter="rz_factors")
    assert total > 0


@needs_native
@pytest.mark.parametrize("hard", [False, True], ids=["no hard rows", "hard equality"])
def test_identity_z_copies_equal_python(hard):
    """A stack of inequality and equality levels under bounds (optionally a hard equality
    row first: Z is not the identity at level 0, nothing is copied), moving: the copies
    give the Python engine's numbers."""
    rng = np.random.default_rng(11)
    n = 16
    C = rng.standard_normal((10, n))
    C /= np.linalg.norm(C, axis=1)[:, None]
    lo0 = rng.uniform(-0.3, 0.2, 10)
    ineq = qc.Inequality(C, lo0, np.full(10, np.inf))
    eq = qc.Equality(rng.standard_normal((6, n)), rng.standard_normal(6))
    last = qc.Equality(rng.standard_normal((5, n)), rng.standard_normal(5))
    levels = [[ineq, qc.Equality(rng.standard_normal((2, n)), rng.standard_normal(2))], eq, last]
    cons = [qc.Equality(rng.standard_normal((1, n)), [0.1])] if hard else None
    st = qc.Stack(levels, bounds=qc.Bounds(-np.ones(n), np.ones(n)), constraints=cons)
    P, h = native_solver(st)
    total = 0
    for step in range(5):
        ineq.update(lower=lo0 + 0.2 * np.sin(0.8 * step + np.arange(10)))
        total += _check(st, P, h, unique_x=True, counter="identity_products")
    assert (total == 0) if hard else (total >= 5)
