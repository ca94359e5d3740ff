"""The fine-stage PI output stage shared by the per-step DDL controllers."""

from __future__ import annotations

__all__ = ["clamp_with_antiwindup"]


def clamp_with_antiwindup(
    v: float, integ: float, step: float, v_min: float, v_max: float
) -> tuple[float, float]:
    """PI output ``v`` (V, this period's integrator increment ``step`` included) clamped
    to ``[v_min, v_max]``, and the integrator after it.

    The integrator ``integ`` takes ``step`` unless the output is saturated and ``step``
    would push it further into saturation (conditional-integration anti-windup).
    Returns ``(v, integ)``.
    """
    if v > v_max:
        return v_max, integ + step if step < 0.0 else integ
    if v < v_min:
        return v_min, integ + step if step > 0.0 else integ
    return v, integ + step
