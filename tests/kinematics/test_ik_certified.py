"""IK cases of the certified hierarchy: the near-singular speed-limited posture level
agrees across backends, and the stretched Panda with an out-of-reach target runs."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc

FAST = [
    s
    for s in ("daqp", "quadprog", "piqp", "clarabel", "highs", "osqp")
    if s in qc.available_solvers()
]


@pytest.mark.parametrize("solver", FAST)
def test_near_singular_speed_limited_posture_level_agrees(solver):
    """Planar 3R stretched (q3 = 1e-7), the position task beyond the speed limits: the
    backends disagreed on the posture level (27.08-27.17) and daqp raised SolverError."""
    arm = qc.robots.load("planar_nr", n=3)
    q = np.array([0.0, 3.0, 1e-7])
    ee = qc.PositionTask(arm, target=arm.position(q) + np.array([0.5, 0.0]), gain=10.0)
    posture = qc.PostureTask(arm, np.zeros(3), gain=10.0)
    ik = qc.IK(arm, [ee, posture], 0.01, limits=[qc.VelocityLimits(arm, 3.0)], solver=solver)
    _v, sol = ik.step(q)
    assert sol.status == "optimal"
    assert sol.level_residuals[0] == pytest.approx(4.5766396758, rel=1e-9)
    assert sol.level_residuals[1] == pytest.approx(27.16617189, rel=1e-8)


def _panda_run(solver, steps):
    robot = qc.robots.load("panda")
    q = np.zeros(robot.nq)  # stretched
    ee = qc.PositionTask(robot, target=[0.0, 0.0, 2.0], gain=10.0)  # out of reach
    posture = qc.PostureTask(robot, robot.neutral(), gain=1.0)
    ik = qc.IK(robot, [ee, posture], 0.01, solver=solver)
    inaccurate = 0
    for _ in range(steps):
        v, sol = ik.step(q)
        inaccurate += sol.status != "optimal"
        q = robot.integrate(q, v, 0.01)
    return inaccurate


@pytest.mark.parametrize("solver", [s for s in ("daqp", "quadprog") if s in FAST])
def test_stuck_panda_ik_runs_2000_steps(solver):
    """Without the fallback on a QP point outside its rows (daqp: 4.9e-6 outside), every step
    from 1 068 on raised SolverError with daqp; every step must solve."""
    assert _panda_run(solver, 2000) == 0


@pytest.mark.slow
@pytest.mark.parametrize("solver", [s for s in FAST if s not in ("daqp", "quadprog")])
def test_stuck_panda_ik_runs_2000_steps_other_backends(solver):
    assert _panda_run(solver, 2000) == 0
