"""An IK whose hard part cannot hold names the hard task, and for each bound the limit and
the joint -- the same on both engines."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc

ENGINES = ["python", "native"] if qc.core.native.available() else ["python"]
#: Conflict values compared across engines: the rows are built natively or in numpy (equal
#: to rounding, ~1e-15 relative) and then go through the same LP (HiGHS, feasibility
#: tolerances 1e-10 on rows scaled to ~1): 1e-7 relative leaves room for both.
RTOL = 1e-7


@pytest.fixture(scope="module")
def panda() -> qc.Robot:
    return qc.robots.load("panda")


def band_case(panda, engine, method="hierarchical"):
    """A hard band asking the hand to move +x at 50 m/s from the neutral pose (gain 100/s,
    face 0.5 m ahead): the speed limits cannot give it."""
    q = panda.neutral()
    y = panda.position(q)
    band = qc.PositionBand(
        panda, lower=y + [0.5, -np.inf, -np.inf], upper=np.inf, gain=100.0, name="reach band"
    )
    ik = qc.IK(
        panda, [qc.PostureTask(panda, q)], dt=0.01, constraints=[band], method=method,
        engine=engine,
    )  # fmt: skip
    return ik, q


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("method", ["hierarchical", "weighted"])
def test_hard_band_against_the_speed_limits_names_the_joints(panda, engine, method):
    ik, q = band_case(panda, engine, method)
    with pytest.raises(qc.InfeasibleError) as info:
        ik.step(q)
    rows = info.value.conflict
    assert rows[0].task == "reach band" and rows[0].row == 0 and rows[0].kind == "lower"
    assert rows[0].bound == pytest.approx(50.0)  # 100/s · 0.5 m
    bounds = rows[1:]
    assert bounds and all(r.task == "velocity limits" and r.is_bound for r in bounds)
    for r in bounds:
        assert r.joint == f"panda_joint{r.row + 1}"
        assert abs(r.bound) == panda.velocity_limit[r.row]
        assert f"'velocity limits' x[{r.row}] (joint '{r.joint}')" in str(info.value)
    assert "'reach band' row 0: ≥ 50 missed by" in str(info.value)
    # least-violation point: every row missed by the same fraction of max(1, |bound|)
    rel = [r.violation / max(1.0, abs(r.bound)) for r in rows]
    np.testing.assert_allclose(rel, rel[0], rtol=RTOL)


def test_both_engines_name_the_same_ik_conflict(panda):
    if len(ENGINES) < 2:
        pytest.skip("the native engine is not built")
    got = []
    for engine in ENGINES:
        ik, q = band_case(panda, engine)
        with pytest.raises(qc.InfeasibleError) as info:
            ik.step(q)
        got.append(info.value.conflict)
    key = [[(r.task, r.row, r.kind, r.joint) for r in c] for c in got]
    assert key[0] == key[1]
    np.testing.assert_allclose(
        [r.violation for r in got[0]], [r.violation for r in got[1]], rtol=RTOL
    )


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("call", ["step", "step_integrate"])
def test_hard_task_against_a_joint_position_limit(panda, engine, call):
    """Joint 4 at its upper position limit, a hard task asking it to move up at 1 rad/s: the
    position limit (not the speed limit) is named, with the joint."""
    q = np.array([0.1, -0.4, 0.2, panda.upper[3], 0.1, 1.6, 0.5])
    push = qc.Equality(np.eye(panda.nv)[[3]], [1.0], name="push joint 4")
    ik = qc.IK(panda, [qc.PostureTask(panda, q)], dt=0.01, constraints=[push], engine=engine)
    with pytest.raises(qc.InfeasibleError) as info:
        getattr(ik, call)(q)
    rows = info.value.conflict
    assert [(r.task, r.row, r.kind, r.joint) for r in rows] == [
        ("push joint 4", 0, "equality", ""),
        ("joint limits", 3, "upper bound", "panda_joint4"),
    ]
    assert rows[1].bound == 0.0  # K (q_max − q)/dt at the limit
    # x3 = 1 − t = t: both missed by 0.5
    np.testing.assert_allclose([r.violation for r in rows], [0.5, 0.5], rtol=RTOL)
    assert "'joint limits' x[3] (joint 'panda_joint4'): ≤ 0 missed by 0.5" in str(info.value)
