"""The native engine's warm re-solve of many levels.

A warm call first tries each stage's stored working set, at a cost kept low without changing
what it decides:

* of the objective in the working set's QR basis (Q Qf) only the columns the least-squares
  step reads are formed (none when the working set pins the point);
* a level whose own inequality rows carry slack columns is tried in z alone, each working
  slack row's slack eliminated (its objective term a row in z), the other slacks zero, the
  slack rows' multipliers read off their slack columns (``Stats.reduced_trials``);
* the inherited rows' projection C Z is carried from level to level through the orthogonal
  transforms that shrink Z (a row is projected once, when inherited).

Each test runs changing data against the Python engine (level values 1e-9 relative, x to
1e-7 where it is unique), and checks that the trials hit.
"""

from __future__ import annotations

import numpy as np
import pytest
from support.hlsp import load
from test_native import published_module

import qpcoord as qc
from qpcoord.core import native

X_TOL = 1e-7

needs_native = pytest.mark.skipif(
    not native.available(),
    reason=f"the native engine (qpcoord._native) is not built: {native._load_error}",
)


def _solver(P, damping: float):
    from qpcoord.core.native import NativeHierarchy

    return NativeHierarchy(P, damping)


def _check(stack: qc.Stack, xn, rn, unique: bool = True) -> None:
    sp = stack.solve(engine="python")
    np.testing.assert_allclose(rn, sp.level_residuals, rtol=1e-9, atol=1e-10)
    if unique:
        scale = max(1.0, float(np.max(np.abs(sp.x))))
        assert np.max(np.abs(xn - sp.x)) <= X_TOL * scale


def _moving_soth(steps: int):
    """soth_sot (30 variables: 30 joint-limit rows as level 0, then 3 / 3 / 6 / 6 equality
    rows), every right-hand side moved as hierarchy_published.py's re-solve table does."""
    hp = published_module()

    prob = load("soth_sot")
    stack = qc.Stack(prob.levels, bounds=prob.bounds)
    return stack, hp._mover(prob.levels)


@needs_native
def test_soth_warm_trial_equals_the_full_trial_and_python():
    """soth_sot over moving targets: every stage is a warm hit after the first call (level
    0's slack rows tried in z alone; the equality levels pinned by their inherited rows,
    where the trial forms no Q Qf), the Python engine's answer."""
    stack, move = _moving_soth(12)
    P = stack._compiled
    new = _solver(P, stack.damping)
    hits_new = 0
    for step in range(12):
        move(step)
        xn, rn, info_n = new.solve(P)
        _check(stack, xn, rn)
        assert new.counters.reduced_trials == (1 if step else 0)  # level 0's 30 rows
        if step:
            hits_new += info_n["warm_start_hits"]
    levels = len(P.levels)
    # the level stages and the minimum-norm step: all warm hits (the hard phase is empty)
    assert hits_new >= 11 * (levels + 1) - 2


@needs_native
def test_an_unchanged_stack_hits_every_stage_with_the_reduced_trial():
    """The same numbers twice: the second call's trial hits every stage that ran an active
    set, and returns the first call's x."""
    stack, move = _moving_soth(1)
    move(0)
    P = stack._compiled
    new = _solver(P, stack.damping)
    x1, _, info1 = new.solve(P)
    x2, _, info2 = new.solve(P)
    ran = sum(
        1
        for it in [
            info1["hard_iterations"],
            *info1["active_set_iterations"],
            info1["min_norm_iterations"],
        ]
        if it
    )
    assert info2["warm_start_hits"] == ran > 0
    assert np.max(np.abs(x1 - x2)) <= 1e-12 * max(1.0, float(np.max(np.abs(x1))))


def _conflicting_stack(seed: int, n: int = 12):
    """Inequality levels that conflict with each other and with the box (slack rows and
    inherited rows in one trial), weighted rows, equality rows beside them."""
    rng = np.random.default_rng(seed)
    levels, ineqs = [], []
    for k in range(4):
        C = rng.standard_normal((6, n))
        C /= np.linalg.norm(C, axis=1)[:, None]
        lo = rng.uniform(0.3, 0.9, 6)
        kw = {"weight": rng.uniform(0.5, 3.0, 6)} if k % 2 else {}
        ineq = qc.Inequality(C, lo, lo + 0.2, **kw)
        ineqs.append(ineq)
        if k == 2:
            levels.append([qc.Equality(rng.standard_normal((2, n)), rng.standard_normal(2)), ineq])
        else:
            levels.append(ineq)
    levels.append(qc.Equality(rng.standard_normal((3, n)), rng.standard_normal(3)))
    stack = qc.Stack(levels, bounds=qc.Bounds(-0.6 * np.ones(n), 0.6 * np.ones(n)))
    return stack, ineqs


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_changing_inherited_rows_and_slack_rows_match_the_full_trial(seed):
    """Conflicting, weighted inequality levels over the box whose bounds move every call
    (the rows a level inherits change between calls; some stored sets hit, some miss and
    seed): the reduced trial equals the Python engine at every step, and hits."""
    stack, ineqs = _conflicting_stack(seed)
    P = stack._compiled
    new = _solver(P, stack.damping)
    base = [(t.lower.copy(), t.upper.copy()) for t in ineqs]
    hits_new = reduced = 0
    for step in range(15):
        for j, (t, (lo, hi)) in enumerate(zip(ineqs, base, strict=True)):
            d = 0.15 * np.sin(0.4 * step + j + np.arange(lo.size))
            t.update(lower=lo + d, upper=hi + d)
        xn, rn, info_n = new.solve(P)
        _check(stack, xn, rn)
        hits_new += info_n["warm_start_hits"]
        reduced += new.counters.reduced_trials
    assert hits_new > 0
    assert reduced >= 14  # from the second call on, at least one level per call


@needs_native
def test_reduced_trial_with_rows_the_equalities_fix():
    """A level whose inequality rows sit beside equality rows and hard rows held at their
    value (lo = hi inherited rows in every working set): the reduced trial's point on them
    equals Python's over moving targets."""
    rng = np.random.default_rng(7)
    n = 10
    Ch = rng.standard_normal((2, n))
    hard = qc.Inequality(Ch, np.zeros(2), np.zeros(2))  # rows held at 0
    C = rng.standard_normal((5, n))
    ineq = qc.Inequality(C, np.full(5, 0.5), np.full(5, 1.0), weight=rng.uniform(1, 2, 5))
    eq = qc.Equality(rng.standard_normal((2, n)), rng.standard_normal(2))
    post = qc.Equality(np.eye(n), np.zeros(n))
    stack = qc.Stack(
        [[eq, ineq], post], bounds=qc.Bounds(-np.ones(n), np.ones(n)), constraints=[hard]
    )
    P = stack._compiled
    new = _solver(P, stack.damping)
    b0, lo0 = eq.b.copy(), ineq.lower.copy()
    reduced = 0
    for step in range(10):
        eq.update(b=b0 + 0.3 * np.sin(0.5 * step + np.arange(2)))
        ineq.update(lower=lo0 + 0.1 * np.cos(0.3 * step + np.arange(5)), upper=np.full(5, 1.0))
        xn, rn, _ = new.solve(P)
        _check(stack, xn, rn)
        reduced += new.counters.reduced_trials
    assert reduced > 0
