"""Hygiene of the core: quiet backends, bounded solve time, no
non-finite number reaching a backend, read-only task data, clear errors on bad input.

Each test here failed before the change it guards (the message or behaviour it replaced is
quoted in its docstring).
"""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from conftest import SOLVERS
from support.arrays import force_write

import qpcoord as qc
from qpcoord.core import backends
from qpcoord.core.backends import DEFAULT_TIME_LIMIT, deadline, solve_dense_qp


def _stack(seed: int = 0):
    """Three levels (equality, soft inequality, posture), a hard row and bounds."""
    rng = np.random.default_rng(seed)
    n = 6
    eq = qc.Equality(rng.standard_normal((3, n)), rng.standard_normal(3), name="track")
    band = qc.Inequality(rng.standard_normal((2, n)), lower=-0.1, upper=0.1, name="band")
    post = qc.Equality(np.eye(n), np.zeros(n), name="posture")
    hard = qc.Inequality(np.ones((1, n)), upper=1.0, name="hard")
    bounds = qc.Bounds(-0.3 * np.ones(n), 0.3 * np.ones(n), name="box")
    tasks = dict(eq=eq, band=band, post=post, hard=hard, bounds=bounds)
    return qc.Stack([eq, band, post], bounds=bounds, constraints=[hard]), tasks


# --------------------------------------------------------------------------------------
# 1. quiet
# --------------------------------------------------------------------------------------


def test_solves_write_nothing_to_stdout_or_stderr(capfd, solver):
    """HiGHS printed its banner and OSQP "Polishing not needed - no active set detected"."""
    capfd.readouterr()
    for method in ("hierarchical", "weighted"):
        _stack()[0].solve(solver=solver, method=method)
        # no constraint active at the optimum: OSQP's polishing printed here
        A = np.eye(3)
        qc.Stack([qc.Equality(A[:2], np.ones(2)), qc.Inequality(np.ones((1, 3)), upper=100)]).solve(
            solver=solver, method=method
        )
    out, err = capfd.readouterr()
    assert out == "" and err == ""


def test_a_fresh_process_prints_nothing_on_any_backend():
    """The HiGHS banner is printed once per process, by the first HiGHS object: only a fresh
    interpreter shows it."""
    code = textwrap.dedent(
        """
        import numpy as np, qpcoord as qc
        for s in qc.available_solvers():
            for m in ("hierarchical", "weighted"):
                qc.Stack([qc.Equality(np.eye(3)[:2], np.ones(2)),
                          qc.Inequality(np.ones((1, 3)), upper=100)],
                         bounds=qc.Bounds(-5, 5)).solve(solver=s, method=m)
        """
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout == "" and res.stderr == ""


# --------------------------------------------------------------------------------------
# 2. bounded time
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), "1", True])
def test_time_limit_is_validated(bad):
    with pytest.raises(ValueError, match="time_limit"):
        _stack()[0].solve(time_limit=bad)


def test_default_and_infinite_time_limit(monkeypatch):
    """Every solve runs under a deadline unless the caller lifts it with ``math.inf``."""
    seen = []
    real = backends._DIRECT["daqp"]

    def spy(*args):
        seen.append(backends._DEADLINE.get())
        return real(*args)

    monkeypatch.setitem(backends._DIRECT, "daqp", spy)
    stack = _stack()[0]
    t0 = time.perf_counter()
    stack.solve(solver="daqp")
    assert seen and all(t0 < at <= t0 + DEFAULT_TIME_LIMIT + 1 for at in seen)
    seen.clear()
    stack.solve(solver="daqp", time_limit=math.inf)
    assert seen and all(at is None for at in seen)
    assert backends._DEADLINE.get() is None  # reset after the solve


def test_nested_deadlines_keep_the_earlier():
    with deadline(1.0) as outer:
        with deadline(100.0) as inner:
            assert inner.at == outer.at
        with deadline(0.5) as inner:
            assert inner.at < outer.at
    assert backends._DEADLINE.get() is None


@pytest.mark.parametrize("solver_name", SOLVERS)
def test_no_qp_starts_after_the_deadline(solver_name):
    H, f = np.eye(3), np.ones(3)
    G, lo, hi = np.ones((1, 3)), np.array([-1.0]), np.array([1.0])
    with deadline(1e-9):
        time.sleep(1e-3)
        res = solve_dense_qp(solver_name, H, f, G, lo, hi)
    assert res.code == backends.FAILED and "time limit" in res.message


def test_time_limit_bounds_the_fallback_chain(monkeypatch):
    """A backend that uses up the time and fails: the fallbacks (quadprog, daqp, proxqp --
    proxqp once ran 72 s in C code) are not started, and the error says why."""

    def slow_failure(H, f, G, lo, hi, lb, ub, y0):
        time.sleep(0.3)
        return backends.QPResult(None, backends.FAILED, "daqp exitflag -5")

    monkeypatch.setitem(backends._DIRECT, "daqp", slow_failure)
    stack = _stack()[0]
    t0 = time.perf_counter()
    with pytest.raises(qc.SolverError, match=r"time limit of 0\.2 s reached"):
        stack.solve(solver="daqp", method="weighted", time_limit=0.2)
    assert time.perf_counter() - t0 < 0.6  # one slow call, nothing after it


def _big_qp(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    M = rng.standard_normal((n, n))
    H = M.T @ M / n + 1e-3 * np.eye(n)
    G = rng.standard_normal((n, n))
    return H, 10 * rng.standard_normal(n), G, np.full(n, -np.inf), rng.random(n)


def test_quadprog_is_not_started_when_it_cannot_end_in_time():
    """quadprog cannot be interrupted (10.7 s on n = m = 1600, measured)."""
    H, f, G, lo, hi = _big_qp(1500)
    t0 = time.perf_counter()
    with deadline(0.5):
        res = solve_dense_qp("quadprog", H, f, G, lo, hi)
    assert time.perf_counter() - t0 < 0.1
    assert res.code == backends.FAILED and "cannot be interrupted" in res.message


def test_proxqp_runs_in_chunks_under_a_deadline():
    """proxqp has no time limit: its iterations are chunked to the time left."""
    H, f, G, lo, hi = _big_qp(400)
    with deadline(math.inf):
        free = solve_dense_qp("proxqp", H, f, G, lo, hi)
    t0 = time.perf_counter()
    with deadline(30.0):  # generous: one chunk, same answer
        res = solve_dense_qp("proxqp", H, f, G, lo, hi)
    assert res.code == backends.OK and np.abs(res.y - free.y).max() < 1e-8
    with deadline(0.02):
        t0 = time.perf_counter()
        res = solve_dense_qp("proxqp", H, f, G, lo, hi)
    # the set-up (a factorisation) is not interruptible; the iterations are
    assert time.perf_counter() - t0 < 0.5


@pytest.mark.parametrize("solver_name", ["daqp", "highs", "osqp", "clarabel", "scs"])
def test_backends_get_the_time_left(solver_name, monkeypatch):
    """The time left reaches the backend's own time-limit setting."""
    if solver_name not in SOLVERS:
        pytest.skip(f"{solver_name} not installed")
    got = {}
    if solver_name == "daqp":
        import daqp

        real = daqp.solve

        def spy(*args, **kwargs):
            got["limit"] = kwargs.get("time_limit")
            return real(*args, **kwargs)

        monkeypatch.setattr(daqp, "solve", spy)
    else:
        import qpsolvers

        real = qpsolvers.solve_problem

        def spy(*args, **kwargs):
            got["limit"] = kwargs.get(backends._TIME_OPTION[solver_name])
            return real(*args, **kwargs)

        monkeypatch.setattr(qpsolvers, "solve_problem", spy)
    H, f = np.eye(3), np.ones(3)
    G, lo, hi = np.ones((1, 3)), np.array([-1.0]), np.array([1.0])
    with deadline(0.75):
        res = solve_dense_qp(solver_name, H, f, G, lo, hi)
    assert res.code == backends.OK
    assert 0 < got["limit"] <= 0.75


# --------------------------------------------------------------------------------------
# 3. NaN/inf never reaches a backend
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["hierarchical", "weighted"])
@pytest.mark.parametrize(
    "which, attr, message",
    [
        ("eq", "b", r"Equality 'track': b contains nan at index 0"),
        ("eq", "A", r"Equality 'track': A contains nan at row 0, column 0"),
        ("band", "lower", r"Inequality 'band': lower contains nan at index 0"),
        ("band", "C", r"Inequality 'band': C contains inf at row 0, column 0"),
        ("hard", "upper", r"Inequality 'hard': upper contains nan at index 0"),
        ("bounds", "lower", r"Bounds 'box': lower contains nan at index 0"),
    ],
)
def test_nonfinite_data_written_behind_the_task_is_caught_at_solve_time(
    which, attr, message, method, monkeypatch
):
    """Before: "the closed-form solution is not finite" naming no task, or a backend's
    non-finite answer (proxqp ran for minutes on a NaN written into Bounds.lower)."""
    stack, tasks = _stack()
    stack.solve(method=method)
    arr = getattr(tasks[which], attr)
    value = np.inf if attr == "C" else np.nan
    force_write(arr, (0, 0) if arr.ndim == 2 else 0, value)

    def never(*args, **kwargs):
        raise AssertionError("a backend was called with non-finite data")

    monkeypatch.setattr(backends, "_DIRECT", {})
    monkeypatch.setattr(backends, "_solve_generic", never)
    with pytest.raises(ValueError, match=message + r".*found at solve time"):
        stack.solve(method=method)


def test_persistent_theta_is_checked():
    """Before: a NaN in θ ran proxqp for 72 s then raised SolverError; a wrong length gave
    numpy's matmul message."""
    t = qc.Equality(np.eye(2), np.ones(2), name="target")
    pq = qc.Stack([t], bounds=qc.Bounds(-1, 1)).persistent()
    pq.parametrize(2, {t: (np.zeros(2), np.eye(2))})
    np.testing.assert_allclose(pq.solve_theta(np.array([0.5, 2.0])), [0.5, 1.0], atol=1e-9)
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=r"solve_theta: theta\[1\] = nan is not finite"):
        pq.solve_theta(np.array([0.5, np.nan]))
    with pytest.raises(ValueError, match=r"solve_theta: theta\[0\] = inf is not finite"):
        pq.solve_theta(np.array([np.inf, 0.0]))
    with pytest.raises(ValueError, match=r"theta must have shape \(2,\).*got \(3,\)"):
        pq.solve_theta(np.ones(3))
    with pytest.raises(TypeError, match="theta is complex"):
        pq.solve_theta(np.ones(2) * 1j)
    with pytest.raises(ValueError, match=r"write_tasks: theta\[0\] = nan"):
        pq.write_tasks(np.array([np.nan, 0.0]))
    assert time.perf_counter() - t0 < 1.0
    np.testing.assert_allclose(pq.solve_theta(np.array([0.25, 0.0])), [0.25, 0.0], atol=1e-9)


# --------------------------------------------------------------------------------------
# 4. in-place writes: one rule
# --------------------------------------------------------------------------------------


def test_task_arrays_are_read_only():
    """Before: PersistentQP ignored an in-place write to task.A (its answer 0.68 off a
    fresh solve); an inf written in place returned x = 0 with residuals [nan, 0]."""
    stack, tasks = _stack()
    arrays = [
        tasks["eq"].A,
        tasks["eq"].b,
        tasks["eq"].weight,
        tasks["eq"].sqrt_weight,
        tasks["band"].C,
        tasks["band"].lower,
        tasks["band"].upper,
        tasks["bounds"].lower,
        tasks["bounds"].upper,
    ]
    for arr in arrays:
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = 1.0
    # the caller's arrays are copied, never frozen
    A = np.eye(2)
    qc.Equality(A, np.zeros(2))
    A[0, 0] = 2.0


def test_update_is_the_way_and_persistent_sees_it():
    t = qc.Equality(np.eye(2), np.ones(2), name="t")
    stack = qc.Stack([t])
    pq = stack.persistent()
    np.testing.assert_allclose(pq.solve().x, [1.0, 1.0], atol=1e-8)
    version = t.matrix_version
    t.update(A=np.array([[5.0, 0.0], [0.0, 1.0]]))
    assert t.matrix_version == version + 1
    np.testing.assert_allclose(pq.solve().x, stack.solve(method="weighted").x, atol=1e-9)
    np.testing.assert_allclose(pq.solve().x, [0.2, 1.0], atol=1e-8)


def test_internal_in_place_paths_keep_working_and_bump_versions():
    """Kinematic tasks write per step with ``_assign`` and the IK fills its Bounds through
    ``_writable()`` + ``_touch()``: explicit private paths, counted."""
    t = qc.Equality(np.eye(2), np.ones(2))
    b0 = t.b
    v = t.matrix_version
    t._assign(A=np.array([[2.0, 0.0], [0.0, 1.0]]), b=np.array([4.0, 1.0]))
    assert t.b is b0 and t.matrix_version == v + 1 and not t.b.flags.writeable
    np.testing.assert_allclose(qc.Stack([t]).solve().x, [2.0, 1.0])
    with pytest.raises(ValueError, match="non-finite"):
        t._assign(b=np.array([np.nan, 0.0]))
    ineq = qc.Inequality(np.eye(2), lower=-1.0, upper=1.0)
    ineq._assign(np.array([-2.0, -2.0]), np.array([2.0, 2.0]))
    np.testing.assert_allclose(ineq.upper, [2.0, 2.0])
    B = qc.Bounds(-np.ones(2), np.ones(2))
    version = B.version
    lo, hi = B._writable()
    lo[:] = -0.5
    B._touch()
    assert B.version == version + 1
    np.testing.assert_allclose(B.lower, [-0.5, -0.5])
    with pytest.raises(ValueError, match="scalars"):
        qc.Bounds(-1.0, 1.0)._writable()


# --------------------------------------------------------------------------------------
# 5. bad input
# --------------------------------------------------------------------------------------


def test_zero_rows_is_named():
    """Before: numpy's "zero-size array to reduction operation minimum"."""
    with pytest.raises(ValueError, match=r"Equality 'e': A has no rows \(shape \(0, 3\)\)"):
        qc.Equality(np.zeros((0, 3)), np.zeros(0), name="e")
    with pytest.raises(ValueError, match=r"Inequality 'i': C has no rows"):
        qc.Inequality(np.zeros((0, 3)), upper=np.zeros(0), name="i")


@pytest.mark.parametrize("value", [1e-320, 1e-200, 1e200])
def test_unsquarable_magnitudes_are_named(value):
    """Before: 1e-320 gave an IndexError inside quadprog (and RuntimeWarnings on stderr)."""
    A = np.eye(2)
    A[1, 0] = value
    with pytest.raises(ValueError, match=r"Equality 'e': A\[1, 0\] = .* is outside"):
        qc.Equality(A, np.ones(2), name="e")
    t = qc.Equality(np.eye(2), np.ones(2), name="e")
    with pytest.raises(ValueError, match=r"A\[1, 0\]"):
        t.update(A=A)
    with pytest.raises(ValueError, match=r"Inequality 'i': C\[1, 0\]"):
        qc.Inequality(A, upper=1.0, name="i")


def test_complex_input_is_a_type_error():
    """Before: accepted, imaginary part dropped (a ComplexWarning on stderr)."""
    with pytest.raises(TypeError, match=r"Equality 'e': A is complex"):
        qc.Equality(np.eye(2) * (1 + 1j), np.ones(2), name="e")
    with pytest.raises(TypeError, match=r"Equality 'e': b is complex"):
        qc.Equality(np.eye(2), [1.0, 1j], name="e")
    with pytest.raises(TypeError, match=r"Inequality 'i': upper is complex"):
        qc.Inequality(np.eye(2), upper=np.array([1.0, 2.0 + 0j]), name="i")
    with pytest.raises(TypeError, match=r"Bounds 'bounds': lower is complex"):
        qc.Bounds(np.zeros(2) + 0j, np.ones(2))
    t = qc.Equality(np.eye(2), np.ones(2), name="e")
    with pytest.raises(TypeError, match="A is complex"):
        t.update(A=np.eye(2) + 0j)


@pytest.mark.parametrize(
    "method, bounded", [("hierarchical", False), ("hierarchical", True), ("nullspace", False)]
)
def test_nonfinite_data_on_the_closed_form_paths_is_named(method, bounded):
    """Equality-only stacks are solved in closed form (no backend); a NaN there gave
    "the closed-form solution is not finite" naming no task."""
    eq = qc.Equality(np.ones((1, 3)), 1.0, name="sum")
    post = qc.Equality(np.eye(3), np.zeros(3), name="posture")
    stack = qc.Stack([eq, post], bounds=qc.Bounds(-1, 1) if bounded else None)
    stack.solve(method=method)
    force_write(post.b, 1, np.nan)
    with pytest.raises(ValueError, match=r"Equality 'posture': b contains nan at index 1"):
        stack.solve(method=method)


# --------------------------------------------------------------------------------------
# 6. weighted: the persistent workspace and the general path
# --------------------------------------------------------------------------------------


def test_persistent_regularises_a_singular_hessian_instead_of_falling_back():
    """Regression, traced to the regularisation: ``PersistentQP`` once added ε to a copy of
    H's diagonal (``H.flat[::k][:n] += ε``), so it solved the unregularised QP -- exact when
    the levels make H positive definite (the general path, regularised in z around the hard
    phase's point, was 2e-3 away in x on the 3-level stack of test_persistent with
    weight_ratio 1e-3; 1.1e-8 from cvxpy's unregularised QP) -- and with a singular H
    every step fell back to the general path."""
    t = qc.Equality(np.ones((1, 3)), 1.0, name="sum")
    stack = qc.Stack([t], bounds=qc.Bounds(-1, 1))
    pq = stack.persistent()
    sol = pq.solve()
    assert pq.regularized and sol.info["persistent"] and pq.fallbacks == 0
    np.testing.assert_allclose(sol.x, stack.solve(method="weighted").x, atol=1e-7)
    full = qc.Stack([t, qc.Equality(np.eye(3), np.zeros(3))]).persistent()
    assert not full.regularized  # positive definite: the exact weighted QP
