"""Metrology faults for :func:`.simulate.simulate` (``faults=``): reproducible sensor failures.

Each helper returns what ``simulate(..., faults=...)`` accepts — a dict ``{sample: value}``
or a callable ``(k, y) -> value`` (``k`` the sample index, ``y`` the true reading, m) — so a
fault seen on the bench can be replayed on every controller::

    run = ddl.simulate(plant, ddl.LQR(), r, faults=faults.burst(2000, 8))
    run.metrics["rejected_samples"]   # 8

Helpers combine with :func:`combine` (later faults win where they overlap).
"""

from __future__ import annotations

import math

__all__ = ["sample", "burst", "stuck", "spike", "combine"]


def _index(name: str, value) -> int:
    k = int(value)
    if k != value or k < 0:
        raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
    return k


def sample(k: int, value: float = math.nan) -> dict:
    """One sample ``k`` replaced by ``value`` (m; default NaN)."""
    return {_index("k", k): float(value)}


def burst(start: int, length: int, value: float = math.nan) -> dict:
    """``length`` consecutive samples from ``start`` replaced by ``value`` (m; default NaN)."""
    start = _index("start", start)
    length = _index("length", length)
    return {k: float(value) for k in range(start, start + length)}


def stuck(start: int, length: int):
    """Stuck sensor: from sample ``start``, the reading taken there repeats for ``length``
    samples (then the true reading returns). Returns a callable ``(k, y) -> value``."""
    start = _index("start", start)
    length = _index("length", length)
    held = [math.nan]

    def fault(k, y):
        if k == start:
            held[0] = y
        return held[0] if start <= k < start + length else y

    return fault


def spike(k: int, amplitude: float) -> object:
    """Sample ``k`` offset by ``amplitude`` (m) from the true reading. Returns a callable."""
    k = _index("k", k)
    amplitude = float(amplitude)

    def fault(j, y):
        return y + amplitude if j == k else y

    return fault


def combine(*faults):
    """One callable applying several faults (dicts or callables) in order."""
    parts = []
    for f in faults:
        if isinstance(f, dict):
            table = dict(f)
            parts.append(lambda k, y, t=table: t.get(k, y))
        elif callable(f):
            parts.append(f)
        else:
            raise ValueError(f"a fault must be a dict or a callable (k, y) -> y, got {f!r}")

    def fault(k, y):
        out = y
        for p in parts:
            out = p(k, out)
        return out

    return fault
