"""Small dense linear algebra shared by the stack methods.

Damping rule (used by every method, documented in ``docs/stack.md``): for a level matrix
``M = U diag(s) Vᵀ`` with largest singular value ``s₀``,

- a singular value ``s ≤ rank_tol = max(M.shape) · ε_machine · s_ref`` is zero: that direction
  is left free for lower levels (numerical rank, as :func:`numpy.linalg.matrix_rank`);
- above the *damping threshold* ``τ = damping · s_ref`` the direction is solved exactly
  (gain ``1/s``, the Moore–Penrose pseudo-inverse);
- between the two the gain is ``s/τ²``: continuous at ``s = τ``, bounded by ``1/τ``, and
  going to 0 with ``s`` (a damped least-squares filter that only acts near singularity).

Here ``s_ref = max(s₀, ‖A‖_F)``, with ``A`` the level's rows *before* projection on the
freedom the levels above left: a level that becomes dependent on them (an algorithmic
singularity, ``s₀ → 0`` while ``‖A‖`` stays) is damped, and one lying entirely in their span
has rank 0. Both are relative, so scaling a whole level by a positive weight does not change
the solution.

LAPACK is called directly (:mod:`scipy.linalg.lapack`): for the 3×7 … 30×30 matrices of a
control step, :func:`numpy.linalg.svd`'s Python wrapper costs more than the factorisation
(measured 27 µs vs 9 µs for a 6×7 SVD on the project's 2-core machine).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

__all__ = [
    "svd",
    "filtered_svd",
    "filtered_gains",
    "null_space",
    "numerical_rank",
    "all_finite",
]

_EPS = np.finfo(float).eps
_dgesvd = lapack.dgesvd


def svd(M: np.ndarray, full: bool = True):
    """SVD ``M = U diag(s) Vt``; ``Vt`` is square (r × r) whenever ``full`` or ``m ≥ r``.

    With ``full=False`` and ``m ≥ r``, ``U`` is thin (m × r). Falls back to numpy if LAPACK
    reports a failure.
    """
    m, r = M.shape
    if m == 0 or r == 0:
        return np.zeros((m, m)), np.zeros(0), np.eye(r)
    U, s, Vt, info = _dgesvd(M, compute_uv=1, full_matrices=1 if (full or m < r) else 0)
    if info != 0:  # pragma: no cover - LAPACK convergence failure
        return np.linalg.svd(M, full_matrices=True)
    return U, s, Vt


def numerical_rank(s: np.ndarray, shape: tuple[int, int], scale: float = 0.0) -> int:
    """Number of singular values above ``max(shape) · ε · max(s₀, scale)``.

    ``scale`` is the size of the matrix *before* projection: a projected level whose rows
    lie in the span of the levels above is rounding noise (``s₀ ~ 1e-17``) and must count
    as rank 0, which a tolerance relative to its own ``s₀`` would miss.
    """
    if s.size == 0:
        return 0
    ref = max(float(s[0]), scale)
    if ref == 0.0:
        return 0
    tol = max(shape) * _EPS * ref
    if s[-1] > tol:
        return s.size
    return int(np.count_nonzero(s > tol))


def filtered_gains(s: np.ndarray, tau: float) -> np.ndarray:
    """Gains ``1/s`` for ``s ≥ τ`` and ``s/τ²`` below (see module docstring)."""
    if tau <= 0.0 or s.min() >= tau:
        return 1.0 / s
    return np.where(s >= tau, 1.0 / np.maximum(s, tau), s / (tau * tau))


def filtered_svd(M: np.ndarray, damping: float, scale: float = 0.0):
    """SVD of ``M`` with its numerical rank and filtered inverse gains.

    Parameters
    ----------
    M : ndarray, shape (m, r)
    damping : float
        Relative damping threshold (dimensionless, ``≥ 0``).
    scale : float
        Size of the matrix before projection (e.g. its Frobenius norm); the rank tolerance
        and the damping threshold ``τ = damping · max(s₀, scale)`` are relative to it, so a
        level that becomes dependent on the levels above (an algorithmic singularity) is
        damped instead of inverted with a huge gain.

    Returns
    -------
    U : ndarray, shape (m, m) or (m, r)
    s : ndarray, shape (min(m, r),)
    Vt : ndarray, shape (r, r)
        Rows ``Vt[:rank]`` span the row space, ``Vt[rank:]`` the null space of ``M``.
    rank : int
    gains : ndarray, shape (rank,)
        ``1/s`` above the threshold, ``s/τ²`` below it.
    tau : float
        The damping threshold used.
    """
    U, s, Vt = svd(M, full=False)
    rank = numerical_rank(s, M.shape, scale)
    if rank == 0:
        return U, s, Vt, 0, s[:0], 0.0
    tau = damping * max(float(s[0]), scale)
    return U, s, Vt, rank, filtered_gains(s[:rank], tau), tau


def null_space(F: np.ndarray, scale: float = 0.0) -> np.ndarray:
    """Orthonormal basis (columns) of the null space of ``F`` (numerical rank as above,
    relative to ``max(s₀, scale)``)."""
    r = F.shape[1]
    if F.shape[0] == 0:
        return np.eye(r)
    _, s, Vt = svd(F, full=True)
    return Vt[numerical_rank(s, F.shape, scale) :].T


def all_finite(a: np.ndarray) -> bool:
    """``True`` if every entry of ``a`` is finite (neither NaN nor ±inf).

    One ``isfinite`` and one reduction: as cheap as the ``math.isfinite(a.sum())`` idiom on
    control-step sizes, but exact and silent — a sum overflows to ``inf`` (and numpy prints a
    ``RuntimeWarning``) on large *finite* entries such as ``1e308``, or makes NaN of ``+inf``
    and ``-inf``.
    """
    return bool(np.isfinite(a).all())
