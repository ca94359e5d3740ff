"""Smoke tests of the Panda IK benchmark (qpcoord.studies.bench_ik). No timing assertions: only
the rows' shape and what the controllers achieve are checked."""

from __future__ import annotations

import numpy as np
import pytest

from qpcoord.cli import main
from qpcoord.studies.bench_ik import format_ik_table, pink_available, run_ik_bench

KEYS = {
    "controller",
    "median_us",
    "p90_us",
    "final_error_m",
    "max_error_m",
    "bound_steps",
    "steps",
    "scenario",
    "solver",
}


@pytest.fixture(scope="module")
def waypoint_rows():
    return run_ik_bench(steps=1200, scenario="waypoints")


def test_rows_have_every_field(waypoint_rows):
    names = [r["controller"] for r in waypoint_rows]
    assert names[:2] == ["qpcoord hierarchical", "qpcoord weighted"]
    assert ("pink" in names) == pink_available()
    for r in waypoint_rows:
        assert set(r) == KEYS
        assert r["steps"] == 1200 and r["solver"] == "daqp"
        assert np.isfinite(r["median_us"]) and r["p90_us"] >= r["median_us"] > 0


def test_strict_hierarchy_reaches_the_waypoints(waypoint_rows):
    by = {r["controller"]: r for r in waypoint_rows}
    # 0.3 s per waypoint at 50/s (speed-limited at first): the strict position task
    # converges; the weighted QP's posture term keeps it ~mm short
    assert by["qpcoord hierarchical"]["final_error_m"] < 1e-4  # measured 7e-6
    assert by["qpcoord hierarchical"]["final_error_m"] < by["qpcoord weighted"]["final_error_m"]


def test_table_has_one_line_per_row(waypoint_rows):
    table = format_ik_table(waypoint_rows)
    assert len(table.splitlines()) == 2 + len(waypoint_rows)
    assert "qpcoord hierarchical" in table


def test_tight_scenario_binds_the_speed_bounds():
    rows = run_ik_bench(steps=1000, scenario="tight", include_pink=False)
    by = {r["controller"]: r for r in rows}
    assert by["qpcoord hierarchical"]["bound_steps"] > 0
    assert by["qpcoord hierarchical"]["max_error_m"] < by["qpcoord weighted"]["max_error_m"]


@pytest.mark.parametrize(
    "kwargs, match",
    [({"scenario": "fast"}, "scenario"), ({"steps": 3}, "steps"), ({"steps": True}, "steps")],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        run_ik_bench(**kwargs)


def test_cli_bench_ik_quick(capsys):
    assert main(["bench", "ik", "--quick", "--scenario", "waypoints"]) == 0
    out = capsys.readouterr().out
    assert "| waypoints | qpcoord hierarchical | daqp |" in out
