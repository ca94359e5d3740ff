"""Search of general 5R geometries for the thesis's arm of Example 4.1.

The thesis gives the 5R3D's link lengths (``l0 = … = l4 = 1 m``, ``l5 = 0.5 m``), its start
``q0`` and the Lissajous of Eq. 3.3, but no joint axes. qpcoord's arm
(:mod:`qpcoord.robots.spatial_5r`) puts ``q0`` 1.14 rad from the path. This module asks
whether *any* 5R geometry with the thesis's link lengths has

1. ``ζ(q0)`` on the Lissajous start point ``Y(0)`` (the thesis integrates from ``q0`` at
   ``t = 0``), and
2. Theorem 4.2's hypothesis along the path: ``[J; ω₄; ω₅]`` (Example 4.4's
   ``ω₄ = dq₁ + dq₅``, ``ω₅ = dq₂ + dq₄``) non-singular on the Thm 4.2 motion from ``q0``
   over one period.

Geometry (more general than Denavit–Hartenberg with base and tool transforms, which it
contains): link ``i`` is the vector ``lᵢ uᵢ`` in the frame of joint ``i`` (``u₀`` in the
world frame), joint ``i`` turns about the unit axis ``aᵢ`` of the previous frame by
``qᵢ + offᵢ``. With two angles per unit vector: 6 × 2 (links) + 5 × 2 (axes) + 5 (offsets)
= 27 parameters, :data:`N_PARAMS`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..kinematics.paths import LissajousSphere
from .spatial_5r import LENGTHS, Q0_THESIS

__all__ = [
    "N_PARAMS",
    "Candidate",
    "PinvRun",
    "forward",
    "forward_batch",
    "pinv_sections",
    "search",
    "thm42_hypothesis",
]

N_PARAMS = 27
OMEGA_45 = np.array([[1.0, 0.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0, 0.0]])


def _unit(theta: float, phi: float) -> np.ndarray:
    return np.array([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def _split(p: np.ndarray):
    links = [_unit(p[2 * i], p[2 * i + 1]) for i in range(6)]
    axes = [_unit(p[12 + 2 * i], p[13 + 2 * i]) for i in range(5)]
    return links, axes, p[22:27]


def forward(params, q) -> tuple[np.ndarray, np.ndarray]:
    """Tip position (m) and position Jacobian (m/rad, 3 × 5) of the geometry ``params``.

    Parameters
    ----------
    params : array_like, shape (27,)
        Geometry (rad): link directions, joint axes, joint offsets (module docstring).
    q : array_like, shape (5,)
        Joint angles (rad).
    """
    p = np.asarray(params, dtype=float)
    q = np.asarray(q, dtype=float)
    if p.shape != (N_PARAMS,) or q.shape != (5,):
        raise ValueError(
            f"params must have shape ({N_PARAMS},) and q (5,), got {p.shape}, {q.shape}"
        )
    links, axes, off = _split(p)
    R = np.eye(3)
    pos = LENGTHS[0] * links[0]
    joints, zs = [], []
    for i in range(5):
        z = R @ axes[i]
        joints.append(pos.copy())
        zs.append(z)
        R = R @ _rot(axes[i], q[i] + off[i])
        pos = pos + LENGTHS[i + 1] * (R @ links[i + 1])
    J = np.column_stack([np.cross(z, pos - o) for z, o in zip(zs, joints, strict=True)])
    return pos, J


@dataclass(frozen=True)
class Candidate:
    """One geometry of the search: how far ``ζ(q0)`` is from ``Y(0)`` (m) and, along the
    Thm 4.2 motion from ``q0`` over one period, the smallest singular values of
    ``[J; ω₄; ω₅]`` and of ``J`` and the largest tracking error (m)."""

    params: np.ndarray
    start_gap_m: float
    sigma_min_thm42: float
    sigma_min_J: float
    max_tracking_m: float
    closure_rad: float


def thm42_hypothesis(params, q0=Q0_THESIS, steps: int = 200, path=None) -> tuple:
    """Integrate the Thm 4.2 motion ``[J; ω₄; ω₅] q̇ = (Ẏ, 0, 0)`` from ``q0`` over one
    period (RK4, ``steps`` per period) on ``params``; returns (smallest σ of ``[J; ω₄; ω₅]``,
    smallest σ of ``J``, largest ``‖ζ(q) − Y‖`` (m), closure ``‖q(T) − q(0)‖`` (rad)).
    Stops early (σ = 0) where the matrix is singular."""
    path = path or LissajousSphere()
    dt = path.period / steps
    q = np.asarray(q0, dtype=float).copy()
    smin, sj, err = np.inf, np.inf, 0.0

    def rate(q, t):
        y, J = forward(params, q)
        A = np.vstack((J, OMEGA_45))
        s = np.linalg.svd(A, compute_uv=False)
        vel = path.velocity(t)
        return (
            np.linalg.solve(A, np.r_[vel, 0.0, 0.0]),
            s[-1],
            np.linalg.svd(J, compute_uv=False)[-1],
            np.linalg.norm(y - path.position(t)),
        )

    t = 0.0
    for _ in range(steps):
        k1, s1, j1, e1 = rate(q, t)
        smin, sj, err = min(smin, s1), min(sj, j1), max(err, e1)
        if s1 < 1e-6:
            return 0.0, sj, err, np.inf
        k2 = rate(q + dt / 2 * k1, t + dt / 2)[0]
        k3 = rate(q + dt / 2 * k2, t + dt / 2)[0]
        k4 = rate(q + dt * k3, t + dt)[0]
        q = q + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t += dt
    _, s_end, j_end, e_end = rate(q, t)
    return (
        float(min(smin, s_end)),
        float(min(sj, j_end)),
        float(max(err, e_end)),
        float(np.linalg.norm(q - np.asarray(q0))),
    )


def search(starts: int = 200, seed: int = 0, steps: int = 200) -> list[Candidate]:
    """Seeded bounded search: ``starts`` random geometries (uniform link and axis directions
    on the sphere, offsets in [−π, π)), each moved by ``scipy.optimize.least_squares``
    (at most 200 evaluations) onto ``ζ(q0) = Y(0)`` with a small pull towards its start,
    then checked by :func:`thm42_hypothesis`.

    Returns
    -------
    list of Candidate
        One per start, in start order.
    """
    if starts < 1:
        raise ValueError(f"starts must be >= 1, got {starts!r}")
    path = LissajousSphere()
    y0 = path.position(0.0)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(starts):
        p0 = np.empty(N_PARAMS)
        p0[:22:2] = np.arccos(rng.uniform(-1.0, 1.0, 11))  # polar angles, uniform on sphere
        p0[1:22:2] = rng.uniform(-np.pi, np.pi, 11)
        p0[22:] = rng.uniform(-np.pi, np.pi, 5)

        def res(p, p0=p0):
            return np.r_[forward(p, Q0_THESIS)[0] - y0, 1e-3 * (p - p0)]

        sol = least_squares(res, p0, max_nfev=200)
        gap = float(np.linalg.norm(forward(sol.x, Q0_THESIS)[0] - y0))
        if gap > 1e-6:
            out.append(Candidate(sol.x, gap, np.nan, np.nan, np.nan, np.nan))
            continue
        s42, sj, err, clos = thm42_hypothesis(sol.x, steps=steps, path=path)
        out.append(Candidate(sol.x, gap, s42, sj, err, clos))
    return out


def _check_batch(params, q) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(params, dtype=float)
    q = np.asarray(q, dtype=float)
    if p.ndim != 2 or p.shape[1] != N_PARAMS:
        raise ValueError(f"params must have shape (k, {N_PARAMS}), got {p.shape}")
    if q.shape != (p.shape[0], 5):
        raise ValueError(f"q must have shape ({p.shape[0]}, 5), got {q.shape}")
    return p, q


def _unit_batch(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)


def _rot_batch(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues rotations, ``axis`` (k, 3) unit, ``angle`` (k,) rad → (k, 3, 3)."""
    k = axis.shape[0]
    K = np.zeros((k, 3, 3))
    K[:, 0, 1], K[:, 0, 2] = -axis[:, 2], axis[:, 1]
    K[:, 1, 0], K[:, 1, 2] = axis[:, 2], -axis[:, 0]
    K[:, 2, 0], K[:, 2, 1] = -axis[:, 1], axis[:, 0]
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def forward_batch(params, q) -> tuple[np.ndarray, np.ndarray]:
    """:func:`forward` for ``k`` geometries at once.

    Parameters
    ----------
    params : array_like, shape (k, 27)
        Geometries (rad), as in :func:`forward`.
    q : array_like, shape (k, 5)
        Joint angles (rad), one row per geometry.

    Returns
    -------
    tuple of numpy.ndarray
        Tip positions (m), shape (k, 3), and position Jacobians (m/rad), shape (k, 3, 5).
    """
    p, q = _check_batch(params, q)
    k = p.shape[0]
    links = _unit_batch(p[:, 0:12:2], p[:, 1:12:2])  # (k, 6, 3)
    axes = _unit_batch(p[:, 12:22:2], p[:, 13:22:2])  # (k, 5, 3)
    off = p[:, 22:27]
    R = np.broadcast_to(np.eye(3), (k, 3, 3)).copy()
    pos = LENGTHS[0] * links[:, 0]
    joints, zs = [], []
    for i in range(5):
        zs.append(np.einsum("kij,kj->ki", R, axes[:, i]))
        joints.append(pos)
        R = R @ _rot_batch(axes[:, i], q[:, i] + off[:, i])
        pos = pos + LENGTHS[i + 1] * np.einsum("kij,kj->ki", R, links[:, i + 1])
    J = np.stack([np.cross(z, pos - o) for z, o in zip(zs, joints, strict=True)], axis=-1)
    return pos, J


@dataclass(frozen=True)
class PinvRun:
    """Poincaré sections of long ``J⁺`` runs on ``k`` geometries (:func:`pinv_sections`).

    Attributes
    ----------
    sections : numpy.ndarray, shape (periods + 1, k, 5)
        Joint angles (rad) at ``t = jT``.
    max_tracking_m : numpy.ndarray, shape (k,)
        Largest ``‖ζ(q) − Y‖`` (m) at the RK4 steps.
    min_sigma_J : numpy.ndarray, shape (k,)
        Smallest singular value of ``J`` (m/rad) at the RK4 steps.
    """

    sections: np.ndarray
    max_tracking_m: np.ndarray
    min_sigma_J: np.ndarray


def pinv_sections(
    params, q0=Q0_THESIS, periods: int = 100, steps: int = 200, gain: float = 1.0, path=None
) -> PinvRun:
    """Long runs of the pseudo-inverse scheme (Eq. 4.1 with position feedback)
    ``q̇ = J⁺(Ẏ_ref + K (Y_ref − ζ(q)))`` from ``q0`` on ``k`` geometries at once.

    The scheme and integrator of ``qc.simulate(arm, qc.schemes.PseudoInverse(arm, gain=K),
    ...)`` -- classical RK4, ``steps`` per period of the path, ``J⁺ = Jᵀ(JJᵀ)⁻¹`` -- vectorised
    over the geometries (the planar counterpart is ``examples/ch4_long_runs.py``'s
    ``batch_pinv_sections``).

    Parameters
    ----------
    params : array_like, shape (k, 27)
        Geometries (rad).
    q0 : array_like, shape (5,)
        Start (rad), the same for every geometry (the thesis's by default).
    periods, steps : int
        Number of path periods and RK4 steps per period (≥ 1).
    gain : float
        ``K`` (1/s), ≥ 0.
    path : optional
        The task (default :class:`qpcoord.kinematics.paths.LissajousSphere`).

    Returns
    -------
    PinvRun
    """
    if periods < 1 or steps < 1:
        raise ValueError(f"periods and steps must be >= 1, got {periods!r}, {steps!r}")
    if not np.isfinite(gain) or gain < 0:
        raise ValueError(f"gain must be a finite number >= 0 (1/s), got {gain!r}")
    p = np.atleast_2d(np.asarray(params, dtype=float))
    q = np.tile(np.asarray(q0, dtype=float), (p.shape[0], 1))
    p, q = _check_batch(p, q)
    path = path or LissajousSphere()
    dt = path.period / steps
    out = np.empty((periods + 1, *q.shape))
    out[0] = q
    err = np.zeros(p.shape[0])
    smin = np.full(p.shape[0], np.inf)

    def f(q, t, record=False):
        y, J = forward_batch(p, q)
        e = path.velocity(t) + gain * (path.position(t) - y)
        if record:
            nonlocal err, smin
            err = np.maximum(err, np.linalg.norm(y - path.position(t), axis=1))
            smin = np.minimum(smin, np.linalg.svd(J, compute_uv=False)[:, -1])
        lam = np.linalg.solve(J @ np.swapaxes(J, 1, 2), e[:, :, None])
        return (np.swapaxes(J, 1, 2) @ lam)[:, :, 0]

    for j in range(periods):
        for i in range(steps):
            t = (j * steps + i) * dt
            k1 = f(q, t, record=True)
            k2 = f(q + 0.5 * dt * k1, t + 0.5 * dt)
            k3 = f(q + 0.5 * dt * k2, t + 0.5 * dt)
            k4 = f(q + dt * k3, t + dt)
            q = q + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        out[j + 1] = q
    return PinvRun(out, err, smin)
