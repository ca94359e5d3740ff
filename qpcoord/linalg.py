"""Small dense linear algebra shared by the stack methods.

Damping rule (used by every method, documented in ``docs/stack.md``): for a level matrix
``M = U diag(s) Vᵀ`` with largest singular value ``s₀``,

- a singular value ``s ≤ rank_tol = max(M.shape) · ε_machine · s₀`` is zero: that direction is
  left free for lower levels (numerical rank, as :func:`numpy.linalg.matrix_rank`);
- above the *damping threshold* ``τ = damping · s₀`` the direction is solved exactly
  (gain ``1/s``, the Moore–Penrose pseudo-inverse);
- between the two the gain is ``s/τ²``: continuous at ``s = τ``, bounded by ``1/τ``, and
  going to 0 with ``s`` (a damped least-squares filter that only acts near singularity).

The threshold is relative to ``s₀``, so scaling a whole level by a positive weight does not
change the solution.
"""

from __future__ import annotations

import numpy as np

__all__ = ["filtered_svd", "filtered_gains", "null_space"]

_EPS = np.finfo(float).eps


def filtered_svd(M: np.ndarray, damping: float):
    """Full SVD of ``M`` with its numerical rank and filtered inverse gains.

    Parameters
    ----------
    M : ndarray, shape (m, r)
    damping : float
        Relative damping threshold ``τ/s₀`` (dimensionless, ``≥ 0``).

    Returns
    -------
    U : ndarray, shape (m, m)
    s : ndarray, shape (min(m, r),)
    Vt : ndarray, shape (r, r)
        Rows ``Vt[:rank]`` span the row space, ``Vt[rank:]`` the null space of ``M``.
    rank : int
    gains : ndarray, shape (rank,)
        ``1/s`` above the threshold, ``s/τ²`` below it.
    """
    U, s, Vt = np.linalg.svd(M, full_matrices=True)
    if s.size == 0 or s[0] == 0.0:
        return U, s, Vt, 0, s[:0]
    rank_tol = max(M.shape) * _EPS * s[0]
    rank = int(np.count_nonzero(s > rank_tol))
    return U, s, Vt, rank, filtered_gains(s[:rank], damping * s[0])


def filtered_gains(s: np.ndarray, tau: float) -> np.ndarray:
    """Gains ``1/s`` for ``s ≥ τ`` and ``s/τ²`` below (see module docstring)."""
    if tau <= 0.0:
        return 1.0 / s
    return np.where(s >= tau, 1.0 / np.maximum(s, tau), s / (tau * tau))


def null_space(F: np.ndarray) -> np.ndarray:
    """Orthonormal basis (columns) of the null space of ``F`` (numerical rank as above)."""
    r = F.shape[1]
    if F.shape[0] == 0:
        return np.eye(r)
    _, s, Vt = np.linalg.svd(F, full_matrices=True)
    if s.size == 0 or s[0] == 0.0:
        return np.eye(r)
    rank = int(np.count_nonzero(s > max(F.shape) * _EPS * s[0]))
    return Vt[rank:].T
