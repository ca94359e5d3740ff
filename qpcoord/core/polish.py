"""Active-set polishing of an approximate QP solution.

Interior-point, ADMM and augmented-Lagrangian backends return points that are optimal to
their tolerances (≈1e-8 … 1e-10), not to machine precision. In a strict hierarchy a level's
optimum is frozen for every lower level, so such errors propagate (helper measurements:
2–4e-6 relative on ill-conditioned stacks). :func:`polish` guesses the active set from the
returned point, solves the equality-constrained QP on it exactly (null-space method) and
keeps the result only if it is feasible and no worse than the backend's point.

When no exact solve on a guessed active set is feasible -- typical of a level whose Hessian
is nearly singular (``AᵀA`` plus the tiny regularisation: the backend's point is then only
loosely determined along the null space of ``A`` and its active set is a guess) -- a
*truncated* refinement is tried: from the smallest move of the point onto the active set,
a few Newton steps on the active set restricted to the eigen-directions of ``NᵀHN`` with
eigenvalue above ``1e-6`` of the largest. They fix the well-determined part of the
objective (the task residual) and leave the poorly determined directions alone. It too
is kept only if feasible and no worse. Otherwise the backend's point is returned
unchanged. Active-set backends (daqp,
quadprog) are exact already and are not polished.
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
#: Eigenvalue cut of the fallback refinement, relative to the largest (module docstring).
PROX = 1e-6
#: Refinement steps of the fallback.
PROX_STEPS = 2


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
    for tol in ACTIVE_TOLS:
        out = _polish_at(H, f, G, lo, hi, lb, ub, y, tol, OBJ_SLACK, prox=PROX)
        if out is not None:
            return out
    return y


def _polish_at(H, f, G, lo, hi, lb, ub, y, tol, slack, prox: float = 0.0):
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
        Ur, sr, Vr = U[:, :rank], s[:rank], Vt[:rank].T
        # on the active set: the exact solve starts from its minimum-norm point, the
        # proximal one from the smallest move of y onto it
        base = np.zeros(k) if not prox else y
        yp = base + Vr @ ((Ur.T @ (b - A @ base)) / sr)
        if np.abs(A @ yp - b).max() > POLISH_FEAS_TOL * max(1.0, float(np.abs(b).max())):
            return None  # inconsistent guess (degenerate active set)
        N = Vt[rank:].T
    else:
        yp = y.copy() if prox else np.zeros(k)
        N = np.eye(k)
    if N.shape[1]:
        Hn = N.T @ H @ N
        if prox:
            # Newton steps in the well-determined eigen-directions of Hn only
            lam, V = np.linalg.eigh(Hn)
            keep = lam > prox * max(float(lam[-1]), 1e-300)
            V, lam = V[:, keep], lam[keep]
            yn = yp
            for _ in range(PROX_STEPS):
                yn = yn - N @ (V @ ((V.T @ (N.T @ (f + H @ yn))) / lam))
        else:
            try:
                yn = yp + N @ np.linalg.solve(Hn, -(N.T @ (f + H @ yp)))
            except np.linalg.LinAlgError:
                return None
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
