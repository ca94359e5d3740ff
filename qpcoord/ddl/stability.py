"""The coordinator's coarse-loop gain margin measured on the simulated plant.

:func:`.loops.coarse_gain_margin` predicts the margin from the plant's linearisation;
:func:`simulated_coarse_margin` measures it on the plant the simulator integrates
(:class:`.plant.DualStage`): the coordinator's coarse gain is multiplied by ``κ`` until the
carriage mode, kicked at rest, grows instead of decaying; the margin is that critical ``κ``
(bisection in ``log κ``).

The measurement removes what the linear margin leaves out on purpose: Coulomb friction and
stiction (they hold a still carriage and damp a small oscillation, but while the carriage
slides the friction force is constant and the linear loop is what remains, so an unstable
loop rings with an amplitude of about the sliding speed / (2π f_mode)) and the metrology
quantisation. Everything else — the nonlinear stepper torque, the detent, the flexure, the
sub-stepped integration, the coordinator's own ``step`` with its carriage estimate and
pre-compensation — is the simulator's.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import signal

from ._check import positive

__all__ = ["simulated_coarse_margin", "coarse_growth_rate"]


def _frictionless(plant):
    from .plant import DualStage

    st = dataclasses.replace(plant.stepper, coulomb_torque=0.0, static_torque=0.0)
    return DualStage(fine=plant.fine, stepper=st, flexure=plant.flexure, resolution=0.0)


def coarse_growth_rate(
    plant,
    fs: float,
    coarse_bandwidth: float,
    *,
    y_c: float,
    current: float = 1.5,
    duration: float = 1.0,
    kick: float = 1.0e-5,
) -> float:
    """Growth rate (1/s, < 0: decaying) of the carriage mode in the closed coordinator loop.

    ``plant`` without friction and quantisation is reset at rest with the carriage at ``y_c``
    (m) and the piezo at mid-stroke; a :class:`.coordinator.SisoCoordinator` with
    ``coarse_bandwidth`` (Hz) holds the output there; the carriage is kicked with a velocity
    ``kick`` (m/s) and the envelope of its motion band-passed around the carriage mode (Hilbert
    transform) is fitted by ``exp(σ t)`` over ``duration`` (s) minus its first and last
    tenth.
    """
    from .coordinator import SisoCoordinator

    fs = positive("fs", fs)
    duration = positive("duration", duration)
    sim = _frictionless(plant)
    y = sim.reset(fs, coarse0=y_c)
    ctl = SisoCoordinator(coarse_bandwidth=coarse_bandwidth, current=current)
    ctl.reset(sim, fs, y, y, check_margin=False)
    sim.yd_c = float(kick)
    n = int(round(duration * fs))
    yc = np.empty(n)
    step = sim.step
    cstep = ctl.step
    r = y
    for k in range(n):
        y = step(*cstep(y, r))
        yc[k] = sim.y_c
    if not np.all(np.isfinite(yc)):
        return math.inf
    fmode = sim.coarse_resonance(y_c, current)
    sos = signal.butter(
        2, [0.5 * fmode, min(2.0 * fmode, 0.45 * fs)], "bandpass", fs=fs, output="sos"
    )
    env = np.abs(signal.hilbert(signal.sosfiltfilt(sos, yc - yc.mean())))
    lo, hi = n // 10, n - n // 10
    t = np.arange(lo, hi) / fs
    return float(np.polyfit(t, np.log(np.maximum(env[lo:hi], 1e-300)), 1)[0])


def simulated_coarse_margin(
    plant,
    fs: float,
    coarse_bandwidth: float,
    *,
    y_c: float,
    current: float = 1.5,
    duration: float = 1.0,
    rel_tol: float = 0.01,
) -> float:
    """Gain margin (absolute) of the coordinator's coarse loop measured in simulation.

    The coarse gain ``κ · coarse_bandwidth`` is raised until the kicked carriage mode grows
    (:func:`coarse_growth_rate` > 0): the returned ``κ`` is the critical factor, to a
    relative accuracy ``rel_tol``. Compare with :func:`.loops.coarse_gain_margin` at the
    same carriage position ``y_c`` (m).

    Parameters
    ----------
    plant : DualStage
        The plant (its stepper, flexure and fine stage; friction and quantisation are removed).
    fs : float
        Sampling rate, Hz.
    coarse_bandwidth : float
        Nominal coarse-loop bandwidth, Hz.
    y_c : float
        Carriage position of the test, m.
    current : float
        Field amplitude, A.
    duration : float
        Simulated time per trial, s.
    rel_tol : float
        Relative width of the final bracket of ``κ``.
    """
    bw = positive("coarse_bandwidth", coarse_bandwidth)
    rel_tol = positive("rel_tol", rel_tol)

    def grows(kappa: float) -> bool:
        rate = coarse_growth_rate(
            plant, fs, kappa * bw, y_c=y_c, current=current, duration=duration
        )
        return rate > 0.0

    lo, hi = 1.0, 1.0
    if grows(1.0):
        while grows(lo):
            lo *= 0.5
            if lo < 1e-3:
                raise ValueError(f"the carriage mode grows at every gain down to {lo * bw} Hz")
        hi = 2.0 * lo
    else:
        hi = 2.0
        while not grows(hi):
            lo = hi
            hi *= 2.0
            if hi > 1e3:
                return math.inf
    while hi / lo > 1.0 + rel_tol:
        mid = math.sqrt(lo * hi)
        if grows(mid):
            hi = mid
        else:
            lo = mid
    return math.sqrt(lo * hi)
