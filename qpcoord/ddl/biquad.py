"""Scalar, allocation-free second-order-section filters for the per-step controllers.

``scipy.signal.sosfilt`` called once per sample costs ≈ 60 µs (``ddl-facts``); a cascade of
biquads kept as plain Python lists and advanced with scalar arithmetic costs ≈ 1 µs.
"""

from __future__ import annotations

from scipy import signal

__all__ = ["butterworth_sections", "filter_sample"]


def butterworth_sections(order: int, cutoff: float, fs: float, x0: float) -> list[list[float]]:
    """Low-pass Butterworth of ``order`` at ``cutoff`` Hz for sampling rate ``fs`` Hz, as
    biquads ``[b0, b1, b2, a1, a2, z0, z1]`` (transposed direct form II) started in steady
    state at the input ``x0``."""
    sos = signal.butter(order, cutoff, fs=fs, output="sos")
    zi = signal.sosfilt_zi(sos) * x0
    return [
        [float(c[0]), float(c[1]), float(c[2]), float(c[4]), float(c[5]), float(z[0]), float(z[1])]
        for c, z in zip(sos, zi, strict=True)
    ]


def filter_sample(sections: list[list[float]], x: float) -> float:
    """Advance the cascade by one input sample ``x``; returns the output (state in place)."""
    for q in sections:
        out = q[0] * x + q[5]
        q[5] = q[1] * x - q[3] * out + q[6]
        q[6] = q[2] * x - q[4] * out
        x = out
    return x
