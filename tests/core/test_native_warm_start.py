"""The native engine's warm start: a re-solve from the stored working sets gives the cold
answer and the Python engine's.

A warm call first tries each stage's stored working set (a hit when it is still optimal):
over moving targets every warm answer equals a cold solve's; an unchanged stack hits every
stage; moving bounds make rows leave the working sets, whose QR is then downdated (Givens)
instead of refactorised. The trial is cheap without changing what it decides: of the
objective in the working set's QR basis only the columns the least-squares step reads are
formed, and a level whose own inequality rows carry slack columns is tried in ``z`` alone.
"""

from __future__ import annotations

import numpy as np
import pytest
from support.families import build, stack
from support.hlsp import load
from support.native_engine import X_TOL, assert_same, needs_native
from support.published import published_module
from support.stacks import hard_random_stack, inequality_shifts

import qpcoord as qc


@needs_native
def test_warm_start_gives_the_cold_answer():
    """A moving target over 30 steps: each warm re-solve equals a fresh (cold) stack's."""
    spec = build("mixed_levels", 1)
    warm = stack(spec)
    hits = 0
    rng = np.random.default_rng(3)
    eq = spec["levels"][2]
    for _ in range(30):
        eq.update(b=np.clip(eq.b + 0.02 * rng.standard_normal(eq.b.shape[0]), -1, 1))
        sw = warm.solve(engine="native")
        sc = stack(spec).solve(engine="native")
        sp = stack(spec).solve(engine="python")
        assert_same(sp, sw)
        assert_same(sc, sw)
        hits += sw.info["warm_start_hits"]
    assert hits > 0  # the stored working sets were optimal at least once


@needs_native
def test_repeated_solve_is_a_warm_hit():
    s = stack(build("inequality_levels", 0))
    first = s.solve(engine="native")
    second = s.solve(engine="native")
    assert first.info["warm_start_hits"] == 0
    assert second.info["warm_start_hits"] >= 1
    np.testing.assert_allclose(second.x, first.x, atol=1e-12)


@needs_native
@pytest.mark.parametrize("box", [True, False], ids=["box", "published"])
def test_unchanged_humanoid_is_a_warm_hit(box):
    """The LexLS humanoid solved again unchanged: every stage the active set solves is a
    warm hit (its stored working set kept the equality rows lo = hi of the stage, which the
    stored set does not list: without it the box form missed at two levels on every call),
    and x is the cold solve's and the Python engine's. (The cold call finishes its
    minimum-norm stage: the active set takes a step that gains under 1e-15 of a large
    objective but is no rounding, tests/core/test_talos_joint_limit_oracle.py; stopped short,
    the first warm call would reseed that stage.)"""
    P = load("lexls_test01_humanoid", simple_as_bounds=box)
    s = qc.Stack(P.levels, bounds=P.bounds)
    cold = s.solve(engine="native")
    warm = s.solve(engine="native")
    info = warm.info
    assert cold.info["warm_start_hits"] == 0 and cold.info["qp_calls"] > 0
    assert info["warm_start_hits"] == info["qp_calls"] == cold.info["qp_calls"]
    assert info["warm_start_seeded"] == 0
    assert info["hard_iterations"] == 0 and info["min_norm_iterations"] == 0
    # the one level left with iterations is the exact finish of an ill-conditioned level
    # (run after a hit too): a refinement step, not a search
    assert sum(info["active_set_iterations"]) <= 2
    np.testing.assert_allclose(warm.x, cold.x, rtol=0, atol=1e-9)
    sp = s.solve(engine="python")
    scale = max(1.0, float(np.max(np.abs(sp.x))))
    np.testing.assert_allclose(warm.x, sp.x, rtol=0, atol=1e-9 * scale)
    ref = np.asarray(sp.level_residuals)
    gap = np.abs(np.asarray(warm.level_residuals) - ref) / np.maximum(1.0, ref)
    assert gap.max() <= 1e-9


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_downdated_working_sets_give_the_cold_answer(seed):
    """Moving bounds make rows leave the working sets during warm solves; the QR of the
    working set is then downdated (Givens) instead of refactorised. Every step's answer
    equals the refactorising solver's, a cold solve's and the Python engine's (level values
    to 1e-9 relative, x to 1e-9), and downdates did happen."""
    from qpcoord.core.native import NativeHierarchy

    s = hard_random_stack(seed, n=30, levels=6)
    P = s._compiled
    down = NativeHierarchy(P, s.damping)
    cold = NativeHierarchy(P, s.damping)
    move = inequality_shifts(s)
    used = 0
    for step in range(12):
        move(step)
        xd, rd, _ = down.solve(P)
        used += down.counters.downdates
        xc, rc, _ = cold.solve(P, warm=False)
        ref = s.solve(engine="python")
        for r in (rd, rc):
            np.testing.assert_allclose(r, ref.level_residuals, rtol=1e-9, atol=1e-10)
        scale = max(1.0, float(np.max(np.abs(xc))))
        assert np.max(np.abs(xd - xc)) <= 1e-9 * scale
        assert np.max(np.abs(xd - ref.x)) <= X_TOL * scale
    assert used > 0


def _new_solver(P, damping: float):
    from qpcoord.core.native import NativeHierarchy

    return NativeHierarchy(P, damping)


def _same_as_python(stack: qc.Stack, xn, rn, unique: bool = True) -> None:
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
    new = _new_solver(P, stack.damping)
    hits_new = 0
    for step in range(12):
        move(step)
        xn, rn, info_n = new.solve(P)
        _same_as_python(stack, xn, rn)
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
    new = _new_solver(P, stack.damping)
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
    new = _new_solver(P, stack.damping)
    base = [(t.lower.copy(), t.upper.copy()) for t in ineqs]
    hits_new = reduced = 0
    for step in range(15):
        for j, (t, (lo, hi)) in enumerate(zip(ineqs, base, strict=True)):
            d = 0.15 * np.sin(0.4 * step + j + np.arange(lo.size))
            t.update(lower=lo + d, upper=hi + d)
        xn, rn, info_n = new.solve(P)
        _same_as_python(stack, xn, rn)
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
    new = _new_solver(P, stack.damping)
    b0, lo0 = eq.b.copy(), ineq.lower.copy()
    reduced = 0
    for step in range(10):
        eq.update(b=b0 + 0.3 * np.sin(0.5 * step + np.arange(2)))
        ineq.update(lower=lo0 + 0.1 * np.cos(0.3 * step + np.arange(5)), upper=np.full(5, 1.0))
        xn, rn, _ = new.solve(P)
        _same_as_python(stack, xn, rn)
        reduced += new.counters.reduced_trials
    assert reduced > 0
