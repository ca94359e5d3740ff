"""Appendix B: the double-parallelogram blade flexure that guides the DDL carriage.

Two rigid bodies, the main mass ``M`` (carriage with the cat's eye) and the intermediate
platform ``m``, are joined by main blades (stiffness ``k1``) and auxiliary blades (``k1p``)
of length ``l``. Constraints (B.1) ``x2 = x1/2`` and (B.2) ``x3 = −3 x2²/(5 l)`` leave one
degree of freedom ``x1`` (carriage displacement from the flexure's rest position). From the
Lagrangian of appendix B, in the coordinate ``x1``:

* kinetic energy ``½ (M + m/4 + 9 m x1²/(100 l²)) ẋ1²`` (position-dependent mass: the
  intermediate platform moves vertically more and more towards the stroke ends);
* potential energy ``(k1 + k1p) x1²/8``, i.e. spring force ``−(k1 + k1p) x1 / 4``;
* free resonance ``ω0² = (k1 + k1p) / (4M + m + 9 m x1²/(25 l²))`` — the reduced model of
  appendix B (``ω0² = 10α − 5β`` with its α, β, δ).

The thesis gives the load range (−150 N to +150 N over the 70 mm stroke) but not the masses,
blade length or the split between ``k1`` and ``k1p``; the defaults here are assumptions:
M = 5 kg, m = 2 kg, l = 0.1 m, and ``k1 + k1p`` set so that the spring force is exactly
±150 N at ±35 mm (``k1 + k1p = 4 · 150 N / 35 mm``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._check import check_fields

__all__ = ["BladeFlexure"]


@dataclass(frozen=True)
class BladeFlexure:
    """Double-parallelogram blade flexure (appendix B), SI units.

    Attributes
    ----------
    main_mass : float
        ``M``, carriage + cat's eye, kg (assumed).
    platform_mass : float
        ``m``, intermediate platform, kg (assumed).
    blade_length : float
        ``l``, m (assumed).
    stiffness_sum : float
        ``k1 + k1p``, N/m. Default: 4·150 N / 0.035 m, the thesis's ±150 N at the stroke ends.
    half_stroke : float
        Half of the coarse stroke, m (thesis: 70 mm stroke).
    """

    main_mass: float = 5.0
    platform_mass: float = 2.0
    blade_length: float = 0.1
    stiffness_sum: float = 4.0 * 150.0 / 0.035
    half_stroke: float = 0.035

    def __post_init__(self):
        check_fields(
            self,
            ("main_mass", "blade_length", "stiffness_sum", "half_stroke"),
            ("platform_mass",),
        )

    @property
    def spring_rate(self) -> float:
        """Carriage spring rate ``(k1 + k1p)/4``, N/m."""
        return 0.25 * self.stiffness_sum

    @property
    def mass_curvature(self) -> float:
        """Coefficient ``q`` of the position-dependent mass ``M + m/4 + q x²``, kg/m²."""
        return 9.0 * self.platform_mass / (100.0 * self.blade_length**2)

    def force(self, x):
        """Flexure spring force on the carriage at displacement ``x`` (m), N (restoring)."""
        return -self.spring_rate * np.asarray(x, dtype=float)

    def effective_mass(self, x):
        """Carriage-equivalent mass of the flexure at ``x`` (m), kg."""
        x = np.asarray(x, dtype=float)
        return self.main_mass + 0.25 * self.platform_mass + self.mass_curvature * x * x

    def resonance(self, x):
        """Free resonance of the flexure alone (appendix B, Fig B.2) at ``x`` (m), Hz."""
        x = np.asarray(x, dtype=float)
        den = (
            4.0 * self.main_mass
            + self.platform_mass
            + 9.0 * self.platform_mass * x * x / (25.0 * self.blade_length**2)
        )
        return np.sqrt(self.stiffness_sum / den) / (2.0 * math.pi)

    def linear_model(self, x: float):
        """Appendix-B reduced small-signal model ``(A_r, B_r)`` at operating point ``x`` (m).

        State (x1 m, ẋ1 m/s), input the actuator force u (N): ``A_r = [[0, 1], [−ω0², 0]]``,
        ``B_r = [0, 100 l δ]`` with δ of appendix B. The sign of ``ω0²`` is that of a
        restoring spring (the thesis prints it positive in ``A_r``, which would be unstable).
        """
        big_m, m, ll = self.main_mass, self.platform_mass, self.blade_length
        k = self.stiffness_sum
        delta = ll / (25.0 * ll * ll * (m + 4.0 * big_m) + 9.0 * m * x * x)
        # reduced model in (x1, ẋ1): ẍ1 = −ω0² x1 + 100 l δ u
        w2 = 25.0 * ll * delta * k
        a = np.array([[0.0, 1.0], [-w2, 0.0]])
        b = np.array([0.0, 100.0 * ll * delta])
        return a, b
