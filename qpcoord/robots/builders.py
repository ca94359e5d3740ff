"""Python builders for the planar thesis arms (no file needed)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

__all__ = ["planar_chain", "absolute_angle_map"]


def planar_chain(n: int, length: float = 1.0) -> pin.Model:
    """``n`` revolute joints about z, links of ``length`` m along x, end frame ``"tip"``.

    The model's coordinates are relative angles (rad); see :func:`absolute_angle_map`.
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"n must be an integer >= 1, got {n!r}")
    if not np.isfinite(length) or length <= 0:
        raise ValueError(f"length must be a positive number of metres, got {length!r}")
    model = pin.Model()
    model.name = f"planar_{n}r"
    parent = 0
    offset = pin.SE3(np.eye(3), np.array([length, 0.0, 0.0]))
    for i in range(n):
        placement = pin.SE3.Identity() if i == 0 else offset
        parent = model.addJoint(parent, pin.JointModelRZ(), placement, f"q{i + 1}")
        model.appendBodyToJoint(parent, pin.Inertia.Zero(), pin.SE3.Identity())
    model.addFrame(pin.Frame("tip", parent, 0, offset, pin.FrameType.OP_FRAME))
    model.lowerPositionLimit[:] = -np.inf
    model.upperPositionLimit[:] = np.inf
    model.velocityLimit[:] = np.inf
    return model


def absolute_angle_map(n: int) -> np.ndarray:
    """``M`` with ``q_relative = M q_absolute`` (first differences), shape (n, n).

    Absolute angles are measured from the fixed x axis (thesis §3.1.2):
    ``q_abs,i = q_rel,1 + … + q_rel,i``, so ``M`` is the inverse of the lower-triangular
    matrix of ones.
    """
    return np.eye(n) - np.eye(n, k=-1)
