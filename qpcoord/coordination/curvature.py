"""Schemes built on the scalar task ``h(q) = ‖ζ(q) − c‖² − R²`` (thesis §5.4, §5.5).

The end effector stays on a circle (3R) or a sphere (5R) of centre ``c`` exactly when
``h = 0``; ``ω_h = ∇h`` is its 1-form (Eq. 5.15) and ``H = ∇²h`` its Hessian (Eq. 5.16).

- :class:`HessianDirection` -- §5.4: move along the direction of largest curvature of the
  task manifold, ``f₁ = κ V₁`` with ``κ`` a basis of ``ker ω_h`` and ``V₁`` the eigenvector
  of ``κᵀHκ`` of largest ``|λ|``; ``q̇ = α f₁`` with ``α J f₁ = Ẏ`` (Eqs. 5.17–5.18).
- :class:`ComplementaryForm` -- §5.5: a constant 1-form ``ω_c`` tangent to the redundancy
  fibre at a chosen ``q̄``; ``q̇`` spans ``ker [ω_h; ω_c]`` (Eq. 5.21), scaled so that
  ``J q̇ = Ẏ`` (Eq. 5.22). The joints stay in the plane ``ω_c (q − q̄) = 0``: periodic from
  the first period, one periodic response per ``q̄`` (the compliance of Fig. 5.8).

Closed loop (``gain = K > 0``, not in the thesis, which integrates the open-loop maps):
``Ẏ = Ẏ_ref + K (Y_ref − Y)`` and a correction ``−K h d / (ω_h d)`` along a direction ``d``
that leaves the scheme's invariants alone (``d = ω_hᵀ`` for the Hessian scheme, its
projection on ``ker ω_c`` for the complementary form) brings ``h`` back to 0.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import AlgorithmicSingularity
from ..core.linalg import null_space
from ..kinematics.robot import Robot
from ..kinematics.tasks import PositionTask, _gain

__all__ = ["HessianDirection", "ComplementaryForm", "task_function"]


def _robot(robot) -> Robot:
    if not isinstance(robot, Robot):
        raise ValueError(f"robot must be a qpcoord.Robot, got {type(robot).__name__}")
    return robot


def _center(robot: Robot, center, reference) -> np.ndarray:
    c = center if center is not None else getattr(reference, "center", None)
    if c is None:
        raise ValueError(
            "no centre: give center= or run the scheme on a path with a .center "
            "(qpcoord.paths.Circle, LissajousSphere)"
        )
    c = np.asarray(c, dtype=float).reshape(-1)
    if c.shape != (robot.m,) or not np.all(np.isfinite(c)):
        raise ValueError(f"center must be {robot.m} finite coordinates (m), got {c!r}")
    return c


def task_function(robot, q, center, radius: float = 0.0, hessian: bool = True):
    """``(h, ω_h, H)`` of ``h(q) = ‖ζ(q) − c‖² − R²`` at ``q`` (m², m/rad, m/rad²).

    ``ω_h = 2 (y − c)ᵀ J``; ``H = 2 (JᵀJ + Σ_k (y − c)_k H_k)`` (``H_k`` the robot's position
    Hessian rows); ``H`` is ``None`` with ``hessian=False``.
    """
    robot = _robot(robot)
    q = robot.check_configuration(q)
    c = _center(robot, center, None)
    y, J = robot.kinematics(q)
    d = y - c
    h = float(d @ d) - float(radius) ** 2
    omega = 2.0 * d @ J
    if not hessian:
        return h, omega, None
    H = 2.0 * (J.T @ J + np.einsum("k,kij->ij", d, robot.hessian(q)))
    return h, omega, H


class _ScalarTaskScheme:
    def __init__(self, robot, center, gain: float) -> None:
        self.robot = _robot(robot)
        self.center = None if center is None else _center(self.robot, center, None)
        self.task = PositionTask(robot, gain=_gain(gain))
        self.gain = self.task.gain

    def _common(self, q, t, reference, hessian: bool):
        q = self.robot.check_configuration(q)
        c = self.center if self.center is not None else _center(self.robot, None, reference)
        y_ref, v_ref = self.task.reference_at(t, reference)
        radius = float(np.linalg.norm(y_ref - c))
        h, omega, H = task_function(self.robot, q, c, radius, hessian)
        y, J = self.robot._kinematics(q)
        ydot = v_ref + self.gain * (y_ref - y)
        return q, h, omega, H, J, ydot

    def _correction(self, h: float, direction: np.ndarray, omega: np.ndarray) -> np.ndarray:
        if self.gain == 0.0:
            return 0.0
        den = float(omega @ direction)
        if den == 0.0:
            return 0.0
        return -self.gain * h / den * direction


class HessianDirection(_ScalarTaskScheme):
    """§5.4: the maximal-curvature direction of the task manifold, scaled to ``Ẏ``.

    Per step: ``κ`` = orthonormal basis of ``ker ω_h`` (nq × (nq − 1)); ``V₁`` = unit
    eigenvector of ``κᵀ H κ`` with the largest ``|λ|``; ``f₁ = κ V₁``; ``v₁ = J f₁``;
    ``α = v₁·Ẏ / ‖v₁‖²`` (least squares of Eq. 5.17); ``q̇ = α f₁`` (Eq. 5.18). The sign of
    ``V₁`` does not matter (``α`` absorbs it).

    The thesis states that ``J f₁`` cannot vanish "by construction"; it can (``f₁`` may be
    a pure self-motion), so a relative ``‖J f₁‖ / ‖J‖ < tol`` raises
    :class:`~qpcoord.core.errors.AlgorithmicSingularity`. ``info`` keeps, per call, ``eigenvalues``
    and ``gap`` (``(|λ₁| − |λ₂|)/|λ₁|``: near 0 the chosen direction may jump) and
    ``min_gap`` / ``min_speed_ratio`` over the run.

    Parameters
    ----------
    robot : Robot
    center : array_like, optional
        ``c`` (m); default the reference path's ``center``.
    gain : float
        Closed-loop gain ``K`` (1/s), default 0.
    tol : float
        Threshold of ``‖J f₁‖ / ‖J‖₂`` (default 1e-2: below it ``α`` would command more
        than 100 times the joint speed of a direction that moves the end effector).
    """

    def __init__(self, robot, center=None, gain: float = 0.0, tol: float = 1e-2) -> None:
        super().__init__(robot, center, gain)
        if robot.nq - 1 < 1:
            raise ValueError("HessianDirection needs at least 2 joints")
        self.tol = float(tol)
        self.info = {"min_gap": np.inf, "min_speed_ratio": np.inf}

    def direction(self, q, t: float = 0.0, reference=None) -> np.ndarray:
        """The unit vector ``f₁`` (rad) at ``q`` (sign arbitrary)."""
        return self._direction(*self._common(q, t, reference, True)[1:4])[0]

    def _direction(self, h, omega, H):
        kappa = null_space(omega[None, :])
        lam, V = np.linalg.eigh(kappa.T @ H @ kappa)
        order = np.argsort(-np.abs(lam))
        lam = lam[order]
        f1 = kappa @ V[:, order[0]]
        return f1, lam

    def velocity(self, q, t: float = 0.0, reference=None) -> np.ndarray:
        q, h, omega, H, J, ydot = self._common(q, t, reference, True)
        f1, lam = self._direction(h, omega, H)
        v1 = J @ f1
        speed = float(np.linalg.norm(v1))
        ratio = speed / max(float(np.linalg.norm(J, 2)), 1e-300)
        gap = (abs(lam[0]) - abs(lam[1])) / abs(lam[0]) if lam.size > 1 and lam[0] else 1.0
        self.info.update(eigenvalues=lam, gap=gap)
        self.info["min_gap"] = min(self.info["min_gap"], gap)
        self.info["min_speed_ratio"] = min(self.info["min_speed_ratio"], ratio)
        if ratio < self.tol:
            raise AlgorithmicSingularity(
                f"HessianDirection: J f₁ vanishes (‖J f₁‖/‖J‖ = {ratio:.3g}) at t = {t:.6g} s, "
                f"q = {q.tolist()}: the curvature direction is a pure self-motion",
                q=q.copy(),
                t=float(t),
                sigma=ratio,
            )
        alpha = float(v1 @ ydot) / speed**2
        return alpha * f1 + self._correction(h, omega, omega)


class ComplementaryForm(_ScalarTaskScheme):
    """§5.5: a constant complementary 1-form from the fibre tangent at ``q̄`` (compliance).

    ``ω_c`` = orthonormal basis (rows) of ``T_{q̄}𝔖`` = ``ker J(q̄)`` (Eq. 5.19: ``c = v``);
    per step, ``F = ker [ω_h(q); ω_c]`` (nq × (rows − 1): one field on a circle, two on a
    sphere, as in Thm 4.2) and ``q̇ = F a`` with ``a`` the least-squares solution of
    ``J F a = Ẏ`` (Eq. 5.22). Started at ``q̄`` (``simulate(..., start="q0")``), the
    joints stay in the plane ``ω_c (q − q̄) = 0`` and on the task manifold: their
    intersection closes, so the response is periodic from the first period; each ``q̄`` on
    the master fibre gives its own periodic response (Fig. 5.8 A).

    Equivalent to the rigid extension ``[J; ω_c]`` (Def. 5.2) on the path, where
    ``ω_h q̇ = 0``; ``tests/test_curvature.py`` checks it.

    Parameters
    ----------
    robot : Robot
    q_bar : array_like, shape (nq,)
        ``q̄`` (rad), a non-singular configuration on the master fibre (typically a point
        from :func:`qpcoord.coordination.task_manifold.fibre_point`).
    center : array_like, optional
        ``c`` (m); default the reference path's ``center``.
    gain : float
        Closed-loop gain ``K`` (1/s), default 0.
    tol : float
        Relative singular-value threshold of ``[J F]`` below which the scheme raises
        :class:`~qpcoord.core.errors.AlgorithmicSingularity` (default 1e-6).
    """

    def __init__(self, robot, q_bar, center=None, gain: float = 0.0, tol: float = 1e-6) -> None:
        super().__init__(robot, center, gain)
        self.q_bar = self.robot.check_configuration(q_bar, "q_bar").copy()
        N = null_space(self.robot.jacobian(self.q_bar))
        if N.shape[1] != self.robot.nq - self.robot.m:
            raise ValueError(f"q_bar = {self.q_bar.tolist()} is a singular configuration")
        if N.shape[1] == 0:
            raise ValueError("no redundancy: the fibre is a point, there is no ω_c")
        self.omega_c = N.T  # rows
        self._Pc = np.eye(self.robot.nq) - N @ N.T  # projector on ker ω_c
        self.tol = float(tol)
        self.sigma_min = np.inf

    def velocity(self, q, t: float = 0.0, reference=None) -> np.ndarray:
        q, h, omega, _, J, ydot = self._common(q, t, reference, False)
        F = null_space(np.vstack((omega[None, :], self.omega_c)))
        JF = J @ F
        s = np.linalg.svd(JF, compute_uv=False)
        ratio = float(s[-1] / np.linalg.norm(J, 2)) if s.size else 0.0
        self.sigma_min = min(self.sigma_min, ratio)
        if F.shape[1] != self.robot.m - 1 or ratio < self.tol:
            raise AlgorithmicSingularity(
                f"ComplementaryForm: [ω_h; ω_c] or J F lost rank (ratio {ratio:.3g}) at "
                f"t = {t:.6g} s, q = {q.tolist()}",
                q=q.copy(),
                t=float(t),
                sigma=ratio,
            )
        a = np.linalg.lstsq(JF, ydot, rcond=None)[0]
        return F @ a + self._correction(h, self._Pc @ omega, omega)
