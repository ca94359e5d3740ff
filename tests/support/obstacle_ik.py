"""The Panda's hand among seven obstacles (one of each coal shape kind and a floor): its
:class:`~qpcoord.kinematics.collision.CollisionAvoidance` task, the IK of that task above a
hand and a posture, and configurations around its default one (the collision rows' tests,
tests/kinematics/test_collision_native.py, and the allocation count they run in a child)."""

from __future__ import annotations

from collections.abc import Iterator

import coal
import numpy as np

import qpcoord as qc
from qpcoord.kinematics.collision import Box, Capsule, CollisionAvoidance, Obstacle, Sphere

DT = 0.01  # s
#: the Panda's frame that the obstacles surround and the IK's hand task drives
HAND = "panda_hand_tcp"


def placed(p) -> np.ndarray:
    """The placement (4×4) at the point ``p`` (m), unrotated."""
    T = np.eye(4)
    T[:3, 3] = p
    return T


def obstacle_task(robot: qc.Robot, **kw) -> CollisionAvoidance:
    """Avoidance (influence distance 0.15 m, ``kw`` passed on) of seven obstacles within
    0.2 m of the hand at the robot's default configuration."""
    q0 = robot.reference_configuration("default")
    p = robot.frame_pose(q0, HAND)[:3, 3]
    obstacles = [
        Sphere(p + [0.05, 0.0, 0.0], 0.05),
        Box(p + [0.0, 0.1, -0.1], [0.1, 0.05, 0.02]),
        Capsule(p - [0.1, 0.0, 0.0], p + [0.0, 0.1, 0.1], 0.03),
        Obstacle(coal.Cylinder(0.04, 0.2), placed(p - [0.2, 0.0, 0.0]), "cylinder"),
        Obstacle(coal.Cone(0.05, 0.1), placed(p + [0.0, -0.15, 0.0]), "cone"),
        Obstacle(coal.Ellipsoid(0.03, 0.05, 0.08), placed(p + [0.1, -0.1, -0.1]), "ellipsoid"),
        Obstacle(coal.Halfspace(np.array([0.0, 0.0, 1.0]), -0.05), np.eye(4), "floor"),
    ]
    return CollisionAvoidance(robot, obstacles=obstacles, influence_distance=0.15, **kw)


def obstacle_ik(
    robot: qc.Robot, task, q: np.ndarray, engine: str | None, method: str = "hierarchical"
) -> qc.IK:
    """The IK (``DT``, the robot's limits) of ``task`` above the hand driven 0.1 m along x and
    -0.05 m along z from its pose at ``q``, above a posture holding ``q``."""
    T = robot.frame_pose(q, HAND)
    T[:3, 3] += [0.1, 0.0, -0.05]
    hand = qc.FrameTask(robot, HAND, T, gain=5.0)
    posture = qc.PostureTask(robot, q, gain=1.0)
    levels = [task, hand, posture]
    return qc.IK(robot, levels, DT, limits="robot", engine=engine, method=method)


def configurations(robot: qc.Robot, n: int, seed: int) -> Iterator[np.ndarray]:
    """``n`` configurations within the position limits: random ones alternating with the
    default configuration plus N(0, 0.3²) rad."""
    rng = np.random.default_rng(seed)
    q0 = robot.reference_configuration("default")
    lo, hi = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    for i in range(n):
        q = robot.random_configuration(rng) if i % 2 else q0 + 0.3 * rng.standard_normal(robot.nq)
        yield np.clip(q, lo, hi)
