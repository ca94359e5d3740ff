"""Smoke tests of the stack benchmark (qpcoord.studies.bench_stack). No timing assertions, ever:
only the shape of the rows and the validity of the per-step solutions are checked."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import lsq_linear

import qpcoord as qc
from qpcoord.studies.bench_stack import (
    METHOD_ORDER,
    SLOW_SOLVERS,
    ChainScenario,
    format_table,
    run_loops,
    run_stack_bench,
)

KEYS = {
    "n",
    "method",
    "solver",
    "stack",
    "steps",
    "median_us",
    "p90_us",
    "p99_us",
    "mean_us",
    "qp_calls_mean",
    "qp_calls_max",
    "bounds_active",
    "limits_active",
    "task_residual_median",
    "max_bound_violation",
    "failures",
    "failure_messages",
    "note",
}


@pytest.fixture(scope="module")
def quick_rows():
    return run_stack_bench(quick=True)


def test_quick_rows_well_formed(quick_rows):
    solvers = qc.available_solvers()
    assert len(quick_rows) == 2 * (2 * len(solvers) + 1)
    seen = set()
    for r in quick_rows:
        assert set(r) >= KEYS
        seen.add((r["n"], r["method"], r["solver"]))
        assert r["n"] in (7, 30)
        assert r["method"] in METHOD_ORDER
        assert r["failures"] == 0, r["failure_messages"]
        assert 1 <= r["steps"] <= 25
        if r["solver"] in SLOW_SOLVERS:
            assert r["steps"] <= 5 and "slow" in r["note"]
        for k in ("median_us", "p90_us", "p99_us", "mean_us"):
            assert math.isfinite(r[k]) and r[k] > 0
        assert r["median_us"] <= r["p90_us"] <= r["p99_us"]
        assert 0 <= r["qp_calls_mean"] <= r["qp_calls_max"]
        assert r["max_bound_violation"] <= 1e-6
        assert math.isfinite(r["task_residual_median"])
        if r["method"] == "nullspace":
            assert r["solver"] == "none" and r["qp_calls_max"] == 0
            assert math.isnan(r["bounds_active"]) and math.isnan(r["limits_active"])
            assert "no bounds" in r["note"]
        else:
            assert r["solver"] in solvers
            assert 0.0 <= r["bounds_active"] <= 1.0 and 0.0 <= r["limits_active"] <= 1.0
    expected = {(n, m, s) for n in (7, 30) for m in ("hierarchical", "weighted") for s in solvers}
    expected |= {(n, "nullspace", "none") for n in (7, 30)}
    assert seen == expected


def test_format_table(quick_rows):
    text = format_table(quick_rows)
    lines = text.splitlines()
    assert lines[0].split()[:3] == ["n", "method", "solver"]
    for s in qc.available_solvers():
        assert s in text
    assert "hierarchical median / weighted median" in text
    assert "not judged" in text  # quick runs are too short to judge the target
    # one table line per row, then the ratio block
    assert sum(1 for line in lines if line.split()[:1] in (["7"], ["30"])) == len(quick_rows)


def test_options_and_errors():
    rows = run_stack_bench(sizes=(7,), steps=3, solvers="daqp", methods=("weighted",))
    assert [(r["n"], r["method"], r["solver"], r["steps"]) for r in rows] == [
        (7, "weighted", "daqp", 3)
    ]
    with pytest.raises(ValueError, match="solver"):
        run_stack_bench(solvers="no-such-solver", quick=True)
    with pytest.raises(ValueError, match="method"):
        run_stack_bench(methods=("magic",), quick=True)
    with pytest.raises(ValueError, match="steps"):
        run_stack_bench(steps=0)


@pytest.mark.parametrize("n", [7, 30])
def test_scenario_jacobian(n):
    sc = ChainScenario(n)
    q = sc.q_rest + 0.05 * np.cos(np.arange(n))
    p, R, J = sc.kinematics(q)
    assert np.allclose(R.T @ R, np.eye(3))
    eps = 1e-6
    for i in range(n):
        dq = np.zeros(n)
        dq[i] = eps
        p2, R2, _ = sc.kinematics(q + dq)
        W = (R2 @ R.T - np.eye(3)) / eps
        assert np.allclose(J[:3, i], (p2 - p) / eps, atol=1e-5)
        assert np.allclose(J[3:, i], [W[2, 1], W[0, 2], W[1, 0]], atol=1e-5)
    assert np.all(sc.q_min < sc.q_rest) and np.all(sc.q_rest < sc.q_max)
    assert np.all(sc.dq_max > 0)


@pytest.mark.parametrize("n,steps", [(30, 60)])
def test_per_step_solutions_valid(n, steps):
    """Re-check recorded closed-loop solutions against independent references."""
    rows = run_loops(
        n,
        [("hierarchical", "daqp"), ("weighted", "daqp"), ("nullspace", None)],
        steps,
        record=True,
    )
    hier, wei, ns = rows
    for r in rows:
        assert r["failures"] == 0, r["failure_messages"]
        assert np.all(np.isfinite(r["xs"])) and np.all(np.isfinite(r["residuals"]))
    # the scenario makes the velocity bounds bind (and QPs run) within these steps
    assert hier["bounds_active"] > 0 and hier["qp_calls_max"] >= 1
    sc = ChainScenario(n)
    for r in (hier, wei):
        assert np.all(np.abs(r["xs"]) <= sc.dq_max * (1 + 1e-9) + 1e-9)
    checked = 0
    for k in range(0, steps, 6):
        # hierarchical level 0 = bounded least squares of the main task (nothing above it)
        sc.q, sc.t = hier["qs"][k].copy(), k * sc.dt
        J, v, *_ = sc.numbers()
        ref = lsq_linear(J, v, bounds=(-sc.dq_max, sc.dq_max), tol=1e-12, method="bvls")
        best = np.linalg.norm(J @ ref.x - v)
        x = hier["xs"][k]
        assert np.linalg.norm(J @ x - v) <= best + 1e-7 * max(1.0, np.linalg.norm(v))
        assert hier["residuals"][k, 0] == pytest.approx(np.linalg.norm(J @ x - v), abs=1e-9)
        # the recorded solution does not depend on the warm start
        stack, _ = sc.build()
        assert np.allclose(stack.solve(solver="daqp").x, x, atol=1e-7)
        # nullspace: x = J⁺v + (I − J⁺J)·posture
        sc.q, sc.t = ns["qs"][k].copy(), k * sc.dt
        J, v, _, _, pb = sc.numbers()
        Jp = np.linalg.pinv(J)
        expect = Jp @ v + (np.eye(n) - Jp @ J) @ pb
        assert np.allclose(ns["xs"][k], expect, atol=1e-8)
        checked += 1
    assert checked >= 5


def test_loops_reproducible():
    a = run_loops(7, [("hierarchical", "daqp")], 10, record=True)[0]
    b = run_loops(7, [("hierarchical", "daqp"), ("weighted", "quadprog")], 10, record=True)[0]
    assert np.array_equal(a["qs"], b["qs"])
    assert np.allclose(a["xs"], b["xs"], atol=1e-12)
