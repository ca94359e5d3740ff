"""Linearised coarse controllers that move the carriage, and the
thesis's current-driven LQR and PQ (qpcoord.ddl.dither, drive, lqr_current, pq_current)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import qpcoord.ddl as ddl
from qpcoord.ddl.dither import dither_model
from qpcoord.ddl.drive import LinearisingDrive
from qpcoord.ddl.lqr_current import LQRCurrent, design_model_force
from qpcoord.ddl.pq_current import PQCurrent
from qpcoord.ddl.references import fig619_steps

FS = 8000.0


@pytest.fixture(scope="module")
def kolmo():
    return ddl.kolmogorov_opd(2.0, FS, seed=0, preset="paranal_250hz")


def travel(run):
    return float(np.ptp(run.y_c) / np.ptp(run.r))


# ---------------------------------------------------------------------------- dither model
def test_dither_model_matches_a_simulated_carriage():
    """v_d from the formula against the plant's own friction under the square wave."""
    plant = ddl.DualStage()
    st = plant.stepper
    r = st.screw_radius
    fc, fst = st.coulomb_torque / r, st.static_torque / r
    mass = plant.carriage_mass(0.0)
    dm = dither_model(2.0 * fst, fc, fst, mass, FS)
    assert dm.damping == pytest.approx(fc / dm.velocity)
    assert dm.ripple == pytest.approx(dm.velocity * 4 / FS / 8)
    assert dm.ripple < 1.25e-9  # below one metrology quantum
    # drive the plant with the dither alone (currents in quadrature at the carriage)
    plant.reset(FS)
    drive = LinearisingDrive()
    drive.reset(plant)
    v = []
    for k in range(400):
        f = dm.amplitude if k % 4 < 2 else -dm.amplitude
        ia, ib, _ = drive.command(f, plant.y_c)
        plant.step(plant.fine.v_centre, ia, ib)
        v.append(plant.yd_c)
    v = np.array(v[200:])
    assert np.max(np.abs(v)) == pytest.approx(dm.velocity, rel=0.15)
    assert dm.friction(2 * dm.velocity) == pytest.approx(fc)
    assert dm.friction(-0.5 * dm.velocity) == pytest.approx(-0.5 * fc)


def test_dither_model_rejects_bad_input():
    with pytest.raises(ValueError, match="amplitude"):
        dither_model(30.0, 31.4, 40.8, 491.0, FS)
    with pytest.raises(ValueError, match="period"):
        dither_model(80.0, 31.4, 40.8, 491.0, FS, period=3)
    with pytest.raises(ValueError, match="static"):
        dither_model(80.0, 31.4, 20.0, 491.0, FS)
    with pytest.raises(ValueError, match="dither_ratio"):
        ddl.PILinearised(dither_ratio=0.9)
    with pytest.raises(ValueError, match="friction"):
        ddl.PILinearised(friction="coulomb")


# ---------------------------------------------------------------------------- drive
def test_drive_cancels_flexure_and_detent_and_saturates():
    plant = ddl.DualStage()
    drive = LinearisingDrive(current=1.5, d_current=0.0)
    drive.reset(plant)
    st = plant.stepper
    y = 20e-3  # flexure loaded
    ia, ib, f = drive.command(100.0, y)
    th = y * st.electrical_per_metre
    torque = st.torque_constant * (ia * math.cos(th) - ib * math.sin(th))
    torque -= st.detent_torque * math.sin(4 * th)
    force = torque / st.screw_radius - plant.flexure.spring_rate * y
    assert force == pytest.approx(100.0, rel=1e-9) and f == 100.0 and not drive.saturated
    ia, ib, f = drive.command(1e5, 0.0)
    assert drive.saturated and math.hypot(ia, ib) == pytest.approx(1.5)
    assert f == pytest.approx(drive.force_max)
    with pytest.raises(ValueError, match="force"):
        drive.command(math.nan, 0.0)


# ---------------------------------------------------------------------------- finding 1
@pytest.mark.parametrize("cls", [ddl.PILinearised, ddl.FlatnessBased], ids=lambda c: c.__name__)
def test_linearised_controllers_move_the_carriage(cls, kolmo):
    """The audit's case: friction-free design sticks (travel 0), the default carries."""
    stuck = ddl.simulate(ddl.DualStage(), cls(friction="none"), 3.0 * kolmo, FS)
    assert travel(stuck) < 0.05
    for scale in (1.0, 3.0):
        run = ddl.simulate(ddl.DualStage(), cls(), scale * kolmo, FS)
        m = run.metrics
        assert travel(run) > 0.8, scale
        assert m["saturated_steps"] == 0 and not m["lost_sync"]
        assert m["power"] < 0.05  # far below the direct coil's 2.25 W
    # the stuck design leaves the excursion to the fine stage: less margin to its stops
    assert stuck.metrics["fine_margin_min"] < run.metrics["fine_margin_min"]


def test_dithered_coarse_pi_meets_its_rule():
    plant = ddl.DualStage()
    ctl = ddl.PILinearised()
    ctl.reset(plant, FS, plant.reset(FS), 0.0)
    mass, c = plant.carriage_mass(0.0), plant.stepper.viscous_damping + ctl.dither.damping
    s = 2j * math.pi * 2.0
    loop = (ctl._ckp + ctl._cki / s) / (s * (mass * s + c))
    assert abs(loop) == pytest.approx(1.0, rel=1e-9)
    assert 180 + math.degrees(np.angle(loop)) == pytest.approx(75.8, abs=0.1)
    st = plant.stepper
    gap = (st.static_torque - st.coulomb_torque) / st.screw_radius  # stiction excess, N
    assert ctl._ckp * 1e-6 > 2.0 * gap  # a 1 µm error is worth twice the stiction excess


# ---------------------------------------------------------------------------- finding 2
def test_force_model_is_the_linearised_carriage():
    plant = ddl.DualStage()
    mo = design_model_force(plant, FS)
    assert mo.inputs == ("v", "F")
    a = mo.continuous.A
    assert a[3, 2] == 0.0  # no magnetic spring: the drive cancels the flexure
    assert a[3, 3] == pytest.approx(-plant.stepper.viscous_damping / plant.carriage_mass())
    assert mo.continuous.B[3, 1] == pytest.approx(1.0 / plant.carriage_mass())
    assert mo.Nx[2] == pytest.approx(1.0) and mo.Nu[1] == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ValueError, match="y_c"):
        design_model_force(plant, FS, y_c=1.0)


def test_lqr_current_design_rule_and_no_rate_limit():
    ctl = LQRCurrent().design(ddl.DualStage(), FS)
    rep = ctl.report()
    assert rep["peak_sensitivity"] <= 1.6 and rep["max_pole_modulus"] < 1.0
    assert ctl.max_speed == math.inf
    # power on Kolmogorov: amplitude-controlled, ≪ the direct coil's 2.25 W
    r = ddl.kolmogorov_opd(1.0, FS, seed=0, preset="paranal_250hz")
    run = ddl.simulate(ddl.DualStage(), LQRCurrent(), r, FS)
    assert run.metrics["power"] < 0.05 and travel(run) > 0.5
    # a 5 mm step without rate limit: the carriage gets there far faster than 3 mm/s allows
    step = fig619_steps(1.0, FS)["centre"]
    run = ddl.simulate(ddl.DualStage(), LQRCurrent(), step, FS)
    k = int(0.5 * FS)
    assert abs(run.y[k] - step[k]) < 1e-6
    assert np.max(np.abs(np.diff(run.y_c))) * FS > 0.03


def test_pq_current_hands_over_at_its_crossover():
    ctl = PQCurrent().design(ddl.DualStage(), FS)
    rep = ctl.report()
    assert rep["pq_crossover_hz"] == pytest.approx(60.0, rel=0.1)
    assert rep["coarse_share"][10.0] > 0.95 and rep["coarse_share"][234.0] < 0.25
    assert rep["max_pole_modulus"] < 1.0 and rep["phase_margin_deg"] > 45.0
    with pytest.raises(ValueError, match="lowpass_ratio"):
        PQCurrent(lowpass_ratio=1.0)
    with pytest.raises(ValueError, match="lowpass corner"):
        PQCurrent(pq_crossover=1000.0).design(ddl.DualStage(), FS)
    with pytest.raises(RuntimeError, match="design"):
        PQCurrent().report()


def test_pq_current_coarse_steps_through_stiction(kolmo):
    """Design without friction: the carriage waits until the fine stage's share builds the
    breakaway force (≈ F_s/(ω_pq c) ≈ 7 µm), then jumps — the thesis's stepping."""
    run = ddl.simulate(ddl.DualStage(), PQCurrent(), 3.0 * kolmo, FS)
    assert run.metrics["saturated_steps"] == 0
    moving = np.abs(np.diff(run.y_c)) > 0
    assert 0.0 < moving.mean() < 0.9  # sticks part of the time, moves part of the time
