"""The robot layer: a Pinocchio robot, kinematic tasks and limits, IK, paths, simulation.

================  ==================================================================
module            holds
================  ==================================================================
``robot``         :class:`~qpcoord.Robot` (a Pinocchio model and its frames)
``tasks``         kinematic tasks and limits (position, posture, bands, joint limits)
``ik``            :class:`~qpcoord.IK`: one stack per control step from tasks
``paths``         reference paths (circles, lines, ...)
``simulation``    :func:`~qpcoord.simulate` and :class:`~qpcoord.Trajectory`
================  ==================================================================

Builds on :mod:`qpcoord.core` only.
"""
