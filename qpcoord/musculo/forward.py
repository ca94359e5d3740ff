"""Appendix A's forward model: activation dynamics and the arm driven by muscle forces.

Fig. A.3 closes the thesis's algorithm with the *system*: neural excitations ``s`` drive the
muscle activities ``a`` (first order, time constant τ, the ``a ≈ s`` of Eq. A.15), the
linear force law ``F = a F_max`` (Eq. A.13) gives the muscle forces, and the arm moves by
its equation of motion (Eqs A.1–A.6) under the generalised forces ``Q = W(q) F`` (Eq. A.19):

    ȧ = (s − a) / τ,        M(q) q̈ + h(q, q̇) = W(q) a F_max

with ``h`` the Coriolis, centrifugal and gravity terms (``model.generalised_forces(q, q̇,
0)``). The 17 states are (q, q̇, a), as counted in §A.2. :func:`simulate` integrates this
open loop (as the thesis's Fig. A.3: no feedback from the realised motion ``y``) for a
sampled excitation history; the activation equation is integrated exactly over each step
with ``s`` held (τ = 40 µs is far below any useful step), the arm with classical RK4.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ForwardRun", "TAU_ACTIVATION", "acceleration", "simulate"]

#: Activation time constant τ of §A.2 (s): "τ (40 [µs]) its small time constant".
TAU_ACTIVATION = 40e-6


@dataclass(frozen=True)
class ForwardRun:
    """An integrated forward run.

    Attributes
    ----------
    t : numpy.ndarray, shape (k,)
        Times (s).
    q, qd : numpy.ndarray, shape (k, 3)
        Realised posture (rad) and rates (rad/s).
    a : numpy.ndarray, shape (k, m)
        Muscle activities (dimensionless, 0..1).
    left_range : bool
        True if the posture left the model's range and the run stopped early (then ``t``
        ends there).
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    a: np.ndarray
    left_range: bool


def acceleration(model, q, qd, forces) -> np.ndarray:
    """Joint accelerations ``q̈ = M⁻¹ (W F − h(q, q̇))`` (rad/s²) under muscle forces F (N).

    Parameters
    ----------
    model : qpcoord.robots.shoulder.ShoulderModel
        The shoulder.
    q, qd : array_like, shape (3,)
        Posture (rad, inside the model range) and rates (rad/s).
    forces : array_like, shape (m,)
        Muscle forces (N).
    """
    q = model.check_posture(q)
    qd = np.asarray(qd, dtype=float)
    F = np.asarray(forces, dtype=float)
    if qd.shape != (3,) or not np.all(np.isfinite(qd)):
        raise ValueError(f"qd must be 3 finite rates (rad/s), got {qd!r}")
    if F.shape != (model.n_muscles,) or not np.all(np.isfinite(F)):
        raise ValueError(f"forces must be {model.n_muscles} finite forces (N), got {F!r}")
    h = model.generalised_forces(q, qd, np.zeros(3))
    return np.linalg.solve(model.mass_matrix(q), model.moment_arms(q) @ F - h)


def _excitation_at(times: np.ndarray, s: np.ndarray, t: float) -> np.ndarray:
    k = int(np.searchsorted(times, t, side="right") - 1)
    k = min(max(k, 0), len(times) - 2)
    w = (t - times[k]) / (times[k + 1] - times[k])
    w = min(max(w, 0.0), 1.0)
    return (1.0 - w) * s[k] + w * s[k + 1]


def simulate(
    model,
    times,
    excitations,
    q0,
    qd0,
    dt: float = 1e-3,
    tau: float = TAU_ACTIVATION,
) -> ForwardRun:
    """Integrate the forward model open loop for a sampled excitation history.

    Parameters
    ----------
    model : qpcoord.robots.shoulder.ShoulderModel
        The shoulder.
    times : array_like, shape (n,)
        Sample times of the excitations (s), increasing, n ≥ 2.
    excitations : array_like, shape (n, m)
        Neural excitations ``s`` in [0, 1] at those times; linear between samples.
    q0, qd0 : array_like, shape (3,)
        Initial posture (rad) and rates (rad/s); the activities start at ``s(0)``.
    dt : float
        Integration step (s), > 0.
    tau : float
        Activation time constant (s), > 0.

    Returns
    -------
    ForwardRun
        States at ``times[0] + k dt`` up to ``times[-1]``.

    Raises
    ------
    ValueError
        Bad shapes, non-increasing times, excitations outside [0, 1], non-positive dt or tau.
    """
    times = np.asarray(times, dtype=float)
    s = np.asarray(excitations, dtype=float)
    m = model.n_muscles
    if times.ndim != 1 or times.size < 2 or np.any(np.diff(times) <= 0.0):
        raise ValueError(f"times must be increasing, at least 2 samples (s), got {times!r}")
    if s.shape != (times.size, m):
        raise ValueError(f"excitations must have shape {(times.size, m)}, got {s.shape}")
    if not np.all(np.isfinite(s)) or s.min() < -1e-9 or s.max() > 1.0 + 1e-9:
        raise ValueError(f"excitations must lie in [0, 1], got min {s.min()!r}, max {s.max()!r}")
    for what, v in (("dt", dt), ("tau", tau)):
        if not (np.isfinite(v) and v > 0.0):
            raise ValueError(f"{what} must be a positive time (s), got {v!r}")
    q = model.check_posture(q0)
    qd = np.asarray(qd0, dtype=float).copy()
    if qd.shape != (3,) or not np.all(np.isfinite(qd)):
        raise ValueError(f"qd0 must be 3 finite rates (rad/s), got {qd0!r}")
    fmax = model.f_max
    n_steps = int(np.floor((times[-1] - times[0]) / dt + 1e-9))
    T = [times[0]]
    Qs, Qds = [q.copy()], [qd.copy()]
    a = s[0].copy()
    As = [a.copy()]
    decay = np.exp(-dt / tau)
    left = False

    def act(t0: float, a0: np.ndarray, t: float) -> np.ndarray:
        # exact solution of ȧ = (s − a)/τ with s held at s(t0) over [t0, t]
        sk = _excitation_at(times, s, t0)
        return sk + (a0 - sk) * np.exp(-(t - t0) / tau)

    def f(t: float, x: np.ndarray, t0: float, a0: np.ndarray) -> np.ndarray:
        F = act(t0, a0, t) * fmax
        return np.concatenate((x[3:], acceleration(model, x[:3], x[3:], F)))

    t = times[0]
    x = np.concatenate((q, qd))
    for _ in range(n_steps):
        try:
            k1 = f(t, x, t, a)
            k2 = f(t + dt / 2, x + dt / 2 * k1, t, a)
            k3 = f(t + dt / 2, x + dt / 2 * k2, t, a)
            k4 = f(t + dt, x + dt * k3, t, a)
        except ValueError:  # the posture left the model's range
            left = True
            break
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        sk = _excitation_at(times, s, t)
        a = sk + (a - sk) * decay
        t = t + dt
        if not np.all(model.lower - 1e-12 <= x[:3]) or not np.all(x[:3] <= model.upper + 1e-12):
            left = True
            break
        T.append(t)
        Qs.append(x[:3].copy())
        Qds.append(x[3:].copy())
        As.append(a.copy())
    return ForwardRun(np.array(T), np.array(Qs), np.array(Qds), np.array(As), left)
