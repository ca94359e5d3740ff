"""choose_controller: candidates designed on a linear dual stage, checked on fresh
realisations against a spec; the report names the failing items."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest

import qpcoord.ddl as ddl

TS = 1e-4


@pytest.fixture(scope="module")
def plant():
    coarse = control.tf([1.0 / 20.0], [1.0, 2 * 0.3 * 31.4, 31.4**2])
    w = 2 * math.pi * 1500.0
    fine = control.tf([2e-6 * w * w], [1.0, 2 * 0.3 * w, w * w])
    wl = 2 * math.pi * 200.0
    line = ddl.Disturbance(control.tf([2e-3 * wl], [1.0, 2 * 0.02 * wl, wl * wl]), "output")
    return ddl.LinearDualStage(
        coarse,
        fine,
        TS,
        coarse_range=(-50.0, 50.0),
        fine_range=(-10.0, 10.0),
        fine_stroke=40e-6,
        coarse_stroke=0.1,
        disturbances=[line],
        noise_rms=1e-9,
    )


def test_a_reachable_spec_is_met_by_the_choice(plant):
    ch = ddl.choose_controller(plant, ddl.Spec(rms=150e-9, fine_margin=5e-6), steps=1500)
    assert ch.met
    row = next(r for r in ch.candidates if r["name"] == ch.name)
    assert row["rms"] <= 150e-9 and row["fine_margin"] >= 5e-6 and not row["failures"]
    # the choice's law runs: its exported system is the plant's Ts
    assert ch.controller.state_space()[4] == TS


def test_an_unreachable_spec_reports_every_failing_item(plant):
    ch = ddl.choose_controller(plant, ddl.Spec(rms=1e-9, peak_sensitivity=1.01), steps=1500)
    assert not ch.met
    for row in ch.candidates:
        if "error" in row:
            assert "unstable" in row["error"]
            continue
        assert any(f.startswith("rms ") for f in row["failures"])
        assert any(f.startswith("peak |S| ") for f in row["failures"])
    assert "spec NOT met" in str(ch)


def test_surrogate_keeps_the_spectrum_not_the_signal():
    x = ddl.kolmogorov_opd(0.2, 8000.0, seed=2, preset="paranal_250hz")
    s = ddl.surrogate(x, seed=5)
    a, b = np.abs(np.fft.rfft(x - x.mean())), np.abs(np.fft.rfft(s - s.mean()))
    # same magnitudes: one FFT and its inverse apart (rounding of the largest bin)
    np.testing.assert_allclose(b, a, atol=1e-9 * a.max())
    assert np.corrcoef(x, s)[0, 1] < 0.9
    with pytest.raises(ValueError, match="recording must be"):
        ddl.surrogate([1.0, np.nan, 2.0, 3.0], seed=0)
