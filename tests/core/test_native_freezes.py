"""The freeze after a level: its shortcuts equal the general freeze and the Python engine.

A level whose equalities have full column rank in the remaining freedom and which leaves no
violated row has no freedom left (``r <- 0`` directly); a wide level whose active set ends with
no violated row is frozen from the QR of its rows (``Stats.wide_freezes``); a level that leaves
violated rows takes the general freeze. A change of ``Z`` by many rows is applied in the compact
WY form (the x86-64-v3 build, FMA: ``Stats.wy_applications``); a level 0 without hard rows
starts from ``Z = I`` (its products are copies: ``Stats.identity_products``). Each build
(baseline, x86-64-v3 where the CPU runs it) takes its paths. Every test compares with the
Python engine (level values ``LEVEL_TOL`` relative, x where unique).
"""

from __future__ import annotations

import numpy as np
import pytest
from support.hlsp import load
from support.native_engine import LEVEL_TOL, native_solver, needs_native, path_check
from support.published import published_module

import qpcoord as qc
from qpcoord.core import native

#: each shortcut's counter (``Stats``)
COUNTER = {"full_rank": "full_rank_freezes", "wide": "wide_freezes"}


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
        total += path_check(st, P, h, COUNTER[switch], True)[0]
    assert total >= 6


@needs_native
@pytest.mark.parametrize("switch", ["full_rank", "wide"])
def test_violated_rows_beside_a_wide_or_full_rank_level_take_the_general_freeze(switch):
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
@pytest.mark.parametrize("variant", ["baseline", "x86-64-v3"])
@pytest.mark.parametrize("switch", ["full_rank", "wide"])
def test_each_build_takes_the_shortcuts_on_the_arm(monkeypatch, variant, switch):
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
        total += path_check(st, P, h, COUNTER[switch], True)[0]
    assert total >= 4


def _fma() -> bool:
    """The loaded extension is the x86-64-v3 build (FMA: the WY form of the changes of Z)."""
    return native.load().ISA == "x86-64-v3"


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("rows", [15, 16, 18, 20], ids=lambda r: f"{r} rows")
def test_wide_levels_under_inherited_rows_by_wy(seed, rows):
    """An inequality level of 30 rows over 64 variables (its rows inherited: the carried
    projection), then wide equality levels of 15-20 rows (16 and more: the WY form on Z and
    on Cin Z in the FMA build; 15: the loop), then a last level: x is unique and equals the
    Python engine's over changing targets."""
    rng = np.random.default_rng(seed)
    n = 64
    C = rng.standard_normal((30, n))
    C /= np.linalg.norm(C, axis=1)[:, None]
    lo0 = rng.uniform(-1.0, -0.2, 30)
    ineq = qc.Inequality(C, lo0, np.full(30, np.inf))
    e1 = qc.Equality(rng.standard_normal((rows, n)), rng.standard_normal(rows))
    e2 = qc.Equality(rng.standard_normal((rows, n)), rng.standard_normal(rows))
    last = qc.Equality(rng.standard_normal((n, n)), rng.standard_normal(n))
    st = qc.Stack([ineq, e1, e2, last], bounds=qc.Bounds(-5 * np.ones(n), 5 * np.ones(n)))
    P, h = native_solver(st)
    b1 = e1.b.copy()
    total = 0
    for step in range(4):
        ineq.update(lower=lo0 + 0.3 * np.sin(0.7 * step + np.arange(30)))
        e1.update(b=b1 + 0.2 * np.cos(step + np.arange(rows)))
        total += path_check(st, P, h, "wy_applications", True)[0]
    assert (total > 0) == (rows >= 16 and _fma())


@needs_native
@pytest.mark.parametrize("variant", ["baseline", "x86-64-v3"])
@pytest.mark.parametrize("counter", ["null_space_freezes", "wy_applications"])
def test_each_build_takes_the_freezes_of_the_humanoid(monkeypatch, variant, counter):
    """Each build (baseline, x86-64-v3 where this CPU runs it) on the moving humanoid: the
    null-space freeze is taken by both, the WY form by the x86-64-v3 build only (FMA), and
    the level values equal the Python engine's (the builds round differently)."""
    try:
        mod = native.import_variant(variant)
    except (native.NativeUnavailableError, ValueError):
        pytest.skip(f"no {variant} build on this machine")
    monkeypatch.setattr(native, "_module", mod)
    hp = published_module()
    prob = load("lexls_test01_humanoid")
    st = qc.Stack(prob.levels, bounds=prob.bounds)
    P, h = native_solver(st)
    assert type(h._solver).__module__ == mod.__name__
    move = hp._mover(prob.levels)
    total = 0
    for step in range(3):
        move(step)
        total += path_check(st, P, h, counter, False)[0]
    if counter == "wy_applications" and variant == "baseline":
        assert total == 0
    else:
        assert total >= 3


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
        total += path_check(st, P, h, "identity_products", True)[0]
    assert (total == 0) if hard else (total >= 5)
