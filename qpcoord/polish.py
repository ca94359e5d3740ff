"""Active-set polishing of an approximate QP solution.

Interior-point, ADMM and augmented-Lagrangian backends return points that are optimal to
their tolerances (≈1e-8 … 1e-10), not to machine precision. In a strict hierarchy a level's
optimum is frozen for every lower level, so such errors propagate (helper measurements:
2–4e-6 relative on ill-conditioned stacks). :func:`polish` guesses the active set from the
returned point, solves the equality-constrained QP on it exactly (null-space method) and
keeps the result only if it is feasible and no worse than the backend's point — otherwise
the backend's point is returned unchanged. Active-set backends (daqp, quadprog) are exact
already and are not polished.
"""

from __future__ import annotations

import numpy as np

from .linalg import numerical_rank, svd
from .tolerance import at_bounds, within

__all__ = ["polish"]

#: Relative distances to a bound under which a row is taken as active (tried in turn).
ACTIVE_TOLS = (1e-7, 1e-5)
#: Relative objective increase the exact point may cost over the backend's point.
OBJ_SLACK = 1e-7
#: Relative feasibility tolerance the polished point must meet.
POLISH_FEAS_TOL = 1e-10


def polish(H, f, G, lo, hi, lb, ub, y: np.ndarray, obj_slack: float = 0.0) -> np.ndarray:
    """Refine ``y`` for ``min ½yᵀHy + fᵀy, lo ≤ G y ≤ hi, lb ≤ y ≤ ub`` on its active set.

    Returns the refined point, or ``y`` itself when no active-set guess gives a feasible
    point that is no worse (within ``max(OBJ_SLACK, obj_slack)``, relative: a point found
    with the rows opened by ``δ`` may beat the exact one by about ``δ``).
    """
    slack = max(OBJ_SLACK, obj_slack)
    for tol in ACTIVE_TOLS:
        out = _polish_at(H, f, G, lo, hi, lb, ub, y, tol, slack)
        if out is not None:
            return out
    return y


def _polish_at(H, f, G, lo, hi, lb, ub, y, tol, slack):
    k = y.shape[0]
    gy = G @ y
    a_lo, a_hi = at_bounds(gy, lo, hi, tol)
    rows = [G[a_lo], G[a_hi]]
    rhs = [lo[a_lo], hi[a_hi]]
    if lb is not None:
        b_lo, b_hi = at_bounds(y, lb, ub, tol)
        eye = np.eye(k)
        rows += [eye[b_lo], eye[b_hi]]
        rhs += [lb[b_lo], ub[b_hi]]
    A = np.vstack(rows)
    b = np.concatenate(rhs)
    if A.shape[0]:
        U, s, Vt = svd(A, full=True)
        rank = numerical_rank(s, A.shape)
        yp = Vt[:rank].T @ ((U[:, :rank].T @ b) / s[:rank])
        if np.abs(A @ yp - b).max() > POLISH_FEAS_TOL * max(1.0, float(np.abs(b).max())):
            return None  # inconsistent guess (degenerate active set)
        N = Vt[rank:].T
    else:
        yp = np.zeros(k)
        N = np.eye(k)
    if N.shape[1]:
        Hn = N.T @ H @ N
        try:
            u = np.linalg.solve(Hn, -(N.T @ (f + H @ yp)))
        except np.linalg.LinAlgError:
            return None
        yn = yp + N @ u
    else:
        yn = yp
    if not np.all(np.isfinite(yn)):
        return None
    if not within(G @ yn, lo, hi, POLISH_FEAS_TOL):
        return None
    if lb is not None and not within(yn, lb, ub, POLISH_FEAS_TOL):
        return None

    def obj(v):
        return 0.5 * v @ (H @ v) + f @ v

    fy, fn = obj(y), obj(yn)
    # the backend's point may sit outside the rows by the opening RELAX (≤ 1e-6) and gain
    # that much from it: allow the exact point to be worse by as much
    if fn > fy + slack * max(1.0, abs(fy)):
        return None
    return yn
