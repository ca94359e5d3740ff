"""Vector fields and 1-forms on the joint space (thesis §3.6, chapter 4).

Vector fields and 1-forms are callables of the configuration ``q`` (rad): a field returns
an ``(n,)`` vector, a set of 1-forms a ``(k, n)`` array of covectors (rows).

- :func:`field_jacobian` -- ``∂f/∂q`` of a field: analytic when the field has a
  ``jacobian(q)`` method (e.g. :class:`PseudoInverseField`), complex-step when it accepts a
  complex ``q`` (exact to rounding), else a 4th-order central difference (never a plain
  forward difference);
- :func:`lie_bracket` -- ``[f, g](q) = ∂g/∂q f − ∂f/∂q g``;
- :func:`involutivity_defect` / :func:`is_involutive` -- the rank test of Def. 3.13: every
  bracket of the fields lies in their span;
- :func:`bracket_determinant` -- ``det[f₁, f₂, [f₁, f₂]]`` in 3-D (Lemma 4.1, Ex. 4.3);
- :func:`dual_fields` -- an orthonormal basis of the fields annihilated by a set of 1-forms
  (Thm 4.2 step 3), with its orientation carried along a path;
- :class:`PseudoInverseField` -- ``f(q) = J(q)⁺ v``, the pull-back of a task-space vector by
  the pseudo-inverse (§4.3.1–4.3.2), with its analytic Jacobian from the robot's Hessian;
- :func:`pullback` -- the 1-form ``ω(q) = c(ζ(q)) J(q)`` of a task-space covector field
  ``c`` (e.g. ``ω₁ = ∇_q h`` for an output manifold ``h(y) = 0``).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np

from ..core.linalg import null_space, svd

__all__ = [
    "field_jacobian",
    "lie_bracket",
    "involutivity_defect",
    "is_involutive",
    "bracket_determinant",
    "dual_fields",
    "PseudoInverseField",
    "pullback",
]

_CS_STEP = 1e-30  # complex-step size: no subtractive cancellation, so it can be tiny


def _q(q) -> np.ndarray:
    arr = np.asarray(q, dtype=float).reshape(-1)
    if arr.size == 0 or not np.all(np.isfinite(arr)):
        raise ValueError(f"q must be a non-empty finite vector (rad), got {q!r}")
    return arr


def _value(f: Callable, q: np.ndarray, what: str = "field") -> np.ndarray:
    v = np.asarray(f(q), dtype=float).reshape(-1)
    if v.shape != q.shape:
        raise ValueError(
            f"{what} {getattr(f, '__name__', f)!r} returned {v.shape[0]} values at a "
            f"configuration of {q.shape[0]} joints"
        )
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{what} returned a non-finite value at q = {q.tolist()}")
    return v


def _accepts_complex(f: Callable, q: np.ndarray) -> bool:
    try:
        with warnings.catch_warnings():  # a field that casts to float warns: not usable
            warnings.simplefilter("ignore", np.exceptions.ComplexWarning)
            out = np.asarray(f(q + 1j * _CS_STEP * np.eye(q.size)[0]))
    except (TypeError, ValueError):
        return False
    return np.iscomplexobj(out) and out.reshape(-1).shape == q.shape


def field_jacobian(f: Callable, q) -> np.ndarray:
    """``D[i, j] = ∂f_i/∂q_j`` at ``q`` (see the module docstring for how).

    Raises
    ------
    ValueError
        ``f(q)`` has the wrong size or is not finite.
    """
    q = _q(q)
    _value(f, q)
    jac = getattr(f, "jacobian", None)
    if callable(jac):
        D = np.asarray(jac(q), dtype=float)
        if D.shape != (q.size, q.size):
            raise ValueError(f"field jacobian must be {q.size}×{q.size}, got {D.shape}")
        return D
    n = q.size
    if _accepts_complex(f, q):
        cols = [
            np.imag(np.asarray(f(q + 1j * _CS_STEP * e)).reshape(-1)) / _CS_STEP for e in np.eye(n)
        ]
        return np.array(cols).T
    # 4th-order central difference, step ∝ ε^(1/5)
    h = 1e-3 * max(1.0, float(np.abs(q).max()))
    cols = []
    for e in np.eye(n):
        f2, f1 = _value(f, q + 2 * h * e), _value(f, q + h * e)
        b1, b2 = _value(f, q - h * e), _value(f, q - 2 * h * e)
        cols.append((-f2 + 8 * f1 - 8 * b1 + b2) / (12 * h))
    return np.array(cols).T


def lie_bracket(f: Callable, g: Callable, q) -> np.ndarray:
    """Lie bracket ``[f, g](q) = (∂g/∂q) f(q) − (∂f/∂q) g(q)``.

    The thesis uses the opposite sign (``(∂f/∂q) g − (∂g/∂q) f``): its Lemma 4.1
    determinant ``−(1 + q₁²)²`` is ``+(1 + q₁²)²`` here (measured, ``tests/test_geometry.py``);
    involutivity does not depend on the sign.
    """
    q = _q(q)
    return field_jacobian(g, q) @ _value(f, q) - field_jacobian(f, q) @ _value(g, q)


def involutivity_defect(fields, q) -> float:
    """Largest distance of a bracket ``[fᵢ, fⱼ]`` from ``span{f}``, relative to
    ``‖(∂fⱼ/∂q) fᵢ‖ + ‖(∂fᵢ/∂q) fⱼ‖`` (the two terms whose difference is the bracket).

    0 (to rounding) for an involutive set (Def. 3.13); of order 1 when a bracket leaves
    the span.

    Raises
    ------
    ValueError
        Fewer than two fields, or fields that are dependent at ``q`` (the distribution
        loses rank there: involutivity is not defined by this test).
    """
    q = _q(q)
    fields = list(fields)
    if len(fields) < 2:
        raise ValueError("give at least two vector fields")
    F = np.array([_value(f, q) for f in fields]).T
    _, s, _ = svd(F, full=False)
    if s[-1] <= 1e-10 * max(1.0, s[0]):
        raise ValueError(
            f"the fields are dependent at q = {q.tolist()} (smallest singular value "
            f"{s[-1]:.3g}): the distribution loses rank there"
        )
    Q, _ = np.linalg.qr(F)
    D = [field_jacobian(f, q) for f in fields]
    worst = 0.0
    for i in range(len(fields)):
        for j in range(i + 1, len(fields)):
            t1, t2 = D[j] @ F[:, i], D[i] @ F[:, j]
            b = t1 - t2  # [fᵢ, fⱼ]
            # relative to the two terms whose difference it is: commuting fields give a
            # rounding-level bracket whose direction means nothing
            scale = float(np.linalg.norm(t1) + np.linalg.norm(t2))
            if scale == 0.0:
                continue
            worst = max(worst, float(np.linalg.norm(b - Q @ (Q.T @ b))) / scale)
    return worst


def is_involutive(fields, q, tol: float = 1e-8) -> bool:
    """Def. 3.13 at ``q``: every bracket lies in the span of the fields (to ``tol``)."""
    return involutivity_defect(fields, q) <= tol


def bracket_determinant(f1: Callable, f2: Callable, q) -> float:
    """``det[f₁, f₂, [f₁, f₂]]`` at ``q`` for two fields on a 3-D space (Lemma 4.1):
    non-zero means the pair is not involutive there."""
    q = _q(q)
    if q.size != 3:
        raise ValueError(f"bracket_determinant needs a 3-D configuration, got {q.size}")
    return float(
        np.linalg.det(np.column_stack((_value(f1, q), _value(f2, q), lie_bracket(f1, f2, q))))
    )


def dual_fields(forms, q, previous: np.ndarray | None = None) -> np.ndarray:
    """Orthonormal basis (columns) of the fields annihilated by the 1-forms at ``q``.

    Parameters
    ----------
    forms : callable or array_like, shape (k, n)
        The covectors (rows), or ``forms(q)``.
    q : array_like, shape (n,)
    previous : ndarray, shape (n, n − k), optional
        The basis at the previous point of a path: the new basis is rotated to the one
        closest to it (orthogonal Procrustes), so it has no sign flips or jumps along the
        path.

    Raises
    ------
    ValueError
        Wrong sizes, or 1-forms that are dependent at ``q`` (rank lost: Thm 4.2 needs
        them independent).
    """
    q = _q(q)
    W = np.atleast_2d(np.asarray(forms(q) if callable(forms) else forms, dtype=float))
    if W.shape[1] != q.size:
        raise ValueError(f"1-forms must have {q.size} columns, got shape {W.shape}")
    _, s, _ = svd(W, full=False)
    if W.shape[0] > q.size or s[-1] <= 1e-10 * max(1.0, s[0]):
        raise ValueError(
            f"the {W.shape[0]} 1-forms are dependent at q = {q.tolist()} (smallest "
            f"singular value {s[-1]:.3g}): their dual fields are not defined there"
        )
    N = null_space(W)
    if previous is not None:
        P = np.asarray(previous, dtype=float)
        if P.shape != N.shape:
            raise ValueError(f"previous basis must have shape {N.shape}, got {P.shape}")
        U, _, Vt = np.linalg.svd(N.T @ P)
        N = N @ (U @ Vt)
    return N


class PseudoInverseField:
    """``f(q) = J(q)⁺ v``: a task-space vector ``v`` pulled back by the pseudo-inverse.

    Its Jacobian is analytic (full-row-rank ``J``):
    ``∂(J⁺)/∂qᵢ = (I − J⁺J)(∂ᵢJ)ᵀ(JJᵀ)⁻¹ − J⁺(∂ᵢJ)J⁺`` with ``∂ᵢJ`` from the robot's
    Hessian.

    Parameters
    ----------
    robot : Robot
    v : array_like, shape (rows,)
        Constant task-space vector (m/s for a velocity field).
    """

    def __init__(self, robot, v) -> None:
        self.robot = robot
        self.v = np.asarray(v, dtype=float).reshape(-1)
        if self.v.shape != (robot.m,) or not np.all(np.isfinite(self.v)):
            raise ValueError(f"v must be {robot.m} finite numbers, got {v!r}")
        self.__name__ = f"J⁺{self.v.tolist()}"

    def _pinv(self, q):
        J = self.robot.jacobian(q)
        G = J @ J.T
        if np.linalg.cond(G) > 1e12:
            raise ValueError(f"J is singular at q = {np.asarray(q).tolist()}: J⁺ undefined")
        Gi = np.linalg.inv(G)
        return J, J.T @ Gi, Gi

    def __call__(self, q) -> np.ndarray:
        _, Jp, _ = self._pinv(q)
        return Jp @ self.v

    def jacobian(self, q) -> np.ndarray:
        """``∂f/∂q`` (analytic, from the robot's Hessian)."""
        J, Jp, Gi = self._pinv(q)
        H = self.robot.hessian(q)  # H[k, j, i] = ∂J[k, j]/∂q_i
        n = J.shape[1]
        P = np.eye(n) - Jp @ J
        D = np.empty((n, n))
        for i in range(n):
            dJ = H[:, :, i]
            D[:, i] = (P @ dJ.T @ Gi - Jp @ dJ @ Jp) @ self.v
        return D


def pullback(robot, covector: Callable) -> Callable:
    """1-form ``ω(q) = c(ζ(q)) J(q)`` from a task-space covector field ``c(y)``.

    E.g. for an output manifold ``h(y) = 0``, ``c = ∇_y h`` gives ``ω₁ = ∇_q h``.
    """

    def form(q) -> np.ndarray:
        y, J = robot.kinematics(q)
        c = np.asarray(covector(y), dtype=float).reshape(-1)
        if c.shape != (robot.m,):
            raise ValueError(f"covector(y) must return {robot.m} values, got {c.shape}")
        return (c @ J).reshape(1, -1)

    return form
