"""DDL plant (qpcoord.ddl.DualStage): parameters, linearisation, chirp identification, limits."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest

import qpcoord.ddl as ddl
from qpcoord.ddl.identify import coarse_frf, fine_frf, peak_frequency

FS = 8000.0


def hold_currents(plant, current=1.5):
    a = plant.equilibrium_phase(current)
    return current * math.sin(a), current * math.cos(a)


def test_linearise_modes_and_gains():
    plant = ddl.DualStage()
    sys = plant.linearise()
    assert isinstance(sys, control.StateSpace)
    freqs = sorted(np.abs(np.linalg.eigvals(sys.A)) / (2 * math.pi))
    assert freqs[0] == pytest.approx(120.0, rel=0.01)  # calibrated electromechanical mode
    assert freqs[-1] == pytest.approx(300.0, rel=1e-9)  # piezo model
    dc = control.dcgain(sys)  # outputs (y, y_f, y_c) × inputs (v, alpha)
    assert dc[1, 0] == pytest.approx(3e-6, rel=1e-9)  # 30 µm / 10 V
    st = plant.stepper
    # rotor follows the field, softened by the detent and flexure springs at the centre
    k_mag = st.torque_constant * 1.5 * st.pole_pairs / st.screw_radius**2
    expected = st.screw_radius / st.pole_pairs * k_mag / plant.coarse_stiffness(0.0)
    assert dc[2, 1] == pytest.approx(expected, rel=1e-9)
    assert 0.9 < expected / (st.screw_radius / st.pole_pairs) < 1.0
    cur = plant.linearise(inputs="currents")
    assert cur.ninputs == 3 and cur.noutputs == 3


def test_chirp_identifies_coarse_resonance_near_120hz_at_centre():
    plant = ddl.DualStage()
    f, h, coh = coarse_frf(plant, fs=FS, y_c=0.0)
    fr = peak_frequency(f, h, fmin=30.0, fmax=300.0)
    assert abs(fr - 120.0) / 120.0 < 0.10, fr
    assert np.abs(h).max() > 5.0  # a sharp, lightly damped peak
    assert not plant.lost_sync


def test_chirp_identifies_piezo_bandwidth():
    plant = ddl.DualStage()
    f, h, _ = fine_frf(plant, fs=FS)
    bw = ddl.bandwidth_3db(f[5:], h[5:], reference=1.0)
    assert bw == pytest.approx(300.0, rel=0.1)


def test_flexure_load_range_and_resonance_vs_position():
    fl = ddl.BladeFlexure()
    assert float(fl.force(0.035)) == pytest.approx(-150.0)
    assert float(fl.force(-0.035)) == pytest.approx(150.0)
    x = np.linspace(-0.035, 0.035, 71)
    fr = fl.resonance(x)
    assert np.all(np.diff(fr[35:]) < 0) and np.allclose(fr, fr[::-1])
    a, _ = fl.linear_model(0.02)
    w = np.sqrt(-a[1, 0]) / (2 * math.pi)
    assert w == pytest.approx(float(fl.resonance(0.02)), rel=1e-12)
    plant = ddl.DualStage()
    assert plant.coarse_resonance(0.034) < plant.coarse_resonance(0.0)


def test_fine_stage_saturates_and_stops():
    plant = ddl.DualStage()
    plant.reset(FS)
    ia, ib = hold_currents(plant)
    for _ in range(200):
        plant.step(10.0, ia, ib)
    assert plant.y_f == pytest.approx(30e-6, abs=1e-9)
    plant.step(50.0, ia, ib)  # clipped to 10 V: pushes into the stop
    assert plant.fine_saturated and plant.y_f == 30e-6 and plant.yd_f == 0.0
    assert plant.v_applied == 10.0
    for _ in range(400):
        plant.step(5.0, ia, ib)
    assert plant.y_f == pytest.approx(15e-6, rel=1e-6)
    assert not plant.fine_saturated


def test_stiction_holds_then_breaks_away():
    plant = ddl.DualStage()
    plant.reset(FS)
    x0 = plant.y_c
    st = plant.stepper
    a0 = plant.equilibrium_phase(1.5)
    # a field offset whose torque is below stiction: the carriage does not move
    small = 0.5 * st.static_torque / (st.torque_constant * 1.5)
    for _ in range(100):
        plant.step(5.0, 1.5 * math.sin(a0 + small), 1.5 * math.cos(a0 + small))
    assert plant.y_c == x0
    big = 0.2
    for _ in range(100):
        plant.step(5.0, 1.5 * math.sin(a0 + big), 1.5 * math.cos(a0 + big))
    assert plant.y_c - x0 > 0.5 * big * st.screw_radius / st.pole_pairs


def test_loss_of_synchronism_is_detected():
    plant = ddl.DualStage()
    plant.reset(FS)
    a0 = plant.equilibrium_phase(1.5)
    for k in range(200):  # slow field rotation: the rotor follows
        a = a0 + 0.002 * k
        plant.step(5.0, 1.5 * math.sin(a), 1.5 * math.cos(a))
    assert not plant.lost_sync
    for k in range(400):  # 0.5 rad per step = 4000 rad/s electrical: far beyond pull-out
        a = a0 + 0.4 + 0.5 * k
        plant.step(5.0, 1.5 * math.sin(a), 1.5 * math.cos(a))
    assert plant.lost_sync and plant.sync_slip_steps > 0


def test_metrology_quantisation_and_seeded_noise():
    plant = ddl.DualStage(noise_rms=2e-9)
    ia = ib = None
    out = []
    for _ in range(2):
        plant.reset(FS, y0=1e-4, seed=3)
        ia, ib = hold_currents(plant)
        out.append([plant.step(5.0, ia, ib) for _ in range(50)])
    assert out[0] == out[1]
    q = np.asarray(out[0]) / 1.25e-9
    assert np.allclose(q, np.round(q), atol=1e-6)
    plant.reset(FS, y0=1e-4, seed=4)
    assert [plant.step(5.0, ia, ib) for _ in range(50)] != out[0]


class _Backlash:
    """A tiny hysteresis element (play operator, 0.5 V wide) to test duck typing."""

    def __init__(self):
        self.calls = 0

    def reset(self):
        self.out = None

    def step(self, volts):
        self.calls += 1
        if self.out is None:
            self.out = volts
        self.out = min(max(self.out, volts - 0.25), volts + 0.25)
        return self.out


def test_hysteresis_duck_typing():
    hyst = _Backlash()
    plant = ddl.DualStage(hysteresis=hyst)
    plant.reset(FS)
    ia, ib = hold_currents(plant)
    for _ in range(300):
        plant.step(6.0, ia, ib)
    up = plant.y_f
    for _ in range(300):
        plant.step(5.9, ia, ib)  # inside the play: no motion
    assert plant.y_f == pytest.approx(up, abs=1e-12)
    assert up == pytest.approx(3e-6 * 5.75, rel=1e-6)
    assert hyst.calls >= 600
    with pytest.raises(ValueError, match="hysteresis"):
        ddl.DualStage(hysteresis=object())


def test_bad_input():
    plant = ddl.DualStage()
    with pytest.raises(ValueError, match="fs"):
        plant.reset(500.0)
    with pytest.raises(ValueError, match="coarse stroke"):
        plant.reset(FS, y0=0.05)
    plant.reset(FS)
    with pytest.raises(ValueError, match="non-finite"):
        plant.step(float("nan"), 0.0, 1.5)
    with pytest.raises(ValueError, match="gain"):
        ddl.FineParams(gain=-1.0)
    with pytest.raises(ValueError, match="static_torque"):
        ddl.StepperParams(static_torque=0.001)
    with pytest.raises(ValueError, match="inputs"):
        plant.linearise(inputs="voltage")
