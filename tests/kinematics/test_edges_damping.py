"""Levenberg–Marquardt damping per task (``lm_damping=``): an unreachable target settles, a
reachable one still converges, the damping rows vanish at the target, bad values are named."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc
from qpcoord.kinematics.tasks import LMDamping

DT = 0.01
Q0 = np.array([0.0, -1.2, 1.6, -1.9, -1.57, 0.0])


@pytest.fixture(scope="module")
def ur10():
    return qc.robots.load("ur10")


def _run(robot, target_xyz, lm, engine, steps):
    T = robot.frame_pose(Q0, "tool0").copy()
    T[:3, 3] = target_xyz
    task = qc.FrameTask(robot, "tool0", T, gain=1 / DT, lm_damping=lm)
    ik = qc.IK(robot, [task, qc.PostureTask(robot, Q0)], dt=DT, engine=engine)
    q, vs, errors = Q0.copy(), [], []
    for _ in range(steps):
        q, v, _ = ik.step_integrate(q)
        vs.append(v)
        errors.append(np.linalg.norm(task.compute_error(q)))
    return np.array(vs), np.array(errors), task


def _reversals(vs: np.ndarray, floor: float) -> int:
    """Sign changes of a joint velocity between two steps, both above ``floor`` (rad/s)."""
    big = np.abs(vs) > floor
    flips = np.sign(vs[1:]) * np.sign(vs[:-1]) < 0
    return int(np.sum(flips & big[1:] & big[:-1]))


@pytest.mark.parametrize("engine", ["native", "python"])
def test_unreachable_target_settles(ur10, engine):
    # 3.7 m from the base: the UR10 reaches 1.3 m. Without damping every joint reverses at
    # every step at its speed limit (thousands of reversals in the last 500 steps)
    vs, errors, _ = _run(ur10, [3.7, 0.0, 0.5], 0.0, engine, 600)
    assert _reversals(vs[-300:], 1e-6) > 100
    vs, errors, task = _run(ur10, [3.7, 0.0, 0.5], 1.0, engine, 2000)
    assert _reversals(vs[-500:], 1e-6) == 0
    # |v| -> 0: the speed limits are ~3 rad/s; 1e-6 of them is settled
    assert np.linalg.norm(vs[-1]) < 1e-6
    assert errors[-1] > 2.0  # still far: the target is out of reach
    assert task.lm_rows.mu > 0


@pytest.mark.parametrize("engine", ["native", "python"])
def test_reachable_target_converges_as_fast(ur10, engine):
    target = ur10.frame_pose(Q0, "tool0")[:3, 3] + [0.2, -0.1, 0.1]
    _, plain, _ = _run(ur10, target, 0.0, engine, 60)
    _, damped, task = _run(ur10, target, 1.0, engine, 60)
    first = int(np.argmax(plain < 1e-6))
    assert plain[first] < 1e-6
    # within 10 % of the undamped step count (mu ~ |e|^2 fades as the error does)
    assert damped[int(np.ceil(1.1 * first))] < 1e-6
    assert damped[-1] < 1e-9
    # the damping rows are (near) zero once the task is met: sqrt(mu) ~ |e|
    assert np.abs(task.lm_rows.task.A).max() < 1e-8


def test_rows_zero_at_target_and_placed_in_the_level(ur10):
    T = ur10.frame_pose(Q0, "tool0")
    task = qc.FrameTask(ur10, "tool0", T, lm_damping=3.0)
    assert isinstance(task.lm_rows, LMDamping)
    ik = qc.IK(ur10, [task, qc.PostureTask(ur10, Q0)], dt=DT, engine="python")
    assert task.lm_rows in ik._dynamic
    assert task.lm_rows.task in ik.stack.levels[0]
    ik.step(Q0)
    # at the target: e is rounding of a ~1 m pose (two FK paths), mu = 3 |e|^2 ~ 1e-32
    assert task.lm_rows.mu < 1e-28
    assert not task.lm_rows.task.A.any()  # below LM_ERROR_FLOOR: exactly zero
    # away from the target: mu = lm_damping * |e|^2 (unit weights)
    q = Q0 + 0.1
    ik.step(q)
    e = task.compute_error(q)
    assert task.lm_rows.mu == pytest.approx(3.0 * e @ e, rel=1e-12)
    np.testing.assert_allclose(task.lm_rows.task.A, np.sqrt(3.0 * e @ e) * np.eye(6))


@pytest.mark.parametrize("engine", ["native", "python"])
@pytest.mark.parametrize("offset", [1e-12, 5e-7])
def test_a_met_task_leaves_its_null_space_to_the_levels_below(ur10, engine, offset):
    """A damped task whose error is below LM_ERROR_FLOOR has zero damping rows, so the
    posture below moves the arm in the task's null space (rows of any positive size would
    fix it: in a strict hierarchy a tiny row is still a row)."""
    target = ur10.frame_pose(Q0, "tool0")[:3, 3] + [offset, 0.0, 0.0]
    task = qc.FramePositionTask(ur10, "tool0", target, gain=1 / DT, lm_damping=1.0)
    ik = qc.IK(ur10, [task, qc.PostureTask(ur10, Q0 + 0.2, gain=1.0)], dt=DT, engine=engine)
    v, _ = ik.step(Q0)
    assert not task.lm_rows.task.A.any()
    # the posture's pull (gain 1/s, 0.2 rad per joint) in the 3-dimensional null space
    assert np.linalg.norm(v) > 0.05
    J = ur10.frame_jacobian(Q0, "tool0")[:3]
    np.testing.assert_allclose(J @ v, np.array([offset, 0.0, 0.0]) / DT, rtol=0, atol=1e-9)


def test_without_damping_no_rows(ur10):
    task = qc.FrameTask(ur10, "tool0", ur10.frame_pose(Q0, "tool0"))
    assert task.lm_rows is None and task.lm_damping == 0.0
    ik = qc.IK(ur10, [task], dt=DT)
    assert len(ik.stack.levels[0]) == 1


def test_engines_agree(ur10):
    target = [1.1, 0.4, 0.9]
    vn, _, _ = _run(ur10, target, 0.5, "native", 40)
    vp, _, _ = _run(ur10, target, 0.5, "python", 40)
    # the same rows (Python-built for the damped task) solved by two engines: they agree to
    # the engines' tolerance relative to the speeds (~3 rad/s)
    np.testing.assert_allclose(vn, vp, atol=1e-6 * 3.0)


def test_band_damping_is_its_distance_outside(ur10):
    y = ur10.position(Q0)
    band = qc.PositionBand(ur10, lower=y + [0.1, -1.0, -1.0], upper=np.inf, lm_damping=2.0)
    band.update(Q0, dt=DT)
    band.lm_rows.update(Q0, dt=DT)
    # 0.1 m below the lower face on x, inside on the other rows
    assert band.lm_rows.mu == pytest.approx(2.0 * 0.1**2, rel=1e-9)
    inside = qc.PositionBand(ur10, lower=y - 1.0, upper=y + 1.0, lm_damping=2.0)
    inside.update(Q0, dt=DT)
    assert inside.lm_rows.mu == 0.0


def test_every_task_class_takes_lm_damping(ur10):
    T = ur10.frame_pose(Q0, "tool0")
    tasks = [
        qc.FrameTask(ur10, "tool0", T, lm_damping=1.0),
        qc.FramePositionTask(ur10, "tool0", T[:3, 3], lm_damping=1.0),
        qc.OrientationTask(ur10, "tool0", T[:3, :3], lm_damping=1.0),
        qc.RelativeFrameTask(ur10, "tool0", "base_link", np.eye(4), lm_damping=1.0),
        qc.ComTask(ur10, [0.1, 0.0, 0.5], lm_damping=1.0),
        qc.ComBand(ur10, -0.1, 0.1, lm_damping=1.0),
        qc.PostureTask(ur10, Q0 + 0.2, lm_damping=1.0),
        qc.PotentialTask(ur10, lambda q: q - Q0, lm_damping=1.0),
        qc.JointCouplingTask(ur10, ["shoulder_pan_joint", "elbow_joint"], [1, -1], lm_damping=1.0),
    ]
    ik = qc.IK(ur10, [tasks], dt=DT, engine="python")
    v, sol = ik.step(Q0 + 0.05)
    assert np.all(np.isfinite(v))
    for task in tasks:
        assert task.lm_rows is not None and task.lm_rows.mu >= 0.0


@pytest.mark.parametrize("bad", [-1.0, np.nan, np.inf, "1", True, None])
def test_bad_lm_damping_is_named(ur10, bad):
    with pytest.raises(ValueError, match="lm_damping"):
        qc.FrameTask(ur10, "tool0", lm_damping=bad)
    with pytest.raises(ValueError, match="lm_damping"):
        qc.PostureTask(ur10, Q0, lm_damping=bad)
    with pytest.raises(ValueError, match="lm_damping"):
        qc.ComBand(ur10, -1.0, 1.0, lm_damping=bad)


@pytest.mark.parametrize("engine", ["native", "python"])
def test_damped_task_below_another_level_settles(ur10, engine):
    # level 0 holds the wrist joints still; the unreachable pose task at level 1 is damped
    hold = qc.OneFormTask(ur10, np.eye(6)[3:], name="wrist still")
    T = ur10.frame_pose(Q0, "tool0").copy()
    T[:3, 3] = [3.7, 0.0, 0.5]
    task = qc.FrameTask(ur10, "tool0", T, gain=1 / DT, lm_damping=1.0)
    ik = qc.IK(ur10, [hold, task, qc.PostureTask(ur10, Q0)], dt=DT, engine=engine)
    q, vs = Q0.copy(), []
    for _ in range(1500):
        q, v, _ = ik.step_integrate(q)
        vs.append(v)
    vs = np.array(vs)
    assert np.abs(vs[:, 3:]).max() < 1e-9 * 3.0  # level 0 held (engine tolerance on ~3 rad/s)
    assert _reversals(vs[-500:], 1e-6) == 0
    assert np.linalg.norm(vs[-1]) < 1e-6


def test_damped_hard_constraint_is_refused(ur10):
    task = qc.FrameTask(ur10, "tool0", ur10.frame_pose(Q0, "tool0"), lm_damping=1.0)
    with pytest.raises(ValueError, match="lm_damping"):
        qc.IK(ur10, [qc.PostureTask(ur10, Q0)], dt=DT, constraints=[task])


class _Height(qc.KinematicTask):
    """A user task writing its rows in _refresh (no error recorded), with compute_error."""

    def __init__(self, robot, z, lm_damping=0.0):
        super().__init__(robot, 1, gain=10.0, name="height", lm_damping=lm_damping)
        self.z = z

    def compute_error(self, q):
        return self.robot.frame_pose(q, "tool0")[2:3, 3] - self.z

    def _refresh(self, q, t, dt, reference):
        J = self.robot.frame_jacobian(q, "tool0")[2:3]
        return self.task._assign(J, -self.gain * self.compute_error(q))


class _RowsOnly(_Height):
    compute_error = qc.KinematicTask.compute_error

    def _refresh(self, q, t, dt, reference):
        J = self.robot.frame_jacobian(q, "tool0")[2:3]
        return self.task._assign(J, np.zeros(1))


def test_user_task_damping_reads_its_error(ur10):
    z = ur10.frame_pose(Q0, "tool0")[2, 3]
    task = _Height(ur10, z - 0.2, lm_damping=2.0)
    ik = qc.IK(ur10, [task], dt=DT, engine="python")
    ik.step(Q0)
    assert task.lm_rows.task.A[0, 0] == pytest.approx(np.sqrt(2.0 * 0.2**2), rel=1e-9)
    rows_only = _RowsOnly(ur10, z, lm_damping=1.0)
    ik = qc.IK(ur10, [rows_only], dt=DT, engine="python")
    with pytest.raises(ValueError, match="lm_damping needs the task's error"):
        ik.step(Q0)
