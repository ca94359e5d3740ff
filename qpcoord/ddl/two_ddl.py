"""Simultaneous coordination of two DDLs (thesis §6.3, Figs 6.12–6.14).

Both DDLs act on the same optical path, each keeps its own controller and metrology. DDL 1
tracks the reference ``r``; its tracking error, minus a derivative prediction of its own
response ``P1 y1 = k s y1``, is fed as the reference of DDL 2::

    r2 = (r − y1) − k ẏ1,        y = y1 + y2,        Y/R = 2F − F² − k s F²    (F1 = F2 = F)

Everything here is measured on the simulated closed loops (:func:`.simulate.simulate` with
the nonlinear plant and the coordinator): DDL 2 only needs DDL 1's measured output, so the
two loops are simulated one after the other with the exact per-sample coupling (DDL 2 at
sample k uses y1 measured at sample k; ẏ1 is the backward difference). Frequency responses
are H1 estimates from a white-noise reference; bandwidths are the −3 dB frequencies.
"""

from __future__ import annotations

import numpy as np

from ._check import nonnegative, positive
from .identify import bandwidth_3db, chirp_frf
from .simulate import simulate

__all__ = [
    "analytic_gain",
    "second_order",
    "fine_loop_model",
    "simulate_two_ddl",
    "two_ddl_frf",
    "two_ddl_steps",
    "combine",
    "overshoot",
]


def combine(f_resp, s, k: float):
    """Analytic two-DDL response ``2F − F² − k s F²`` from a single-DDL response ``F``.

    ``f_resp`` complex response(s) at Laplace points ``s`` (rad/s), ``k`` in s.
    """
    f_resp = np.asarray(f_resp)
    return 2.0 * f_resp - f_resp**2 - k * np.asarray(s) * f_resp**2


def second_order(s, natural_frequency: float, damping: float):
    """``F(s) = ωn² / (s² + 2ζωn s + ωn²)`` at Laplace points ``s`` (rad/s).

    ``natural_frequency`` in Hz, ``damping`` ζ (dimensionless, > 0).
    """
    fn = positive("natural_frequency", natural_frequency)
    zeta = positive("damping", damping)
    wn = 2.0 * np.pi * fn
    s = np.asarray(s)
    return wn * wn / (s * s + 2.0 * zeta * wn * s + wn * wn)


def analytic_gain(
    damping: float, natural_frequency: float = 300.0, k: float = 0.0, *, points: int = 20000
) -> dict:
    """−3 dB bandwidth gain of two DDLs, ``2F − F² − k s F²``, over one second-order ``F``.

    The thesis models a closed-loop DDL "as a second-order system with the fine stage's
    characteristics" (§6.3); this is the bandwidth enhancement of its combination formula for
    such an ``F``. Without predictor (``k = 0``) the gain depends on ζ only.

    Parameters
    ----------
    damping : float
        ζ of ``F`` (> 0).
    natural_frequency : float
        ωn of ``F``, Hz (the thesis's piezo: about 300 Hz, Fig 6.6).
    k : float
        Predictor gain ``P₁ = k s``, s (≥ 0).
    points : int
        Log-spaced frequency points from ωn/1000 to 100 ωn.

    Returns
    -------
    dict
        ``bw_single``, ``bw_dual`` (Hz) and ``gain = bw_dual / bw_single``.
    """
    fn = positive("natural_frequency", natural_frequency)
    positive("damping", damping)
    k = nonnegative("k", k)
    points = int(points)
    if points < 100:
        raise ValueError(f"points must be >= 100, got {points}")
    f = np.logspace(np.log10(fn) - 3.0, np.log10(fn) + 2.0, points)
    s = 2j * np.pi * f
    single = second_order(s, fn, damping)
    dual = combine(single, s, k)
    bw1 = bandwidth_3db(f, single, reference=1.0)
    bw2 = bandwidth_3db(f, dual, reference=1.0)
    return {"bw_single": bw1, "bw_dual": bw2, "gain": bw2 / bw1}


def fine_loop_model(plant, controller, fs: float = 8000.0):
    """Linear closed-loop model ``F = C G / (1 + C G)`` of one DDL (r → y), discrete time.

    ``G`` is the ZOH discretisation of the plant's piezo model, ``C`` the coordinator's PI
    (``(kp + ki/s)/K_f``, backward-Euler integral as in :class:`SisoCoordinator`). The coarse
    stage is left out: behind the 10 Hz filter it only acts at low frequency, which is the
    thesis's argument that a DDL "can be seen as a second-order system with the fine stage's
    characteristics" (§6.3). Returns a python-control ``TransferFunction`` (dt = 1/fs).
    """
    import control

    fs = positive("fs", fs)
    fp = plant.fine
    a, b = fp.continuous()
    g = control.c2d(control.ss(a, b.reshape(2, 1), [[1.0, 0.0]], [[0.0]]), 1.0 / fs, "zoh")
    kp = controller.fine_kp / fp.gain
    ki = controller.fine_ki / fp.gain
    c = control.tf([kp + ki / fs, -kp], [1.0, -1.0], 1.0 / fs)
    loop = c * control.tf(g)
    return control.feedback(loop, 1)


def simulate_two_ddl(
    make_plant,
    make_controller,
    reference,
    fs: float = 8000.0,
    k: float = 0.0,
    *,
    positions=(0.0, 0.0),
    seed: int = 0,
):
    """Simulate DDL 1 tracking ``reference`` and DDL 2 fed with its error (§6.3).

    Parameters
    ----------
    make_plant, make_controller : callable
        Zero-argument factories (each DDL gets its own plant and controller).
    reference : array_like
        Optical-path reference relative to the start, m (``reference[0]`` should be 0).
    fs : float
        Sampling rate, Hz.
    k : float
        Gain of the derivative predictor ``P1 = k s``, s (0: no predictor).
    positions : (float, float)
        Operating outputs of the two DDLs, m (the relative reference is added to them).
    seed : int
        Metrology-noise seed (DDL 2 uses ``seed + 1``).

    Returns
    -------
    dict
        ``y`` (combined relative output, m), ``y1``, ``y2`` (relative outputs, m),
        ``r2`` (reference given to DDL 2, relative, m), ``run1``, ``run2`` (:class:`Run`).
    """
    fs = positive("fs", fs)
    k = nonnegative("k", k)
    r = np.asarray(reference, dtype=float)
    p1, p2 = positions
    run1 = simulate(make_plant(), make_controller(), p1 + r, fs, seed=seed)
    y1 = run1.y - p1
    dy1 = np.diff(y1, prepend=y1[0]) * fs
    r2 = (r - y1) - k * dy1
    run2 = simulate(make_plant(), make_controller(), p2 + r2, fs, seed=seed + 1)
    y2 = run2.y - p2
    return {"y": y1 + y2, "y1": y1, "y2": y2, "r2": r2, "run1": run1, "run2": run2}


def two_ddl_frf(
    make_plant,
    make_controller,
    fs: float = 8000.0,
    k: float = 0.0,
    *,
    duration: float = 4.0,
    amplitude: float = 0.2e-6,
    nperseg: int = 2048,
    seed: int = 0,
):
    """Measured closed-loop frequency responses of one DDL, two DDLs, two DDLs + predictor.

    The reference is white Gaussian noise of ``amplitude`` m rms (seeded), small enough for
    the fine stage to stay far inside its stroke.

    Returns
    -------
    dict
        ``f`` (Hz); complex responses ``single`` (y1/r), ``dual`` (k = 0) and ``dual_pred``
        (the given k); their −3 dB bandwidths ``bw_single``, ``bw_dual``, ``bw_dual_pred``
        (Hz) and the gains ``gain_dual = bw_dual / bw_single``,
        ``gain_dual_pred = bw_dual_pred / bw_single``; ``coherence`` of the single loop.
    """
    fs = positive("fs", fs)
    amplitude = positive("amplitude", amplitude)
    n = int(round(positive("duration", duration) * fs))
    rng = np.random.default_rng(seed)
    r = amplitude * rng.standard_normal(n)
    r -= r[0]
    out = {}
    res0 = simulate_two_ddl(make_plant, make_controller, r, fs, 0.0, seed=seed)
    f, h1, coh = chirp_frf(r, res0["y1"], fs, nperseg)
    _, h2, _ = chirp_frf(r, res0["y"], fs, nperseg)
    if k > 0.0:
        resk = simulate_two_ddl(make_plant, make_controller, r, fs, k, seed=seed)
        _, hk, _ = chirp_frf(r, resk["y"], fs, nperseg)
    else:
        hk = h2
    sel = f > 0
    out["f"] = f[sel]
    out["single"] = h1[sel]
    out["dual"] = h2[sel]
    out["dual_pred"] = hk[sel]
    out["coherence"] = coh[sel]
    out["bw_single"] = bandwidth_3db(out["f"], out["single"], reference=1.0)
    out["bw_dual"] = bandwidth_3db(out["f"], out["dual"], reference=1.0)
    out["bw_dual_pred"] = bandwidth_3db(out["f"], out["dual_pred"], reference=1.0)
    out["gain_dual"] = out["bw_dual"] / out["bw_single"]
    out["gain_dual_pred"] = out["bw_dual_pred"] / out["bw_single"]
    return out


def overshoot(y, final: float) -> float:
    """Relative overshoot of a step response ``y`` towards ``final`` (0 if none)."""
    y = np.asarray(y, dtype=float)
    return float(max(0.0, (np.max(y) - final) / final)) if final > 0 else 0.0


def two_ddl_steps(
    make_plant,
    make_controller,
    fs: float = 8000.0,
    k: float = 0.0,
    *,
    amplitude: float = 1e-6,
    duration: float = 0.05,
    t0: float = 0.005,
    seed: int = 0,
):
    """Step responses (Fig 6.14b) of one DDL, two DDLs and two DDLs + predictor.

    Returns a dict with ``t`` (s), ``r`` and the outputs ``single``, ``dual``, ``dual_pred``
    (relative, m), their overshoots (fraction) and 10–90 % rise times (s).
    """
    fs = positive("fs", fs)
    amplitude = positive("amplitude", amplitude)
    n = int(round(positive("duration", duration) * fs))
    t = np.arange(n) / fs
    r = np.where(t >= t0, amplitude, 0.0)
    res0 = simulate_two_ddl(make_plant, make_controller, r, fs, 0.0, seed=seed)
    resk = simulate_two_ddl(make_plant, make_controller, r, fs, k, seed=seed)
    out = {"t": t, "r": r, "single": res0["y1"], "dual": res0["y"], "dual_pred": resk["y"]}
    for name in ("single", "dual", "dual_pred"):
        y = out[name]
        out[f"overshoot_{name}"] = overshoot(y, amplitude)
        after = t >= t0
        ya, ta = y[after], t[after]
        i10 = np.flatnonzero(ya >= 0.1 * amplitude)
        i90 = np.flatnonzero(ya >= 0.9 * amplitude)
        out[f"rise_{name}"] = (
            float(ta[i90[0]] - ta[i10[0]]) if i10.size and i90.size else float("inf")
        )
    return out
