"""Muscle-force sharing (thesis appendix A) as one prioritised stack.

``sharing`` holds the stack formulation (:func:`distribute`, :class:`MuscleSharing`) and the
thesis's two-step method (:func:`two_step`); the shoulder model itself is a robot
description (:mod:`qpcoord.robots.shoulder`). Builds on :mod:`qpcoord.core` only.
"""

from .sharing import (
    FEASIBLE_TOL,
    Distribution,
    MuscleSharing,
    activations,
    distribute,
    two_step,
)

__all__ = [
    "Distribution",
    "MuscleSharing",
    "distribute",
    "two_step",
    "activations",
    "FEASIBLE_TOL",
]
