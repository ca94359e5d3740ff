"""The native integrator (``src/native/integrate.hpp``) against ``pinocchio.integrate``, and
:meth:`IK.step_integrate <qpcoord.IK.step_integrate>` against ``step`` + ``robot.integrate``."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from support.native_engine import needs_native
from support.native_ik import manifold_robot

import qpcoord as qc
from qpcoord.core import native
from qpcoord.kinematics.native_step import integration_plan


@pytest.fixture(scope="module")
def robots() -> dict[str, qc.Robot]:
    out = {"panda": qc.robots.load("panda"), "manifold": manifold_robot()}
    for name in ("talos", "kinova"):  # kinova: continuous joints
        try:
            out[name] = qc.robots.load(name)
        except ValueError:  # example-robot-data missing
            pass
    return out


def _robot(robots, name: str) -> qc.Robot:
    if name not in robots:
        pytest.skip(f"{name} not available")
    return robots[name]


@needs_native
@pytest.mark.parametrize("name", ["panda", "talos", "kinova", "manifold"])
def test_native_integrator_matches_pinocchio(robots, name):
    robot = _robot(robots, name)
    plan = integration_plan(robot)
    assert plan is not None
    mod = native.load()
    rng = np.random.default_rng(7)
    for k in range(300):
        q = robot.random_configuration(k)
        # speeds from 1e-12 to 30 (rotations past pi included), zero, and two dt
        scale = 0.0 if k == 0 else 10.0 ** rng.uniform(-12, 1.5)
        v = rng.normal(size=robot.nv) * scale
        dt = 1e-3 if k % 2 else 1.0
        out = np.full(robot.nq, np.nan)
        mod.integrate_configuration(plan, q, v, dt, out)
        expected = np.asarray(pin.integrate(robot.model, q, v * dt))
        np.testing.assert_allclose(out, expected, rtol=0, atol=1e-14, err_msg=f"sample {k}")


def test_plan_merges_vector_joints_and_declines_other_joints(robots):
    assert integration_plan(robots["panda"]) == [0, 0, 0, 7]
    kinds = integration_plan(robots["manifold"])[0::4]
    assert kinds == [3, 0, 1, 2, 0, 1, 0]
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelPlanar(), pin.SE3.Identity(), "base")
    model.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
    model.addFrame(pin.Frame("tip", j, 0, pin.SE3.Identity(), pin.OP_FRAME))
    assert integration_plan(qc.Robot(model, "tip")) is None


def _ik(robot: qc.Robot, q: np.ndarray, engine: str) -> qc.IK:
    frame = robot.frame
    T = robot.frame_pose(q, frame).copy()
    T[:3, 3] += [0.05, -0.04, 0.03]
    hand = qc.FrameTask(robot, frame, T, gain=20.0)
    limits = [qc.VelocityLimits(robot, 2.0)]
    return qc.IK(robot, [hand, qc.PostureTask(robot, q, gain=1.0)], 0.01, limits=limits,
                 engine=engine)  # fmt: skip


@needs_native
@pytest.mark.parametrize("name", ["panda", "talos", "manifold"])
def test_step_integrate_is_step_then_integrate(robots, name):
    robot = _robot(robots, name)
    if robot.frame is None:
        robot = robot.with_frame("gripper_right_base_link")
    q = (
        robot.reference_configuration("half_sitting")
        if robot.name == "talos"
        else robot.random_configuration(2)
    )
    a, b = _ik(robot, q, "native"), _ik(robot, q, "native")
    assert a._native.integrates
    qa = qb = q
    for step in range(20):
        qn, v, sol = a.step_integrate(qa)
        vb, solb = b.step(qb)
        np.testing.assert_array_equal(v, vb, err_msg=f"step {step}")
        assert sol.status == solb.status and a.last is sol
        np.testing.assert_allclose(
            qn, robot.integrate(qa, v, a.dt), rtol=0, atol=1e-14, err_msg=f"step {step}"
        )
        qa, qb = qn, robot.integrate(qb, vb, b.dt)
    assert qn is not a._native.q_next  # the caller's own array


def test_step_integrate_falls_back_to_robot_integrate(robots):
    robot = robots["panda"]
    q = robot.random_configuration(2)
    ik = _ik(robot, q, "python")
    qn, v, _ = ik.step_integrate(q)
    np.testing.assert_array_equal(qn, robot.integrate(q, v, ik.dt))
    with pytest.raises(ValueError, match="q must have 7 entries"):
        ik.step_integrate(q[:3])


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_robot_integrate_fast_path_keeps_its_checks(robots):
    """A fixed-base arm's float64 arrays take the short path of Robot.integrate: the same
    result as q + v dt, and every bad input still gets the full checks' message."""
    robot = robots["panda"]
    q = robot.random_configuration(4)
    v = np.linspace(-1.0, 1.0, robot.nv)
    np.testing.assert_array_equal(robot.integrate(q, v, 1e-3), q + v * 1e-3)
    np.testing.assert_array_equal(robot.integrate(list(q), list(v), 1), q + v)
    bad_v = v.copy()
    bad_v[1] = np.nan
    with pytest.raises(ValueError, match=r"^v\[1\] is nan: velocities must be finite$"):
        robot.integrate(q, bad_v, 1e-3)
    bad_q = q.copy()
    bad_q[2] = -np.inf
    with pytest.raises(ValueError, match=r"^q\[2\] is -inf: configurations must be finite$"):
        robot.integrate(bad_q, v, 1e-3)
    with pytest.raises(ValueError, match="dt must be finite"):
        robot.integrate(q, v, np.inf)
    with pytest.raises(ValueError, match="v must have nv = 7 entries"):
        robot.integrate(q, v[:3], 1e-3)
    huge = np.full(robot.nv, 1e308)  # sums overflow: the full path, which accepts it
    np.testing.assert_array_equal(robot.integrate(q, huge, 1.0), q + huge)


@needs_native
def test_kernels_count_matrix_changes_for_a_persistent_solver(robots):
    """The kernels bump ``task.task.matrix_version`` as ``_assign(A, b)`` does (a posture
    writes only ``b``), so a PersistentQP on ``ik.stack`` sees the new ``A``."""
    from qpcoord.core.persistent import PersistentQP

    robot = robots["panda"]
    q = robot.random_configuration(5)
    ik = _ik(robot, q, "native")
    hand, posture = ik._dynamic
    ik.step(q)
    before = (hand.task.matrix_version, posture.task.matrix_version)
    ik.step(q)
    assert hand.task.matrix_version == before[0] + 1
    assert posture.task.matrix_version == before[1]
    qp = PersistentQP(ik.stack)
    assert qp.solve().info["setups"] == 1
    for k in range(5):
        q = robot.integrate(q, ik.step(q)[0], 0.05)  # new rows, written natively
        sol = qp.solve()
        assert sol.info["persistent"] and sol.info["setups"] == k + 2  # it saw A change
        expected = ik.stack.solve(method="weighted").x
        np.testing.assert_allclose(sol.x, expected, rtol=0, atol=1e-9, err_msg=str(k))
