"""Starting outside a joint position limit: detected, reported or refused.

:class:`~qpcoord.IK` checks the configuration of its first step (and of the steps after
:meth:`~qpcoord.IK.reset`) against its position limits (:class:`JointLimits`, and the
position limits an :class:`AccelerationLimits` brakes before) until the robot is back inside
them; after that the check costs nothing. ``IK(..., outside_limits="recover")`` lets the
limits bring the joints back (within the speed and acceleration limits: see
:meth:`IK.refresh <qpcoord.IK.refresh>`) and reports each step in
``Solution.info["outside_limits"]``; ``"raise"`` raises :class:`OutsideLimitsError`.
"""

from __future__ import annotations

import numpy as np

from .robot import Robot
from .tasks import AccelerationLimits, JointLimits

__all__ = ["OutsideLimitsError", "StartCheck", "OUTSIDE_LIMITS", "OUTSIDE_TOLERANCE"]

#: The start-up policies of ``IK(..., outside_limits=...)``.
OUTSIDE_LIMITS = ("recover", "raise")

#: A joint is outside a limit when it is more than this past it (rad, m): rounding of a
#: configuration integrated onto its limit (q ~ 1-10, relative 1e-16) stays far below it.
OUTSIDE_TOLERANCE = 1e-10


class OutsideLimitsError(ValueError):
    """The IK's start configuration is outside joint position limits
    (``IK(..., outside_limits="raise")``).

    Attributes
    ----------
    joints : dict[str, float]
        Joint name -> signed excess (rad, m): ``q − q_max`` (> 0) above its upper limit,
        ``q − q_min`` (< 0) below its lower limit.
    """

    def __init__(self, message: str, joints: dict[str, float]) -> None:
        super().__init__(message)
        self.joints = joints


def _velocity_names(robot: Robot) -> list[str]:
    """A name per velocity index: the joint's (``name`` or ``name[k]`` for a joint of several
    velocities), ``v[i]`` where the robot's coordinates are not the model's joints."""
    names = [f"v[{i}]" for i in range(robot.nv)]
    if robot.coordinate_map is not None:
        return names
    model = robot.model
    for jid in range(1, model.njoints):
        joint = model.joints[jid]
        name = model.names[jid]
        for k in range(joint.nv):
            names[joint.idx_v + k] = name if joint.nv == 1 else f"{name}[{k}]"
    return names


class StartCheck:
    """The start-up check of one IK (built by it).

    Parameters
    ----------
    robot : Robot
    limits : sequence of Limit
        The IK's limits; its :class:`JointLimits` and the ``position_limits`` of its
        :class:`AccelerationLimits` are checked.
    policy : {"recover", "raise"}

    Attributes
    ----------
    pending : bool
        Whether the next step checks its configuration (from the start or a reset until a
        step starts inside every limit).
    """

    def __init__(self, robot: Robot, limits, policy: str) -> None:
        if policy not in OUTSIDE_LIMITS:
            raise ValueError(f"outside_limits must be 'recover' or 'raise', got {policy!r}")
        self.robot = robot
        self.policy = policy
        self._position = [lim for lim in limits if isinstance(lim, JointLimits)]
        self._position += [
            lim.position_limits
            for lim in limits
            if isinstance(lim, AccelerationLimits) and lim.position_limits is not None
        ]
        self._names = _velocity_names(robot) if self._position else []
        self.pending = bool(self._position)

    def reset(self) -> None:
        """Check the next steps again (after :meth:`IK.reset <qpcoord.IK.reset>`)."""
        self.pending = bool(self._position)

    def outside(self, q: np.ndarray) -> dict[str, float]:
        """Joint name -> signed excess (rad, m) of every joint outside a limit at ``q``."""
        found: dict[str, float] = {}
        for lim in self._position:
            up, down = lim.distances(q)
            for i in np.flatnonzero((up < -OUTSIDE_TOLERANCE) | (down < -OUTSIDE_TOLERANCE)):
                excess = -float(up[i]) if up[i] < 0 else float(down[i])
                name = self._names[int(lim.joints[i])]
                if abs(excess) > abs(found.get(name, 0.0)):
                    found[name] = excess
        return found

    def check(self, q) -> dict[str, float] | None:
        """At a pending step: the joints outside their limits at ``q`` (nq,), or ``None``
        (then no later step is checked). Raises :class:`OutsideLimitsError` under
        ``policy="raise"``."""
        found = self.outside(self.robot.check_configuration(q))
        if not found:
            self.pending = False
            return None
        if self.policy == "raise":
            listed = ", ".join(f"{name} by {excess:+.4g}" for name, excess in found.items())
            raise OutsideLimitsError(
                f"q starts outside the joint position limits of {len(found)} joint(s): "
                f"{listed} (rad or m; + above the upper limit, - below the lower); "
                "outside_limits='recover' brings them back",
                found,
            )
        return found
