"""Exact feedback linearisation of the PM stepper: a carriage force command → coil currents.

The "Amplitude = controlled, Phase = fixed" drive of thesis Table 6.2 (the interface of its
PI-linearised, flatness, LQR and PQ controllers): the field is placed in quadrature with the
estimated rotor angle ``θ̂e = p ŷ_c / r_screw`` and its amplitude commands the torque, which
also cancels the modelled flexure spring and detent torque::

    i_q = (F r + k_f ŷ_c r + T_d sin 4θ̂e) / K_m,     |i_q| ≤ current
    α = θ̂e + atan2(i_q, i_d),   I = √(i_q² + i_d²),   i_a = I sin α,   i_b = I cos α

so that the carriage obeys ``M ÿ_c + c ẏ_c = F − F_friction``. A small direct-axis current
``i_d`` keeps the commanded field angle continuous when the torque changes sign (a pure
quadrature field would jump by π, which the plant's synchronism check cannot tell from a
slip). :class:`.pi_linearised.PILinearised` has the same law inline (with its friction
handling); :class:`LinearisingDrive` serves the global-structure controllers
(:mod:`.lqr_current`, :mod:`.pq_current`).
"""

from __future__ import annotations

import math

from ._check import finite, nonnegative, positive

__all__ = ["LinearisingDrive"]


class LinearisingDrive:
    """Force-to-currents map of the feedback-linearised stepper (module docstring).

    Parameters
    ----------
    current : float
        Limit of the quadrature current |i_q|, A.
    d_current : float
        Direct-axis current i_d, A (≥ 0).

    Attributes (after :meth:`reset`)
    --------------------------------
    force_max : float
        Force at the current limit, ``current · K_m / r_screw``, N.
    saturated : bool
        Whether the last :meth:`command` hit the current limit.
    """

    def __init__(self, current: float = 1.5, d_current: float = 0.01):
        self.current = positive("current", current)
        self.d_current = nonnegative("d_current", d_current)
        self.saturated = False

    def reset(self, plant) -> None:
        """Take the model (stepper, flexure) from ``plant`` (a :class:`.plant.DualStage`)."""
        st = plant.stepper
        self._r = st.screw_radius
        self._ne = st.pole_pairs / st.screw_radius
        self._km = st.torque_constant
        self._td = st.detent_torque
        self._kflex = plant.flexure.spring_rate
        self.force_max = self.current * self._km / self._r
        self.saturated = False

    def command(self, force: float, y_c: float) -> tuple[float, float, float]:
        """Currents for carriage force ``force`` (N) at estimated position ``y_c`` (m).

        Returns ``(i_a, i_b, force_applied)``: the coil currents (A) and the force the
        model receives after the current limit (N, flexure and detent cancelled).
        """
        force = finite("force", force)
        r = self._r
        th = self._ne * y_c
        load = self._kflex * y_c * r + self._td * math.sin(4.0 * th)
        iq = (force * r + load) / self._km
        cur = self.current
        self.saturated = False
        if iq > cur:
            iq = cur
            self.saturated = True
        elif iq < -cur:
            iq = -cur
            self.saturated = True
        applied = (iq * self._km - load) / r if self.saturated else force
        idc = self.d_current
        alpha = th + math.atan2(iq, idc)
        amp = math.hypot(iq, idc)
        return amp * math.sin(alpha), amp * math.cos(alpha), applied
