"""The thesis's LQR: current (amplitude) controlled, no rate limit — :class:`LQRCurrent`.

Thesis §6.4.2 groups its LQR with "the other methods based on exact feedback linearization"
(Table 6.2: global structure; 0.015 W in Table 6.1, against 2.25 W for the direct coil's
fixed-amplitude field) and says that for it "no such speed limitation can be introduced,
which leads to a random behavior caused by de-synchronization between rotor and the
generated magnetic field" (Fig 6.19a). :class:`LQRCurrent` is that controller on our plant:

* design model (:func:`design_model_force`): the fine stage as in :func:`.lqr.design_model`
  and the feedback-linearised carriage ``M ÿ_c + c ẏ_c = F`` (flexure and detent cancelled by
  :class:`.drive.LinearisingDrive`, friction not modelled), inputs ``(v, F)``;
* the same LQR + integral action + steady-state Kalman current estimator as :class:`.lqr.LQR`
  (weights :func:`.lqr.default_weights` with the force's Bryson scale ``force_max`` in place
  of the phase's, observer :func:`.lqr.kalman_gain`), the force mapped to coil currents at
  the observer's carriage estimate, ``|i_q| ≤ current``, **no rate limit**; the integral
  freezes and the observer sees the applied force when the current or the voltage clips.

Default weights (rules): ``force_max`` = half the drive's range (825 N at 1.5 A, as the
voltage's 5 V is half its range); ``error_max`` = 1.4 µm, the smallest value keeping peak
|S| ≤ 1.6 (the rule of :class:`.lqr.LQR`, by :func:`.lqr.tune_error_max`'s bisection on
this model at 8 kHz: 1.34 µm, rounded up). Friction (31 N Coulomb, 41 N stiction) is left
to the integral action and the observer's process noise, as a standard LQR would.

:class:`.lqr.LQR` (field phase at fixed amplitude, 3 mm/s rate limit) is qpcoord's improved
variant beside it: it cannot lose synchronism and does not stick, at 2.25 W.
"""

from __future__ import annotations

import math

import numpy as np

from ._check import positive
from .drive import LinearisingDrive
from .guard import MeasurementGuard
from .lqr import (
    LQR,
    STATES,
    DesignModel,
    default_weights,
    discretise_model,
    kalman_gain,
    solve_dare,
)

__all__ = ["design_model_force", "LQRCurrent"]

FORCE_INPUTS = ("v", "F")


def design_model_force(plant, fs: float, y_c: float = 0.0, current: float = 1.5) -> DesignModel:
    """Discrete design model with the carriage force as coarse input (module docstring).

    States ``(y_f, ẏ_f, y_c, ẏ_c)`` (m, m/s), inputs ``(v − v_op [V], F [N])``, output
    ``y = y_f + y_c``; ``alpha_op`` is 0 (no operating phase: the drive places the field).
    """
    import control

    fs = positive("fs", fs)
    current = positive("current", current)
    h = plant.coarse_half_stroke
    if not -h <= y_c <= h:
        raise ValueError(f"y_c = {y_c!r} m is outside the coarse stroke ±{h} m")
    m = plant.carriage_mass(y_c)
    fa, fb = plant.fine.continuous()
    a = np.zeros((4, 4))
    a[:2, :2] = fa
    a[2, 3] = 1.0
    a[3, 3] = -plant.stepper.viscous_damping / m
    b = np.zeros((4, 2))
    b[1, 0] = fb[1]
    b[3, 1] = 1.0 / m
    c = np.array([[1.0, 0.0, 1.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    sysc = control.ss(
        a,
        b,
        c,
        np.zeros((3, 2)),
        states=list(STATES),
        inputs=list(FORCE_INPUTS),
        outputs=["y", "y_f", "y_c"],
    )
    return discretise_model(sysc, plant.fine, fs, float(y_c), current, 0.0, FORCE_INPUTS)


class LQRCurrent(LQR):
    """LQR + integral + Kalman observer on the feedback-linearised DDL (module docstring).

    Parameters
    ----------
    Q, R : array_like, optional
        Weights as :class:`.lqr.LQR` (``R`` on ``(v [V], F [N])``). Default
        :func:`.lqr.default_weights` with ``error_max`` and ``alpha_max = force_max``.
    current : float
        Limit of the quadrature current, A.
    d_current : float
        Direct-axis current, A (:class:`.drive.LinearisingDrive`).
    error_max : float
        Bryson scale of the output error, m (default weights only).
    force_max : float, optional
        Bryson scale of the force, N (default: half the force at ``current``).
    sigma_force, sigma_v, design_plant, y_c_op, guard
        As :class:`.lqr.LQR`.
    """

    def __init__(
        self,
        Q=None,
        R=None,
        current: float = 1.5,
        d_current: float = 0.01,
        error_max: float = 1.4e-6,
        force_max: float | None = None,
        sigma_force: float | None = None,
        sigma_v: float = 0.05,
        design_plant=None,
        y_c_op: float | None = None,
        guard: MeasurementGuard | None = None,
    ):
        super().__init__(Q, R, current, 1.0, sigma_force, sigma_v, design_plant, y_c_op, guard)
        self.max_speed = math.inf  # no rate limit (the thesis's LQR)
        self.error_max = positive("error_max", error_max)
        self.force_max = None if force_max is None else positive("force_max", force_max)
        self.drive = LinearisingDrive(current, d_current)

    def design(self, plant, fs: float, y_c_op: float = 0.0) -> LQRCurrent:
        """Compute ``model``, ``Q``, ``R``, ``P``, ``K``, ``M`` for ``plant`` at ``fs`` Hz."""
        dp = plant if self.design_plant is None else self.design_plant
        self.model = model = design_model_force(dp, fs, y_c_op, self.current)
        st = dp.stepper
        fmax = self.force_max
        if fmax is None:
            fmax = 0.5 * self.current * st.torque_constant / st.screw_radius
        if self._q_in is None:
            self.Q, self.R = default_weights(model, error_max=self.error_max, alpha_max=fmax)
        else:
            self.Q, self.R = self._q_in.copy(), self._r_in.copy()
        self.P, self.K = solve_dare(model.Aa, model.Ba, self.Q, self.R)
        self.M, self.P_kalman = kalman_gain(model, self.sigma_force, self.sigma_v, plant=dp)
        return self

    def reset(self, plant, fs: float, y0: float, r0: float) -> None:
        """Design at the carriage position (or ``y_c_op``) and start at rest."""
        super().reset(plant, fs, y0, r0)
        dp = plant if self.design_plant is None else self.design_plant
        self.drive.reset(dp)

    def step(self, y: float, r: float) -> tuple[float, float, float]:
        """One period: measured output ``y`` (m), reference ``r`` (m) → (V, A, A)."""
        y, r, x, v, uf, clipped = self._feedback(y, r)
        # the drive turns the force deviation into phase currents (its saturation clips)
        ia, ib, uf = self.drive.command(uf, x[2] + self.model.y_c_op)
        self._predict(y, r, x, v, uf, clipped or self.drive.saturated)
        return v, ia, ib
