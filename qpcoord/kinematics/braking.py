"""Braking distance of a joint: the fastest velocity from which it still stops at a limit.

A joint at distance ``D`` (rad, m) from a position limit moves toward it at ``v`` for one
control step ``dt``, then decelerates by at most ``s = a dt`` per step (``a``: the largest
deceleration). With a position-limit box of gain ``K`` (:class:`~qpcoord.JointLimits`:
``v ≤ (K/dt) D`` at every step; ``K = 1``: the joint may land on its limit in one step), the
fastest braking ``v_j = v − j s`` keeps every box iff, for every ``j ≥ 0``,

``v ≤ f(j) = (K D/dt + s (1 − K/2) j + (K s/2) j²) / (1 + K j)``

(``v_j ≤ (K/dt) D_j`` with ``D_j = D − dt Σ_{i<j} v_i``). :func:`braking_speed` is
``min_j f(j)``: the discrete form of ``v ≤ √(2 a D)`` (``K = 1``: ``f(j) = D/((j+1) dt) +
s j/2``) that holds step by step. From a state that meets it, ``v_{k+1} = max(v_k − s, 0)``
meets it again (the braking sequence's tail), so a box ``v ≤ braking_speed(D)`` always meets
an acceleration box ``|v − v_prev| ≤ a dt`` and the position-limit box.
"""

from __future__ import annotations

import numpy as np

__all__ = ["braking_speed"]


def braking_speed(
    distance: np.ndarray, deceleration: np.ndarray, dt: float, gain: float = 1.0
) -> np.ndarray:
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
    gain : float
        ``K`` in ``(0, 1]`` of the position-limit box ``v ≤ (K/dt) D`` kept at every step
        (dimensionless, :class:`~qpcoord.JointLimits`' gain), default 1.

    Returns
    -------
    numpy.ndarray
        ``min_j f(j)`` (rad/s, m/s; see the module) for ``D ≥ 0``, at an integer next to the
        minimiser of ``f`` over real ``j ≥ 0``; ``(K/dt) D`` (the box's push back) outside the
        limit or with ``a = inf``; ``inf`` where ``D`` is.
    """
    D = np.asarray(distance, dtype=float)
    a = np.broadcast_to(np.asarray(deceleration, dtype=float), D.shape)
    K = float(gain)
    s = a * dt
    A = (K / dt) * np.maximum(D, 0.0)
    B = s * (1.0 - 0.5 * K)
    C = 0.5 * K * s
    best = A.copy()
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        # f = (A + B j + C j²)/(1 + K j) is convex in j ≥ 0 (or increasing): its real
        # minimiser solves C K j² + 2 C j + (B − K A) = 0
        root = (np.sqrt(C * C - C * K * (B - K * A)) - C) / (C * K)
        j0 = np.floor(np.where(np.isfinite(root) & (root > 0.0), root, 0.0))
        for j in (j0, j0 + 1.0):
            f = (A + B * j + C * j * j) / (1.0 + K * j)
            np.minimum(best, np.where(np.isnan(f), np.inf, f), out=best)
    outside = D < 0
    if outside.any():
        best = np.where(outside, (K / dt) * D, best)
    return best
