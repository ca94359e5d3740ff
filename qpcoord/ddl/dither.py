"""Friction under a dither: the averaged (describing-function) model the linearised coarse
controllers are designed on.

A square-wave force ``±A`` of period ``n`` control periods (``n = 4``: ``fs/4``, 2 kHz at
8 kHz) added to the carriage force keeps a carriage with Coulomb friction ``F_c`` and
stiction ``F_s < A`` sliding back and forth: it never sticks. Over one dither period the
friction then averages to a smooth function of the mean velocity ``u``. With the viscous
force neglected during one period (``c v_d ≪ A``) the steady oscillation has the velocity
amplitude (the carriage accelerates at ``(A + F_c)/M`` while moving against the dither and
``(A − F_c)/M`` with it, for half a period ``T/2 = n/(2 fs)`` in all)::

    v_d = (T/2) (A² − F_c²) / (2 A M)

and, approximating the velocity waveform by a triangle of amplitude ``v_d`` about ``u``, the
averaged friction is linear below ``v_d`` and Coulomb above::

    F̄(u) = F_c · clip(u / v_d, −1, 1),      c_d = F_c / v_d   (slope at u = 0, N·s/m)

The carriage's position ripple is ``v_d T/8`` (≈ 1 nm with the PRIMA defaults: ``A = 2 F_s =
82 N``, ``M = 491 kg``, 2 kHz). This is the classical remedy for stiction in precision
positioning (Armstrong-Hélouvry, Dupont & Canudas de Wit, Automatica 30(7), 1994, §5.4).
"""

from __future__ import annotations

from dataclasses import dataclass

from ._check import positive

__all__ = ["DitherModel", "dither_model"]


@dataclass(frozen=True)
class DitherModel:
    """Averaged friction under a square-wave dither (SI units; module docstring).

    Attributes
    ----------
    amplitude : float
        Dither force amplitude A, N.
    period : int
        Dither period, control periods (even).
    coulomb : float
        Coulomb friction force F_c, N.
    velocity : float
        Dither velocity amplitude v_d, m/s.
    damping : float
        Equivalent viscous coefficient ``c_d = F_c / v_d`` at zero mean velocity, N·s/m.
    ripple : float
        Position ripple amplitude ``v_d T / 8``, m.
    """

    amplitude: float
    period: int
    coulomb: float
    velocity: float
    damping: float
    ripple: float

    def friction(self, u: float) -> float:
        """Averaged friction force at mean velocity ``u`` (m/s), N (opposes ``u``)."""
        x = u / self.velocity
        if x > 1.0:
            x = 1.0
        elif x < -1.0:
            x = -1.0
        return self.coulomb * x


def dither_model(
    amplitude: float, coulomb: float, static: float, mass: float, fs: float, period: int = 4
) -> DitherModel:
    """Averaged friction of a carriage of ``mass`` kg under a ``±amplitude`` N square wave.

    Parameters
    ----------
    amplitude : float
        Dither force amplitude, N; must exceed the stiction force ``static``.
    coulomb, static : float
        Coulomb and static friction forces, N (``coulomb <= static``).
    mass : float
        Carriage-equivalent mass, kg.
    fs : float
        Control rate, Hz.
    period : int
        Dither period in control periods (even, ≥ 2).

    Raises
    ------
    ValueError
        Non-positive arguments, ``amplitude <= static``, or an odd/short ``period``.
    """
    amplitude = positive("amplitude", amplitude)
    coulomb = positive("coulomb", coulomb)
    static = positive("static", static)
    mass = positive("mass", mass)
    fs = positive("fs", fs)
    if int(period) != period or period < 2 or int(period) % 2:
        raise ValueError(f"period must be an even integer >= 2, got {period!r}")
    if static < coulomb:
        raise ValueError(f"static = {static!r} N must be >= coulomb = {coulomb!r} N")
    if amplitude <= static:
        raise ValueError(f"amplitude = {amplitude!r} N must exceed the stiction force {static!r} N")
    t = int(period) / fs
    v = 0.5 * t * (amplitude * amplitude - coulomb * coulomb) / (2.0 * amplitude * mass)
    return DitherModel(amplitude, int(period), coulomb, v, coulomb / v, v * t / 8.0)
