"""Model reduction of a stable discrete linear law: square-root balanced truncation.

:func:`balanced_truncation` keeps the ``order`` states of a stable discrete system with the
largest Hankel singular values (the states both most excited by the input and most seen at
the outputs). The error bound: ``‖G − G_r‖_∞ ≤ 2 Σ_{i>order} σ_i`` in the scaled units.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_discrete_lyapunov

__all__ = ["balanced_truncation", "hankel_singular_values"]


def _check(ss):
    a, b, c, d, ts = ss
    a, b, c, d = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (a, b, c, d))
    n = a.shape[0]
    if a.shape != (n, n):
        raise ValueError(f"A must be square, got shape {a.shape}")
    if b.shape[0] != n or c.shape[1] != n or d.shape != (c.shape[0], b.shape[1]):
        raise ValueError(f"B, C, D do not fit A: {b.shape}, {c.shape}, {d.shape}")
    for name, x in (("A", a), ("B", b), ("C", c), ("D", d)):
        if not np.all(np.isfinite(x)):
            raise ValueError(f"{name} is not finite")
    rho = float(np.max(np.abs(np.linalg.eigvals(a)))) if n else 0.0
    if rho >= 1.0:
        raise ValueError(f"the system must be stable (spectral radius {rho:.6g} >= 1)")
    return a, b, c, d, float(ts)


def _factor(w: np.ndarray) -> np.ndarray:
    """``L`` with ``L Lᵀ = w`` for a symmetric positive semi-definite ``w`` (rounding may make
    tiny eigenvalues negative: they are cut at 0)."""
    lam, v = np.linalg.eigh(0.5 * (w + w.T))
    return v * np.sqrt(np.maximum(lam, 0.0))[None, :]


def _gramian_factors(a, b, c):
    # states in units of their reachability: the Lyapunov solves see entries of one scale
    lc = _factor(solve_discrete_lyapunov(a, b @ b.T))
    lo = _factor(solve_discrete_lyapunov(a.T, c.T @ c))
    return lc, lo


def hankel_singular_values(ss, input_scale=1.0, output_scale=1.0) -> np.ndarray:
    """Hankel singular values (descending) of the stable discrete ``ss = (A, B, C, D, Ts)``
    with inputs divided by ``input_scale`` and outputs by ``output_scale`` (their units)."""
    a, b, c, _, _ = _check(ss)
    b = b * np.atleast_1d(input_scale)[None, :]
    c = c / np.atleast_1d(output_scale)[:, None]
    lc, lo = _gramian_factors(a, b, c)
    return np.linalg.svd(lo.T @ lc, compute_uv=False)


def balanced_truncation(ss, order: int, input_scale=1.0, output_scale=1.0):
    """The stable discrete ``ss = (A, B, C, D, Ts)`` reduced to ``order`` states.

    Parameters
    ----------
    ss : tuple
        ``(A, B, C, D, Ts)``, stable (spectral radius < 1).
    order : int
        States kept, ``1 ≤ order ≤ n``; at most the number of non-zero Hankel singular
        values.
    input_scale, output_scale : float or sequence
        Typical size of each input and output (their units): the truncation weighs the
        channels in these units (a law from metres to a voice-coil command and a piezo
        displacement has outputs of very different sizes).

    Returns
    -------
    tuple
        ``(A_r, B_r, C_r, D, Ts)`` in balanced coordinates, and the Hankel singular values
        as a second element: ``(reduced, hsv)``.
    """
    a, b, c, d, ts = _check(ss)
    n = a.shape[0]
    if int(order) != order or not 1 <= order <= n:
        raise ValueError(f"order must be an integer in 1..{n}, got {order!r}")
    r = int(order)
    si = np.atleast_1d(np.asarray(input_scale, dtype=float))
    so = np.atleast_1d(np.asarray(output_scale, dtype=float))
    lc, lo = _gramian_factors(a, b * si[None, :], c / so[:, None])
    u, s, vt = np.linalg.svd(lo.T @ lc)
    if s[r - 1] <= 1e-14 * s[0]:
        raise ValueError(
            f"order {r} keeps Hankel singular values down to {s[r - 1]:.3g} (largest "
            f"{s[0]:.3g}): the system has fewer independent states; choose a lower order"
        )
    sr = 1.0 / np.sqrt(s[:r])
    t = lc @ vt[:r].T * sr[None, :]
    ti = (u[:, :r] * sr[None, :]).T @ lo.T
    return (ti @ a @ t, ti @ b, c @ t, d.copy(), ts), s
