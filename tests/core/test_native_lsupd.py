"""The native active set's least-squares step by the slack structure.

A level's least squares runs in ``y = (z, w)``, one slack per inequality row. A slack whose
row is outside the working set appears in its own objective row only (``sw_i w_i``): the
step takes it to zero in closed form, and the rest of the step, on ``z`` and the slacks of
the working rows, is the minimum-norm solution of a small system (one QR of its transpose)
when that system has full row rank, instead of the QR of the projected objective on all of
``y`` (the LexLS humanoid's level 0, 72 rows). Every step here equals the Python engine
(level values 1e-9 relative, x where unique), and the slack step was taken
(``Stats.slack_steps``).
"""

from __future__ import annotations

import importlib.util
import subprocess
from pathlib import Path

import numpy as np
import pytest
from support.hlsp import load
from test_native import (
    LEVEL_TOL,
    X_TOL,
    _conflict_scenario,
    _hard_random_stack,
    native_solver,
    needs_native,
    published_module,
    published_stack,
)

import qpcoord as qc


def _check(stack, P, h, unique_x: bool = True) -> tuple[int, int]:
    """Solve natively and with the Python engine; compare; return (slack steps,
    iterations)."""
    xn, rn, info = h.solve(P)
    steps = h.counters.slack_steps
    sp = stack.solve(engine="python")
    ref = sp.level_residuals
    assert np.all(np.abs(rn - ref) <= LEVEL_TOL * np.maximum(1.0, ref)), (rn, ref)
    scale = max(1.0, float(np.max(np.abs(sp.x))))
    if unique_x:
        assert np.max(np.abs(xn - sp.x)) <= X_TOL * scale
    return steps, int(np.sum(info["active_set_iterations"]))


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_conflicting_rows_many_iterations_equal_python(seed):
    """Levels of conflicting unit inequality rows beside a few equality rows, warm over
    moving bounds (misses, seeded starts, rows entering and leaving): the slack step is
    taken at many iterations and every step equals the Python engine."""
    st = _hard_random_stack(seed, n=30, levels=6)
    P, h = native_solver(st)
    ineqs = [t for lev in st.levels for t in lev if isinstance(t, qc.Inequality)]
    total = iters = 0
    for step in range(8):
        for j, t in enumerate(ineqs):
            shift = 0.05 * np.sin(0.7 * step + j)
            t.update(lower=t.lower + shift, upper=t.upper + shift)
        s, it = _check(st, P, h)
        total += s
        iters += it
    assert iters >= 20  # the active set works (not only warm hits)
    assert total >= 10


@needs_native
@pytest.mark.parametrize("seed", [0, 1])
def test_degenerate_rows_and_zero_weights(seed):
    """Degenerate working sets: duplicated and opposite rows (dependent rows of G_w: the
    general path), row weights from 1e-8 to 1e4 (slack columns of very different scale), a
    level whose equality rows are rank-deficient, tight boxes: equal to the Python engine,
    and the slack step still taken where it applies."""
    rng = np.random.default_rng(seed)
    n = 12
    C = rng.standard_normal((8, n))
    C = np.vstack([C, C[:3], -C[3:5]])  # duplicates and opposite rows
    C /= np.linalg.norm(C, axis=1)[:, None]
    lo = rng.uniform(0.3, 0.8, C.shape[0])
    w = np.ones(C.shape[0])
    w[[1, 9]] = 1e-8  # the row may be violated almost at no cost
    w[[2, 6]] = 1e4
    rank2 = rng.standard_normal((5, 2)) @ rng.standard_normal((2, n))
    ineq = qc.Inequality(C, lo, np.full(C.shape[0], np.inf), weight=w)
    eq = qc.Equality(rank2, rng.standard_normal(5))
    low = qc.Inequality(rng.standard_normal((6, n)), -np.ones(6) * 0.2, np.ones(6) * 0.2)
    st = qc.Stack([[ineq, eq], low], bounds=qc.Bounds(-0.6 * np.ones(n), 0.6 * np.ones(n)))
    P, h = native_solver(st)
    lo0 = lo.copy()
    total = 0
    for step in range(8):
        ineq.update(lower=lo0 + 0.2 * np.sin(0.9 * step + np.arange(lo0.size)))
        s, _ = _check(st, P, h, unique_x=False)
        total += s
    assert total > 0


@needs_native
@pytest.mark.parametrize("box", [False, True], ids=["rows", "box"])
def test_moving_humanoid_equals_python(box):
    """The LexLS humanoid (88 variables, 5 levels; level 0: 72 inequality rows) moved as
    hierarchy_published's re-solve table: level values equal the Python engine's. The slack step is
    taken at level 0's warm trials and iterations; the box form's level 0 rows are bounds (no slack
    reaches its active sets: only equal)."""
    st, move = published_stack("lexls_test01_humanoid", box)
    P, h = native_solver(st)
    total = 0
    for step in range(6):
        move(step)
        s, _ = _check(st, P, h, unique_x=False)
        total += s
    assert (total == 0) if box else (total > 0)


@pytest.mark.engine_independent
@needs_native
def test_the_slack_step_allocates_nothing(tmp_path, hierarchy_driver):
    """The C++ driver (counts malloc; src/native/tools/driver.cpp) on the moving humanoid
    and conflicting levels, warm and cold: no heap allocation after the first pass (the
    slack step runs on these problems: the tests above)."""
    root = Path(__file__).resolve().parents[2]
    tools = root / "src" / "native" / "tools"
    spec = importlib.util.spec_from_file_location("dump_problems", tools / "dump_problems.py")
    dp = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(dp)
    dp.dump_stack("humanoid", *dp.published("humanoid"), 6, tmp_path)
    dp.dump("conflict", _conflict_scenario, 10, tmp_path)
    exe = hierarchy_driver
    for name in ("humanoid", "conflict"):
        for mode in ("warm", "cold"):
            out = subprocess.run(
                [str(exe), str(tmp_path / f"{name}.bin"), "2", mode],
                capture_output=True, text=True, timeout=300,
            )  # fmt: skip
            assert out.returncode == 0, (name, mode, out.stderr)
            assert "allocations after the first pass 0" in out.stdout, (name, mode, out.stdout)


@needs_native
@pytest.mark.parametrize("case", ["humanoid", "ill_conditioned"])
def test_exact_finish_of_an_ill_conditioned_level_equals_python(case):
    """An ill-conditioned level is finished to rounding (a second active set right after the
    first ended optimal, started from that end's factorisation and last step): the Python
    engine's level values, and the same numbers, bit for bit, when every cached
    factorisation is dropped before the call. Cases: the moving humanoid (its level 4:
    sigma_min / |A| ~ 5e-5) and a random ill-conditioned equality level under conflicting
    inequality rows."""
    from qpcoord.core.native import NativeHierarchy

    if case == "humanoid":
        hp = published_module()
        prob = load("lexls_test01_humanoid")
        st = qc.Stack(prob.levels, bounds=prob.bounds)
        mover = hp._mover(prob.levels)
    else:
        rng = np.random.default_rng(5)
        n = 20
        U, _ = np.linalg.qr(rng.standard_normal((30, n)))
        V, _ = np.linalg.qr(rng.standard_normal((n, n)))
        A = U @ np.diag(np.logspace(0, -5, n)) @ V.T  # sigma_min / sigma_max = 1e-5
        C = rng.standard_normal((12, n))
        C /= np.linalg.norm(C, axis=1)[:, None]
        ineq = qc.Inequality(C, rng.uniform(0.2, 0.6, 12), np.full(12, np.inf))
        eq = qc.Equality(A, rng.standard_normal(30))
        st = qc.Stack([ineq, eq], bounds=qc.Bounds(-np.ones(n), np.ones(n)))
        lo0 = ineq.lower.copy()

        def mover(step: int) -> None:
            ineq.update(lower=lo0 + 0.1 * np.sin(0.6 * step + np.arange(12)))

    P = st._compiled
    new = NativeHierarchy(P, st.damping)
    plain = NativeHierarchy(P, st.damping)
    for step in range(5):
        mover(step)
        xn, rn, _ = new.solve(P)
        plain._solver.invalidate_caches()
        xp, rp, _ = plain.solve(P)
        assert np.array_equal(xn, xp) and np.array_equal(rn, rp)
        ref = st.solve(engine="python").level_residuals
        assert np.all(np.abs(rn - ref) <= LEVEL_TOL * np.maximum(1.0, ref)), (rn, ref)
