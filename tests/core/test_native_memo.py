"""The native engine's memo of the freezes (``Hierarchy.freeze_memo``, issue 24, session 15).

A level's freeze -- the change of the null-space basis Z, of the free dimension r and of
the carried projection of the inherited rows -- is a function of Z and of that projection on
entry, of the level's rows and of the freeze's kind, rank and violated rows; none of them
depends on the targets or on the bounds' values. A re-solve whose matrices did not change
(targets, bounds moved: the benchmarks' re-solves, an LTI coordinator) restores the stored
outputs of the level's last freeze instead of applying its reflectors to Z again. The tests
compare a solver with the memo on against one with it off, bit for bit (x's and the level
values' bits, the info dicts), along sequences in which each level's matrix stays, changes,
or comes back to an earlier value (a memo keyed on too little would restore a stale Z there),
and check that the memo was used where the matrices repeat and not used where they change.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_native import needs_native, published_stack, switch_pair

import qpcoord as qc


def _bits(v: np.ndarray) -> np.ndarray:
    """The float64 entries' bits (0.0 and -0.0 differ)."""
    return np.ascontiguousarray(v, dtype=np.float64).view(np.uint64)


def _same_step(P, new, plain, warm: bool = True) -> int:
    """One solve by each: x, level values and info bit for bit the same; returns the memo's
    hits in ``new`` (``plain`` has none)."""
    xn, rn, infon = new.solve(P, warm=warm)
    xp, rp, infop = plain.solve(P, warm=warm)
    np.testing.assert_array_equal(_bits(xn), _bits(xp))
    np.testing.assert_array_equal(_bits(rn), _bits(rp))
    assert infon == infop
    assert plain._solver.freeze_memo_hits == 0
    return new._solver.freeze_memo_hits


def _random_stack(seed: int):
    """A stack of n = 6..12 variables, 3..5 levels mixing equality levels (some rank-
    deficient, some wide) and inequality levels that bind, a box half of the time; returns
    (stack, tasks, matrices): each task's original matrix, and a second one to switch to."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(6, 13))
    tasks, mats = [], []
    for _ in range(int(rng.integers(3, 6))):
        m = int(rng.integers(1, n))
        rank = int(rng.integers(1, m + 1))
        A = rng.standard_normal((m, rank)) @ rng.standard_normal((rank, n))
        A2 = A + 0.1 * rng.standard_normal((m, n))
        if rng.random() < 0.5:
            tasks.append(qc.Equality(A, rng.standard_normal(m)))
        else:
            tasks.append(qc.Inequality(A, upper=-rng.random(m)))
        mats.append((A, A2))
    box = rng.random() < 0.5
    bounds = qc.Bounds(-np.ones(n), np.ones(n)) if box else None
    return qc.Stack(tasks, bounds=bounds), tasks, mats, rng


def _move(task, rng, A=None) -> None:
    """New targets (and matrix ``A`` if given) for an Equality or an Inequality."""
    if isinstance(task, qc.Equality):
        task.update(A=A, b=task.b + 0.3 * rng.standard_normal(task.b.shape[0]))
    else:
        m = task.C.shape[0]
        task.update(C=A, upper=-rng.random(m))


@needs_native
@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_memo_equals_the_freezes_computed_along_changing_matrices(seed):
    """Each step moves every target and, per level, keeps the matrix, switches to the other
    one or back (then the stored freeze of the first matrices may be restored: correct only
    if the memo's key holds every input): the solver with the memo equals the one without,
    bit for bit, each step, warm or cold. (Seeds 0-59 of this generator: 251 restored
    freezes in 600 steps.)"""
    stack, tasks, mats, rng = _random_stack(seed)
    P, new, plain = switch_pair(stack, "freeze_memo")
    current = [0] * len(tasks)
    for _step in range(10):
        for i, task in enumerate(tasks):
            if rng.random() < 0.3:
                current[i] = 1 - current[i]
                _move(task, rng, mats[i][current[i]])
            else:
                _move(task, rng)
        _same_step(P, new, plain, warm=bool(rng.random() < 0.8))


@needs_native
def test_memo_restores_every_freeze_of_a_re_solve_and_none_of_a_changed_stack():
    """A 30-variable chain of 3 / 3 / 6 / 6 equality rows under a binding box (the
    benchmarks' chain30): once the memo is warm (two solves per level), every freeze of a
    re-solve with moved targets is restored, bit for bit what the freezes give; a step whose
    first level's matrix changed restores none (Z differs below it)."""
    rng = np.random.default_rng(3)
    n = 30
    rows = []
    for m, upto in ((3, n), (3, 20), (6, 15), (6, n)):
        J = np.zeros((m, n))
        J[:, :upto] = rng.standard_normal((m, upto))
        rows.append(J / np.linalg.norm(J, axis=1, keepdims=True))
    tasks = [qc.Equality(J, rng.uniform(-0.5, 0.5, J.shape[0])) for J in rows]
    stack = qc.Stack(tasks, bounds=qc.Bounds(-0.5 * np.ones(n), 0.5 * np.ones(n)))
    P, new, plain = switch_pair(stack, "freeze_memo")
    base = [t.b.copy() for t in tasks]
    hits = []
    for step in range(12):
        for t, b0 in zip(tasks, base, strict=True):
            t.update(b=b0 + 0.2 * np.sin(0.05 * step + np.arange(b0.shape[0])))
        hits.append(_same_step(P, new, plain))
    assert plain._solver.wide_freezes > 0  # the binding levels' freezes
    assert hits[-1] > 0 and hits[-1] == hits[-2]  # every freeze of the warm re-solve
    tasks[0].update(A=rows[0] + 1e-3 * rng.standard_normal(rows[0].shape))
    assert _same_step(P, new, plain) == 0


@needs_native
@pytest.mark.parametrize("unit", [False, True], ids=["rows", "unit rows"])
def test_memo_on_the_moving_published_humanoid(unit):
    """The LexLS humanoid moved as hierarchy_published's re-solve table (targets only): bit
    for bit the freezes' results, and restored freezes from the third step on."""
    st_, move = published_stack("lexls_test01_humanoid", False, unit)
    P, new, plain = switch_pair(st_, "freeze_memo")
    hits = []
    for step in range(5):
        move(step)
        hits.append(_same_step(P, new, plain))
    assert hits[-1] > 0


@needs_native
def test_memo_switch_and_counter_are_exposed():
    """``freeze_memo`` is on by default, settable, and its counter is 0 before any solve."""
    stack = qc.Stack([qc.Equality(np.eye(3)[:2], np.ones(2)), qc.Equality(np.eye(3), np.zeros(3))])
    P, new, plain = switch_pair(stack, "freeze_memo")
    assert new._solver.freeze_memo and not plain._solver.freeze_memo
    assert new._solver.freeze_memo_hits == 0
