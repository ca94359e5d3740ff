"""Relative-tolerance tests of values against two-sided bounds (±inf allowed).

One place for the tolerance rule used throughout the stack: a bound ``b`` is met to ``tol``
when the value is within ``tol · max(1, |b|)`` of it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["widen", "within", "at_bounds"]


def widen(lo: np.ndarray, hi: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """``(lo − tol·max(1,|lo|), hi + tol·max(1,|hi|))``; infinite bounds stay infinite.

    A wrong-sided infinity (``lo = +inf``, written in place past the checks) gives NaN, which
    meets no comparison, silently: the solve-time check names it (the library never prints).
    """
    with np.errstate(invalid="ignore"):
        return lo - tol * np.maximum(1.0, np.abs(lo)), hi + tol * np.maximum(1.0, np.abs(hi))


def within(values: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: float) -> bool:
    """True if ``lo − tol·max(1,|lo|) ≤ values ≤ hi + tol·max(1,|hi|)``."""
    if values.size == 0:
        return True
    if (values <= hi).all() and (values >= lo).all():
        return True  # exactly inside: the common case, no widening needed
    low, high = widen(lo, hi, tol)
    return bool((values <= high).all() and (values >= low).all())


def at_bounds(values: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: float):
    """Masks of the entries at (or beyond) their lower / upper bound, to ``tol`` relative."""
    at_lo = np.isfinite(lo) & (values - lo <= tol * np.maximum(1.0, np.abs(lo)))
    at_hi = np.isfinite(hi) & (hi - values <= tol * np.maximum(1.0, np.abs(hi))) & ~at_lo
    return at_lo, at_hi
