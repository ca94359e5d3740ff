"""The coarse-loop gain margin predicted by the linear model against the margin measured on
the simulated plant (gain raised until the kicked carriage mode grows)."""

from __future__ import annotations

import math

import pytest

import qpcoord.ddl as ddl
from qpcoord.ddl.loops import _gain_margin_at, coarse_gain_margin, coarse_operating_points
from qpcoord.ddl.stability import coarse_growth_rate, simulated_coarse_margin

FS = 8000.0


def test_operating_points_are_the_softest_detent_phases():
    plant = ddl.DualStage()
    step = plant.stepper.full_step
    pts = coarse_operating_points(plant)
    assert pts[0] == pytest.approx(0.5 * step)
    for y in pts:
        # cos 4θ_e = −1: the detent spring is at its most negative there
        th = y * plant.stepper.electrical_per_metre
        assert math.cos(4.0 * th) == pytest.approx(-1.0, abs=1e-9)
        assert abs(y) <= plant.coarse_half_stroke
    # softer than the centre: lower mode, less margin
    assert plant.coarse_resonance(pts[0]) < plant.coarse_resonance(0.0) - 8.0
    ctl = ddl.SisoCoordinator()
    assert (
        coarse_gain_margin(ctl, plant, FS, n=4000)[0]
        < _gain_margin_at(ctl, plant, FS, 4000, 0.0)[0]
    )


@pytest.mark.parametrize(("bandwidth", "y_c"), [(2.0, 0.0), (2.0, 5.0e-6), (8.0, 5.0e-6)])
def test_predicted_margin_matches_the_simulated_plant(bandwidth, y_c):
    # The linearisation is of the very equations the simulator integrates (friction aside):
    # the two agree to the bisection's 1 % plus the ZOH-vs-sub-stepped integration and the
    # finite kick (measured ≤ 1.4 % over the stroke at 1–8 Hz); 3 % leaves room for neither
    # and fails on a model evaluated at the wrong operating point (16 % apart within one
    # full step).
    plant = ddl.DualStage()
    ctl = ddl.SisoCoordinator(coarse_bandwidth=bandwidth)
    predicted = _gain_margin_at(ctl, plant, FS, 4000, y_c)[0]
    measured = simulated_coarse_margin(plant, FS, bandwidth, y_c=y_c, duration=0.6)
    assert measured == pytest.approx(predicted, rel=0.03)


def test_the_worst_point_margin_is_what_the_simulation_sees_above_the_centre_margin():
    # Between the centre's edge (5.17 Hz) and the worst point's (4.43 Hz) the carriage at
    # the worst point rings up: the margin model must not be the centre's.
    plant = ddl.DualStage()
    y_c = coarse_operating_points(plant)[0]
    assert coarse_growth_rate(plant, FS, 4.8, y_c=y_c, duration=0.6) > 0.0
    assert coarse_growth_rate(plant, FS, 4.8, y_c=0.0, duration=0.6) < 0.0
    assert coarse_gain_margin(ddl.SisoCoordinator(coarse_bandwidth=4.8), plant, FS)[0] < 1.0
