"""compare(): rows, failures recorded, mismatch cases, formatting; simulate's timing hook."""

from __future__ import annotations

import math

import numpy as np
import pytest

import qpcoord.ddl as ddl
from qpcoord.ddl.compare import (
    METRICS,
    Case,
    DelayedPlant,
    DesignedOn,
    compare,
    default_cases,
    format_grid,
    format_table,
    mismatched_plant,
    qualitative_grid,
)
from qpcoord.ddl.lqr import LQR
from qpcoord.ddl.pq import PQ

FS = 8000.0


class _FailsOnReset:
    def reset(self, plant, fs, y0, r0):
        raise RuntimeError("no design for you")

    def step(self, y, r):  # pragma: no cover - never reached
        return 5.0, 0.0, 1.5


class _FailsMidRun(ddl.SisoCoordinator):
    def reset(self, plant, fs, y0, r0):
        super().reset(plant, fs, y0, r0)
        self._k = 0

    def step(self, y, r):
        self._k += 1
        if self._k == 100:
            raise FloatingPointError("diverged at step 100")
        return super().step(y, r)


@pytest.fixture(scope="module")
def rows():
    ctls = {
        "coordinator": ddl.SisoCoordinator,
        "LQR": LQR,
        "PQ": PQ,
        "reset-fails": _FailsOnReset,
        "step-fails": _FailsMidRun,
        "ctor-fails": lambda: 1 / 0,
    }
    return compare(ctls, seeds=(0, 1), duration=0.4, step_duration=0.6, fs=FS)


def test_rows_are_well_formed(rows):
    cases = [c.name for c in default_cases()]
    assert cases == [
        "kolmogorov",
        "step_centre",
        "step_extremity",
        "mismatch+",
        "mismatch-",
        "latency2",
    ]
    # seeded cases once per seed, steps once: 4 × 2 + 2 = 10 runs per controller
    assert len(rows) == 6 * 10
    for r in rows:
        for k in ("controller", "case", "seed", "error", "lost_sync", *METRICS):
            assert k in r
    good = [r for r in rows if r["controller"] in ("coordinator", "LQR", "PQ")]
    for r in good:
        assert r["error"] is None
        assert r["rmse"] > 0 and math.isfinite(r["power"])
        assert r["step_time_median"] > 0 and r["step_time_p99"] >= r["step_time_median"]
        assert isinstance(r["lost_sync"], bool)
        if r["case"].startswith("step"):
            assert "settle_time" in r and r["saturated_steps"] > 0  # 5 mm ≫ the piezo stroke
        elif r["case"] == "latency2" and r["controller"] == "LQR":
            # 2 periods of latency exceed the LQR's delay margin (1): it oscillates
            assert r["rmse"] > 1e-6
        else:
            assert math.isnan(r["settle_time"]) and r["saturated_steps"] == 0
            assert r["rmse"] < 70e-9  # the spec, on 0.4 s


def test_failing_controllers_are_recorded_not_raised(rows):
    for name, text in (
        ("reset-fails", "RuntimeError: no design for you"),
        ("step-fails", "FloatingPointError: diverged at step 100"),
        ("ctor-fails", "ZeroDivisionError"),
    ):
        sel = [r for r in rows if r["controller"] == name]
        assert len(sel) == 10
        assert all(text in r["error"] for r in sel)
        assert all(math.isnan(r["rmse"]) for r in sel)
    table = format_table(rows)
    assert "| reset-fails | kolmogorov | failed: RuntimeError: no design for you" in table
    grid = qualitative_grid(rows)
    assert grid["RMS error"]["ctor-fails"] == "n/a"


def test_table_and_grid(rows):
    table = format_table(rows)
    lines = table.strip().splitlines()
    assert lines[0].startswith("| controller | case | RMSE [nm]")
    assert len(lines) == 2 + 6 * 6  # header + one line per (controller, case)
    grid = qualitative_grid(rows)
    assert set(grid) == {
        "RMS error",
        "e_max",
        "Power dissipation",
        "Step response",
        "Robustness",
        "Latency tolerance",
    }
    assert grid["Power dissipation"]["coordinator"] == "+"  # 2.25 W: within the 5 W spec
    best = min(
        ("coordinator", "LQR", "PQ"),
        key=lambda c: np.median(
            [r["rmse"] for r in rows if r["controller"] == c and r["case"] == "kolmogorov"]
        ),
    )
    assert grid["RMS error"][best] == "++++"
    text = format_grid(rows)
    assert text.splitlines()[0].startswith("| | coordinator | LQR | PQ |")


def test_mismatched_plant_and_designed_on():
    up = mismatched_plant(1.2)
    base = ddl.DualStage()
    assert up.fine.gain == pytest.approx(1.2 * base.fine.gain)
    assert up.flexure.stiffness_sum == pytest.approx(1.2 * base.flexure.stiffness_sum)
    assert up.stepper.coulomb_torque == pytest.approx(1.2 * base.stepper.coulomb_torque)
    assert up.stepper.static_torque == pytest.approx(1.2 * base.stepper.static_torque)
    assert up.stepper.inertia == base.stepper.inertia
    with pytest.raises(ValueError, match="factor"):
        mismatched_plant(-1.0)

    seen = {}

    class Spy(ddl.SisoCoordinator):
        def reset(self, plant, fs, y0, r0):
            seen["plant"] = plant
            super().reset(plant, fs, y0, r0)

    nominal = ddl.DualStage()
    true = mismatched_plant(0.8)
    r = ddl.kolmogorov_opd(0.2, FS, seed=0, preset="paranal_250hz")
    wrapped = DesignedOn(Spy(), nominal)
    run = ddl.simulate(true, wrapped, r, FS)
    assert seen["plant"] is nominal
    # the nominal plant starts where the true one does (carriage, applied voltage)
    assert nominal.fs == FS and nominal.y_c == run.y_c[0]
    assert nominal.v_applied == pytest.approx(true.fine.v_centre)
    assert nominal.fine.gain != true.fine.gain
    assert run.y_c_hat.size == r.size  # the wrapped controller's estimate is logged


def test_delayed_plant_delays_commands_by_whole_periods():
    plain, late = ddl.DualStage(), DelayedPlant(ddl.DualStage(), 2)
    plain.reset(FS)
    late.reset(FS)
    assert late.fine is late.plant.fine and late.output_range == plain.output_range
    cmds = [(5.0 + k, 0.0, 1.5) for k in range(4)]
    for c in cmds:
        late.step(*c)
    # the first command was held for 3 periods (2 padding + its own), then the second
    for c in [cmds[0]] * 3 + [cmds[1]]:
        plain.step(*c)
    assert late.y_f == plain.y_f and late.v_applied == plain.v_applied == 6.0
    with pytest.raises(ValueError, match="delay"):
        DelayedPlant(ddl.DualStage(), -1)
    with pytest.raises(ValueError, match="latency"):
        default_cases(latency=1.5)


def test_custom_references_dict():
    r = ddl.kolmogorov_opd(0.2, FS, seed=4, preset="paranal_250hz")
    rows = compare({"PQ": PQ}, references={"mine": r, "case": Case("c2", lambda s: r)}, fs=FS)
    assert [x["case"] for x in rows] == ["mine", "c2"]
    assert rows[0]["rmse"] == pytest.approx(rows[1]["rmse"])


def test_bad_input():
    with pytest.raises(ValueError, match="controllers"):
        compare({})
    with pytest.raises(ValueError, match="'x'"):
        compare({"x": 3})
    with pytest.raises(ValueError, match="seeds"):
        compare({"PQ": PQ}, seeds=())
    with pytest.raises(ValueError, match="mismatch"):
        default_cases(mismatch=1.5)
    with pytest.raises(ValueError, match="references"):
        compare({"PQ": PQ}, references=[1, 2])


def test_simulate_timing_hook_is_optional():
    r = ddl.kolmogorov_opd(0.1, FS, seed=0, preset="paranal_250hz")
    plain = ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(), r, FS)
    assert plain.step_times.size == 0 and "step_time_median" not in plain.metrics
    timed = ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(), r, FS, timing=True)
    assert timed.step_times.size == r.size and np.all(timed.step_times > 0)
    assert timed.metrics["step_time_p99"] >= timed.metrics["step_time_median"]
    # identical trajectories with and without timing
    np.testing.assert_array_equal(plain.y, timed.y)
    np.testing.assert_array_equal(plain.v, timed.v)
