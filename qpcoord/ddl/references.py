"""Reference signals for the DDL: atmospheric differential piston (OPD), steps and ramps.

Atmospheric OPD
---------------
Frozen-flow differential piston between two apertures of diameter ``D`` separated by a
baseline ``B`` parallel to the wind ``v``, von Kármán phase spectrum (κ in cycles/m)::

    Φ(κ) = 0.023 r0^(−5/3) (κ² + L0^(−2))^(−11/6)                      [rad² m²]
    S(f) = 4 sin²(π f B / v) · (2/v) ∫ dκy Φ(f/v, κy) [2 J1(π D κ)/(π D κ)]² (λ/2π)²

(one-sided, m²/Hz; r0 at λ = 500 nm; the OPD is achromatic). Because the baseline is along
the wind the interference factor depends on f only and is applied exactly; the smooth
integral is evaluated on a log grid and interpolated. Asymptotic regimes (Conan et al.):
∝ f^(−2/3) below ≈ 0.2 v/B, ∝ f^(−8/3) up to ≈ 0.3 v/D, ∝ f^(−17/3) above (with L0 = ∞).
Several layers (speed, fraction of the turbulence strength Cn² — ``r0_i = r0 w_i^(−3/5)``)
add their spectra. Vibration lines (centre Hz, rms m, width Hz) add Gaussian PSD bumps.

Synthesis is by FFT shaping: ``X_k = N √(S(f_k) Δf)/2 (a + i b)`` with a, b standard normal
(seeded), inverse real FFT, ``oversample``× the requested length generated and the start
kept (so the signal is not periodic and keeps content below 1/duration).

Presets
-------
``"paranal"``: one ground layer, 10 m/s, r0 = 0.126 m (0.8″ seeing), L0 = 25 m, B = 100 m,
D = 1.8 m (AT) — values from ``ddl-facts.md``. A single frozen layer has almost nothing
above 50 Hz.

``"paranal_250hz"``: the thesis's test case "Kolmogorov with content up to 250 Hz, small
amplitudes (< 1 µm) above 50 Hz" (§6.1.2). The thesis does not give its generator; this
preset is an assumption made explicit: the same turbulence split in a ground layer (80 % of
Cn², 10 m/s) and a fast layer (20 %, 40 m/s), plus telescope vibration lines at 18, 47, 80,
150 and 230 Hz with 50, 30, 20, 10 and 5 nm rms (frequencies of the kind reported for VLTI
vibrations; amplitudes picked as AT-like levels, not fitted to any result), band-limited at
250 Hz.

``"paranal_250hz_lf10"``: ``"paranal_250hz"`` with 10× the turbulence power below ≈ 2 Hz
(``low_freq_gain=10``, ``low_freq_corner=2``): a stronger low-frequency wander (longer
baseline, larger outer scale or slower seeing) for designs that must keep the fine stage off
its stops. Any preset takes ``low_freq_gain`` / ``low_freq_corner`` as overrides.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

from ._check import finite, nonnegative, positive

__all__ = [
    "PRESETS",
    "Layer",
    "VibrationLine",
    "kolmogorov_opd",
    "opd_psd",
    "step_reference",
    "ramp_reference",
    "fig619_steps",
]

WAVELENGTH = 500e-9  # m, wavelength at which r0 is specified


@dataclass(frozen=True)
class Layer:
    """A frozen turbulent layer: wind speed (m/s) and fraction of the total Cn² (0–1]."""

    speed: float
    weight: float = 1.0

    def __post_init__(self):
        positive("Layer.speed", self.speed)
        w = positive("Layer.weight", self.weight)
        if w > 1.0:
            raise ValueError(f"Layer.weight must be in (0, 1], got {self.weight!r}")


@dataclass(frozen=True)
class VibrationLine:
    """A narrow vibration line: centre frequency (Hz), rms amplitude (m), Gaussian width (Hz)."""

    frequency: float
    rms: float
    width: float = 0.5

    def __post_init__(self):
        positive("VibrationLine.frequency", self.frequency)
        nonnegative("VibrationLine.rms", self.rms)
        positive("VibrationLine.width", self.width)


PRESETS: dict[str, dict] = {
    "paranal": {
        "baseline": 100.0,
        "aperture": 1.8,
        "r0": 0.126,
        "L0": 25.0,
        "layers": (Layer(10.0, 1.0),),
        "lines": (),
        "f_max": None,
    },
    "paranal_250hz": {
        "baseline": 100.0,
        "aperture": 1.8,
        "r0": 0.126,
        "L0": 25.0,
        "layers": (Layer(10.0, 0.8), Layer(40.0, 0.2)),
        "lines": (
            VibrationLine(18.0, 50e-9),
            VibrationLine(47.0, 30e-9),
            VibrationLine(80.0, 20e-9),
            VibrationLine(150.0, 10e-9),
            VibrationLine(230.0, 5e-9),
        ),
        "f_max": 250.0,
    },
}
PRESETS["paranal_250hz_lf10"] = {
    **PRESETS["paranal_250hz"],
    "low_freq_gain": 10.0,
    "low_freq_corner": 2.0,
}

#: Keywords of :func:`opd_psd` every preset accepts as overrides besides its own entries.
_EXTRA_PARAMS = ("low_freq_gain", "low_freq_corner")


def _piston_integral(kx: np.ndarray, r0: float, L0: float, aperture: float) -> np.ndarray:
    """∫ dκy Φ(kx, κy) A(κ)² (λ/2π)² over κy ∈ ℝ for each kx (cycles/m); m² per cycles/m."""
    kmax = 60.0 / aperture if aperture > 0 else 1e3
    ky = np.concatenate(([0.0], np.logspace(-7, math.log10(kmax), 500)))
    kx = np.asarray(kx, dtype=float)[:, None]
    k2 = kx * kx + ky[None, :] ** 2
    inv_l02 = 0.0 if not math.isfinite(L0) else 1.0 / (L0 * L0)
    phi = 0.023 * r0 ** (-5.0 / 3.0) * (k2 + inv_l02) ** (-11.0 / 6.0)
    if aperture > 0:
        z = math.pi * aperture * np.sqrt(k2)
        with np.errstate(invalid="ignore", divide="ignore"):
            air = np.where(z > 1e-12, 2.0 * special.j1(z) / np.where(z > 1e-12, z, 1.0), 1.0)
        phi = phi * air * air
    integ = 2.0 * np.trapezoid(phi, ky, axis=1)  # symmetric in κy
    return integ * (WAVELENGTH / (2.0 * math.pi)) ** 2


def opd_psd(
    f,
    *,
    baseline: float = 100.0,
    aperture: float = 1.8,
    r0: float = 0.126,
    L0: float = 25.0,
    layers=(Layer(10.0, 1.0),),
    lines=(),
    f_max: float | None = None,
    low_freq_gain: float = 1.0,
    low_freq_corner: float = 2.0,
) -> np.ndarray:
    """One-sided PSD of the differential-piston OPD at frequencies ``f`` (Hz), m²/Hz.

    Parameters
    ----------
    f : array_like
        Frequencies, Hz (> 0).
    baseline : float
        Telescope separation B, m (parallel to the wind).
    aperture : float
        Telescope diameter D, m (0: point apertures, no aperture filtering).
    r0 : float
        Fried parameter at 500 nm, m.
    L0 : float
        Outer scale, m (``inf`` for pure Kolmogorov).
    layers : sequence of Layer
        Frozen layers (speed m/s, Cn² fraction); weights need not sum to 1.
    lines : sequence of VibrationLine
        Vibration lines added as Gaussian bumps of the given rms.
    f_max : float, optional
        Band limit, Hz: the PSD is zero above it.
    low_freq_gain : float
        Factor on the turbulence (layers') PSD at low frequency, > 0 (1: none): the layers'
        sum is multiplied by ``1 + (g − 1)/(1 + (f/f_lf)⁴)`` — ``g`` well below the corner,
        1 well above it. Vibration lines are not scaled.
    low_freq_corner : float
        Corner ``f_lf`` of that factor, Hz.
    """
    f = np.atleast_1d(np.asarray(f, dtype=float))
    if np.any(~np.isfinite(f)) or np.any(f <= 0):
        raise ValueError("f must be finite and > 0")
    baseline = positive("baseline", baseline)
    aperture = nonnegative("aperture", aperture)
    r0 = positive("r0", r0)
    L0 = float(L0)
    if not L0 > 0:
        raise ValueError(f"L0 must be > 0 (inf allowed), got {L0!r}")
    out = np.zeros_like(f)
    lf = np.log(f)
    for layer in layers:
        if not isinstance(layer, Layer):
            layer = Layer(*layer)
        v = layer.speed
        r0_i = r0 * layer.weight ** (-3.0 / 5.0)
        grid = np.logspace(math.log10(f.min()) - 0.1, math.log10(f.max()) + 0.1, 240)
        g = _piston_integral(grid / v, r0_i, L0, aperture) * (2.0 / v)
        smooth = np.exp(np.interp(lf, np.log(grid), np.log(np.maximum(g, 1e-300))))
        out += 4.0 * np.sin(math.pi * f * baseline / v) ** 2 * smooth
    low_freq_gain = positive("low_freq_gain", low_freq_gain)
    low_freq_corner = positive("low_freq_corner", low_freq_corner)
    if low_freq_gain != 1.0:
        out *= 1.0 + (low_freq_gain - 1.0) / (1.0 + (f / low_freq_corner) ** 4)
    for line in lines:
        if not isinstance(line, VibrationLine):
            line = VibrationLine(*line)
        out += (
            line.rms**2
            / (line.width * math.sqrt(2.0 * math.pi))
            * np.exp(-0.5 * ((f - line.frequency) / line.width) ** 2)
        )
    if f_max is not None:
        out[f > positive("f_max", f_max)] = 0.0
    return out


def _synth(psd_fn, n: int, fs: float, seed: int, oversample: int) -> np.ndarray:
    nbig = int(n * oversample)
    nbig += nbig % 2
    df = fs / nbig
    fk = np.arange(1, nbig // 2) * df
    s = psd_fn(fk)
    rng = np.random.default_rng(seed)
    a = rng.standard_normal(fk.size)
    b = rng.standard_normal(fk.size)
    spec = np.zeros(nbig // 2 + 1, dtype=complex)
    spec[1 : nbig // 2] = nbig * np.sqrt(s * df) / 2.0 * (a + 1j * b)
    x = np.fft.irfft(spec, n=nbig)
    return x[:n]


def kolmogorov_opd(
    duration: float,
    fs: float,
    seed: int = 0,
    *,
    preset: str | None = "paranal",
    oversample: int = 4,
    **params,
) -> np.ndarray:
    """Synthetic atmospheric differential-piston OPD, m, sampled at ``fs``.

    Parameters
    ----------
    duration : float
        Length, s.
    fs : float
        Sampling rate, Hz.
    seed : int
        Seed: the same seed gives the same signal.
    preset : str or None
        Name in :data:`PRESETS` (``"paranal"``, ``"paranal_250hz"``,
        ``"paranal_250hz_lf10"``); ``None`` starts from
        the ``"paranal"`` values. Keyword ``params`` override the preset's entries.
    oversample : int
        Generate this many times the length and keep the start (≥ 1).
    **params
        ``baseline``, ``aperture``, ``r0``, ``L0``, ``layers``, ``lines``, ``f_max``,
        ``low_freq_gain``, ``low_freq_corner`` — see
        :func:`opd_psd`.

    Returns
    -------
    numpy.ndarray
        ``round(duration·fs)`` samples, zero mean over the generated record, m.
    """
    duration = positive("duration", duration)
    fs = positive("fs", fs)
    if preset is None:
        preset = "paranal"
    if preset not in PRESETS:
        raise ValueError(f"preset must be one of {sorted(PRESETS)}, got {preset!r}")
    unknown = set(params) - set(PRESETS[preset]) - set(_EXTRA_PARAMS)
    if unknown:
        raise ValueError(f"unknown OPD parameter(s): {sorted(unknown)}")
    cfg = {**PRESETS[preset], **params}
    oversample = int(oversample)
    if oversample < 1:
        raise ValueError(f"oversample must be >= 1, got {oversample!r}")
    n = int(round(duration * fs))
    if n < 2:
        raise ValueError(f"duration·fs must give at least 2 samples, got {duration!r}·{fs!r}")
    return _synth(lambda fk: opd_psd(fk, **cfg), n, fs, int(seed), oversample)


def ramp_reference(
    duration: float,
    fs: float,
    start: float,
    stop: float,
    t0: float = 0.0,
    rate: float | None = None,
) -> np.ndarray:
    """Constant ``start`` until ``t0``, then a move to ``stop`` at ``rate`` (m/s), then hold.

    ``rate=None`` gives a step at ``t0``. All positions in m, times in s.
    """
    duration = positive("duration", duration)
    fs = positive("fs", fs)
    start = finite("start", start)
    stop = finite("stop", stop)
    t0 = nonnegative("t0", t0)
    t = np.arange(int(round(duration * fs))) / fs
    if rate is None:
        return np.where(t < t0, start, stop)
    rate = positive("rate", rate)
    move = np.clip((t - t0) * rate, 0.0, abs(stop - start))
    return start + math.copysign(1.0, stop - start) * move


def step_reference(
    duration: float,
    fs: float,
    amplitude: float = 5e-3,
    centre: float = 0.0,
    t0: float = 0.1,
    rate: float | None = None,
) -> np.ndarray:
    """A step (or ramp with ``rate`` m/s) of ``amplitude`` m centred on ``centre`` m at ``t0`` s.

    The reference goes from ``centre − amplitude/2`` to ``centre + amplitude/2``.
    """
    amplitude = finite("amplitude", amplitude)
    centre = finite("centre", centre)
    return ramp_reference(
        duration, fs, centre - 0.5 * amplitude, centre + 0.5 * amplitude, t0=t0, rate=rate
    )


def fig619_steps(duration: float = 4.0, fs: float = 8000.0, rate=None) -> dict[str, np.ndarray]:
    """The two 5000 µm steps of thesis Fig 6.19: at the stroke centre and towards its end.

    ``"centre"``: −2.5 mm → +2.5 mm (no flexure load at the middle); ``"extremity"``:
    27.5 mm → 32.5 mm (flexure load ≈ 118–139 N with the default flexure). Outputs in m.
    """
    return {
        "centre": step_reference(duration, fs, 5e-3, 0.0, rate=rate),
        "extremity": step_reference(duration, fs, 5e-3, 30e-3, rate=rate),
    }
