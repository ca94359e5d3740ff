"""The native IK step's test problems: robots, start configurations, one stack per task
kind, and the same stack on both engines (tests/kinematics/test_native_*.py)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import qpcoord as qc
from qpcoord.kinematics.frame_tasks import ComTask, FramePositionTask, FrameTask, OrientationTask
from qpcoord.kinematics.paths import Circle, HorizontalCircle

DT = 0.01
#: the controlled frame and the default-frame robot of each test robot
FRAMES = {"panda": "panda_hand_tcp", "planar_3r": "tip", "talos": "gripper_right_base_link"}


def ik_robots() -> dict[str, qc.Robot]:
    """The robots of the native IK tests by name (Talos where example-robot-data has it)."""
    out = {"panda": qc.robots.load("panda"), "planar_3r": qc.robots.load("planar_3r")}
    try:
        out["talos"] = qc.robots.load("talos")
    except ValueError:  # example-robot-data missing
        pass
    return out


def manifold_robot() -> qc.Robot:
    """Free-flyer root, then revolute, continuous, spherical and prismatic joints."""
    model = pin.Model()
    parent = 0
    joints = [
        pin.JointModelFreeFlyer(),
        pin.JointModelRZ(),
        pin.JointModelRUBY(),
        pin.JointModelSpherical(),
        pin.JointModelPX(),
        pin.JointModelRUBX(),
        pin.JointModelRY(),
    ]
    for i, joint in enumerate(joints):
        placement = pin.SE3(np.eye(3), np.array([0.0 if i == 0 else 0.3, 0.0, 0.0]))
        parent = model.addJoint(parent, joint, placement, f"j{i}")
        model.appendBodyToJoint(parent, pin.Inertia.Random(), pin.SE3.Identity())
    model.addFrame(
        pin.Frame("tip", parent, 0, pin.SE3(np.eye(3), np.array([0.3, 0, 0])), pin.OP_FRAME)
    )
    return qc.Robot(model, "tip")


def robot_or_skip(robots, name: str) -> qc.Robot:
    if name not in robots:
        pytest.skip(f"{name} not available")
    return robots[name]


def start_configuration(robot: qc.Robot) -> np.ndarray:
    if robot.name == "talos":
        return robot.reference_configuration("half_sitting")
    return robot.random_configuration(3)


def ee_robot(robot: qc.Robot) -> qc.Robot:
    """A robot whose default frame is the controlled frame (shares the model)."""
    frame = FRAMES[robot.name]
    return robot if robot.frame == frame else robot.with_frame(frame)


def target_pose(robot: qc.Robot, q: np.ndarray) -> np.ndarray:
    frame = FRAMES[robot.name]
    T = robot.frame_pose(q, frame).copy()
    T[:3, :3] = T[:3, :3] @ pin.exp3(np.array([0.2, -0.3, 0.4]))
    T[:3, 3] += [0.05, -0.04, 0.03]
    return T


def kind_levels(robot: qc.Robot, kind: str, q: np.ndarray) -> list:
    """A fresh stack of one task kind (with masks, weights, feed-forward) and a posture."""
    frame = FRAMES[robot.name]
    ee = ee_robot(robot)
    if kind == "position":
        task = qc.PositionTask(ee, target=ee.position(q) + 0.05, gain=7.0, weight=2.0)
    elif kind == "position_path":
        path = (
            Circle(radius=0.2)
            if ee.m == 2
            else HorizontalCircle(ee.position(q) + [0.0, 0.0, 0.02], 0.1, 2.0)
        )
        task = qc.PositionTask(ee, target=path, gain=5.0)
    elif kind == "frame_position":
        task = FramePositionTask(robot, frame, gain=3.0, mask="x z", weight=2.0)
        task.set_target(robot.frame_pose(q, frame)[:3, 3] + 0.03, velocity=[0.1, -0.2, 0.3])
    elif kind == "pose":
        task = FrameTask(
            robot, frame, gain=2.0, position_weight=2.0, orientation_weight=0.5, mask="x y rz ry"
        )
        task.set_target(target_pose(robot, q), velocity=[0.1, 0.0, -0.1, 0.2, 0.1, -0.3])
    elif kind == "pose_split":
        task = FrameTask(robot, frame, gain=2.5, mask="x z rx ry", error="split", name="split")
        task.set_target(target_pose(robot, q), velocity=[0.1, 0.2, -0.1, 0.3, -0.1, 0.2])
    elif kind == "pose_plain":
        task = FrameTask(robot, frame, target_pose(robot, q), gain=4.0)
    elif kind == "orientation":
        task = OrientationTask(robot, frame, gain=1.5, mask="rx rz", weight=3.0)
        task.set_target(target_pose(robot, q), velocity=[0.3, -0.2, 0.1])
    elif kind == "com":
        task = ComTask(robot, gain=2.0, mask="xy", weight=4.0)
        task.set_target(robot.com(q) + [0.01, -0.02, 0.0], velocity=[0.05, 0.0, 0.1])
    else:
        raise AssertionError(kind)
    w = np.linspace(0.5, 2.0, qc.PostureTask(robot, q).task.shape[0])
    posture = qc.PostureTask(robot, robot.random_configuration(9), gain=1.5, weight=w)
    return [task, posture]


KINDS = ["position", "position_path", "frame_position", "pose", "pose_split", "orientation", "com"]


def engine_pair(robot, factory, dt: float = DT, **options):
    """A native-step IK and a Python-engine IK of two copies of one stack (``dt`` s)."""
    return (
        qc.IK(robot, factory(), dt, engine="native", **options),
        qc.IK(robot, factory(), dt, engine="python", **options),
    )


def closed_loop_agrees(ikn, ikp, q0: np.ndarray, steps: int, rel_tol: float = 1e-9) -> np.ndarray:
    """Step both IKs from the native step's configurations for ``steps`` steps of the IKs'
    ``dt``, asserting
    the same ``v`` at each to ``rel_tol`` of the velocities' scale (``max(1, |v|∞)``, rad/s:
    each engine solves the same QP to its KKT tolerance 1e-9 relative to that scale; a caller
    whose levels are worse conditioned passes a looser one and says why). Returns the last
    configuration."""
    q = q0.copy()
    for step in range(steps):
        vn, _ = ikn.step(q)
        vp, _ = ikp.step(q)
        tol = rel_tol * max(1.0, float(np.abs(vp).max()))
        np.testing.assert_allclose(vn, vp, rtol=0, atol=tol, err_msg=f"step {step}")
        q = ikn.robot.integrate(q, vn, ikn.dt)
    return q
