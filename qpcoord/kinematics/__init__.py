"""The robot layer: a Pinocchio robot, kinematic tasks and limits, IK, paths, simulation.

================  ==================================================================
module            holds
================  ==================================================================
``robot``         :class:`~qpcoord.Robot` (a Pinocchio model and its frames)
``tasks``         kinematic tasks and limits: the public base classes
                  :class:`KinematicTask` (``compute_error`` / ``compute_jacobian``) and
                  :class:`Limit` (``box``), position, posture, bands, joint position /
                  speed / acceleration limits
``ik``            :class:`~qpcoord.IK`: one stack per control step from tasks
``paths``         reference paths (circles, lines, ...)
``simulation``    :func:`~qpcoord.simulate` and :class:`~qpcoord.Trajectory`
================  ==================================================================

Every task and limit acts on the robot's velocity ``v`` (size ``robot.nv``); the next
configuration is ``robot.integrate(q, v, dt)``.

Builds on :mod:`qpcoord.core` only.
"""

from .ik import DEFAULT_IK_DAMPING, IK, ik_step, inverse_kinematics
from .robot import Robot
from .simulation import Trajectory, simulate
from .tasks import (
    TASK_KINDS,
    AccelerationLimits,
    JointLimits,
    KinematicTask,
    Limit,
    OneFormTask,
    PositionBand,
    PositionTask,
    PostureTask,
    PotentialTask,
    VelocityLimits,
)

__all__ = [
    "Robot",
    "IK",
    "ik_step",
    "inverse_kinematics",
    "DEFAULT_IK_DAMPING",
    "simulate",
    "Trajectory",
    "KinematicTask",
    "Limit",
    "TASK_KINDS",
    "PositionTask",
    "PositionBand",
    "PostureTask",
    "PotentialTask",
    "OneFormTask",
    "JointLimits",
    "VelocityLimits",
    "AccelerationLimits",
]
