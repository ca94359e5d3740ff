"""A one-sided OPD power spectral density: given, estimated from a recording, or from a preset.

:class:`OpdPsd` holds ``(f, S)`` (Hz, m²/Hz) and evaluates it anywhere by log-log
interpolation; :meth:`OpdPsd.from_signal` estimates it from one recorded reference and
:meth:`OpdPsd.synthesize` draws new references with the same statistics (FFT shaping, as
:func:`.references.kolmogorov_opd`).

Estimation from one record of ``T`` seconds (``from_signal``): the mean is removed, a
Hann-windowed periodogram of the whole record is taken (resolution ``1/T``) and averaged in
log-spaced bands (``bands_per_decade``, 12 by default) — the band average keeps the power
``∫ S df`` of narrow vibration lines while taking out most of the periodogram's 100 %
scatter. Below the lowest resolved band the spectrum is extended down to ``f_min/20`` with
the power law fitted on the lowest decade, its slope clipped to [−8/3, 0]: one record says
nothing below ``1/T``. −8/3 is the steepest slope of turbulent differential piston below
``0.3 v/D`` (Conan et al.; flatter below ``v/L0`` and ``0.2 v/B``), so the extension does not
invent more low-frequency power than a Kolmogorov sky could have — an assumption the design
report states. (Unclipped, a record with a strong wander fits ≈ −4 and the extension puts
≈ 10⁵× the power at 0.03 Hz; held flat, it under-estimates it and a design from a 2-s record
saturated on 10-s references: both measured, ``docs/ch6.md``.)
"""

from __future__ import annotations

import math

import numpy as np

from ._check import positive

__all__ = ["OpdPsd", "psd_arg"]


class OpdPsd:
    """One-sided PSD of an OPD reference, m²/Hz, on a frequency grid (Hz).

    Parameters
    ----------
    f : array_like
        Frequencies, Hz: finite, > 0, strictly increasing, at least 2.
    S : array_like
        PSD at ``f``, m²/Hz: finite, ≥ 0, not all zero.

    Notes
    -----
    Between grid points the PSD is interpolated linearly in log-log (a zero value is
    interpolated linearly); outside ``[f[0], f[-1]]`` it is zero.
    """

    def __init__(self, f, S):
        f = np.asarray(f, dtype=float).ravel()
        s = np.asarray(S, dtype=float).ravel()
        if f.size < 2 or f.shape != s.shape:
            raise ValueError(
                f"f and S must be 1-D arrays of the same length >= 2, got {f.shape} and {s.shape}"
            )
        if not np.all(np.isfinite(f)) or np.any(f <= 0.0) or np.any(np.diff(f) <= 0.0):
            raise ValueError("f must be finite, > 0 and strictly increasing (Hz)")
        if not np.all(np.isfinite(s)) or np.any(s < 0.0) or not np.any(s > 0.0):
            raise ValueError("S must be finite, >= 0 and positive somewhere (m²/Hz)")
        self.f = f
        self.S = s

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_preset(cls, preset: str = "paranal_250hz", f_min: float = 0.01, **params) -> OpdPsd:
        """The analytic PSD of :func:`.references.opd_psd` for a preset (keyword overrides),
        tabulated from ``f_min`` Hz to the preset's band limit (or 4 kHz)."""
        from .references import PRESETS, opd_psd

        if preset not in PRESETS:
            raise ValueError(f"preset must be one of {sorted(PRESETS)}, got {preset!r}")
        cfg = {**PRESETS[preset], **params}
        f_max = cfg.get("f_max") or 4000.0
        f = np.unique(np.concatenate((np.geomspace(positive("f_min", f_min), f_max, 3000),)))
        # resolve the vibration lines (Gaussian bumps a few tenths of a hertz wide)
        for line in cfg.get("lines", ()):
            fl, w = (line.frequency, line.width) if hasattr(line, "frequency") else line[::2]
            f = np.union1d(f, np.linspace(max(f[0], fl - 5 * w), fl + 5 * w, 81))
        f = f[f <= f_max]
        return cls(f, opd_psd(f, **cfg))

    @classmethod
    def from_signal(cls, reference, fs: float, bands_per_decade: int = 12) -> OpdPsd:
        """Estimate from one recorded reference (1-D, metres at ``fs`` Hz); see module."""
        fs = positive("fs", fs)
        x = np.asarray(reference, dtype=float)
        if x.ndim != 1 or x.size < 16:
            raise ValueError(f"reference must be 1-D with >= 16 samples, got shape {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError("reference must be finite")
        n = x.size
        w = np.hanning(n)
        spec = np.fft.rfft((x - x.mean()) * w)
        pxx = 2.0 * np.abs(spec) ** 2 / (fs * np.sum(w * w))
        fk = np.fft.rfftfreq(n, 1.0 / fs)
        fk, pxx = fk[2:-1], pxx[2:-1]  # drop DC and the bin the window merges with it
        edges = 10.0 ** np.arange(
            math.floor(math.log10(fk[0]) * bands_per_decade) / bands_per_decade,
            math.log10(fk[-1]) + 1.0 / bands_per_decade,
            1.0 / bands_per_decade,
        )
        idx = np.digitize(fk, edges)
        fb, sb = [], []
        for j in np.unique(idx):
            sel = idx == j
            fb.append(math.exp(np.mean(np.log(fk[sel]))))
            sb.append(float(np.mean(pxx[sel])))
        fb, sb = np.array(fb), np.array(sb)
        # extend below the lowest band with the lowest decade's power law (see module)
        low = (fb <= 10.0 * fb[0]) & (sb > 0)
        slope = -8.0 / 3.0
        if np.count_nonzero(low) >= 3:
            slope = float(np.polyfit(np.log(fb[low]), np.log(sb[low]), 1)[0])
        slope = min(0.0, max(-8.0 / 3.0, slope))
        fx = np.geomspace(fb[0] / 20.0, fb[0], 8)[:-1]
        s0 = sb[0] if sb[0] > 0 else float(sb[sb > 0][0])
        sx = s0 * (fx / fb[0]) ** slope
        return cls(np.concatenate((fx, fb)), np.concatenate((sx, sb)))

    # ------------------------------------------------------------------ use
    def __call__(self, f) -> np.ndarray:
        """PSD at ``f`` (Hz), m²/Hz (zero outside the tabulated range)."""
        f = np.asarray(f, dtype=float)
        out = np.zeros_like(f)
        inside = (f >= self.f[0]) & (f <= self.f[-1])
        if np.any(inside):
            pos = self.S > 0
            if np.all(pos):
                out[inside] = np.exp(np.interp(np.log(f[inside]), np.log(self.f), np.log(self.S)))
            else:
                out[inside] = np.interp(f[inside], self.f, self.S)
        return out

    def grid(self, fs: float, n: int = 4000) -> np.ndarray:
        """A log grid from ``f[0]`` to ``min(f[-1], fs/2)`` with the table's own points, Hz."""
        hi = min(self.f[-1], 0.5 * fs)
        g = np.geomspace(self.f[0], hi, n)
        return np.union1d(g, self.f[self.f <= hi])

    def variance(self, gain2=None, fs: float | None = None) -> float:
        """``∫ |H|² S df`` over the table (m²); ``gain2(f)`` returns ``|H(f)|²`` (default 1)."""
        f = self.f if fs is None else self.grid(fs)
        s = self(f)
        if gain2 is not None:
            s = s * np.asarray(gain2(f), dtype=float)
        return float(np.trapezoid(s, f))

    @property
    def rms(self) -> float:
        """Total rms of the spectrum, m."""
        return math.sqrt(self.variance())

    def synthesize(self, duration: float, fs: float, seed: int = 0, oversample: int = 4):
        """A new reference with this PSD: ``round(duration·fs)`` samples, m (FFT shaping)."""
        from .references import _synth

        duration = positive("duration", duration)
        fs = positive("fs", fs)
        n = int(round(duration * fs))
        if n < 2:
            raise ValueError(f"duration·fs must give at least 2 samples, got {duration!r}·{fs!r}")
        return _synth(self, n, fs, int(seed), int(oversample))

    def __repr__(self) -> str:
        return (
            f"OpdPsd({self.f.size} points, {self.f[0]:.3g}–{self.f[-1]:.3g} Hz, "
            f"rms {self.rms * 1e6:.3g} µm)"
        )


def psd_arg(reference, fs: float) -> tuple[OpdPsd, np.ndarray | None]:
    """A design's ``reference`` argument as ``(psd, record)``.

    Accepts a 1-D array of metres at ``fs`` (the PSD is estimated; ``record`` is the array),
    an :class:`OpdPsd`, or a pair ``(f, S)`` (``record`` is None). Raises ValueError naming
    ``reference`` for NaN samples, fewer than one second of samples, or a non-positive PSD.
    """
    if isinstance(reference, OpdPsd):
        return reference, None
    if isinstance(reference, tuple) and len(reference) == 2:
        try:
            return OpdPsd(*reference), None
        except ValueError as exc:
            raise ValueError(f"reference (f, S) is not a valid PSD: {exc}") from None
    r = np.asarray(reference, dtype=float)
    if r.ndim != 1:
        raise ValueError(f"reference must be 1-D (metres at fs), got shape {r.shape}")
    bad = np.flatnonzero(~np.isfinite(r))
    if bad.size:
        raise ValueError(f"reference is not finite at sample {bad[0]} (value {r[bad[0]]!r})")
    if r.size < fs:
        raise ValueError(
            f"reference has {r.size} samples: less than one second at fs = {fs!r} Hz "
            f"(need >= {int(math.ceil(fs))})"
        )
    return OpdPsd.from_signal(r, fs), r
