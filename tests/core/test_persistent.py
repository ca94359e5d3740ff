"""qpcoord.core.persistent.PersistentQP: the weighted QP of a fixed-matrix stack, persistent
daqp."""

from __future__ import annotations

import cvxpy as cp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support.stacks import region_problem

import qpcoord as qc
from qpcoord.core.persistent import PersistentQP

pytestmark = pytest.mark.skipif("daqp" not in qc.available_solvers(), reason="needs daqp")


def build(seed: int = 0, n: int = 12, weight_ratio: float = 1e-2):
    rng = np.random.default_rng(seed)
    track = qc.Equality(rng.normal(size=(6, n)), np.zeros(6), weight=2.0, name="track")
    soft = qc.Inequality(rng.normal(size=(4, n)), -np.ones(4), np.ones(4), name="soft")
    effort = qc.Equality(np.eye(n), np.zeros(n), name="effort")
    hard_in = qc.Inequality(rng.normal(size=(3, n)), -0.5, 0.5, name="hard in")
    hard_eq = qc.Equality(rng.normal(size=(1, n)), [0.1], name="hard eq")
    bounds = qc.Bounds(-np.ones(n), np.ones(n))
    stack = qc.Stack(
        [track, soft, effort],
        bounds=bounds,
        constraints=[hard_in, hard_eq],
        weight_ratio=weight_ratio,
    )
    return stack, (track, soft, effort, hard_in, hard_eq, bounds), rng


def weighted_oracle(tasks, rho: float, reg_scale: float):
    """The same weighted QP, posed in cvxpy (Clarabel, tight tolerances)."""
    track, soft, effort, hard_in, hard_eq, bounds = tasks
    n = track.A.shape[1]
    x, s = cp.Variable(n), cp.Variable(soft.C.shape[0])
    cost = (
        cp.sum_squares(cp.multiply(track.sqrt_weight, track.A @ x - track.b))
        + rho * cp.sum_squares(s)
        + rho**2 * cp.sum_squares(effort.A @ x - effort.b)
        + reg_scale * cp.sum_squares(x)
    )
    cons = [
        soft.C @ x - s <= soft.upper,
        soft.C @ x - s >= soft.lower,
        hard_in.C @ x <= hard_in.upper,
        hard_in.C @ x >= hard_in.lower,
        hard_eq.A @ x == hard_eq.b,
        x <= bounds.upper,
        x >= bounds.lower,
    ]
    cp.Problem(cp.Minimize(cost), cons).solve(
        solver="CLARABEL", tol_gap_abs=1e-12, tol_gap_rel=1e-12, tol_feas=1e-12
    )
    return x.value


def test_matches_a_cvxpy_weighted_qp_over_many_steps():
    stack, tasks, rng = build()
    track, soft, effort, *_ = tasks
    pq = PersistentQP(stack)
    H = 2.0 * track.A.T @ track.A + 1e-4 * np.eye(12)  # the regularisation's scale
    reg = stack.regularization * max(1.0, float(np.diag(H + 1e-4 * np.eye(12)).max()))
    worst = 0.0
    for k in range(15):
        track.update(b=3.0 * np.sin(0.3 * k + np.arange(6)))
        effort.update(b=0.2 * rng.normal(size=12))
        sol = pq.solve()
        assert sol.info["persistent"] and sol.method == "weighted"
        ref = weighted_oracle(tasks, 1e-2, reg)
        worst = max(worst, float(np.abs(sol.x - ref).max()))
        assert sol.level_residuals[0] == pytest.approx(
            np.linalg.norm(track.sqrt_weight * (track.A @ sol.x - track.b)), abs=1e-12
        )
    assert worst < 1e-6  # measured 1e-9 (Clarabel's tolerance)
    assert pq.setups == 1 and pq.fallbacks == 0


def test_agrees_with_the_general_weighted_method():
    stack, tasks, _ = build(3)
    tasks[0].update(b=np.linspace(-2, 2, 6))
    a = PersistentQP(stack).solve().x
    b = stack.solve(method="weighted", solver="daqp").x
    np.testing.assert_allclose(a, b, atol=1e-7)


@pytest.mark.parametrize(
    "solver", [s for s in ("daqp", "quadprog", "proxqp") if s in qc.available_solvers()]
)
def test_general_weighted_path_is_not_biased_by_its_regularisation(solver):
    """Regression: the general path once added ε = 1e-9·max diag in the reduced coordinates,
    centred on the hard phase's point; against a last level weighted 1e-6
    (``weight_ratio=1e-3``) that pulled x by up to 9.4e-3 from PersistentQP's answer (30
    seeds, every backend). Now ε‖x‖², x-space scale, only where H is singular, as
    PersistentQP: measured 1.8e-8 (daqp), 6e-9 (quadprog, proxqp)."""
    worst = 0.0
    for seed in range(10):
        stack, tasks, _ = build(seed, weight_ratio=1e-3)
        tasks[0].update(b=np.linspace(-2, 2, 6))
        tasks[2].update(b=0.2 * np.random.default_rng(seed).normal(size=12))
        a = PersistentQP(stack).solve().x
        b = stack.solve(method="weighted", solver=solver).x
        worst = max(worst, float(np.abs(a - b).max()))
    assert worst < 1e-7, worst


def test_a_changed_matrix_or_weight_rebuilds_the_workspace():
    stack, tasks, _ = build(5)
    track = tasks[0]
    pq = PersistentQP(stack)
    pq.solve()
    track.update(A=track.A * 1.5)
    sol = pq.solve()
    assert pq.setups == 2
    np.testing.assert_allclose(sol.x, stack.solve(method="weighted", solver="daqp").x, atol=1e-4)
    track.update(weight=3.0)
    pq.solve()
    assert pq.setups == 3
    track._assign(A=track.A * 0.5)  # the trusted in-place path counts too
    pq.solve()
    assert pq.setups == 4


def test_bounds_changes_are_read_every_step():
    stack, tasks, _ = build(7)
    bounds = tasks[-1]
    tasks[0].update(b=5.0 * np.ones(6))
    pq = PersistentQP(stack)
    bounds.update(lower=-0.2 * np.ones(12), upper=0.2 * np.ones(12))
    x = pq.solve().x
    assert np.abs(x).max() <= 0.2 + 1e-12
    assert np.isclose(np.abs(x).max(), 0.2)  # binds


def test_inconsistent_hard_constraints_raise_through_the_fallback():
    n = 3
    t = qc.Equality(np.eye(n), np.zeros(n))
    hard = qc.Inequality(np.ones((1, n)), lower=10.0)
    stack = qc.Stack([t], bounds=qc.Bounds(-np.ones(n), np.ones(n)), constraints=[hard])
    with pytest.raises(qc.InfeasibleError):
        PersistentQP(stack).solve()


def test_a_stack_without_constraints_or_bounds():
    t = qc.Equality([[1.0, 1.0]], [2.0])
    sol = PersistentQP(qc.Stack([t])).solve()
    np.testing.assert_allclose(sol.x, [1.0, 1.0], atol=1e-8)


def test_bad_arguments():
    with pytest.raises(ValueError, match="Stack"):
        PersistentQP("stack")
    stack, _, _ = build()
    with pytest.raises(ValueError, match="weight_ratio"):
        PersistentQP(stack, weight_ratio=2.0)


def test_stack_persistent_is_the_same_object_kind():
    stack, _, _ = build(11)
    pq = stack.persistent()
    assert isinstance(pq, PersistentQP) and pq.stack is stack


@pytest.mark.parametrize("engine", [None, "python"])
def test_parametric_form_equals_the_task_form(engine):
    """b and limits affine in θ: solve_theta(θ) = solve() once the tasks hold those values,
    on the default engine (native where built) and the Python one (its daqp workspace is
    whitened: f_u(θ) is affine in θ through the whitened map, no triangular solve)."""
    stack, tasks, rng = build(13)
    track, soft, effort, hard_in, hard_eq, bounds = tasks
    pq = stack.persistent(engine=engine)
    assert engine is None or pq.engine == engine
    p = 3
    maps = {
        track: (rng.normal(size=6), rng.normal(size=(6, p))),
        hard_in: (
            (-0.5 * np.ones(3), np.zeros((3, p))),
            (0.5 + np.zeros(3), 0.1 * np.ones((3, p))),
        ),
    }
    pq.parametrize(p, maps)
    for _ in range(5):
        theta = rng.normal(size=p)
        x = pq.solve_theta(theta).copy()
        pq.write_tasks(theta)
        np.testing.assert_allclose(track.b, maps[track][0] + maps[track][1] @ theta)
        np.testing.assert_allclose(x, pq.solve().x, atol=1e-9)
    assert pq.fallbacks == 0


def test_parametric_form_reports_and_falls_back():
    stack, tasks, rng = build(17)
    track, soft, effort, hard_in, hard_eq, bounds = tasks
    pq = stack.persistent()
    with pytest.raises(ValueError, match="write_tasks"):
        pq.write_tasks(np.zeros(2))
    with pytest.raises(ValueError, match="shape"):
        pq.parametrize(2, {track: (np.zeros(6), np.zeros((5, 2)))})
    with pytest.raises(ValueError, match="not in the stack"):
        pq.parametrize(2, {qc.Equality(np.eye(12), np.zeros(12)): (0.0, np.zeros((12, 2)))})
    with pytest.raises(ValueError, match="size"):
        pq.parametrize(0, {})
    # hard rows pushed to an inconsistent box: the general path raises, after the tasks
    # were given θ's values
    pq.parametrize(
        1, {hard_in: ((np.full(3, 5.0), np.zeros((3, 1))), (np.full(3, 6.0), np.zeros((3, 1))))}
    )
    with pytest.raises(qc.InfeasibleError):
        pq.solve_theta(np.zeros(1))
    np.testing.assert_array_equal(hard_in.lower, 5.0)
    assert pq.fallbacks == 1


def test_parametric_unconstrained_shortcut_matches_the_qp():
    """No soft inequality: the unconstrained optimum is affine in θ and used when it meets
    the bounds and hard rows; otherwise daqp. Both agree with the task-form solve."""
    rng = np.random.default_rng(23)
    n = 8
    track = qc.Equality(rng.normal(size=(4, n)), np.zeros(4), name="track")
    effort = qc.Equality(np.eye(n), np.zeros(n), name="effort")
    hard = qc.Inequality(rng.normal(size=(2, n)), -1.0, 1.0, name="hard")
    stack = qc.Stack([track, effort], bounds=qc.Bounds(-np.ones(n), np.ones(n)), constraints=[hard])
    pq = stack.persistent()
    pq.parametrize(2, {track: (np.zeros(4), rng.normal(size=(4, 2)))})
    active = 0
    for scale in (0.01, 0.1, 1.0, 10.0, 0.01):
        theta = scale * rng.normal(size=2)
        x = pq.solve_theta(theta).copy()
        pq.write_tasks(theta)
        ref = pq.solve().x
        np.testing.assert_allclose(x, ref, atol=1e-9)
        active += int(np.isclose(np.abs(x).max(), 1.0) or np.abs(hard.C @ x).max() > 1 - 1e-9)
    assert 0 < active < 5  # both paths were exercised


def reference_x(stack, pq, theta):
    """The same QP through the task form: the daqp workspace, no region law (the general
    ``Stack.solve(method="weighted")`` path opens hard rows by 1e-6, so it is not exact)."""
    pq.write_tasks(theta)
    return pq.solve().x


def oracle_x(stack, pq, hard, theta):
    """The same weighted QP posed in cvxpy (Clarabel, tight tolerances)."""
    track = stack.levels[0][0]
    pq.write_tasks(theta)
    n = track.A.shape[1]
    H = track.A.T @ track.A + stack.weight_ratio * np.eye(n)
    eps = stack.regularization * max(1.0, float(H.diagonal().max()))
    x = cp.Variable(n)
    cost = (
        cp.sum_squares(track.A @ x - track.b)
        + stack.weight_ratio * cp.sum_squares(x)
        + eps * cp.sum_squares(x)
    )
    cons = [hard.C @ x <= hard.upper, hard.C @ x >= hard.lower, cp.abs(x) <= 0.5]
    cp.Problem(cp.Minimize(cost), cons).solve(
        solver="CLARABEL", tol_gap_abs=1e-12, tol_gap_rel=1e-12, tol_feas=1e-12
    )
    return x.value


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_critical_regions_answer_the_same_qp(seed):
    """A slow θ trajectory through many active sets: the cached regions answer most steps
    and every answer equals the daqp workspace's (1e-9) and cvxpy's (1e-6) solution."""
    stack, pq, rng, hard = region_problem(seed)
    theta = np.zeros(3)
    direction = rng.normal(size=3)
    worst = worst_oracle = 0.0
    for k in range(300):
        theta = 3.0 * np.sin(0.02 * k) * direction + 0.3 * np.sin(0.11 * k)
        x = pq.solve_theta(theta).copy()
        worst = max(worst, float(np.abs(x - reference_x(stack, pq, theta)).max()))
        if k % 30 == 0:
            err = np.abs(x - oracle_x(stack, pq, hard, theta)).max()
            worst_oracle = max(worst_oracle, float(err))
    assert worst < 1e-9
    assert worst_oracle < 1e-6
    assert pq.region_steps > 150 and pq.qp_steps > 0 and pq.fallbacks == 0
    assert len(pq._regions) >= 2  # constrained regions were learnt, not only the free one


def test_alternating_active_sets_stay_off_the_solver():
    """θ jumping between two points with different active sets: after each region is
    learnt (second sighting) no QP is solved any more."""
    stack, pq, rng, _ = region_problem(4)
    d = rng.normal(size=3)
    a, b = 2.5 * d / np.linalg.norm(d), -2.5 * d / np.linalg.norm(d)
    for _ in range(6):
        pq.solve_theta(a)
        pq.solve_theta(b)
    qp = pq.qp_steps
    for _ in range(20):
        xa = pq.solve_theta(a).copy()
        xb = pq.solve_theta(b).copy()
    assert pq.qp_steps == qp
    assert len(pq._regions) == 2  # two different constrained regions
    np.testing.assert_allclose(xa, reference_x(stack, pq, a), atol=1e-7)
    np.testing.assert_allclose(xb, reference_x(stack, pq, b), atol=1e-7)


def test_dependent_active_rows_are_left_to_the_solver():
    """A hard row duplicated: at a point where both copies are active the region is
    degenerate (not cached) and the solver answers, correctly."""
    n = 4
    A = np.eye(n)
    track = qc.Equality(A, np.zeros(n), name="track")
    row = np.ones((1, n))
    hard = qc.Inequality(np.vstack((row, row)), -np.inf, 1.0, name="twice the same row")
    stack = qc.Stack([track], bounds=qc.Bounds(-5 * np.ones(n), 5 * np.ones(n)), constraints=[hard])
    pq = stack.persistent()
    pq.parametrize(1, {track: (np.zeros(n), np.ones((n, 1)))})
    for t in (2.0, 2.0, 2.0, 2.1):
        x = pq.solve_theta(np.array([t])).copy()
        np.testing.assert_allclose(row @ x, 1.0, atol=1e-9)  # the sum is held at its limit
        np.testing.assert_allclose(x, np.full(n, 0.25), atol=1e-7)
    assert pq.fallbacks == 0


def test_solve_theta_needs_parametrize():
    stack, tasks, rng = build(3)
    with pytest.raises(ValueError, match="parametrize"):
        stack.persistent().solve_theta(np.zeros(2))


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    thetas=st.lists(
        st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3), min_size=2, max_size=12
    ),
)
def test_region_answers_equal_the_solver_property(seed, thetas):
    """Any θ sequence (each θ repeated so that regions get built and then used): every
    answer equals the daqp workspace's solution of the same QP."""
    stack, pq, _, _ = region_problem(seed)
    for theta in thetas:
        theta = np.array(theta)
        for _ in range(3):
            x = pq.solve_theta(theta).copy()
        np.testing.assert_allclose(x, reference_x(stack, pq, theta), atol=1e-8)
    assert pq.fallbacks == 0
