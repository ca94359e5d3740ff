"""Measurement faults: the shared MeasurementGuard and every controller.

Each controller runs 0.3 s of the paranal_250hz Kolmogorov reference at 8 kHz (seed 0); a
fault is injected at 0.15 s and the run is compared with the fault-free run of the same seed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import qpcoord.ddl as ddl
from qpcoord.ddl import faults
from qpcoord.ddl.guard import (
    MeasurementGuard,
    carriage_speed_bound,
    describe_bounds,
    fine_speed_bound,
    max_jump,
)

FS = 8000.0
N = 2400  # 0.3 s
KF = 1200  # fault at 0.15 s
W25 = int(0.025 * FS)  # 25 ms
Q = 1.25e-9  # metrology quantum, m

CONTROLLERS = {
    "coordinator": ddl.SisoCoordinator,
    "LQR": ddl.LQR,
    "PQ": ddl.PQ,
    "MPC": ddl.MPC,
    "PILinearised": ddl.PILinearised,
    "FlatnessBased": ddl.FlatnessBased,
}


@pytest.fixture(scope="module")
def reference():
    return ddl.kolmogorov_opd(N / FS, FS, seed=0, preset="paranal_250hz")


_CLEAN = {}


def clean_run(name, reference):
    if name not in _CLEAN:
        _CLEAN[name] = ddl.simulate(ddl.DualStage(), CONTROLLERS[name](), reference, FS)
    return _CLEAN[name]


def faulty_run(name, reference, fault):
    return ddl.simulate(ddl.DualStage(), CONTROLLERS[name](), reference, FS, faults=fault)


def rms(x):
    return math.sqrt(float(np.mean(np.asarray(x) ** 2)))


def assert_finite_commands(run):
    for a in (run.v, run.i_a, run.i_b):
        assert np.all(np.isfinite(a))


# ---------------------------------------------------------------------------- the rule
def test_bounds_of_the_default_plant():
    b = describe_bounds(ddl.DualStage(), FS)
    # piezo: 10 V range, 300 Hz, ζ = 0.7 -> 27.2 mm/s; carriage: 4847 N / 14790 N·s/m
    assert b["fine_speed_bound"] == pytest.approx(0.02718, rel=1e-3)
    assert b["carriage_speed_bound"] == pytest.approx(0.3277, rel=1e-3)
    assert b["fine_jump"] == pytest.approx(3.398e-6, rel=1e-3)
    assert b["carriage_jump"] == pytest.approx(40.96e-6, rel=1e-3)
    assert b["max_jump"] == pytest.approx(66.54e-6, rel=1e-3)
    assert b["output_range"] == pytest.approx((-0.035, 0.03503))


@pytest.mark.parametrize("zeta", [0.3, 0.7, 1.0, 1.5])
def test_fine_speed_bound_is_reached_by_bang_bang(zeta):
    """The closed form equals (v_max − v_min) × the upward variation of the sampled h(t)."""
    import dataclasses

    from scipy import signal

    fp = dataclasses.replace(ddl.FineParams(), damping=zeta)
    wn = 2.0 * math.pi * fp.natural_frequency
    t = np.linspace(0.0, 60.0 / (zeta * wn), 40001)
    _, h = signal.impulse(signal.lti([fp.gain * wn * wn], [1.0, 2.0 * zeta * wn, wn * wn]), T=t)
    tv = (fp.v_max - fp.v_min) * float(np.sum(np.maximum(np.diff(h), 0.0)))
    assert fine_speed_bound(fp) == pytest.approx(tv, rel=1e-3)


def test_no_viscous_damping_means_no_jump_bound():
    import dataclasses

    st = dataclasses.replace(ddl.StepperParams(), viscous_damping=0.0)
    plant = ddl.DualStage(stepper=st)
    assert carriage_speed_bound(plant) == math.inf
    assert max_jump(plant, FS) == math.inf


def test_guard_unit():
    plant = ddl.DualStage()
    plant.reset(FS)
    g = MeasurementGuard()
    g.reset(plant, FS, 1e-5, 1e-5)
    j = g.max_jump
    assert g.filter(1e-5 + 0.5 * j, 0.0, -1.0) == (1e-5 + 0.5 * j, 0.0)
    last = 1e-5 + 0.5 * j
    for bad in (last + 1.01 * j, math.nan, math.inf, -math.inf, 0.1):
        y, _ = g.filter(bad, 0.0, 7e-6)
        assert y == 7e-6  # the prediction
    assert g.rejected == 5
    # the allowance grows with the periods since the last accepted sample: 6 periods now
    y, _ = g.filter(last + 5.5 * j, 0.0, 0.0)
    assert y == last + 5.5 * j and g.rejected == 5
    # a non-finite prediction falls back on the last accepted measurement
    assert g.filter(math.nan, 0.0, math.nan)[0] == last + 5.5 * j
    # references: non-finite or unreachable -> last valid one
    assert g.filter(last + 5.5 * j, math.nan, 0.0)[1] == 0.0
    assert g.filter(last + 5.5 * j, 2e-6, 0.0)[1] == 2e-6
    assert g.filter(last + 5.5 * j, 1.0, 0.0)[1] == 2e-6
    assert g.rejected_references == 2
    with pytest.raises(ValueError, match="max_jump"):
        MeasurementGuard(max_jump=-1.0)
    with pytest.raises(ValueError, match="guard"):
        ddl.LQR(guard="yes")


# ---------------------------------------------------------------------------- simulate hook
def test_simulate_fault_hook(reference):
    clean = clean_run("coordinator", reference)
    assert clean.metrics["rejected_samples"] == 0
    assert clean.y_sensor.size == 0
    run = faulty_run(
        "coordinator", reference, faults.combine(faults.sample(KF), faults.spike(5, 1e-9))
    )
    assert math.isnan(run.y_sensor[KF]) and np.isfinite(run.y).all()
    assert run.y_sensor[5] == pytest.approx(run.y[5] + 1e-9)
    with pytest.raises(ValueError, match="sample index"):
        faulty_run("coordinator", reference, {N: 0.0})
    with pytest.raises(ValueError, match="faults must be"):
        faulty_run("coordinator", reference, [1, 2])


def test_unguarded_controller_still_fails_loudly(reference):
    """Without a guard a NaN reaches the plant, which raises."""

    class NoGuard:
        def reset(self, plant, fs, y0, r0):
            self.v = plant.v_applied

        def step(self, y, r):
            return self.v + 0.0 * y, 0.0, 1.5

    with pytest.raises(ValueError, match="non-finite command"):
        faulty_run_ctl = ddl.simulate(
            ddl.DualStage(), NoGuard(), reference, FS, faults={3: math.nan}
        )
        del faulty_run_ctl


# ---------------------------------------------------------------------------- every controller
@pytest.mark.parametrize("name", list(CONTROLLERS))
@pytest.mark.parametrize("value", [math.nan, 0.1], ids=["nan", "0.1m"])
def test_single_fault_rejected_and_recovered(name, value, reference):
    clean = clean_run(name, reference)
    run = faulty_run(name, reference, faults.sample(KF, value))
    assert run.metrics["rejected_samples"] == 1
    assert_finite_commands(run)
    # no saturation caused by the fault, no slip
    assert run.metrics["saturated_steps"] == clean.metrics["saturated_steps"] == 0
    assert not run.metrics["lost_sync"]
    # within 25 ms the error is back to the fault-free run's: window RMSE within 5 % (+1 q)
    # and no sample further than 4 quanta from the fault-free error
    w = slice(KF + W25, N)
    e, e0 = run.error[w], clean.error[w]
    assert rms(e) <= 1.05 * rms(e0) + Q
    assert np.max(np.abs(e - e0)) <= 4 * Q
    # and even the fault's own period is barely disturbed (the prediction stands in)
    assert np.max(np.abs(run.error[KF:] - clean.error[KF:])) <= 10 * Q


@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_nan_burst(name, reference):
    """8 consecutive NaNs (1 ms) and a 50 ms NaN blackout: counted, no NaN, recovered."""
    clean = clean_run(name, reference)
    for length, tol in ((8, 200e-9), (400, 1e-6)):
        run = faulty_run(name, reference, faults.burst(KF - 400, length))
        assert run.metrics["rejected_samples"] == length
        assert_finite_commands(run)
        assert run.metrics["saturated_steps"] == 0
        end = KF - 400 + length
        assert np.max(np.abs(run.error[end:] - clean.error[end:])) <= tol
        # 25 ms after the burst the error is at its fault-free level
        w = slice(end + W25, N)
        assert rms(run.error[w]) <= 1.1 * rms(clean.error[w]) + Q


@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_stuck_sensor(name, reference):
    """A sensor frozen for 20 ms is a *possible* reading: not rejected, and no NaN, no slip."""
    run = faulty_run(name, reference, faults.stuck(KF - 400, 160))
    assert run.metrics["rejected_samples"] == 0
    assert_finite_commands(run)
    assert not run.metrics["lost_sync"]
    assert np.isfinite(run.metrics["rmse"])


@pytest.mark.parametrize("name", list(CONTROLLERS))
def test_nan_reference_is_held(name):
    plant = ddl.DualStage()
    ctl = CONTROLLERS[name]()
    y = plant.reset(FS, y0=1e-6)
    ctl.reset(plant, FS, y, 1e-6)
    for k in range(20):
        r = math.nan if k in (3, 4) else 1e-6
        y_in = math.inf if k == 10 else y
        cmd = ctl.step(y_in, r)
        assert all(math.isfinite(c) for c in cmd)
        y = plant.step(*cmd)
    assert ctl.guard.rejected_references == 2
    assert ctl.guard.rejected == 1
