"""Linear frequency responses of the thesis coordinator's closed loop (for design and checks).

The :class:`.coordinator.SisoCoordinator` loop, linearised about rest with a perfect fine-stage
model in the coordinator (so that ``ŷ_c = y_c``) and no clipping, at sampling period ``h``::

    r_c   = F(z) r                                  Butterworth coarse reference filter
    c     = a z/(z − 1) (r_c − y_c)                 commanded carriage position, a = 2π f_c,bw h
    y_c   = G_c(z) c                                coarse stage (ZOH of the linearised
                                                    stepper + flexure, α → y_c, with the
                                                    120 Hz mode), c = α · lead/(2π p)
    v     = C(z) e + (r_c − c)/K_f                  fine PI + pre-compensation (feedforward)
    y_f   = P_f(z) v,   e = r − y_c − y_f           piezo (ZOH), output error

with ``C(z) = (k_p + k_i h z/(z − 1))/K_f``. Solving gives the reference-to-signal responses
``H_c = y_c/r``, ``H_f = y_f/r`` (the **fine-stage share** of the reference) and
``H_e = e/r = 1 − H_c − H_f``. For a stationary reference of one-sided PSD ``S(f)`` (m²/Hz) the
fine-stage excursion has variance ``∫ |H_f|² S df`` and the tracking error ``∫ |H_e|² S df``.

The coarse loop ``L_c = a z/(z − 1) G_c(z)`` is what can excite the carriage mode: its gain
margin (phase crossover at the ≈ 120 Hz mode) is reported by :func:`coarse_gain_margin`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal
from scipy.linalg import expm

from .fine import fine_zoh

__all__ = [
    "LoopResponses",
    "coordinator_responses",
    "coarse_gain_margin",
    "coarse_frequency",
    "coarse_operating_points",
]


@dataclass(frozen=True)
class LoopResponses:
    """Reference-to-signal frequency responses of the coordinator loop (dimensionless, m/m).

    Attributes
    ----------
    f : ndarray
        Frequencies, Hz.
    coarse, fine, error : ndarray of complex
        ``y_c/r``, ``y_f/r`` and ``e/r`` at ``f``.
    coarse_loop : ndarray of complex
        Coarse open loop ``L_c`` at ``f``.
    """

    f: np.ndarray
    coarse: np.ndarray
    fine: np.ndarray
    error: np.ndarray
    coarse_loop: np.ndarray


def coarse_operating_points(plant) -> tuple[float, ...]:
    """Carriage positions (m) where the coarse loop has the least gain margin.

    The softest point of the detent cycle (``cos 4θ_e = −1``, i.e. ``y_c`` an odd multiple of
    half a full step) next to the stroke centre and next to each stroke end: the detent
    stiffness is smallest there, which raises the static gain from field phase to carriage
    position and lowers the carriage mode, and at the ends the flexure load also lowers the
    magnetic stiffness (load angle).
    """
    step = plant.stepper.full_step
    h = plant.coarse_half_stroke
    k_end = math.floor(h / step - 0.5)
    end = (k_end + 0.5) * step
    if end < 0.5 * step:
        return (0.5 * step,) if 0.5 * step <= h else (0.0,)
    return (0.5 * step, end, -end)


def _coarse_zoh(
    plant, fs: float, current: float, y_c: float = 0.0
) -> tuple[np.ndarray, np.ndarray, float]:
    """ZOH discretisation of the carriage (α → y_c) of the plant linearised at ``y_c`` (m),
    and the carriage metres per electrical radian."""
    sys = plant.linearise(y_c, current, "phase")
    a = np.asarray(sys.A, dtype=float)[2:, 2:]
    b = np.asarray(sys.B, dtype=float)[2:, 1:2]
    h = 1.0 / fs
    m = np.zeros((3, 3))
    m[:2, :2] = a * h
    m[:2, 2:] = b * h
    e = expm(m)
    st = plant.stepper
    return e[:2, :2], e[:2, 2:], st.screw_radius / st.pole_pairs


def _eval_2x2(ad, bd, z: np.ndarray) -> np.ndarray:
    """``[1, 0] (zI − A)⁻¹ B`` for a 2-state system at the points ``z`` (vectorised)."""
    a11, a12, a21, a22 = ad[0, 0], ad[0, 1], ad[1, 0], ad[1, 1]
    b1, b2 = bd[0], bd[1]
    det = (z - a11) * (z - a22) - a12 * a21
    return ((z - a22) * b1 + a12 * b2) / det


def coordinator_responses(ctl, plant, fs: float, f, y_c: float = 0.0) -> LoopResponses:
    """Frequency responses of ``ctl`` (a :class:`SisoCoordinator`) on ``plant`` at ``fs`` Hz.

    Parameters
    ----------
    ctl : SisoCoordinator
        Gives ``fine_kp``, ``fine_ki``, ``coarse_cutoff``, ``coarse_order``,
        ``coarse_bandwidth``, ``current``, ``feedforward`` and ``fine_model``.
    plant : DualStage
        Plant parameters (linearised at ``y_c``; its state is not used).
    fs : float
        Sampling rate, Hz.
    f : array_like
        Frequencies, Hz, in (0, fs/2).
    y_c : float
        Carriage position of the linearisation, m (default: the stroke centre).

    Returns
    -------
    LoopResponses
    """
    f = np.asarray(f, dtype=float)
    h = 1.0 / fs
    z = np.exp(2j * math.pi * f * h)
    fm = plant.fine if ctl.fine_model is None else ctl.fine_model
    # fine stage: the plant's own parameters; the controller's K_f from its model
    a11, a12, a21, a22, b1, b2 = fine_zoh(plant.fine, h)
    pf = _eval_2x2(np.array([[a11, a12], [a21, a22]]), np.array([b1, b2]), z)
    kf = fm.gain
    cpi = (ctl.fine_kp + ctl.fine_ki * h * z / (z - 1.0)) / kf
    # coarse: reference filter, integral phase loop, carriage dynamics
    sos = signal.butter(ctl.coarse_order, ctl.coarse_cutoff, fs=fs, output="sos")
    _, filt = signal.sosfreqz(sos, worN=f, fs=fs)
    ad, bd, m_per_rad = _coarse_zoh(plant, fs, ctl.current, y_c)
    gc = _eval_2x2(ad, bd[:, 0], z) / m_per_rad  # y_c per metre of commanded position
    a = 2.0 * math.pi * ctl.coarse_bandwidth * h
    integ = a * z / (z - 1.0)
    lc = integ * gc
    c_over_r = integ * filt / (1.0 + lc)
    hc = gc * c_over_r
    ff = (filt - c_over_r) / kf if ctl.feedforward else 0.0
    hf = (pf * cpi * (1.0 - hc) + pf * ff) / (1.0 + pf * cpi)
    return LoopResponses(f=f, coarse=hc, fine=hf, error=1.0 - hc - hf, coarse_loop=lc)


def coarse_frequency(plant, current: float = 1.5, y_c: float = 0.0) -> float:
    """Undamped frequency of the carriage mode at carriage position ``y_c`` (m), Hz."""
    return plant.coarse_resonance(y_c, current)


def coarse_gain_margin(ctl, plant, fs: float, n: int = 20000) -> tuple[float, float]:
    """Gain margin of the coarse loop ``L_c`` (absolute, not dB) and its frequency, Hz.

    The smallest over the carriage's operating points (:func:`coarse_operating_points`).
    At each, evaluated on a dense grid from 1 Hz to 0.45 fs; the phase crossover is where
    ``L_c`` crosses the negative real axis (next to the carriage mode for every stable
    setting). ``inf`` if the phase never crosses −180°.
    """
    best, fbest = math.inf, math.nan
    for y_c in coarse_operating_points(plant):
        gm, fgm = _gain_margin_at(ctl, plant, fs, n, y_c)
        if gm < best:
            best, fbest = gm, fgm
    return best, fbest


def _gain_margin_at(ctl, plant, fs: float, n: int, y_c: float) -> tuple[float, float]:
    fmode = coarse_frequency(plant, ctl.current, y_c)
    f = np.unique(
        np.concatenate(
            (
                np.geomspace(1.0, 0.45 * fs, n // 2),
                np.linspace(0.5 * fmode, min(2.0 * fmode, 0.45 * fs), n // 2),
            )
        )
    )
    lc = coordinator_responses(ctl, plant, fs, f, y_c).coarse_loop
    im = lc.imag
    cross = np.flatnonzero((np.sign(im[:-1]) != np.sign(im[1:])) & (lc.real[:-1] < 0.0))
    if cross.size == 0:
        return math.inf, math.nan
    best, fbest = math.inf, math.nan
    for k in cross:
        t = im[k] / (im[k] - im[k + 1])
        re = lc.real[k] + t * (lc.real[k + 1] - lc.real[k])
        gm = 1.0 / abs(re)
        if gm < best:
            best, fbest = gm, float(f[k] + t * (f[k + 1] - f[k]))
    return best, fbest
