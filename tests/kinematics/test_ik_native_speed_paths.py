"""The native IK step's speed paths: the strict step's answer in one
native call (``IKStep.solve_step``), the native check-and-copy of a target vector
(``spatial_finite_copy``, ``frame_tasks._vector``), and the IKStep's cyclic garbage
collection (``tp_traverse`` / ``tp_clear``)."""

from __future__ import annotations

import gc
import weakref

import numpy as np
import pinocchio as pin
import pytest
from support.native_engine import needs_native

import qpcoord as qc
from qpcoord.core import native
from qpcoord.core.polish import KKT_TOL
from qpcoord.kinematics import frame_tasks

DT = 0.01
FRAME = "panda_hand_tcp"


@pytest.fixture(scope="module")
def panda() -> qc.Robot:
    return qc.robots.load("panda")


def _ik(robot: qc.Robot, q: np.ndarray, engine: str, pose: bool = False) -> tuple:
    """The ``ik_peers.py`` Panda stack: hand (position or pose) over a posture, joint and
    speed limits."""
    T = robot.frame_pose(q, FRAME).copy()
    if pose:
        hand = qc.FrameTask(robot, FRAME, T, gain=0.5 / DT)
    else:
        hand = qc.FramePositionTask(robot, FRAME, T[:3, 3], gain=0.5 / DT)
    posture = qc.PostureTask(robot, q.copy(), gain=0.1 / DT)
    limits = [qc.JointLimits(robot, gain=0.5), qc.VelocityLimits(robot, np.full(robot.nv, 0.8))]
    solver = "daqp" if engine == "python" else None
    ik = qc.IK(robot, [hand, posture], DT, limits=limits, solver=solver, engine=engine)
    return ik, hand, T


@needs_native
@pytest.mark.parametrize("pose", [False, True])
def test_the_one_call_step_follows_the_python_engine(panda, pose):
    """A closed loop (set_target + step_integrate, the benchmark's step) on the native engine
    (one solve_step call: x, res, info and q_next copies) and the Python engine: the same
    velocities at each q of the loop (the Python engine's solver is DAQP: 1e-8), q_next the
    robot's integration; every answer a new array, the IK's v_prev and last updated."""
    q0 = panda.random_configuration(5)
    ikn, hn, T = _ik(panda, q0, "native", pose)
    ikp, hp, _ = _ik(panda, q0, "python", pose)
    ikm, hm, _ = _ik(panda, q0, "native", pose)  # main's calls: step(), info(), copies
    nm = ikm._native
    c = T[:3, 3].copy()
    qn = q0.copy()
    prev = None
    for k in range(60):
        T[:3, 3] = c + 0.1 * np.array([np.cos(0.2 * k) - 1.0, np.sin(0.2 * k), 0.0])
        target = T if pose else T[:3, 3]
        hn.set_target(target)
        hp.set_target(target)
        hm.set_target(target)
        q_next, v, sol = ikn.step_integrate(qn)
        pin.computeJointJacobians(panda.model, panda.data, qn)
        assert nm._solver.step(qn, k > 0, 10.0, True) == 0
        assert np.array_equal(v, nm.x) and np.array_equal(q_next, nm.q_next)  # bit for bit
        assert np.array_equal(sol.level_residuals, nm.res)
        assert sol.info == nm._solver.info(KKT_TOL)
        vp, solp = ikp.step(qn)  # at the native trajectory's q
        np.testing.assert_allclose(v, vp, rtol=0, atol=1e-8)
        np.testing.assert_allclose(q_next, panda.integrate(qn, v, DT), rtol=0, atol=1e-14)
        np.testing.assert_allclose(sol.level_residuals, solp.level_residuals, atol=1e-9)
        assert sol.status == "optimal" and sol.solver == "native"
        assert sol.info["engine"] == "native" and sol.info["uncertified"] == []
        assert q_next is not ikn._native.q_next and v is not ikn._native.x
        assert sol.level_residuals is not ikn._native.res
        assert ikn.last is sol and np.array_equal(ikn.v_prev, v)
        if prev is not None:  # the previous step's arrays are left alone
            assert prev[0] is not q_next and not np.shares_memory(prev[1], v)
        prev = (q_next, v)
        qn = q_next
    v1, sol1 = ikn.step(qn)  # step (no integration) on the same compiled call
    assert ikn._native.q_next_out is None
    np.testing.assert_allclose(v1, ikp.step(qn)[0], rtol=0, atol=1e-9)


@needs_native
def test_a_failed_one_call_step_raises_and_the_next_step_recovers(panda):
    """A bad q through the one-call step: the named ValueError, no solution kept; the next
    step solves."""
    q = panda.random_configuration(2)
    ik, _, _ = _ik(panda, q, "native")
    bad = q.copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match="q"):
        ik.step_integrate(bad)
    q_next, v, sol = ik.step_integrate(q)
    assert np.all(np.isfinite(q_next)) and sol.status == "optimal"


@needs_native
def test_native_finite_copy_checks_then_copies():
    """spatial_finite_copy: a float64 vector of out's length (any stride) with a finite sum
    is copied; anything else returns False and leaves out alone."""
    copy = native.load().spatial_finite_copy
    out = np.full(3, 7.0)
    v = np.array([1.0, -2.0, 3.5])
    assert copy(v, out) and np.array_equal(out, v) and out is not v
    strided = np.arange(6.0)[::2]
    assert copy(strided, out) and np.array_equal(out, [0.0, 2.0, 4.0])
    for bad in (
        np.array([1.0, np.nan, 0.0]),
        np.array([np.inf, 0.0, 0.0]),
        np.array([1e308, 1e308, 0.0]),  # an overflowing sum: the full checks decide
        np.zeros(4),
        np.zeros((1, 3)),
        np.zeros(3, dtype=np.float32),
        np.zeros(3, dtype=">f8"),
        np.zeros(3, dtype=int),
        [1.0, 2.0, 3.0],
    ):
        out[...] = 7.0
        assert not copy(bad, out)
        assert np.all(out == 7.0)
    with pytest.raises(TypeError, match="out"):
        copy(v, np.zeros(3, dtype=np.float32))
    with pytest.raises(TypeError, match="out"):
        copy(v, np.zeros(6)[::2])


@pytest.mark.parametrize("built", [True, False])
def test_vector_targets_are_checked_and_copied_on_both_paths(panda, built, monkeypatch):
    """FramePositionTask.set_target with and without the native copy: a new array equal to
    the target; the same messages for a bad one."""
    if built and not native.available():
        pytest.skip("native engine not built")
    if not built:
        monkeypatch.setattr(frame_tasks, "_native_finite_copy", lambda: None)
    task = qc.FramePositionTask(panda, FRAME, np.zeros(3))
    for value in (np.array([0.3, 0.1, 0.5]), np.arange(6.0)[::2], [0.1, 0.2, 0.3], (1, 2, 3)):
        task.set_target(value)
        assert task.target is not value and task.target.dtype == np.float64
        assert task.target.flags.c_contiguous and task.target.shape == (3,)
        np.testing.assert_array_equal(task.target, np.asarray(value, dtype=float))
    before = task.target.copy()
    for bad, msg in (
        (np.array([0.0, np.nan, 1.0]), "target must be finite"),
        (np.array([1e308, 1e308, 0.0]), None),
        (np.zeros(4), "target must be 3 numbers"),
    ):
        if msg is None:  # finite entries whose sum overflows: accepted by the full checks
            task.set_target(bad)
            np.testing.assert_array_equal(task.target, bad)
            task.set_target(before)
            continue
        with pytest.raises(ValueError, match=msg):
            task.set_target(bad)
        np.testing.assert_array_equal(task.target, before)


@needs_native
@pytest.mark.parametrize("pose", [False, True])
def test_a_cycle_through_the_native_ik_step_is_collected(panda, pose):
    """A task that refers back to its IK (a monkeypatched attribute) makes a cycle through
    the native step, whose slots hold the task (and the task its slots): the garbage
    collector frees the cycle."""
    q = panda.random_configuration(1)
    ik, hand, _ = _ik(panda, q, "native", pose)
    ik.step_integrate(q)
    hand.owner = ik  # the cycle: ik -> native step -> its slot -> hand -> ik
    alive = weakref.ref(ik)
    alive_task = weakref.ref(hand)
    del ik, hand
    gc.collect()
    assert alive() is None and alive_task() is None
