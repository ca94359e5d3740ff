"""Two DDLs on one optical path (thesis §6.3), measured on the simulated closed loops."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord.ddl as ddl
from qpcoord.ddl.two_ddl import combine, simulate_two_ddl, two_ddl_frf, two_ddl_steps

FS = 8000.0


@pytest.fixture(scope="module")
def frf():
    return two_ddl_frf(ddl.DualStage, ddl.SisoCoordinator, FS, k=6e-4, duration=1.0)


def test_dual_bandwidth_gain_measured(frf):
    assert 300.0 < frf["bw_single"] < 600.0
    assert frf["gain_dual"] > 1.2  # two DDLs: 1 − S² instead of 1 − S
    assert frf["gain_dual_pred"] >= frf["gain_dual"] - 0.02


def test_measured_dual_matches_analytic_combination(frf):
    band = (frf["f"] > 5) & (frf["f"] < 400)
    pred = combine(frf["single"], 2j * np.pi * frf["f"], 0.0)
    rel = np.abs(pred[band] - frf["dual"][band]) / np.abs(frf["dual"][band])
    assert rel.max() < 0.05


def test_predictor_reduces_step_overshoot():
    s = two_ddl_steps(ddl.DualStage, ddl.SisoCoordinator, FS, k=6e-4, duration=0.02)
    assert s["overshoot_dual"] > s["overshoot_dual_pred"] > 0.0
    assert s["rise_dual_pred"] < s["rise_single"]


def test_second_ddl_reference_is_first_error():
    r = np.zeros(200)
    r[50:] = 1e-7
    res = simulate_two_ddl(ddl.DualStage, ddl.SisoCoordinator, r, FS, k=0.0)
    np.testing.assert_allclose(res["r2"], r - res["y1"])
    with pytest.raises(ValueError, match="k"):
        simulate_two_ddl(ddl.DualStage, ddl.SisoCoordinator, r, FS, k=-1.0)


def test_linear_fine_loop_model_matches_measured_single(frf):
    from qpcoord.ddl.two_ddl import fine_loop_model

    f_lin = fine_loop_model(ddl.DualStage(), ddl.SisoCoordinator(), FS)
    band = (frf["f"] > 20) & (frf["f"] < 600)
    z = np.exp(2j * np.pi * frf["f"][band] / FS)
    lin = np.array([f_lin(zi) for zi in z]).ravel()
    rel = np.abs(lin - frf["single"][band]) / np.abs(lin)
    assert rel.max() < 0.05


def test_analytic_gain_of_a_second_order_loop():
    from qpcoord.ddl.two_ddl import analytic_gain, second_order

    # closed form: a second-order F with ζ = 1/√2 has its −3 dB point at ωn exactly
    r = analytic_gain(1 / np.sqrt(2), 300.0)
    assert r["bw_single"] == pytest.approx(300.0, rel=1e-3)
    # without predictor the gain depends on ζ only, and rises with it
    g = [analytic_gain(z, 300.0)["gain"] for z in (0.5, 0.6, 0.7)]
    assert g == pytest.approx([1.49, 1.58, 1.71], abs=0.01)
    assert analytic_gain(0.6, 50.0)["gain"] == pytest.approx(g[1], rel=1e-3)
    # the predictor term −k s F² changes the combined bandwidth (here it narrows it)
    assert analytic_gain(0.6, 300.0, k=2e-4)["gain"] == pytest.approx(1.537, abs=0.01)
    assert second_order(0.0, 300.0, 0.6) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="damping"):
        analytic_gain(0.0)
    with pytest.raises(ValueError, match="points"):
        analytic_gain(0.5, points=10)
