"""qpcoord.ddl.MPC: the prioritised-stack MPC of the dual stage."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc
import qpcoord.ddl as ddl
from qpcoord.ddl.mpc import MPC, prediction_model

FS = 8000.0


def test_prediction_model_matches_the_plant_for_small_moves():
    """The discrete model predicts the plant's response to a small voltage step."""
    plant = ddl.DualStage()
    plant.reset(FS)
    A, B = prediction_model(plant, FS)
    alpha = plant.equilibrium_phase(1.5)
    x = np.array([plant.y_f, 0.0, 0.0, 0.0, 0.0])
    v = plant.v_applied + 0.5
    for _ in range(40):
        plant.step(v, 1.5 * np.sin(alpha), 1.5 * np.cos(alpha))
        x = A @ x + B @ np.array([v, 0.0])
    assert abs(plant.y_f - x[0]) < 1e-3 * 1.5e-6  # the fine stage is linear: exact to 0.1 %


def test_kolmogorov_tracking_keeps_the_margin():
    r = ddl.kolmogorov_opd(0.25, FS, seed=3, preset="paranal_250hz")
    mpc = MPC()
    run = ddl.simulate(ddl.DualStage(), mpc, r, FS, seed=3)
    m = run.metrics
    assert m["saturated_steps"] == 0 and not m["lost_sync"]
    assert m["rmse"] < 70e-9  # measured 4.7 nm (seed 1, 0.3 s)
    assert m["fine_margin_min"] >= 0.1 * 30e-6 - 1e-9
    assert mpc.fallback_steps == 0
    assert mpc._pq.setups == 1  # the persistent workspace was kept


def test_a_5mm_step_never_drives_the_fine_stage_into_its_stops():
    r = ddl.references.fig619_steps(0.6, FS)["centre"]
    mpc = MPC()
    run = ddl.simulate(ddl.DualStage(), mpc, r, FS)
    m = run.metrics
    assert m["saturated_steps"] == 0 and not m["lost_sync"]
    assert m["fine_margin_min"] >= 3e-6 - 1e-8  # the 10 % margin holds through the move
    # the carriage moves at the synchronism speed limit (3 mm/s) toward the step
    moved = run.y_c[-1] - run.y_c[0]
    assert 0.8 * 3e-3 * 0.5 < abs(moved) <= 3e-3 * 0.6 * 1.05


def test_hierarchical_method_runs_and_keeps_the_margin():
    r = ddl.kolmogorov_opd(0.03, FS, seed=0, preset="paranal_250hz")
    mpc = MPC(method="hierarchical")
    run = ddl.simulate(ddl.DualStage(), mpc, r, FS)
    assert run.metrics["saturated_steps"] == 0 and mpc.fallback_steps == 0
    assert run.metrics["fine_margin_min"] >= 3e-6 - 1e-9


def test_an_infeasible_step_falls_back_and_is_counted():
    plant = ddl.DualStage()
    y = plant.reset(FS, v0=0.0)  # fine stage at 0 µm: below the 3 µm margin
    mpc = MPC()
    mpc.reset(plant, FS, y, y)
    v, ia, ib = mpc.step(y, y)
    assert mpc.fallback_steps == 1
    assert 0.0 <= v <= 10.0 and np.isfinite(ia) and np.isfinite(ib)


def _weighted_cost(mpc, x):
    rho = mpc.weight_ratio
    return float(
        np.sum((mpc.track.A @ x - mpc.track.b) ** 2)
        + rho * np.sum((mpc.centre.A @ x - mpc.centre.b) ** 2)
        + rho**2 * np.sum((mpc.effort.A @ x - mpc.effort.b) ** 2)
    )


def _cvxpy_weighted(mpc):
    """The MPC's weighted QP posed in cvxpy (Clarabel), without the 1e-9 regularisation."""
    import cvxpy as cp

    rho = mpc.weight_ratio
    x = cp.Variable(mpc.stack.n)
    cost = (
        cp.sum_squares(mpc.track.A @ x - mpc.track.b)
        + rho * cp.sum_squares(mpc.centre.A @ x - mpc.centre.b)
        + rho**2 * cp.sum_squares(mpc.effort.A @ x - mpc.effort.b)
    )
    cons = [
        mpc.stroke.C @ x <= mpc.stroke.upper,
        mpc.stroke.C @ x >= mpc.stroke.lower,
        mpc.volts.C @ x <= mpc.volts.upper,
        mpc.volts.C @ x >= mpc.volts.lower,
    ]
    finite = np.isfinite(mpc.bounds.upper)
    cons += [x[finite] <= mpc.bounds.upper[finite], x[finite] >= mpc.bounds.lower[finite]]
    cp.Problem(cp.Minimize(cost), cons).solve(solver="CLARABEL")
    return x.value


def _mpc_after_a_step_move() -> MPC:
    """An MPC six steps into a 0.2 µm step move, its last step's QP in the stack's tasks."""
    plant = ddl.DualStage()
    y = plant.reset(FS)
    mpc = MPC()
    mpc.reset(plant, FS, y, y)
    r = y + 2e-7
    for _ in range(5):
        y = plant.step(*mpc.step(y, r))
    mpc.step(y, r)
    mpc.sync_tasks()  # the last step's QP into the stack's tasks
    return mpc


@pytest.mark.parametrize("solver", qc.available_solvers())
def test_every_backend_solves_the_mpc_qp_alike(solver):
    """The same weighted MPC QP by every backend, against the persistent daqp answer.

    The QP is ill-conditioned (cond(H) ≈ 1.5e9: the effort level weighs 1e-6), so ``x`` is
    loosely determined along cheap directions; the cost is compared. The general path opens
    its rows by 1e-6 and may beat the exact optimum by that much (measured 5e-9 of 2.9e-5).
    """
    mpc = _mpc_after_a_step_move()
    ref = mpc._pq.solve().x  # the QP of the last step, solved again
    sol = mpc.stack.solve(method="weighted", solver=solver)
    j_ref, j = _weighted_cost(mpc, ref), _weighted_cost(mpc, sol.x)
    j_cvx = _weighted_cost(mpc, _cvxpy_weighted(mpc))
    assert abs(j_ref - j_cvx) <= 1e-3 * j_cvx + 1e-10  # the persistent answer vs the oracle
    # interior-point and ADMM backends stop at ~1e-8 tolerances: 6.6e-3 measured (piqp)
    rel = 1e-3 if solver in ("daqp", "quadprog", "proxqp", "highs") else 1e-2
    assert abs(j - j_ref) <= rel * j_ref + 1e-10
    assert np.all(np.abs(sol.x) <= mpc.bounds.upper * (1 + 1e-6) + 1e-9)
    gx = mpc.stroke.C @ sol.x
    assert np.all(gx >= mpc.stroke.lower - 1e-5) and np.all(gx <= mpc.stroke.upper + 1e-5)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"margin": 0.5}, "margin"),
        ({"margin": -0.1}, "margin"),
        ({"blocks": []}, "blocks"),
        ({"blocks": [1, 0]}, "blocks"),
        ({"method": "nullspace"}, "method"),
        ({"weight_ratio": 0.0}, "weight_ratio"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        MPC(**kwargs)


@pytest.mark.parametrize("method", ["hierarchical", "weighted"])
def test_unconstrained_lq_mpc_first_move_is_the_lqr(method):
    """Terminal cost from the Riccati equation: the condensed LQ stack gives −K x₀ for any
    horizon (dual-stage model without the disturbance state, same Q and R as the LQR)."""
    from scipy.linalg import solve_discrete_are

    from qpcoord.ddl.mpc import lq_first_move

    plant = ddl.DualStage()
    plant.reset(FS)
    A, B = prediction_model(plant, FS)
    A, B = A[:4, :4], B[:4]
    # scaled states (µm, mm/s) so that the LQ rows are well conditioned
    T = np.diag([1e6, 1e3, 1e6, 1e3])
    A, B = T @ A @ np.linalg.inv(T), T @ B
    Q = np.diag([1.0, 1e-2, 1.0, 1e-2])
    R = np.diag([1e-2, 1e2])
    P = solve_discrete_are(A, B, Q, R)
    K = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)
    x0 = np.array([2.0, 0.1, -3.0, 0.2])  # µm, mm/s
    u_lqr = -K @ x0
    for N in (1, 5, 20):
        u = lq_first_move(A, B, Q, R, P, N, x0, method=method)
        # weighted: its regularisation 1e-9·max diag(H) biases the cheap input direction
        # (measured 1.8e-6 at N = 1, 3.6e-4 at N = 20); the strict method is exact
        rtol = 1e-8 if method == "hierarchical" else 1e-3
        np.testing.assert_allclose(u, u_lqr, rtol=rtol, atol=1e-10 * np.abs(u_lqr).max())


def test_lq_first_move_bad_weights():
    from qpcoord.ddl.mpc import lq_first_move

    A, B = np.eye(2), np.eye(2)
    with pytest.raises(ValueError, match="Q must be positive semi-definite"):
        lq_first_move(A, B, -np.eye(2), np.eye(2), np.eye(2), 3, np.zeros(2))
    with pytest.raises(ValueError, match="horizon"):
        lq_first_move(A, B, np.eye(2), np.eye(2), np.eye(2), 0, np.zeros(2))


def test_a_missed_deadline_falls_back_and_is_counted():
    r = ddl.kolmogorov_opd(0.02, FS, seed=0, preset="paranal_250hz")
    mpc = MPC(deadline=1e-9)  # no step can meet it
    run = ddl.simulate(ddl.DualStage(), mpc, r, FS)
    assert mpc.late_steps == len(r) and mpc.fallback_steps == 0
    assert run.metrics["saturated_steps"] == 0  # the fine PI holds the stage
    with pytest.raises(ValueError, match="deadline"):
        MPC(deadline=-1.0)


@pytest.mark.parametrize("solver", ["daqp", "quadprog", "clarabel"])
def test_the_python_weighted_qp_matches_the_native_one_on_the_mpc(solver):
    """cond(H) ≈ 1.5e9: daqp and quadprog get the QP in the whitened variables of the
    weighted rows' QR (``WHITENED``), the others the formed H. Measured |Δx| to the native
    engine: daqp and quadprog 8e-12 (7.5e-10 and 3.5e-11 with the formed H), clarabel 4e-11
    (7.9e-4 and a cost 1.1e-3 higher when it was given the whitened rows)."""
    if solver not in qc.available_solvers():
        pytest.skip(f"{solver} not installed")
    mpc = _mpc_after_a_step_move()
    native = mpc.stack.solve(method="weighted", engine="native")
    sol = mpc.stack.solve(method="weighted", solver=solver)
    assert sol.info["qp_calls"] > 0  # the constrained QP, not the closed form
    j_n, j = _weighted_cost(mpc, native.x), _weighted_cost(mpc, sol.x)
    assert abs(j - j_n) <= 1e-9 * j_n, (j, j_n)
    if solver in ("daqp", "quadprog"):
        np.testing.assert_allclose(sol.x, native.x, rtol=0, atol=1e-10)


@pytest.mark.skipif(
    not __import__("qpcoord.core.native", fromlist=["available"]).available(),
    reason="the native engine is not built",
)
def test_the_persistent_daqp_workspace_is_whitened_and_matches_the_native_engine():
    """The Python engine's persistent workspace gives daqp the weighted QP in ``u = T x``
    (``T`` the QR factor of the weighted rows, as the weighted method's ``WHITENED``
    path), not the formed Hessian (cond ≈ 1.5e9 here). Measured over this 0.2 µm step move
    (200 steps): native vs Python ≤ 3.0e-13 relative in x; with the formed Hessian 3.8e-7
    (median 8.8e-9)."""
    from qpcoord.core.persistent import PersistentQP

    plant = ddl.DualStage()
    y = plant.reset(FS)
    mpc = MPC()
    mpc.reset(plant, FS, y, y)
    r = y + 2e-7
    pq = {}
    worst = 0.0
    for _ in range(60):
        u = mpc.step(y, r)
        mpc.sync_tasks()  # this step's QP into the stack's tasks
        if not pq:
            kw = dict(weight_ratio=mpc._pq.weight_ratio, regularization=mpc._pq.regularization)
            pq = {e: PersistentQP(mpc.stack, engine=e, **kw) for e in ("native", "python")}
            assert pq["python"]._T is not None  # the whitened workspace
        xn, xp = pq["native"].solve().x, pq["python"].solve().x
        worst = max(worst, float(np.max(np.abs(xp - xn)) / np.max(np.abs(xn))))
        y = plant.step(*u)
    assert pq["python"].fallbacks == 0 and pq["python"].setups == 1
    assert worst <= 1e-10, worst
