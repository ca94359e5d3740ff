"""Coarse actuator: two-phase permanent-magnet stepper (NEMA 23, 1.8°) on a lead screw.

Torque (current-driven coils, ideal current amplifier; thesis §6.1.7)::

    T = Km (i_a cos θe − i_b sin θe) − Td sin(4 θe),     θe = p θ   (electrical angle)

with ``p = 50`` pole pairs (200 full steps per revolution = 4 p). With the thesis's direct coil
commands ``i_a = I sin α``, ``i_b = I cos α`` this is ``Km I sin(α − θe)``: the rotor aligns its
electrical angle with the field phase α. The lead screw turns the rotor angle θ into the
carriage displacement ``x = (lead / 2π) θ``.

Parameters the thesis does not give (assumptions, typical NEMA 23 datasheet magnitudes):
torque constant 0.35 N·m/A, detent torque 0.01 N·m, lead 2 mm/rev, lead-screw nut Coulomb
friction 0.01 N·m with 1.3× stiction. The rotating inertia (rotor + coupling + screw) is
the one parameter calibrated to a thesis figure: with I = 1.5 A (the thesis's direct-coil
power 2.25 W = I² under Eq 6.6 with R = 0.5 Ω) it puts the linearised electromechanical
mode at 120 Hz at the centre of the stroke (thesis Fig 6.7), including the flexure
mass. The viscous coefficient gives that mode a damping ratio of 0.02 (value in
``ddl-facts.md``; the thesis shows a sharp peak but no number).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ._check import check_fields

__all__ = ["StepperParams"]


@dataclass(frozen=True)
class StepperParams:
    """PM stepper + lead screw + friction parameters (SI units).

    Attributes
    ----------
    pole_pairs : int
        Electrical pole pairs p (1.8° motor: 50).
    torque_constant : float
        Km, N·m/A.
    detent_torque : float
        Td, N·m (period one full step, ``sin 4θe``).
    inertia : float
        Rotating inertia (rotor + coupling + screw), kg·m² (calibrated: 120 Hz mode).
    lead : float
        Lead-screw advance per revolution, m.
    coulomb_torque : float
        Kinetic (Coulomb) friction torque, N·m.
    static_torque : float
        Static friction (stiction) torque, N·m (≥ coulomb_torque).
    viscous_damping : float
        Viscous damping referred to the carriage, N·s/m (ζ ≈ 0.02 at 120 Hz).
    current_max : float
        Current amplifier limit per phase, A.
    resistance : float
        Coil resistance per phase, Ω (thesis Eq 6.6: 0.5 Ω).
    """

    pole_pairs: int = 50
    torque_constant: float = 0.35
    detent_torque: float = 0.01
    inertia: float = 4.9136e-5
    lead: float = 2.0e-3
    coulomb_torque: float = 0.01
    static_torque: float = 0.013
    viscous_damping: float = 14790.0
    current_max: float = 3.0
    resistance: float = 0.5

    def __post_init__(self):
        check_fields(
            self,
            ("pole_pairs", "torque_constant", "inertia", "lead", "current_max", "resistance"),
            ("detent_torque", "coulomb_torque", "static_torque", "viscous_damping"),
        )
        if int(self.pole_pairs) != self.pole_pairs:
            raise ValueError(
                f"StepperParams.pole_pairs must be an integer, got {self.pole_pairs!r}"
            )
        if self.static_torque < self.coulomb_torque:
            raise ValueError(
                "StepperParams.static_torque must be >= coulomb_torque, "
                f"got {self.static_torque!r} < {self.coulomb_torque!r}"
            )

    @property
    def screw_radius(self) -> float:
        """Lead / 2π: carriage metres per rotor radian, m/rad."""
        return self.lead / (2.0 * math.pi)

    @property
    def full_step(self) -> float:
        """Carriage travel of one full step (2π/4 electrical), m."""
        return self.lead / (4.0 * self.pole_pairs)

    @property
    def electrical_per_metre(self) -> float:
        """Electrical radians per metre of carriage travel, rad/m."""
        return self.pole_pairs / self.screw_radius
