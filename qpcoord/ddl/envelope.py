"""Before a run: is a reference within the coarse stage's reach? :func:`check_reference`.

The fine stage absorbs what the coarse loop lags behind. The thesis coordinator's coarse loop
is an integral loop of bandwidth ``f_bw`` on a Butterworth-filtered reference, so a reference
moving at speed ``v`` leaves the fine stage off-centre by about

    ``Δy_f ≈ v · (1/(2π k f_bw) + τ_F)``

(``k`` the static gain from commanded to actual carriage position, 0.93 with the default
flexure; ``τ_F`` the low-frequency group delay of the filter, ``2/(2π f_F)`` for the thesis's
3rd-order 10 Hz Butterworth). The bandwidth a reference **needs** is the smallest ``f_bw`` for
which that stays within ``half stroke − margin`` at the reference's peak speed (measured on
the reference low-passed at ``speed_band``, 10 Hz by default — faster content is the fine
stage's job anyway). The bandwidth the coarse stage **allows** is the largest one keeping the
coarse loop's gain margin at the carriage mode (worst operating point) ≥ ``min_gain_margin``
(6 dB by default, :func:`.loops.coarse_gain_margin`). The rate limit (``max_speed``, 3 mm/s) and the
acceleration the stepper can give the carriage (``K_m I / r_screw`` over the carriage mass)
bound the envelope itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from ._check import positive

__all__ = ["ReferenceCheck", "check_reference", "allowed_bandwidth"]


@dataclass(frozen=True)
class ReferenceCheck:
    """Result of :func:`check_reference` (SI units).

    Attributes
    ----------
    peak_speed, peak_acceleration : float
        Of the reference low-passed at ``speed_band``: m/s, m/s².
    max_speed, max_acceleration : float
        The coarse stage's limits: phase rate limit (m/s) and stepper force / carriage mass
        at the field amplitude (m/s²).
    needed_bandwidth : float
        Coarse-loop bandwidth the peak speed needs, Hz (``inf`` if the filter lag alone
        uses up the stroke).
    allowed_bandwidth : float
        Largest coarse-loop bandwidth with the gain margin kept, Hz.
    excursion_at_default : float
        Predicted fine-stage excursion at the peak speed with the thesis tuning
        (2 Hz, 10 Hz 3rd-order filter), m.
    usable_half_stroke : float
        Half the fine stroke minus the margin, m.
    ok : bool
        The reference is within the coarse stage's reach with the thesis tuning.
    verdict : str
        ``"ok"``, ``"needs tuning"`` (within reach with a faster coarse loop) or
        ``"out of reach"``.
    reason : str
        One line saying why.
    """

    peak_speed: float
    peak_acceleration: float
    max_speed: float
    max_acceleration: float
    needed_bandwidth: float
    allowed_bandwidth: float
    excursion_at_default: float
    usable_half_stroke: float
    ok: bool
    verdict: str
    reason: str


def allowed_bandwidth(plant, fs: float, min_gain_margin: float = 2.0, current: float = 1.5):
    """Largest coarse-loop bandwidth (Hz) whose gain margin at the carriage mode is
    ≥ ``min_gain_margin`` (absolute; 2 = 6 dB), by bisection (the margin falls as 1/bandwidth).
    """
    from .coordinator import SisoCoordinator
    from .loops import coarse_gain_margin

    def gm(bw):
        return coarse_gain_margin(
            SisoCoordinator(coarse_bandwidth=bw, current=current), plant, fs, n=4000
        )[0]

    lo, hi = 0.01, 50.0
    if gm(lo) < min_gain_margin:
        return 0.0
    for _ in range(30):
        mid = math.sqrt(lo * hi)
        if gm(mid) >= min_gain_margin:
            lo = mid
        else:
            hi = mid
    return lo


def _static_gain(plant, current: float) -> float:
    """Carriage position per commanded position at rest (magnetic vs flexure stiffness)."""
    k = plant.coarse_stiffness(0.0, current)
    return (k - plant.flexure.spring_rate) / k


def check_reference(
    reference,
    fs: float,
    plant=None,
    *,
    margin: float | None = None,
    max_speed: float = 3.0e-3,
    current: float = 1.5,
    speed_band: float = 10.0,
    min_gain_margin: float = 2.0,
) -> ReferenceCheck:
    """Say before a run whether the coarse stage can carry ``reference`` (see module).

    Parameters
    ----------
    reference : array_like
        1-D reference, m, sampled at ``fs``; at least one second, finite.
    fs : float
        Sampling rate, Hz (> 0).
    plant : DualStage, optional
        Default: ``DualStage()``.
    margin : float, optional
        Fine-stage distance to keep from its stops, m (default 10 % of the half stroke).
    max_speed : float
        Phase rate limit as a carriage speed, m/s.
    current : float
        Field amplitude, A.
    speed_band : float
        Low-pass (Hz, 2nd-order Butterworth) applied before differentiating.
    min_gain_margin : float
        Gain margin to keep at the carriage mode (absolute).

    Returns
    -------
    ReferenceCheck
    """
    from .plant import DualStage

    if isinstance(fs, bool):
        raise ValueError(f"fs must be finite and > 0, got {fs!r}")
    fs = positive("fs", fs)
    r = np.asarray(reference, dtype=float)
    if r.ndim != 1:
        raise ValueError(f"reference must be 1-D (metres at fs), got shape {r.shape}")
    bad = np.flatnonzero(~np.isfinite(r))
    if bad.size:
        raise ValueError(f"reference is not finite at sample {bad[0]} (value {r[bad[0]]!r})")
    if r.size < fs:
        raise ValueError(f"reference has {r.size} samples: less than one second at fs = {fs!r} Hz")
    plant = DualStage() if plant is None else plant
    half = 0.5 * (plant.fine.stroke_max - plant.fine.stroke_min)
    margin = 0.1 * half if margin is None else float(margin)
    if not (math.isfinite(margin) and 0.0 < margin < half):
        raise ValueError(
            f"margin must be in (0, {half!r}) m (half the fine stroke), got {margin!r}"
        )
    max_speed = positive("max_speed", max_speed)
    speed_band = positive("speed_band", speed_band)
    sos = signal.butter(2, min(speed_band, 0.45 * fs), fs=fs, output="sos")
    rl = signal.sosfiltfilt(sos, r)
    v = np.gradient(rl) * fs
    a = np.gradient(v) * fs
    vpk = float(np.max(np.abs(v)))
    apk = float(np.max(np.abs(a)))
    st = plant.stepper
    amax = st.torque_constant * current / st.screw_radius / plant.carriage_mass(0.0)
    k = _static_gain(plant, current)
    usable = half - margin
    tau_default = 2.0 / (2.0 * math.pi * 10.0)  # 3rd-order Butterworth at 10 Hz
    exc_default = vpk * (1.0 / (2.0 * math.pi * k * 2.0) + tau_default)
    room = usable - vpk * tau_default
    need = math.inf if room <= 0 else vpk / (2.0 * math.pi * k * room)
    allow = allowed_bandwidth(plant, fs, min_gain_margin, current)
    if vpk > max_speed or apk > amax:
        verdict = "out of reach"
        what = "speed" if vpk > max_speed else "acceleration"
        reason = (
            f"peak {what} {vpk * 1e3:.3g} mm/s, {apk * 1e3:.3g} mm/s² exceeds the coarse "
            f"stage's {max_speed * 1e3:.3g} mm/s, {amax * 1e3:.3g} mm/s²"
        )
    elif exc_default <= usable:
        verdict = "ok"
        reason = (
            f"peak speed {vpk * 1e6:.3g} µm/s leaves the fine stage ≈ {exc_default * 1e6:.3g} µm "
            f"off-centre with the thesis tuning (≤ {usable * 1e6:.3g} µm usable)"
        )
    elif need <= allow:
        verdict = "needs tuning"
        reason = (
            f"peak speed {vpk * 1e6:.3g} µm/s needs a coarse bandwidth ≥ {need:.3g} Hz "
            f"(thesis 2 Hz, allowed ≤ {allow:.3g} Hz): use design_coordinator"
        )
    else:
        verdict = "out of reach"
        reason = (
            f"peak speed {vpk * 1e6:.3g} µm/s needs a coarse bandwidth ≥ {need:.3g} Hz but the "
            f"carriage mode allows ≤ {allow:.3g} Hz: the fine stage may reach its stops "
            "(sustained-ramp bound; try design_coordinator, the saturation guard or the MPC)"
        )
    return ReferenceCheck(
        peak_speed=vpk,
        peak_acceleration=apk,
        max_speed=max_speed,
        max_acceleration=amax,
        needed_bandwidth=need,
        allowed_bandwidth=allow,
        excursion_at_default=exc_default,
        usable_half_stroke=usable,
        ok=verdict == "ok",
        verdict=verdict,
        reason=reason,
    )
