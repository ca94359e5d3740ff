"""Talos standing on both soles: the soles, their corners, and the balance stack of the
support-polygon and CoM-band tests (tests/kinematics/test_native_support.py, and the
allocation count it runs in a child): feet held, polygon and band, the right hand reaching
out, a posture."""

from __future__ import annotations

import numpy as np

import qpcoord as qc
from qpcoord.kinematics.frame_tasks import ComBand, SupportPolygon

DT = 1e-3  # s
SOLES = ("left_sole_link", "right_sole_link")
#: the soles' corners (m, sole frame), as benchmarks/ik_peers.py
CORNERS = [[x, y, 0.0] for x in (-0.1, 0.1) for y in (-0.05, 0.05)]
#: the balance stack's polygon margin (m) and hand gain (1/s)
MARGIN, HAND_GAIN = 0.08, 2.0


def balance_stack(robot: qc.Robot, q0: np.ndarray) -> tuple[list, SupportPolygon, ComBand]:
    """``(levels, polygon, band)``: the feet held where they are at ``q0`` (gain 1/``DT``),
    then the support polygon (``MARGIN``) and a CoM band (``y >= c_y - 4 mm``, ``z <= c_z +
    1 mm``, ``c`` the CoM at ``q0``), then the right gripper's target (0.15, 0.05, -0.1) m
    from where it is, then a posture holding ``q0``. The CoM starts 1-2 cm inside the shrunk
    polygon; the hand's reach pushes it out."""
    feet = [qc.FrameTask(robot, s, gain=1.0 / DT) for s in SOLES]
    for foot in feet:
        foot.set_target_from_configuration(q0)
    polygon = SupportPolygon(
        robot, list(SOLES), margin=MARGIN, gain=1.0 / DT, contact_points=CORNERS
    )
    c = robot.com(q0)
    band = ComBand(
        robot,
        lower=[-np.inf, c[1] - 0.004, -np.inf],
        upper=[np.inf, np.inf, c[2] + 1e-3],
        gain=50.0,
    )
    hand = qc.FramePositionTask(
        robot,
        "gripper_right_base_link",
        robot.frame_pose(q0, "gripper_right_base_link")[:3, 3] + [0.15, 0.05, -0.1],
        gain=HAND_GAIN,
    )
    posture = qc.PostureTask(robot, q0, gain=50.0)
    return [feet, [polygon, band], hand, posture], polygon, band
