"""Thesis coordinator + simulate on the DDL plant (short versions of the chapter-6 spec)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import qpcoord.ddl as ddl
from qpcoord.ddl.references import fig619_steps

FS = 8000.0


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_spec_on_250hz_preset_short(seed):
    """2 s instead of 10 s (the example runs 10 s on ≥ 20 seeds)."""
    r = ddl.kolmogorov_opd(2.0, FS, seed=seed, preset="paranal_250hz")
    run = ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(), r, FS)
    m = run.metrics
    assert m["rmse"] < 70e-9
    assert m["saturated_steps"] == 0 and m["fine_margin_min"] > 5e-6
    assert m["power"] < 5.0 and m["power"] == pytest.approx(2.25, rel=1e-6)  # I = 1.5 A
    assert not m["lost_sync"] and m["coarse_stop_steps"] == 0
    for name in ("y", "y_f", "y_c", "y_c_hat", "v", "i_a", "i_b"):
        arr = getattr(run, name)
        assert arr.shape == r.shape and np.all(np.isfinite(arr))
    # the coordinator's carriage estimate follows the true carriage (fine model is exact here)
    assert np.max(np.abs(run.y_c_hat - run.y_c)) < 5e-9


def _drift():
    # 0.1 mm in 2 s (peak 79 µm/s), then hold: 3× the fine stroke, carried by the coarse stage
    t = np.arange(int(3.0 * FS)) / FS
    return 0.05e-3 * (1 - np.cos(math.pi * np.minimum(t, 2.0) / 2.0))


def test_coarse_keeps_fine_centred_on_drift():
    r = _drift()
    run = ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(), r, FS)
    assert run.metrics["saturated_steps"] == 0
    # type-1 coarse loop: lag ≈ v / (2π · 2 Hz) ≈ 6 µm at the peak speed, then back to centre
    assert 3e-6 < run.metrics["fine_excursion"] < 12e-6
    assert run.y_f[-1] == pytest.approx(15e-6, abs=0.5e-6)


def test_feedforward_of_coarse_motion_reduces_error():
    r = _drift()
    with_ff = ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(), r, FS).metrics
    without = ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(feedforward=False), r, FS).metrics
    assert with_ff["rmse"] < 0.95 * without["rmse"]


def test_5mm_steps_centre_and_extremity():
    for name, r in fig619_steps(3.0, FS).items():
        run = ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(), r, FS)
        m = run.metrics
        assert not m["lost_sync"], name
        # the fine stage saturates during the move (5 mm ≫ 30 µm) — reported, not raised
        assert m["saturated_steps"] > 0
        assert abs(run.error[-1]) < 10e-9, name
        assert np.all(np.abs(run.error[-int(0.5 * FS) :]) < 50e-9), name


class _SpinField:
    """A deliberately bad controller: spins the field far faster than the rotor can follow."""

    def reset(self, plant, fs, y0, r0):
        self.a = plant.equilibrium_phase(1.5)

    def step(self, y, r):
        self.a += 0.5
        return 5.0, 1.5 * math.sin(self.a), 1.5 * math.cos(self.a)


def test_lost_synchronism_reported_not_raised():
    run = ddl.simulate(ddl.DualStage(), _SpinField(), np.zeros(800), FS)
    assert run.metrics["lost_sync"] and run.metrics["sync_slip_steps"] > 0
    assert run.y_c_hat.size == 0  # this controller has no estimate: nothing is invented


def test_bad_input():
    plant = ddl.DualStage()
    r = np.zeros(100)
    with pytest.raises(ValueError, match="fine_kp"):
        ddl.SisoCoordinator(fine_kp=-1.0)
    with pytest.raises(ValueError, match="coarse_bandwidth"):
        ddl.SisoCoordinator(coarse_bandwidth=-2.0)
    with pytest.raises(ValueError, match="not finite at sample 3"):
        bad = r.copy()
        bad[3] = np.nan
        ddl.simulate(plant, ddl.SisoCoordinator(), bad, FS)
    with pytest.raises(ValueError, match="leaves the stroke"):
        ddl.simulate(plant, ddl.SisoCoordinator(), np.full(100, 0.04), FS)
    with pytest.raises(ValueError, match="shorter than one control step"):
        ddl.simulate(plant, ddl.SisoCoordinator(), np.zeros(1), FS)
    with pytest.raises(ValueError, match="fs = 800"):
        ddl.simulate(plant, ddl.SisoCoordinator(), r, 800.0)


def test_literal_eq61_is_unstable_and_default_is_not():
    """Eq 6.1 read literally (α = double integral of the error) does not converge."""
    t = np.arange(int(1.5 * FS)) / FS
    r = np.where(t > 0.05, 5e-6, 0.0)
    ok = ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(), r, FS)
    lit = ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(literal_eq61=True), r, FS)
    tail = slice(-int(0.5 * FS), None)
    # default: the carriage settles where the piezo is centred
    assert np.ptp(ok.y_c[tail]) < 0.2e-6
    # literal: the carriage keeps oscillating with a growing or rate-limited amplitude
    assert np.ptp(lit.y_c[tail]) > 20 * np.ptp(ok.y_c[tail])


def test_progress_is_off_by_default(capsys):
    r = np.zeros(400)
    ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(), r, FS)
    assert capsys.readouterr().err == ""
    ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(), r, FS, progress=True)
    assert "100 %" in capsys.readouterr().err
