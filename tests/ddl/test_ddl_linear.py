"""Any linear dual stage: LinearDualStage (validation, discretisation, PRIMA's model) and the
generic controllers (LQG, FrequencySplit, LinearMPC) on it and on the nonlinear DualStage."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest

import qpcoord.ddl as ddl
from qpcoord.ddl import LQG, Disturbance, FrequencySplit, LinearDualStage, LinearMPC
from qpcoord.ddl.lqr import design_model

FS = 8000.0
W0 = 2.0 * math.pi * 0.2
#: a low-frequency output disturbance: what a tracked reference looks like to the design
REF = Disturbance(control.tf([1.0], [1.0, 2.0 * W0, W0 * W0]), "output", 1.0, "reference")


@pytest.fixture(scope="module")
def prima():
    return ddl.DualStage().linear(FS, disturbances=[REF])


@pytest.fixture(scope="module")
def reference():
    r = ddl.kolmogorov_opd(0.25, FS, seed=3, preset="paranal_250hz")
    return r - r[0]


def _mass_spring(k=1.0):
    return (
        np.array([[0.0, 1.0], [-k, -0.1]]),
        np.array([[0.0], [1.0]]),
        np.array([[1.0, 0.0]]),
        np.zeros((1, 1)),
    )


# ---------------------------------------------------------------------------- bad plant data
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (
            {"coarse": (np.zeros((2, 3)), np.zeros((2, 1)), np.zeros((1, 2)), np.zeros((1, 1)))},
            r"coarse\.A must be square",
        ),
        ({"fine": (np.array([[np.nan]]), [[1.0]], [[1.0]], [[0.0]])}, r"fine\.A is not finite"),
        ({"Ts": 0.0}, r"Ts must be a finite sampling period"),
        ({"Ts": math.inf}, r"Ts must be a finite sampling period"),
        ({"fine_stroke": 0.0}, r"fine_stroke must be finite and > 0"),
        ({"coarse_stroke": (1.0, -1.0)}, r"coarse_stroke must have high > low"),
        ({"fine": (*_mass_spring(), 1e-3)}, r"fine is discrete at dt = 0\.001 s but runs at"),
        (
            {"coarse_filter": ([[0.5]], [[1.0]], [[1.0]], [[0.0]], 0.3e-4)},
            r"coarse_filter must be discrete at Ts/M",
        ),
        ({"fine": (*_mass_spring()[:3], np.ones((1, 1)))}, r"fine\.D must be 0"),
        (
            {"disturbances": [Disturbance(control.tf([1.0], [1.0, 0.0]))]},
            r"disturbances\[0\]\.model must be stable",
        ),
        ({"coarse_rate": -1.0}, r"coarse_rate must be > 0"),
    ],
)
def test_bad_plant_data_raises_a_named_value_error(kwargs, match):
    args = {"coarse": _mass_spring(), "fine": _mass_spring(100.0), "Ts": 1e-4}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        LinearDualStage(args.pop("coarse"), args.pop("fine"), args.pop("Ts"), **args)


# ---------------------------------------------------------------------------- discretisation
def test_prima_linear_model_is_the_lqr_design_model(prima):
    m = prima.discrete()
    dm = design_model(ddl.DualStage(), FS)
    # states (y_c, ẏ_c, y_f, ẏ_f, reference...) against (y_f, ẏ_f, y_c, ẏ_c): one ZOH of
    # the same matrices, so equal to the expm's rounding (relative 1e-9 of each block)
    np.testing.assert_allclose(m.A[:2, :2], dm.A[2:, 2:], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(m.A[2:4, 2:4], dm.A[:2, :2], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(m.B[:2, 0], dm.B[2:, 1], rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(m.B[2:4, 1], dm.B[:2, 0], rtol=1e-9, atol=1e-18)
    assert prima.fine_stroke == pytest.approx((-15e-6, 15e-6))
    assert prima.fine_range == pytest.approx((-5.0, 5.0))
    assert m.c_error[0, :4] == pytest.approx([-1.0, 0.0, -1.0, 0.0])  # e = d − y_c − y_f


def test_held_multirate_filter_is_the_fine_rate_simulation():
    # plant ZOH at Ts/M behind a filter at Ts/M whose input is held over Ts, simulated step
    # by step at Ts/M, against the lifted model at Ts (same arithmetic reordered: 1e-9)
    ts, mr = 1e-3, 4
    filt = (
        np.array([[0.2, 0.1], [0.0, 0.5]]),
        np.array([[1.0], [0.5]]),
        np.array([[0.3, -0.2]]),
        np.array([[0.4]]),
        ts / mr,
    )
    plant = LinearDualStage(_mass_spring(40.0), _mass_spring(900.0), ts, coarse_filter=filt)
    m = plant.discrete()
    rng = np.random.default_rng(1)
    u = rng.standard_normal(30)
    from qpcoord.ddl.linear_plant import _zoh

    a, b = _zoh(*_mass_spring(40.0)[:2], ts / mr)
    xf, xp, x = np.zeros(2), np.zeros(2), np.zeros(m.n)
    for uk in u:
        assert (m.c_coarse @ x)[0] == pytest.approx(xp[0], rel=1e-9, abs=1e-15)
        for _ in range(mr):
            v = filt[2] @ xf + filt[3][0] * uk
            xf = filt[0] @ xf + filt[1][:, 0] * uk
            xp = a @ xp + b[:, 0] * v[0]
        x = m.A @ x + m.B[:, 0] * uk


# ---------------------------------------------------------------------------- controllers
def _law_matches_state_space(ctl, e):
    a, b, c, d, ts = ctl.state_space()
    assert c.shape == (2, a.shape[0]) and d.shape == (2, 1) and b.shape == (a.shape[0], 1)
    ctl.reset()
    x = np.zeros(a.shape[0])
    worst = 0.0
    for ek in e:
        u = np.array(ctl.step(ek))
        ref = c @ x + d[:, 0] * ek
        x = a @ x + b[:, 0] * ek
        worst = max(worst, float(np.max(np.abs(u - ref) / (1.0 + np.abs(ref)))))
    return worst


def test_exported_state_space_is_the_law(prima, reference):
    free = LinearDualStage(
        prima.coarse,
        prima.fine,
        prima.Ts,
        coarse_stroke=prima.coarse_stroke,
        fine_stroke=prima.fine_stroke,
        disturbances=[REF],
    )
    e = reference[:400] * 0.1
    # the same recursion evaluated in another order: rounding of the commands' size
    assert _law_matches_state_space(LQG(free), e) < 1e-8
    assert _law_matches_state_space(FrequencySplit(free, 2.0, 150.0), e) < 1e-8


def test_lqg_meets_its_robustness_bound_and_tracks(prima, reference):
    ctl = LQG(prima)
    assert ctl.peak_sensitivity <= 2.0 + 1e-9
    assert ctl.peak_sensitivity > 1.9  # the bisection takes the fastest observer allowed
    run = ddl.simulate_linear(
        prima.with_disturbances(()), ctl, reference.size, signals={"output": reference}
    )
    assert run.metrics["rms"] < 5e-9
    assert run.metrics["fine_out_steps"] == 0 and run.metrics["clipped_steps"] == 0


def test_frequency_split_reaches_its_bandwidths(prima, reference):
    ctl = FrequencySplit(prima, 2.0, 150.0)
    assert ctl.coarse_crossover == pytest.approx(2.0, rel=0.05)
    assert ctl.fine_crossover == pytest.approx(150.0, rel=0.2)
    run = ddl.simulate_linear(
        prima.with_disturbances(()), ctl, reference.size, signals={"output": reference}
    )
    assert run.metrics["rms"] < 70e-9
    assert run.metrics["fine_out_steps"] == 0


def test_mpc_first_move_is_the_lqg_without_active_constraints(prima):
    mpc = LinearMPC(prima)
    q = mpc.lqg
    rng = np.random.default_rng(0)
    x = np.array([1e-7, 1e-4, 1e-7, 1e-4, 1e-6, 1e-6]) * rng.standard_normal(6)
    q._xbar = x.copy()
    u = np.array(mpc.step(float(q._ce @ x)))  # innovation 0: the estimate stays x
    # unit blocks + the LQG's cost-to-go as terminal cost: the same minimiser; the stack's
    # damping threshold (1e-7 of the largest singular value) bounds the difference
    np.testing.assert_allclose(u, -(q.K @ x), rtol=1e-3)


def test_mpc_keeps_the_fine_stroke_first(prima):
    # a 40 µm output step: beyond the fine stroke (±15 µm), so the fine stage alone cannot
    # take it; the stroke level holds it inside its margin while the coarse stage moves
    mpc = LinearMPC(prima, margin=0.1)
    lqg = LQG(prima)
    n = 400
    d = np.full(n, 40e-6)
    r_mpc = ddl.simulate_linear(prima.with_disturbances(()), mpc, n, signals={"output": d})
    r_lqg = ddl.simulate_linear(prima.with_disturbances(()), lqg, n, signals={"output": d})
    assert r_lqg.metrics["fine_max"] > 13.5e-6  # the LQG uses the stroke
    # the level holds the *predicted* stroke; the estimate's error after the step (measured
    # 0.02 µm) is what the true position may exceed it by: 0.1 µm is 0.3 % of the stroke
    assert r_mpc.metrics["fine_max"] <= 12e-6 + 0.1e-6
    assert mpc.fallback_steps == 0


@pytest.mark.parametrize("kind", ["lqg", "split", "mpc"])
def test_generic_controllers_run_the_nonlinear_prima_plant(prima, kind):
    r = ddl.kolmogorov_opd(0.25, FS, seed=3, preset="paranal_250hz")
    law = {
        "lqg": lambda: LQG(prima),
        "split": lambda: FrequencySplit(prima, 2.0, 150.0),
        "mpc": lambda: LinearMPC(prima),
    }[kind]()
    run = ddl.simulate(ddl.DualStage(), ddl.OnDualStage(law), r, FS)
    m = run.metrics
    assert m["saturated_steps"] == 0 and not m["lost_sync"]
    assert m["rmse"] < (70e-9 if kind == "split" else 10e-9)


def test_lqg_robust_rule_checks_stability_not_only_the_peak(prima):
    from qpcoord.ddl.lqg import closed_loop_poles

    ctl = LQG(prima)
    assert np.max(np.abs(closed_loop_poles(prima, ctl))) < 1.0
    other = ddl.DualStage().linear(4000.0)
    with pytest.raises(ValueError, match=r"robust_plants\[0\] must have the plant's"):
        LQG(prima, robust_plants=[other])
    # a controller with the wrong sign destabilises: its peak is reported as inf
    bad = LQG(prima)
    bad.K = -bad.K
    assert np.max(np.abs(closed_loop_poles(prima, bad))) > 1.0
    assert bad.peak() == math.inf


def test_frequency_split_on_an_integrating_coarse_stage():
    # a free 2 kg carriage (force → position, 1/(m s²)): no static gain, so the coarse loop
    # is an LQG whose weight is bisected to the crossover
    ts = 1e-4
    w = 2 * math.pi * 1500.0
    plant = LinearDualStage(
        control.tf([0.5], [1.0, 0.0, 0.0]),
        control.tf([2e-6 * w * w], [1.0, 2 * 0.3 * w, w * w]),
        ts,
        fine_stroke=40e-6,
        disturbances=[REF],
    )
    ctl = FrequencySplit(plant, 20.0, 300.0)
    from qpcoord.ddl.lqg import closed_loop_poles

    assert np.max(np.abs(closed_loop_poles(plant, ctl))) < 1.0
    assert ctl.coarse_crossover == pytest.approx(20.0, rel=0.3)
    assert _law_matches_state_space(ctl, 1e-7 * np.sin(np.arange(300) * 0.05)) < 1e-8
