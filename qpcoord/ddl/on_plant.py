"""Run a controller designed on :meth:`.plant.DualStage.linear` on the nonlinear DualStage.

:class:`OnDualStage` wraps any ``reset()`` / ``step(e) -> (u_c, u_f)`` controller into the
DDL controllers' interface (``reset(plant, fs, y0, r0)``, ``step(y, r) -> (v, i_a, i_b)``,
:func:`.simulate.simulate`): the measured error is ``e = r − y``; the fine command is a
voltage deviation from mid-stroke, the coarse command a field-phase deviation from the
holding phase, applied as direct-coil currents ``i_a = I sin α``, ``i_b = I cos α``.
"""

from __future__ import annotations

import math

from ._check import finite, positive
from .guard import MeasurementGuard, guard_arg

__all__ = ["OnDualStage"]


class OnDualStage:
    """A linear dual-stage controller on the PRIMA :class:`.plant.DualStage`.

    Parameters
    ----------
    law : object
        ``reset()`` and ``step(e) -> (u_c, u_f)``, designed on ``plant.linear(fs, ...)`` (u_c in
        rad electrical, u_f in V, both deviations).
    current : float
        Field amplitude ``I``, A (the one ``plant.linear`` was given).
    guard : MeasurementGuard, optional
        Measurement guard shared by every DDL controller.
    """

    def __init__(self, law, current: float = 1.5, guard: MeasurementGuard | None = None):
        if not (callable(getattr(law, "reset", None)) and callable(getattr(law, "step", None))):
            raise ValueError(f"law must have reset() and step(e), got {law!r}")
        self.law = law
        self.current = positive("current", current)
        self.guard = guard_arg(guard)
        self.y_c_hat = 0.0

    def reset(self, plant, fs: float, y0: float, r0: float) -> None:
        """Initialise at the plant's rest state (``fs`` Hz; ``y0``, ``r0`` in m)."""
        positive("fs", fs)
        finite("y0", y0)
        finite("r0", r0)
        lp = getattr(self.law, "plant", None)
        if lp is not None and abs(lp.Ts * fs - 1.0) > 1e-9:
            raise ValueError(f"the law was designed at Ts = {lp.Ts!r} s, not 1/fs = {1 / fs!r} s")
        self._alpha0 = plant.equilibrium_phase(self.current)
        self._v0 = plant.fine.v_centre
        self._off = r0 - y0  # the error at rest is the law's zero
        self.law.reset()
        self.guard.reset(plant, fs, y0, r0)
        self._y = y0
        self.y_c_hat = y0 - plant.fine.centre

    def step(self, y: float, r: float) -> tuple[float, float, float]:
        """One period: measurement ``y``, reference ``r`` (m) → (V, A, A)."""
        y, r = self.guard.filter(y, r, self._y)
        self._y = y
        uc, uf = self.law.step(r - y - self._off)
        a = self._alpha0 + uc
        cur = self.current
        return self._v0 + uf, cur * math.sin(a), cur * math.cos(a)
