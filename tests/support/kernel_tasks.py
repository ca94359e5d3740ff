"""The native task kernels' test tasks on the Panda and Talos (floating base): the start
configuration, the hand's position task, relative-frame and joint-coupling tasks, the feet of
Talos, limits braking before the position limits, the Talos stack of them all, and small arms
whose posture crosses spherical, free-flyer and planar joints
(tests/kinematics/test_native_kernels_match_python.py, and the allocation count it runs in a
child)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

import qpcoord as qc
from qpcoord.kinematics.frame_tasks import FramePositionTask, FrameTask
from support.native_ik import manifold_robot
from support.talos_balance import SOLES

DT = 1e-3  # s
#: the hand frame of each robot
HAND = {"panda": "panda_hand_tcp", "talos": "gripper_right_base_link"}
#: (frame, reference frame, coupled joints) of each robot: a reference frame on the same
#: chain (shared joints) on the Panda, on the other arm of Talos (over the floating base)
PAIRS = {
    "panda": ("panda_hand_tcp", "panda_link3", ["panda_joint1", "panda_joint3"]),
    "talos": (
        "gripper_right_base_link",
        "gripper_left_base_link",
        ["arm_left_1_joint", "arm_right_1_joint"],
    ),
}


def start(robot: qc.Robot) -> np.ndarray:
    """Talos half-sitting; the Panda bent away from its limits."""
    if robot.name == "talos":
        return robot.reference_configuration("half_sitting")
    return np.array([0.0, -0.4, 0.0, -2.2, 0.0, 1.9, 0.8])


def acceleration(robot: qc.Robot, a: float) -> np.ndarray:
    """``a`` (rad/s²) on every joint, ``inf`` on a floating base's six rows."""
    out = np.full(robot.nv, a)
    if not robot.euclidean:
        out[:6] = np.inf
    return out


def braking_limits(robot: qc.Robot, gain: float, a: float, brake: bool = True) -> list:
    """Joint limits (``gain``), velocity limits and acceleration limits ``a`` (rad/s²) that
    brake before the position limits (``brake``) or ignore them."""
    jl = qc.JointLimits(robot, gain=gain)
    acc = qc.AccelerationLimits(
        robot, acceleration(robot, a), position_limits=jl if brake else None
    )
    return [jl, qc.VelocityLimits(robot), acc]


def hand_task(robot: qc.Robot, q0: np.ndarray, offset, gain: float, lm: float = 0.0):
    """The hand's position task, its target ``offset`` (m) from the hand at ``q0``."""
    frame = HAND[robot.name]
    target = robot.frame_pose(q0, frame)[:3, 3] + offset
    return FramePositionTask(robot, frame, target, gain=gain, lm_damping=lm)


def on_feet(robot: qc.Robot, q0: np.ndarray, levels: list[list]) -> list[list]:
    """``levels``, below a first level holding both soles where they are at ``q0`` on Talos
    (a floating base); as they are on the Panda."""
    if robot.name != "talos":
        return levels
    feet = [FrameTask(robot, s, robot.frame_pose(q0, s), gain=0.5 / DT) for s in SOLES]
    return [feet, *levels]


def relative_task(robot: qc.Robot, q: np.ndarray, mask: str | None, lm: float = 0.0):
    """The hand relative to ``PAIRS``' reference frame, its target the relative pose at ``q``
    moved by 0.4 rad and (0.05, -0.04, 0.03) m."""
    frame, ref, _ = PAIRS[robot.name]
    task = qc.RelativeFrameTask(
        robot, frame, ref, gain=3.0, position_weight=2.0, mask=mask, lm_damping=lm
    )
    task.set_target_from_configuration(q)
    T = task.target.homogeneous.copy()  # away from the start: a rotation of 0.4 rad
    T[:3, :3] = T[:3, :3] @ pin.exp3(np.array([0.12, -0.08, 0.36]))
    T[:3, 3] += [0.05, -0.04, 0.03]
    task.set_target(T)
    return task


def coupling_task(robot: qc.Robot, lm: float = 0.0):
    """``q_a - 0.7 q_b = 0.3`` (rad) on ``PAIRS``' two coupled joints."""
    _, _, joints = PAIRS[robot.name]
    return qc.JointCouplingTask(
        robot, joints, [1.0, -0.7], gain=2.0, offset=0.3, weight=3.0, lm_damping=lm
    )


def talos_kernel_stack(robot: qc.Robot, q0: np.ndarray) -> tuple[list, list]:
    """``(levels, limits)``: feet, a damped hand, a relative frame, a coupling and a
    low-acceleration level on Talos, with acceleration limits braking before the position
    limits."""
    hand = hand_task(robot, q0, [0.3, -0.2, 0.2], gain=0.2 / DT, lm=0.5)
    low = [
        relative_task(robot, q0, "x y z"),
        coupling_task(robot),
        qc.LowAccelerationTask(robot, 1e-3),
    ]
    return on_feet(robot, q0, [[hand], low]), braking_limits(robot, 0.5, 30.0)


def posture_robot(name: str) -> qc.Robot:
    """``manifold``: a free-flyer root (not a posture row), revolute, continuous, spherical
    and prismatic joints; ``nested``: a spherical root, a free-flyer child and a revolute
    joint; ``planar``: a revolute root, a planar child and a revolute joint (every joint a
    posture row); ``composite``: a composite child joint (no native difference)."""
    if name == "manifold":
        return manifold_robot()
    composite = pin.JointModelComposite(pin.JointModelRX())  # not a vector space
    composite.addJoint(pin.JointModelSpherical(), pin.SE3.Identity())
    kinds = {
        "nested": (pin.JointModelSpherical(), pin.JointModelFreeFlyer(), pin.JointModelRX()),
        "planar": (pin.JointModelRZ(), pin.JointModelPlanar(), pin.JointModelRY()),
        "composite": (pin.JointModelRZ(), composite, pin.JointModelRY()),
    }[name]
    model = pin.Model()
    parent = 0
    for i, joint in enumerate(kinds):
        at = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.0 if i == 0 else 0.3]))
        parent = model.addJoint(parent, joint, at, f"j{i}")
        link = pin.Inertia(1.0, np.array([0.0, 0.0, 0.15]), np.diag([0.01, 0.01, 0.002]))
        model.appendBodyToJoint(parent, link, pin.SE3.Identity())
    tip = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.3]))
    model.addFrame(pin.Frame("tip", parent, 0, tip, pin.OP_FRAME))
    # bounded positions: random_configuration samples the translations there
    model.lowerPositionLimit[:] = -1.0
    model.upperPositionLimit[:] = 1.0
    return qc.Robot(model, "tip")


def posture_levels(robot: qc.Robot, q0: np.ndarray) -> list:
    """The tip held at its position above a damped posture toward another configuration."""
    hand = FramePositionTask(robot, "tip", robot.frame_pose(q0, "tip")[:3, 3], gain=0.5 / DT)
    w = np.linspace(0.5, 2.0, qc.PostureTask(robot, q0).task.shape[0])
    q_ref = robot.random_configuration(11)
    return [[hand], [qc.PostureTask(robot, q_ref, gain=0.05 / DT, weight=w, lm_damping=0.3)]]
