"""The thesis 5R3D arm: the joint axes qpcoord chose, why, and what was measured.

The thesis (Fig. 3.1, Example 4.1) gives the link lengths ``l0 = … = l4 = 1 m``,
``l5 = 0.5 m`` but no axes. qpcoord fixes them once, in ``robots/spatial_5r.urdf``, and
never changes them::

                 q3 (y)     q4 (y)
                   o----l3----o
                  /            \\
             l2  /              \\ l4
                /                \\        q2..q5 pitch about their local y axes,
     q2 (y)    o                  o q5 (y)  links along their local x axes
               |                    \\
          l1   |                     \\ l5 = 0.5
   q1 (z) ---- o                      * tip
   yaw         |
               | l0 = 1 (base column, along world z)
            ///////

At ``q = 0`` the arm is stretched horizontally along world x at height ``l0``: joint 1
yaws about world z at the top of the base column, joints 2–5 pitch about y (a planar 4R
arm on a turntable).

Why this arrangement (search over all 3⁵ axis choices × links along z or x, 486 models, of
which 236 are non-degenerate; thesis path and parameters of Example 4.1):

- it is redundant for 3-D positioning (5 joints, Jacobian rank 3 along the path);
- from the thesis start ``q0 = (0.298, 0.165, 0.260, 1.24, 4.37)`` the closest
  configuration on the Lissajous start point (:func:`qpcoord.inverse_kinematics`) is
  ``q_start = (0.2315, 0.3544, 1.0815, 1.9971, 4.4705)``, ``‖q_start − q0‖ = 1.14 rad``
  (no arrangement reaches the path closer than 0.9 rad: the thesis robot was not this one,
  whatever it was);
- the hypothesis of Thm 4.2 holds along the path: with ``ω₄ = dq₁ + dq₅`` and
  ``ω₅ = dq₂ + dq₄`` (Example 4.4) the smallest singular value of ``[J; ω₄; ω₅]`` stays
  ≥ 0.18 over three periods, and ``σ_min(J) ≥ 0.27`` (the path's closest horizontal
  distance to the base axis); the Thm 4.2 motion closes after one period to 6e-12 rad;
- plain pseudo-inverse tracking from the same start also keeps ``σ_min(J) ≥ 0.27`` but its
  joints drift by 0.074 rad per period (the thesis's Fig. 4.3 behaviour).

Common choices that fail the Thm 4.2 hypothesis on this path: z-y-z-y-z (links along z or
x: ``[J; ω₄; ω₅]`` singular within 0.5–2.7 s), z-y-y-z-y (within 1–20 s), z-x-y-y-z,
z-y-x-y-z; z-y-y-y-z with links along z has a joint 5 that never moves the tip.
"""

from __future__ import annotations

import numpy as np

__all__ = ["AXES", "LENGTHS", "Q0_THESIS", "describe"]

#: Joint axes (in each joint's frame), q1..q5.
AXES = ("z", "y", "y", "y", "y")
#: l0..l5 (m).
LENGTHS = (1.0, 1.0, 1.0, 1.0, 1.0, 0.5)
#: Thesis Example 4.1 initial configuration (rad).
Q0_THESIS = np.array([0.298, 0.165, 0.260, 1.24, 4.37])


def describe() -> str:
    """The module's explanation of the chosen axes (a diagram and the measurements)."""
    return __doc__
