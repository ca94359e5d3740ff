"""Tracking metrics of a DDL run (thesis Eqs 6.3–6.6)."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["tracking_metrics", "power"]


def power(i_a, i_b, resistance: float = 0.5) -> float:
    """Eq 6.6: ``P = 2R (i_a,rms² + i_b,rms²)``, W (currents in A, R in Ω)."""
    i_a = np.asarray(i_a, dtype=float)
    i_b = np.asarray(i_b, dtype=float)
    return float(2.0 * resistance * (np.mean(i_a * i_a) + np.mean(i_b * i_b)))


def tracking_metrics(
    error,
    i_a,
    i_b,
    y_f,
    stroke: tuple[float, float],
    fine_saturated,
    resistance: float = 0.5,
) -> dict:
    """Metrics of a run.

    Parameters
    ----------
    error : array_like
        Tracking error ``r − y`` (measured), m.
    i_a, i_b : array_like
        Coil currents, A.
    y_f : array_like
        True fine-stage extension, m.
    stroke : (float, float)
        Fine stroke limits, m.
    fine_saturated : array_like of bool
        Steps in which the fine stage hit a limit.
    resistance : float
        Coil resistance for Eq 6.6, Ω.

    Returns
    -------
    dict
        ``rmse`` (Eq 6.3), ``max_abs`` (Eq 6.4), ``mean_abs`` (Eq 6.5) in m, ``power``
        (Eq 6.6) in W, ``fine_margin_min`` (closest approach of y_f to a stroke limit, m),
        ``saturated_steps`` (int).
    """
    e = np.asarray(error, dtype=float)
    if e.size == 0 or not np.all(np.isfinite(e)):
        raise ValueError("error must be a non-empty finite array")
    y_f = np.asarray(y_f, dtype=float)
    lo, hi = stroke
    margin = np.minimum(y_f - lo, hi - y_f)
    out = {
        "rmse": float(math.sqrt(np.mean(e * e))),
        "max_abs": float(np.max(np.abs(e))),
        "mean_abs": float(np.mean(np.abs(e))),
        "power": power(i_a, i_b, resistance),
        "fine_margin_min": float(margin.min()),
        "saturated_steps": int(np.count_nonzero(fine_saturated)),
    }
    return out
