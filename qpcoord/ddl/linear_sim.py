"""Closed-loop simulation of a :class:`.linear_plant.LinearDualStage`: :func:`simulate_linear`.

The plant is stepped at its sampling period with its discrete model
(:meth:`.linear_plant.LinearDualStage.discrete`): the disturbance models driven by seeded
Gaussian white noise of their variances, optional recorded signals added at the output or
at an actuator's input, measurement noise of ``noise_rms``. Per period the controller gets
the measured error ``e`` and returns ``(u_c, u_f)``; the commands are clipped to the input
ranges and rate limits as hardware would (the controller is told nothing).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["LinearRun", "simulate_linear"]


@dataclass
class LinearRun:
    """One run: time series (one sample per period, SI units) and ``metrics``.

    ``metrics``: ``rms`` (m, of ``e``), ``sigma3`` (3 × std of ``e``, m), ``max_abs`` (m),
    ``fine_max`` / ``coarse_max`` (largest |position|, m), ``fine_margin_min`` (smallest
    distance of ``y_f`` to its stroke ends, m; < 0: outside), ``fine_out_steps`` /
    ``coarse_out_steps`` (steps outside the stroke), ``clipped_steps`` (steps in which a
    command was clipped by a range or rate limit).
    """

    Ts: float
    e: np.ndarray
    y_c: np.ndarray
    y_f: np.ndarray
    u_c: np.ndarray
    u_f: np.ndarray
    metrics: dict = field(default_factory=dict)


def simulate_linear(plant, controller, steps: int, *, seed: int = 0, signals=None) -> LinearRun:
    """Run ``controller`` on ``plant`` for ``steps`` periods from rest.

    Parameters
    ----------
    plant : LinearDualStage
    controller : object
        ``reset()`` and ``step(e) -> (u_c, u_f)`` (e in m, commands in the actuators' input
        units).
    steps : int
        Number of periods.
    seed : int
        Seed of the disturbances' white noise and the measurement noise.
    signals : dict, optional
        Recorded signals added per period: ``"output"`` (m, to the measured error's ``d``),
        ``"coarse"`` / ``"fine"`` (input units, at the actuator's input); each at least
        ``steps`` long.
    """
    steps = int(steps)
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps!r}")
    m = plant.discrete()
    rng = np.random.default_rng(seed)
    sig = {} if signals is None else dict(signals)
    extra = {}
    for key in ("output", "coarse", "fine"):
        if key in sig:
            a = np.asarray(sig.pop(key), dtype=float)
            if a.ndim != 1 or a.size < steps or not np.all(np.isfinite(a[:steps])):
                raise ValueError(f"signals[{key!r}] must be finite, 1-D, >= {steps} samples")
            extra[key] = a[:steps]
    if sig:
        raise ValueError(f"signals: unknown keys {sorted(sig)} (output, coarse, fine)")
    nw = m.G.shape[1]
    w = rng.standard_normal((steps, nw)) * np.sqrt(np.diag(m.W)) if nw else None
    noise = plant.noise_rms * rng.standard_normal(steps) if plant.noise_rms > 0 else None
    A, B, G, Bd = m.A, m.B, m.G, m.B_direct
    ce, cc, cf = m.c_error[0], m.c_coarse[0], m.c_fine[0]
    lo_c, hi_c = plant.coarse_range
    lo_f, hi_f = plant.fine_range
    dc = plant.coarse_rate * plant.Ts
    df = plant.fine_rate * plant.Ts
    out = {k: np.empty(steps) for k in ("e", "y_c", "y_f", "u_c", "u_f")}
    x = np.zeros(m.n)
    uc_prev = uf_prev = 0.0
    clipped = 0
    controller.reset()
    for k in range(steps):
        e = float(ce @ x)
        if "output" in extra:
            e += extra["output"][k]
        if noise is not None:
            e += noise[k]
        if not math.isfinite(e):
            raise FloatingPointError(f"the closed loop diverged at step {k} (e = {e!r})")
        uc, uf = controller.step(e)
        uc0, uf0 = uc, uf
        uc = min(max(uc, lo_c, uc_prev - dc), hi_c, uc_prev + dc)
        uf = min(max(uf, lo_f, uf_prev - df), hi_f, uf_prev + df)
        if uc != uc0 or uf != uf0:
            clipped += 1
        out["e"][k] = e
        out["y_c"][k] = cc @ x
        out["y_f"][k] = cf @ x
        out["u_c"][k] = uc
        out["u_f"][k] = uf
        xn = A @ x + B[:, 0] * uc + B[:, 1] * uf
        if w is not None:
            xn += G @ w[k]
        if "coarse" in extra:
            xn += Bd[:, 0] * extra["coarse"][k]
        if "fine" in extra:
            xn += Bd[:, 1] * extra["fine"][k]
        x = xn
        uc_prev, uf_prev = uc, uf
    run = LinearRun(Ts=plant.Ts, **out)
    e = run.e
    flo, fhi = plant.fine_stroke
    clo, chi = plant.coarse_stroke
    run.metrics = {
        "rms": float(np.sqrt(np.mean(e * e))),
        "sigma3": float(3.0 * np.std(e, ddof=1)) if steps > 1 else 0.0,
        "max_abs": float(np.max(np.abs(e))),
        "fine_max": float(np.max(np.abs(run.y_f))),
        "coarse_max": float(np.max(np.abs(run.y_c))),
        "fine_margin_min": float(min(np.min(run.y_f - flo), np.min(fhi - run.y_f))),
        "fine_out_steps": int(np.count_nonzero((run.y_f < flo) | (run.y_f > fhi))),
        "coarse_out_steps": int(np.count_nonzero((run.y_c < clo) | (run.y_c > chi))),
        "clipped_steps": int(clipped),
    }
    return run
