"""LQR + integral action + Kalman observer on the DDL, and the shared design model."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest
import scipy.linalg as sla

import qpcoord.ddl as ddl
from qpcoord.ddl import lqr
from qpcoord.ddl.references import fig619_steps

FS = 8000.0


@pytest.fixture(scope="module")
def plant():
    return ddl.DualStage()


@pytest.fixture(scope="module")
def model(plant):
    return lqr.design_model(plant, FS)


@pytest.fixture(scope="module")
def designed(plant):
    return lqr.LQR().design(plant, FS)


# ------------------------------------------------------------------ design model
def test_design_model_is_the_zoh_of_the_linearisation(plant, model):
    assert model.A.shape == (4, 4) and model.B.shape == (4, 2) and model.C.shape == (1, 4)
    assert model.states == ("y_f", "yd_f", "y_c", "yd_c") and model.inputs == ("v", "alpha")
    np.testing.assert_array_equal(model.C, [[1.0, 0.0, 1.0, 0.0]])
    # "local" = exactly python-control's ZOH of DualStage.linearise
    local = lqr.design_model(plant, FS, detent="local")
    ref = control.c2d(plant.linearise(0.0, 1.5, inputs="phase"), 1 / FS, "zoh")
    np.testing.assert_allclose(local.A, ref.A, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(local.B, ref.B, rtol=1e-12, atol=1e-18)
    # discrete eigenvalues = exp(continuous eigenvalues · h)
    ec = np.sort_complex(np.exp(np.linalg.eigvals(model.continuous.A) / FS))
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(model.A)), ec, rtol=1e-10)
    # inputs act on their own stage only (fine: v, coarse: α)
    assert np.all(model.B[2:, 0] == 0.0) and np.all(model.B[:2, 1] == 0.0)


def test_average_detent_gives_the_large_signal_static_gain(plant, model):
    st = plant.stepper
    # α → y_c static gain: lead/(2π p), reduced only by the (tiny) flexure spring
    kmag = st.torque_constant * 1.5 * st.pole_pairs / st.screw_radius**2
    expect = st.screw_radius / st.pole_pairs / (1.0 + plant.flexure.spring_rate / kmag)
    g = np.linalg.solve(np.eye(2) - model.A[2:, 2:], model.B[2:, 1])[0]
    assert g == pytest.approx(expect, rel=1e-9)
    local = lqr.design_model(plant, FS, detent="local")
    g_loc = np.linalg.solve(np.eye(2) - local.A[2:, 2:], local.B[2:, 1])[0]
    assert g_loc < 0.94 * g  # the local detent stiffness lowers it by ≈ 7 %


def test_augmented_model_and_command_matrix(model):
    h = 1.0 / FS
    np.testing.assert_array_equal(model.Aa[:4, :4], model.A)
    np.testing.assert_allclose(model.Aa[4], [h, 0.0, h, 0.0, 1.0])
    np.testing.assert_array_equal(model.Ba[4], [0.0, 0.0])
    # command matrix: an equilibrium with y = 1 and the fine stage centred
    nx, nu = model.Nx, model.Nu
    np.testing.assert_allclose(model.A @ nx + model.B @ nu, nx, atol=1e-12)
    assert model.C[0] @ nx == pytest.approx(1.0)
    assert abs(nx[0]) < 1e-12 and abs(nu[0]) < 1e-9  # y_f and v stay at the operating point
    assert model.y_op == pytest.approx(model.y_c_op + 15e-6)
    assert model.v_op == pytest.approx(5.0)


def test_design_model_bad_input(plant):
    with pytest.raises(ValueError, match="fs"):
        lqr.design_model(plant, -8000.0)
    with pytest.raises(ValueError, match="y_c"):
        lqr.design_model(plant, FS, y_c=0.05)
    with pytest.raises(ValueError, match="current"):
        lqr.design_model(plant, FS, current=0.0)
    with pytest.raises(ValueError, match="detent"):
        lqr.design_model(plant, FS, detent="none")


# ------------------------------------------------------------------ Riccati and gains
def test_gain_equals_the_dare_solution(model):
    q, r = lqr.default_weights(model)
    p_c, k_c = lqr.solve_dare(model.Aa, model.Ba, q, r, method="control")
    p_s, k_s = lqr.solve_dare(model.Aa, model.Ba, q, r, method="scipy")
    np.testing.assert_allclose(k_c, k_s, rtol=1e-6)
    np.testing.assert_allclose(p_c, p_s, rtol=1e-6, atol=1e-12 * np.abs(p_s).max())
    a, b = model.Aa, model.Ba
    # the SI DARE holds (relative residual) and K is its gain
    res = a.T @ p_s @ a - p_s - a.T @ p_s @ b @ np.linalg.solve(r + b.T @ p_s @ b, b.T @ p_s @ a)
    res += q
    assert np.abs(res).max() < 1e-7 * np.abs(p_s).max()
    k = np.linalg.solve(r + b.T @ p_s @ b, b.T @ p_s @ a)
    np.testing.assert_allclose(k_s, k, rtol=1e-8)
    assert np.all(np.linalg.eigvalsh(p_s / np.abs(p_s).max()) > -1e-12)
    assert np.abs(np.linalg.eigvals(a - b @ k)).max() < 1.0
    # same K from scipy's DARE on the unscaled problem (where it converges)
    p_raw = sla.solve_discrete_are(a, b, q, r)
    np.testing.assert_allclose(p_raw, p_s, rtol=1e-4, atol=1e-9 * np.abs(p_s).max())


def test_closed_loop_is_stable_and_separates(designed):
    big = designed.closed_loop_matrix()
    ev = np.linalg.eigvals(big)
    assert np.abs(ev).max() < 1.0
    mo = designed.model
    reg = np.linalg.eigvals(mo.Aa - mo.Ba @ designed.K)
    obs = np.linalg.eigvals(mo.A - mo.A @ designed.M[:, None] @ mo.C)
    expect = np.sort(np.abs(np.concatenate([reg, obs])))
    np.testing.assert_allclose(np.sort(np.abs(ev)), expect, rtol=1e-6, atol=1e-9)


def test_default_error_weight_follows_its_rule(plant, designed):
    """Default error_max: the most aggressive value with peak |S| ≤ 1.6 (rounded up)."""
    rep = designed.report()
    assert rep["peak_sensitivity"] <= 1.6
    assert rep["max_pole_modulus"] < 1.0
    assert rep["phase_margin_deg"] > 40.0 and rep["gain_margin_db"] > 6.0
    # the price of the 1 kHz loop: one extra sample of latency leaves PM ≈ 3°, two destabilise
    assert rep["delay_margin_samples"] == 1
    model = designed.model
    tighter = lqr.LQR(*lqr.default_weights(model, error_max=0.8 * 1.3e-6)).design(plant, FS)
    assert tighter.peak_sensitivity()[0] > 1.6


def test_kalman_gain_is_the_filter_dare(plant, model):
    m, pk = lqr.kalman_gain(model, plant=plant)
    c = model.C
    v = plant.resolution**2 / 12.0
    np.testing.assert_allclose(m, (pk @ c.T)[:, 0] / (c @ pk @ c.T + v)[0, 0], rtol=1e-9)
    est = model.A - model.A @ m[:, None] @ c
    assert np.abs(np.linalg.eigvals(est)).max() < 1.0


# ------------------------------------------------------------------ closed-loop runs
def test_tracks_kolmogorov_short():
    """Measured 8.2–8.5 nm RMSE on 1–10 s runs (docs/ch6.md); bound 15 nm on 2 s."""
    r = ddl.kolmogorov_opd(2.0, FS, seed=0, preset="paranal_250hz")
    ctl = lqr.LQR()
    run = ddl.simulate(ddl.DualStage(), ctl, r, FS, timing=True)
    m = run.metrics
    assert m["rmse"] < 15e-9 and m["max_abs"] < 60e-9
    assert m["saturated_steps"] == 0 and not m["lost_sync"]
    assert m["fine_margin_min"] > 10e-6
    assert ctl.clipped_steps == 0
    # the observer's carriage estimate follows the true carriage to within a fraction of a
    # µm (measured max 0.14–0.21 µm, seeds 0–2: the Kalman gain puts −0.54 of each
    # innovation on the fine state, so fast output errors move the split estimate)
    assert np.max(np.abs(run.y_c_hat - run.y_c)[800:]) < 0.5e-6
    # per-step time is reported by benchmarks/ddl_bench.py and the comparison, not asserted
    assert np.isfinite(m["step_time_median"])


def test_5mm_step_rate_limited_and_synchronised():
    r = fig619_steps(2.5, FS)["extremity"]
    ctl = lqr.LQR()
    run = ddl.simulate(ddl.DualStage(), ctl, r, FS)
    m = run.metrics
    assert not m["lost_sync"] and m["sync_slip_steps"] == 0
    assert ctl.clipped_steps > 0  # the phase rate limit is active during the move
    # mean carriage speed over 10 %–90 % of the move ≤ the phase rate limit
    frac = (run.y_c - run.y_c[0]) / 5e-3
    k10 = np.argmax(frac > 0.1)
    k90 = np.argmax(frac > 0.9)
    speed = 4e-3 / ((k90 - k10) / FS)
    assert 0.9 * ctl.max_speed < speed < 1.01 * ctl.max_speed
    assert np.all(np.abs(run.error[-int(0.5 * FS) :]) < 100e-9)


# ------------------------------------------------------------------ bad input
def test_bad_weights_raise_value_error_naming_them(model):
    q, r = lqr.default_weights(model)
    qn = q.copy()
    qn[4, 4] = -1.0
    with pytest.raises(ValueError, match="Q"):
        lqr.LQR(qn, r)
    with pytest.raises(ValueError, match="R"):
        lqr.LQR(q, np.eye(3))
    with pytest.raises(ValueError, match="R"):
        lqr.LQR(q, np.diag([1.0, -1.0]))
    with pytest.raises(ValueError, match="Q"):
        lqr.LQR(q[:4, :4], r)
    with pytest.raises(ValueError, match="both Q and R"):
        lqr.LQR(q, None)
    with pytest.raises(ValueError, match="error_max"):
        lqr.default_weights(model, error_max=-1e-9)
    with pytest.raises(ValueError, match="max_speed"):
        lqr.LQR(max_speed=0.0)
    with pytest.raises(ValueError, match="method"):
        lqr.solve_dare(model.Aa, model.Ba, q, r, method="slycot2")


def test_report_before_design_is_an_error():
    with pytest.raises(RuntimeError):
        lqr.LQR().report()


def test_loop_margins_of_a_known_loop():
    # L(z) = k/(z − 1) with k = 0.5: crossover where |e^{jωh} − 1| = 0.5
    h = 1.0 / FS
    loop = control.tf([0.5], [1.0, -1.0], dt=h)
    mg = lqr.loop_margins(loop, FS)
    w = 2.0 * math.asin(0.25) / h
    assert mg["crossover_hz"] == pytest.approx(w / (2 * math.pi), rel=1e-3)
    # phase at crossover: −(π/2 + ωh/2)
    assert mg["phase_margin_deg"] == pytest.approx(90.0 - math.degrees(w * h / 2), abs=0.05)


def test_unconstrained_finite_horizon_with_terminal_p_gives_the_lqr_move(designed):
    """What the MPC relies on: stage cost (Q, R) + terminal cost P ⇒ first move −K x_a."""
    mo = designed.model
    a, b, q, r, p = mo.Aa, mo.Ba, designed.Q, designed.R, designed.P
    n, m = b.shape
    horizon = 6
    # condensed prediction x_k = A^k x0 + Σ A^{k-1-j} B u_j, k = 1..N
    phi = np.zeros((n * horizon, n))
    gam = np.zeros((n * horizon, m * horizon))
    ak = np.eye(n)
    for k in range(horizon):
        ak = a @ ak
        phi[k * n : (k + 1) * n] = ak
        for j in range(k + 1):
            gam[k * n : (k + 1) * n, j * m : (j + 1) * m] = np.linalg.matrix_power(a, k - j) @ b
    qbar = np.kron(np.eye(horizon), q)
    qbar[-n:, -n:] = p
    rbar = np.kron(np.eye(horizon), r)
    # scale the state so that the normal equations are well conditioned
    s = np.array([1e-6, 1e-3, 1e-6, 1e-3, 1e-9])
    x0 = s * np.random.default_rng(7).standard_normal(n)
    hess = gam.T @ qbar @ gam + rbar
    grad = gam.T @ qbar @ phi @ x0  # (x0ᵀ Q x0 is constant)
    u = np.linalg.solve(hess, -grad)
    np.testing.assert_allclose(u[:m], -designed.K @ x0, rtol=1e-5, atol=1e-12)


@pytest.mark.parametrize("y_c", [-0.03, 0.03])
def test_designs_near_the_stroke_ends_are_stable(plant, y_c):
    ctl = lqr.LQR().design(plant, FS, y_c)
    assert np.abs(np.linalg.eigvals(ctl.closed_loop_matrix())).max() < 1.0
    assert ctl.peak_sensitivity()[0] <= 1.6
    assert ctl.model.y_c_op == y_c and ctl.model.alpha_op == pytest.approx(
        y_c * plant.stepper.electrical_per_metre, abs=0.2
    )
    pq = ddl.PQ().design(plant, FS, y_c)
    assert np.abs(pq.closed_loop_poles()).max() < 1.0
