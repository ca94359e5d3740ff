"""Fine stage: the PI S-325 piezo stack of the DDL as a second-order system (thesis Fig 6.6).

Model: ``G(s) = K ωn² / (s² + 2 ζ ωn s + ωn²)`` from the amplifier voltage (V) to the mirror
displacement (m), 0–10 V → 0–30 µm (static gain K = 3 µm/V), hard stroke limits 0–30 µm.
The thesis gives the static gain and "a bandwidth of approximately 300 Hz" of the identified
second-order approximation; the damping ζ is not given: 0.7 is chosen so that the −3 dB
bandwidth of the model equals ωn (for ζ = 1/√2 exactly), i.e. ≈ 300 Hz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from ._check import check_fields

__all__ = ["FineParams", "fine_zoh"]


@dataclass(frozen=True)
class FineParams:
    """Piezo fine-stage parameters (SI units).

    Attributes
    ----------
    gain : float
        Static gain, m/V (thesis: 30 µm for 10 V).
    natural_frequency : float
        ωn/2π of the second-order model, Hz (thesis: ≈ 300 Hz bandwidth).
    damping : float
        Damping ratio ζ (not in the thesis; 0.7 makes the −3 dB bandwidth ≈ ωn).
    v_min, v_max : float
        Amplifier voltage range, V (0–10 V).
    stroke_min, stroke_max : float
        Hard mechanical limits of the fine displacement, m (0–30 µm). A stage driven into
        a limit stops there (its velocity is set to zero).
    """

    gain: float = 3.0e-6
    natural_frequency: float = 300.0
    damping: float = 0.7
    v_min: float = 0.0
    v_max: float = 10.0
    stroke_min: float = 0.0
    stroke_max: float = 30.0e-6

    def __post_init__(self):
        check_fields(self, ("gain", "natural_frequency", "damping"), (), ("v_min", "v_max"))
        if not self.v_max > self.v_min:
            raise ValueError(f"FineParams.v_max must exceed v_min, got {self.v_max!r}")
        if not self.stroke_max > self.stroke_min:
            raise ValueError(
                f"FineParams.stroke_max must exceed stroke_min, got {self.stroke_max!r}"
            )

    @property
    def centre(self) -> float:
        """Mid-stroke fine displacement, m."""
        return 0.5 * (self.stroke_min + self.stroke_max)

    @property
    def v_centre(self) -> float:
        """Voltage that holds the fine stage at mid-stroke in steady state, V."""
        return self.centre / self.gain

    def continuous(self):
        """Continuous state-space matrices ``(A, B)``; state (y_f m, ẏ_f m/s), input V."""
        wn = 2.0 * math.pi * self.natural_frequency
        a = np.array([[0.0, 1.0], [-wn * wn, -2.0 * self.damping * wn]])
        b = np.array([0.0, self.gain * wn * wn])
        return a, b


def fine_zoh(p: FineParams, dt: float) -> tuple[float, float, float, float, float, float]:
    """Exact zero-order-hold discretisation of the fine stage over ``dt`` seconds.

    Returns
    -------
    tuple of float
        ``(a11, a12, a21, a22, b1, b2)``: ``x⁺ = [[a11, a12], [a21, a22]] x + [b1, b2] v``
        with x = (y_f m, ẏ_f m/s) and v in volts. Plain floats for scalar inner loops.
    """
    a, b = p.continuous()
    m = np.zeros((3, 3))
    m[:2, :2] = a * dt
    m[:2, 2] = b * dt
    e = expm(m)
    return (
        float(e[0, 0]),
        float(e[0, 1]),
        float(e[1, 0]),
        float(e[1, 1]),
        float(e[0, 2]),
        float(e[1, 2]),
    )
