"""The boundary between the Python tasks and the native IK step: the step holds its own copy
of every kernel's parameters (gain, weights, target, feed-forward, faces, limits), set through
typed setters when a task's parameter is assigned, and reads no task attribute while it runs.
The Python tasks are the oracle: after any sequence of assignments the native rows equal
their Python ``_refresh``, on a fixed base and a floating base."""

from __future__ import annotations

import gc
import pickle

import numpy as np
import pinocchio as pin
import pytest
from support.counting_malloc import native_malloc_counts
from support.native_engine import needs_native
from support.native_ik import (
    DT,
    FRAMES,
    KINDS,
    engine_pair,
    ik_robots,
    kind_levels,
    robot_or_skip,
    start_configuration,
)

import qpcoord as qc
from qpcoord.core import native
from qpcoord.kinematics.frame_tasks import ComTask, FrameTask
from qpcoord.kinematics.native_step import TaskKind, native_kind


@pytest.fixture(scope="module")
def robots() -> dict[str, qc.Robot]:
    return ik_robots()


__all__ = ["robots"]  # the fixture, shared with test_native_step


def _assert_rows_match(ikn: qc.IK, ikp: qc.IK, q: np.ndarray, t: float) -> None:
    """The native step's stacked rows and its tasks' own rows against the Python refresh at
    ``q``. Each row is a few tens of flops on numbers of magnitude ``scale`` (the largest
    entry): 1e-12 * scale is thousands of roundings, far below any wrong term."""
    ikn.step(q, t)
    ikp.refresh(q, t)
    Pn, Pp = ikn.stack._compiled, ikp.stack._compiled
    Pp.refresh_stacked()
    scale = max(1.0, float(np.abs(Pp.Aeq).max()), float(np.abs(Pp.beq).max()))
    np.testing.assert_allclose(Pn.Aeq, Pp.Aeq, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(Pn.beq, Pp.beq, rtol=0, atol=1e-12 * scale)
    np.testing.assert_array_equal(Pn.lbs, Pp.lbs)
    np.testing.assert_array_equal(Pn.ubs, Pp.ubs)
    for tn, tp in zip(ikn._dynamic, ikp._dynamic, strict=True):  # the tasks' own rows
        en, ep = tn.task, tp.task
        if isinstance(en, qc.Equality):
            np.testing.assert_allclose(en.A, ep.A, rtol=0, atol=1e-12 * scale)
            np.testing.assert_allclose(en.b, ep.b, rtol=0, atol=1e-12 * scale)
        else:
            s = max(1.0, float(np.abs(ep.C).max()))
            np.testing.assert_allclose(en.C, ep.C, rtol=0, atol=1e-12 * s)
            for a, b in ((en.lower, ep.lower), (en.upper, ep.upper)):
                np.testing.assert_array_equal(np.isinf(a), np.isinf(b))
                ok = np.isfinite(b)
                np.testing.assert_allclose(a[ok], b[ok], rtol=0, atol=1e-12 * s)


def _assign(robot: qc.Robot, kind: str, task, posture, q: np.ndarray, seed: int) -> None:
    """New parameters for ``task`` (of ``kind``) and ``posture``, by assignment and by the
    tasks' setters: the same on both stacks for one seed."""
    rng = np.random.default_rng(seed)
    frame = FRAMES[robot.name]
    task.gain = float(rng.uniform(0.5, 6.0))
    if kind == "position":
        task.target = task.robot.position(q) + rng.uniform(-0.05, 0.05, task.robot.m)
    elif kind == "frame_position":
        task.target = robot.frame_pose(q, frame)[:3, 3] + rng.uniform(-0.05, 0.05, 3)
        task.target_velocity = None if seed % 2 else rng.uniform(-0.2, 0.2, 3)
    elif kind in ("pose", "pose_split", "pose_plain"):
        T = robot.frame_pose(q, frame).copy()
        T[:3, :3] = T[:3, :3] @ pin.exp3(rng.uniform(-0.4, 0.4, 3))
        T[:3, 3] += rng.uniform(-0.05, 0.05, 3)
        task.set_target(T, None if seed % 2 else rng.uniform(-0.3, 0.3, 6))
    elif kind == "orientation":
        R = robot.frame_pose(q, frame)[:3, :3] @ pin.exp3(rng.uniform(-0.4, 0.4, 3))
        task.set_target(R, None if seed % 2 else rng.uniform(-0.3, 0.3, 3))
    elif kind == "com":
        task.target = robot.com(q) + rng.uniform(-0.02, 0.02, 3)
        task.target_velocity = rng.uniform(-0.1, 0.1, 3)
    m = task.task.shape[0]
    task.task.update(weight=rng.uniform(0.5, 3.0, m))  # the Equality's weights: rebound
    posture.q_ref = robot.random_configuration(seed + 100)
    posture.gain = float(rng.uniform(0.5, 3.0))
    posture.task.update(weight=rng.uniform(0.5, 2.0, posture.task.shape[0]))


@needs_native
@pytest.mark.parametrize("name", ["panda", "talos"])
@pytest.mark.parametrize("kind", KINDS)
def test_assigned_parameters_reach_the_kernels(robots, name, kind):
    """Gains, targets, feed-forwards, references and weights assigned between steps (talos:
    a floating base) give the rows of the tasks' Python refresh at random configurations."""
    robot = robot_or_skip(robots, name)
    q0 = start_configuration(robot)
    ikn, ikp = engine_pair(robot, lambda: kind_levels(robot, kind, q0))
    assert not ikn._native._hybrid
    for k in range(4):
        q = robot.random_configuration(20 + k)
        if robot.nq != robot.nv:  # the floating base near the start: its tasks stay sensible
            q[:7] = q0[:7]
        for ik in (ikn, ikp):
            _assign(robot, kind, *ik._dynamic, q, k)
        _assert_rows_match(ikn, ikp, q, 0.13 * k)


@needs_native
def test_the_step_reads_no_task_attribute(robots):
    """A value written into a task's instance dict (no assignment) is not seen by the native
    step, which holds its own copy; the same value assigned is."""
    robot = robots["panda"]
    q = start_configuration(robot)
    ikn, ikp = engine_pair(robot, lambda: kind_levels(robot, "pose", q))
    hand = ikn._dynamic[0]
    P = ikn.stack._compiled
    ikn.step(q)
    rows = P.Aeq.copy(), P.beq.copy()
    for task in (hand, ikp._dynamic[0]):  # behind the step's back
        task.__dict__["gain"] = 50.0
        task.__dict__["_target_T"] = np.eye(4)
    ikn.step(q)
    np.testing.assert_array_equal(P.Aeq, rows[0])  # the same rows: its own copy
    np.testing.assert_array_equal(P.beq, rows[1])
    hand.gain = 50.0  # an assignment: the task's parameters copied again
    _assert_rows_match(ikn, ikp, q, 0.0)


@needs_native
def test_rebound_task_arrays_and_limits_are_followed(robots):
    """An ``update`` that rebinds a kernel's output arrays: the next step writes the new ones
    (and counts its matrix); the limits' gain and speed assigned: the same box."""
    robot = robots["panda"]
    q = start_configuration(robot)
    ikn, ikp = engine_pair(robot, lambda: kind_levels(robot, "frame_position", q))
    task = ikn._dynamic[0]
    old = task.task.A
    task.task.update(A=np.ones_like(old), b=np.zeros(old.shape[0]))
    ikp._dynamic[0].task.update(A=np.ones_like(old), b=np.zeros(old.shape[0]))
    version = task.task.matrix_version
    _assert_rows_match(ikn, ikp, q, 0.0)
    assert task.task.A is not old and task.task.matrix_version == version + 1
    for ik in (ikn, ikp):
        joint, speed = ik.limits
        joint.gain = 0.3
        speed.limit = np.full(robot.nv, 0.2)
    _assert_rows_match(ikn, ikp, q, 0.0)
    assert np.all(ikn.bounds.upper <= 0.2)


@needs_native
def test_bad_parameters_get_the_tasks_messages(robots):
    """Data a kernel cannot use, assigned at any time, raises the task's own message at the
    next step; assigning good data again steps."""
    robot = robots["panda"]
    q = start_configuration(robot)
    hand = FrameTask(robot, FRAMES["panda"], gain=2.0)
    com = ComTask(robot, robot.com(q))
    ik = qc.IK(robot, [hand, com], DT, engine="native")
    with pytest.raises(ValueError, match="no target"):
        ik.step(q)  # no target yet
    hand.set_target(robot.frame_pose(q, FRAMES["panda"]))
    ik.step(q)
    hand.target = None
    with pytest.raises(ValueError, match="no target"):
        ik.step(q)
    hand.set_target_from_configuration(q)
    hand.gain = float("nan")
    with pytest.raises(ValueError, match="non-finite"):
        ik.step(q)
    hand.gain = 1.0
    com.target = [np.nan, 0.0, 0.0]
    with pytest.raises(ValueError, match="non-finite"):
        ik.step(q)
    com.target = robot.com(q)
    v, _ = ik.step(q)
    assert np.all(np.isfinite(v))


@needs_native
def test_a_dropped_step_unbinds_its_tasks_and_tasks_pickle(robots):
    robot = robots["panda"]
    q = start_configuration(robot)
    tasks = kind_levels(robot, "pose", q)
    ik = qc.IK(robot, tasks, DT, engine="native")
    assert all(len(t._bound) == 1 for t in tasks)
    v = ik.step(q)[0]
    copy = pickle.loads(pickle.dumps(ik))  # a new native step, bound to the copies' tasks
    np.testing.assert_array_equal(copy.step(q)[0], v)
    assert all(len(t._bound) == 1 for t in copy._dynamic)
    del ik
    gc.collect()
    assert all(t._bound == () for t in tasks)
    tasks[0].set_target(np.eye(4))  # nothing bound: a plain assignment


def _assert_band_rows_match(ikn: qc.IK, ikp: qc.IK, q: np.ndarray) -> None:
    """The stacked inequality rows and the bands' own rows against the Python refresh (the
    tolerance of :func:`_assert_rows_match`)."""
    _assert_rows_match(ikn, ikp, q, 0.0)
    Pn, Pp = ikn.stack._compiled, ikp.stack._compiled
    scale = max(1.0, float(np.abs(Pp.C).max()))
    finite = np.isfinite(Pp.clo) | np.isfinite(Pp.chi)
    np.testing.assert_allclose(Pn.C, Pp.C, rtol=0, atol=1e-12 * scale)
    for a, b in ((Pn.clo, Pp.clo), (Pn.chi, Pp.chi)):
        np.testing.assert_array_equal(np.isinf(a), np.isinf(b))
        ok = np.isfinite(b)
        np.testing.assert_allclose(a[ok], b[ok], rtol=0, atol=1e-12 * scale)
    assert finite.any()


@needs_native
@pytest.mark.parametrize("name", ["panda", "planar_3r", "talos"])
def test_position_band_kernel_equals_the_python_refresh(robots, name):
    """PositionBand on the default frame (its robot's position rows), as a hard constraint and
    at a soft level, faces and gain assigned between steps: the rows of its Python refresh
    at random configurations near the start (talos: a floating base)."""
    robot = robot_or_skip(robots, name)
    ee = robot.with_frame(FRAMES[name]) if robot.frame != FRAMES[name] else robot
    q0 = start_configuration(robot)

    def build(engine: str) -> tuple[qc.IK, qc.PositionBand]:
        y = ee.position(q0)
        hard = qc.PositionBand(ee, lower=y - 0.02, upper=y + [0.05] * ee.m, gain=10.0)
        soft = qc.PositionBand(ee, lower=[-np.inf] * (ee.m - 1) + [y[-1] + 0.01], gain=5.0)
        levels = [soft, qc.PostureTask(robot, q0, gain=1.0)]
        return qc.IK(robot, levels, DT, constraints=[hard], engine=engine), hard

    (ikn, hn), (ikp, hp) = build("native"), build("python")
    assert not ikn._native._hybrid
    assert [native_kind(t) for t in ikn._native.kernel_tasks].count(TaskKind.POSITION_BAND) == 2
    rng = np.random.default_rng(5)
    for k in range(4):  # near the start, where the hard band can hold
        q = robot.integrate(q0, rng.uniform(-0.3, 0.3, robot.nv), 1.0)
        if k:
            lo = ee.position(q) + rng.uniform(-0.1, 0.0, ee.m)
            gain = float(rng.uniform(2.0, 20.0))
            for band in (hn, hp):
                band.set_band(lower=lo, upper=lo + 0.2)
                band.gain = gain
        _assert_band_rows_match(ikn, ikp, q)


_ALLOCATION_RUN = r"""
import numpy as np, pinocchio as pin, qpcoord as qc
from support.malloc_counts import print_mallocs, print_step_mallocs
from support.native_ik import FRAMES, DT
robot = qc.robots.load("panda")
ee = robot.with_frame(FRAMES["panda"])
q = robot.random_configuration(3)
T = robot.frame_pose(q, FRAMES["panda"])
band = qc.PositionBand(ee, lower=[-np.inf, -np.inf, T[2, 3] - 0.05], gain=10.0)
hand = qc.FrameTask(robot, FRAMES["panda"], T, gain=5.0)
ik = qc.IK(robot, [band, hand, qc.PostureTask(robot, q)], DT, engine="native")
assert not ik._native._hybrid
pin.computeJointJacobians(robot.model, robot.data, q)
slot = ik._native._slots[1]
print_mallocs("set_target", lambda: slot.set_target(T, None))
print_step_mallocs("step", ik, q)
"""


@pytest.mark.engine_independent
@needs_native
@pytest.mark.parametrize("build", native.built_variants() if native.available() else ())
def test_the_step_and_its_target_setter_do_not_allocate(tmp_path, build):
    """The native call with a PositionBand, a FrameTask and a posture, and the kernel's
    target setter (what FrameTask.set_target calls every control step), make no heap
    allocation after the first calls. Each build of the extension."""
    counts = native_malloc_counts(tmp_path, _ALLOCATION_RUN, build)
    assert counts == {"step": 0, "set_target": 0}


@pytest.mark.parametrize("engine", ["native", "python"])
def test_a_parameter_array_written_in_place_raises(engine):
    """The native step holds a copy of a task's parameters: a write into them in place would
    be seen by the Python engine only, so it raises instead (assign, or call the setter)."""
    robot = qc.robots.load("panda")
    q0 = robot.reference_configuration("default")
    hand = qc.FramePositionTask(
        robot, "panda_hand_tcp", robot.frame_pose(q0, "panda_hand_tcp")[:3, 3]
    )
    post = qc.PostureTask(robot, q0)
    qc.IK(robot, [hand, post], dt=0.01, engine=engine)
    for array in (hand.target, post.q_ref):
        with pytest.raises(ValueError, match="read-only"):
            array[0] = 0.0
    mine = q0 + 0.1
    post.q_ref = mine  # an assignment is the setter: the task keeps a read-only copy
    mine[0] = 5.0  # so the caller's array stays the caller's
    assert not post.q_ref.flags.writeable
    np.testing.assert_array_equal(post.q_ref, q0 + 0.1)
