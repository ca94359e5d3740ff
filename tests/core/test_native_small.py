"""The native engine's shortcuts of the freeze after a level's active set (the fixed
per-level costs of small problems such as the Panda IK stack).

A level whose equalities have full column rank r in the remaining freedom (the closed
form's rank is r) and which leaves no violated row has no freedom left: r <- 0 directly, not
by forming F^T (an orthonormal basis of the whole space) and factorising it
(``Stats.full_rank_freezes``).

A wide level (M = A Z with me <= r, its closed form by the QR of M^T) solved by the active
set (its closed form left the bounds or the inherited rows) and leaving no violated row:
Z <- Z Qf, its first rank columns dropped, by M^T's own reflectors (as after a feasible
closed form), not by forming Qf's first rank columns and factorising them again
(``Stats.wide_freezes``).

Every step equals the Python engine (level values 1e-9 relative, x where unique); the
counters show the path taken, and where it must not be taken (a violated row, a rank below
r), it is not.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_native import LEVEL_TOL, native_solver, needs_native, path_check, published_stack

import qpcoord as qc

#: each shortcut's counter (``Stats``)
COUNTER = {"full_rank": "full_rank_freezes", "wide": "wide_freezes"}


def _check(stack: qc.Stack, P, h, unique_x: bool, counter: str) -> int:
    """The Python engine's level values (x where unique); returns the path's ``counter``."""
    return path_check(stack, P, h, counter, unique_x)[0]


def _arm(seed: int, n: int = 9, task_rows: int = 3):
    """A Panda-like IK stack: a wide task (task_rows x n) whose closed form leaves tight
    bounds (its least squares runs the active set on the bound rows), then a posture task
    (n x n, full rank) over what is left. Returns (stack, move(step))."""
    rng = np.random.default_rng(seed)
    J = rng.standard_normal((task_rows, n))
    b0 = 3.0 * rng.standard_normal(task_rows)
    task = qc.Equality(J, b0)
    post = qc.Equality(np.eye(n), 0.1 * rng.standard_normal(n))
    st = qc.Stack([task, post], bounds=qc.Bounds(-0.4 * np.ones(n), 0.4 * np.ones(n)))
    d = rng.standard_normal(task_rows)

    def move(step: int) -> None:
        task.update(b=b0 + 0.2 * np.sin(0.6 * step) * d)

    return st, move


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("switch", ["full_rank", "wide"])
def test_moving_arm_equals_python(seed, switch):
    """The Panda-like stack over changing targets: the wide task's active set ends with no
    violated row (the wide freeze), the posture level has full rank (no freedom left); x is
    unique and equals the Python engine at every step."""
    st, move = _arm(seed)
    P, h = native_solver(st)
    total = 0
    for step in range(6):
        move(step)
        total += _check(st, P, h, unique_x=True, counter=COUNTER[switch])
    assert total >= 6


@needs_native
@pytest.mark.parametrize("seed", [0, 1])
def test_rank_deficient_wide_level_under_inherited_rows(seed):
    """A wide level of rank 4 in 6 rows (its M^T's QR stops at rank 4) under an inherited
    inequality level that its closed form leaves: the wide freeze drops rank columns only,
    then two more levels; equal to the Python engine (x unique)."""
    rng = np.random.default_rng(seed)
    n = 16
    C = rng.standard_normal((10, n))
    C /= np.linalg.norm(C, axis=1)[:, None]
    lo0 = rng.uniform(-0.3, -0.05, 10)
    ineq = qc.Inequality(C, lo0, np.full(10, np.inf))
    A = rng.standard_normal((6, 4)) @ rng.standard_normal((4, n))
    b0 = 4.0 * rng.standard_normal(6)
    wide = qc.Equality(A, b0)
    mid = qc.Equality(rng.standard_normal((5, n)), rng.standard_normal(5))
    last = qc.Equality(np.eye(n), np.zeros(n))
    st = qc.Stack([ineq, wide, mid, last], bounds=qc.Bounds(-np.ones(n), np.ones(n)))
    P, h = native_solver(st)
    total = 0
    for step in range(5):
        ineq.update(lower=lo0 + 0.1 * np.sin(0.8 * step + np.arange(10)))
        wide.update(b=b0 + 0.5 * np.cos(step + np.arange(6)))
        total += _check(st, P, h, unique_x=True, counter="wide_freezes")
    assert total >= 1


@needs_native
@pytest.mark.parametrize("switch", ["full_rank", "wide"])
def test_violated_rows_take_the_general_freeze(switch):
    """A level with equality rows (wide, or of full rank) and an inequality row it cannot
    meet (violated at its optimum): the freeze must hold that row too, so neither shortcut
    is taken; the Python engine's level values."""
    rng = np.random.default_rng(9)
    n = 6
    c = rng.standard_normal(n)
    c /= np.linalg.norm(c)
    rows = 2 if switch == "wide" else n
    cons = [qc.Inequality(c[None, :], [-0.1], [0.1])]
    lev = [
        qc.Equality(rng.standard_normal((rows, n)), rng.standard_normal(rows)),
        qc.Inequality(c[None, :], [5.0], [np.inf]),
    ]
    st = qc.Stack(
        [lev, qc.Equality(rng.standard_normal((3, n)), rng.standard_normal(3))], constraints=cons
    )
    P, h = native_solver(st)
    _, rn, _ = h.solve(P)
    assert getattr(h.counters, COUNTER[switch]) == 0
    sp = st.solve(engine="python")
    assert np.all(np.abs(rn - sp.level_residuals) <= LEVEL_TOL * np.maximum(1.0, rn))


@needs_native
def test_rank_deficient_tall_level_is_not_full_rank():
    """A tall level of rank 5 < r held by the bounds: freedom is left, the full-rank
    shortcut is not taken (the null-space freeze is); the Python engine's level values."""
    rng = np.random.default_rng(4)
    n = 10
    A = rng.standard_normal((14, 5)) @ rng.standard_normal((5, n))
    eq = qc.Equality(A, 3.0 * rng.standard_normal(14))
    last = qc.Equality(np.eye(n), rng.standard_normal(n))
    st = qc.Stack([eq, last], bounds=qc.Bounds(-0.2 * np.ones(n), 0.2 * np.ones(n)))
    P, h = native_solver(st)
    _, rn, _ = h.solve(P)
    # only the last level (full rank in what the first leaves) may take it
    assert h.counters.full_rank_freezes <= 1
    sp = st.solve(engine="python")
    assert np.all(np.abs(rn - sp.level_residuals) <= LEVEL_TOL * np.maximum(1.0, rn))


@needs_native
@pytest.mark.parametrize(
    ("box", "unit"),
    [(False, False), (True, False), (False, True), (True, True)],
    ids=["rows", "box form", "unit rows", "box + unit rows"],
)
@pytest.mark.parametrize("switch", ["full_rank", "wide"])
def test_moving_humanoid_equals_python(box, unit, switch):
    """The LexLS humanoid moved as hierarchy_published's re-solve table: level values equal
    the Python engine's (x: the ill-conditioned minimum-norm point, not compared)."""
    st, move = published_stack("lexls_test01_humanoid", box, unit)
    P, h = native_solver(st)
    for step in range(4):
        move(step)
        _check(st, P, h, unique_x=False, counter=COUNTER[switch])


@needs_native
@pytest.mark.parametrize("variant", ["baseline", "x86-64-v3"])
@pytest.mark.parametrize("switch", ["full_rank", "wide"])
def test_each_build_takes_the_paths(monkeypatch, variant, switch):
    """Each build (baseline, x86-64-v3 where this CPU runs it) on the moving arm: the path
    is taken and x equals the Python engine's."""
    from qpcoord.core import native

    try:
        mod = native.import_variant(variant)
    except (native.NativeUnavailableError, ValueError):
        pytest.skip(f"no {variant} build on this machine")
    monkeypatch.setattr(native, "_module", mod)
    st, move = _arm(0)
    P, h = native_solver(st)
    assert type(h._solver).__module__ == mod.__name__
    total = 0
    for step in range(4):
        move(step)
        total += _check(st, P, h, unique_x=True, counter=COUNTER[switch])
    assert total >= 4
