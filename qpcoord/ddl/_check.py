"""Small argument checks shared by the DDL modules (ValueError naming argument and value)."""

from __future__ import annotations

import math


def positive(name: str, value) -> float:
    """Return ``value`` as float if finite and > 0, else raise ValueError naming it."""
    v = float(value)
    if not math.isfinite(v) or v <= 0.0:
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return v


def nonnegative(name: str, value) -> float:
    """Return ``value`` as float if finite and >= 0, else raise ValueError naming it."""
    v = float(value)
    if not math.isfinite(v) or v < 0.0:
        raise ValueError(f"{name} must be finite and >= 0, got {value!r}")
    return v


def finite(name: str, value) -> float:
    """Return ``value`` as float if finite, else raise ValueError naming it."""
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


def check_fields(obj, positive_fields=(), nonnegative_fields=(), finite_fields=()) -> None:
    """Validate dataclass fields of ``obj`` by name (raises ValueError naming the field)."""
    cls = type(obj).__name__
    for f in positive_fields:
        positive(f"{cls}.{f}", getattr(obj, f))
    for f in nonnegative_fields:
        nonnegative(f"{cls}.{f}", getattr(obj, f))
    for f in finite_fields:
        finite(f"{cls}.{f}", getattr(obj, f))
