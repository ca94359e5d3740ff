"""Braking distance of a joint: the fastest velocity from which it still stops at a limit.

A joint at distance ``D`` (rad, m) from a position limit, moving toward it at ``v`` for one
control step ``dt`` and then decelerating by at most ``a dt`` per step, covers

``g(v) = dt Σ_{j=0}^{n} (v − j a dt)``, ``n = ⌊v / (a dt)⌋``

before it stops. :func:`braking_speed` is the largest ``v`` with ``g(v) ≤ D``: the discrete
form of ``v ≤ √(2 a D)`` that holds step by step. If a step kept ``g(v_k) ≤ D_k``, the next
one can keep it with ``v_{k+1} = max(v_k − a dt, 0)`` (``g`` shifts by one step), so a box
``v ≤ braking_speed(D)`` always meets an acceleration box ``|v − v_prev| ≤ a dt``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["braking_speed"]


def braking_speed(distance: np.ndarray, deceleration: np.ndarray, dt: float) -> np.ndarray:
    """Largest speed toward a limit from which the joint still stops before it.

    Parameters
    ----------
    distance : numpy.ndarray
        Distance ``D`` to the limit (rad, m), ``inf`` for no limit; negative outside it.
    deceleration : numpy.ndarray
        Largest deceleration ``a`` (rad/s², m/s²), > 0, ``inf`` for none (broadcast with
        ``distance``).
    dt : float
        Control period (s), > 0.

    Returns
    -------
    numpy.ndarray
        ``v`` (rad/s, m/s): ``D/((n+1) dt) + a dt n / 2`` with
        ``n = ⌊(√(1 + 8 D / (a dt²)) − 1) / 2⌋`` for ``D ≥ 0`` (``n`` full braking steps
        after the first); ``D / dt`` (one step back to the limit) outside it, or with
        ``a = inf``; ``inf`` where ``D`` is.
    """
    D = np.asarray(distance, dtype=float)
    a = np.broadcast_to(np.asarray(deceleration, dtype=float), D.shape)
    u = a * (dt * dt)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        n = np.floor(0.5 * (np.sqrt(1.0 + 8.0 * np.maximum(D, 0.0) / u) - 1.0))
        v = D / ((n + 1.0) * dt) + 0.5 * a * dt * n
    # D < 0, a = inf (n = 0, a·0 = nan) or D = inf: the plain one-step bound D/dt
    plain = (D < 0) | ~np.isfinite(v)
    if plain.any():
        v = np.where(plain, D / dt, v)
    return v
