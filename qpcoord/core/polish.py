"""Active-set polishing of an approximate QP solution.

Interior-point, ADMM and augmented-Lagrangian backends return points that are optimal to
their tolerances (≈1e-8 … 1e-10), not to machine precision. In a strict hierarchy a level's
optimum is frozen for every lower level, so such errors propagate (measured:
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

import math

import numpy as np

from .linalg import numerical_rank, svd
from .tolerance import at_bounds, within

__all__ = ["polish", "prepare", "kkt_residual", "active_set_ls", "pull_back", "active_rank"]

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
_EPS = float(np.finfo(float).eps)


def active_rank(s: np.ndarray, shape: tuple[int, int], tol: float) -> int:
    """Rank of a guessed active set's rows (singular values ``s``, matrix of ``shape``)
    when rows within ``tol`` of a bound were taken as active: the numerical rank, and no
    singular value under ``tol`` of the largest. Rows dependent to within the activity
    tolerance are one constraint at that tolerance: their tiny singular value would turn
    the rows' ``tol``-level disagreement into an arbitrarily long step (Talos' support
    polygon: two hull edges parallel to 4e-10, a step of 1e7 that the level's value did not
    see; :func:`polish` on two rows parallel to 1e-10 whose bounds differ by 1e-9: a step
    of 10 along a direction of curvature 1e-9, within the objective's slack)."""
    if s.size == 0:
        return 0
    return min(numerical_rank(s, shape), int(np.count_nonzero(s > tol * s[0])))


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
        rank = active_rank(s, A.shape, tol)
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


# ---- certification and exact continuation of a least-squares level ---------------------
#
# A level of the hierarchy is ``min ½‖Q y − c‖²`` subject to ``lo ≤ G y ≤ hi`` (``Q`` the
# level's equality rows in the remaining freedom, with its damping rows and the weighted
# slacks of its inequality rows; ``G`` the inherited rows, the bounds and the level's own
# rows with their slacks). :func:`kkt_residual` checks its optimality conditions at a point;
# :func:`active_set_ls` solves it exactly by a primal active-set method started from a
# feasible point (the backend's answer, pulled back into the rows if needed).

#: Relative KKT residual (stationarity with sign-constrained multipliers, in the
#: column-equilibrated space, per unit of the level's residual norm) under which a level is
#: certified optimal.
KKT_TOL = 1e-9
#: Relative primal feasibility (to the row scale ``max(1, |bound|, ‖y‖∞)``, rows of unit norm)
#: certified point, and distance under which a row counts as active.
KKT_FEAS_TOL = 1e-9
#: A level whose residual norm is under this fraction of its scale ``‖c‖ + ‖Q y‖`` is
#: certified by its value (its objective cannot go below 0).
VALUE_TOL = 1e-10
#: Misses of a row (relative to ``max(1, |bound|)``) that :func:`pull_back` leaves alone: the
#: opening of the rows in the QPs of the active-set backends.
PULL_TOL = 1e-12
#: Iterations of :func:`active_set_ls`, per row and variable.
AS_ITER = 4
#: Relative singular value (to the largest) under which :func:`active_set_ls` counts a
#: direction of its working set's rows as dependent: the rule of the native dual active-set
#: solver for adding a row. A step along such a direction moves the rows by at most this
#: fraction of its length (rounding, 1000× under ``KKT_FEAS_TOL``); 1e-9 there let a step
#: leave a row by 0.36 of its scale.
AS_DEP_TOL = 1e-12


def _row_scale(Gn, lo, hi, y):
    ny = float(np.abs(y).max()) if y.size else 0.0
    b = np.maximum(
        np.where(np.isfinite(lo), np.abs(lo), 0.0), np.where(np.isfinite(hi), np.abs(hi), 0.0)
    )
    return np.maximum(np.maximum(b, ny), 1.0)


def _normalise_rows(G, lo, hi):
    """Rows of ``G`` scaled to unit norm (zero rows dropped) with their bounds."""
    if G.shape[0] == 0:
        return G, lo, hi
    nr = np.sqrt(np.einsum("ij,ij->i", G, G))
    keep = nr > 0.0
    nr = nr[keep]
    return G[keep] / nr[:, None], lo[keep] / nr, hi[keep] / nr


def _col_scale(Q, Gn):
    """Jacobi column scaling: ``1/max(‖Q_:j‖, ‖Gn_:j‖)`` (1 for an empty column)."""
    cq = np.sqrt(np.einsum("ij,ij->j", Q, Q)) if Q.shape[0] else np.zeros(Q.shape[1])
    cg = np.sqrt(np.einsum("ij,ij->j", Gn, Gn)) if Gn.shape[0] else np.zeros(Q.shape[1])
    c = np.maximum(cq, cg)
    c[c == 0.0] = 1.0
    return 1.0 / c


class Prepared:
    """A level's rows prepared once for its certificate (:func:`prepare`)."""

    __slots__ = ("Gn", "lo", "hi", "bscale", "norms", "S")

    def __init__(self, Gn, lo, hi, norms):
        self.Gn, self.lo, self.hi, self.norms = Gn, lo, hi, norms
        # the bound part of the row scale max(1, |bound|, ‖y‖∞): fixed for the level
        self.bscale = np.maximum(
            np.maximum(
                np.where(np.isfinite(lo), np.abs(lo), 0.0),
                np.where(np.isfinite(hi), np.abs(hi), 0.0),
            ),
            1.0,
        )
        self.S = None  # column scaling, computed by the first call that needs it

    def col_scale(self, Q):
        if self.S is None:
            self.S = _col_scale(Q, self.Gn)
        return self.S


def prepare(Q, G, lo, hi) -> Prepared:
    """The level's rows normalised to unit norm (with their norms and the bound part of
    their scale), computed once per level and passed to :func:`kkt_residual`,
    :func:`active_set_ls` and :func:`pull_back` as ``prepared`` (they would otherwise
    normalise the same rows at every call). The column scaling is left to the first call
    that needs it (a level met exactly does not)."""
    if G.shape[0] == 0:
        return Prepared(G, lo, hi, np.zeros(0))
    nr = np.sqrt(np.einsum("ij,ij->i", G, G))
    keep = nr > 0.0
    if keep.all():
        return Prepared(G / nr[:, None], lo / nr, hi / nr, nr)
    k = nr[keep]
    return Prepared(G[keep] / k[:, None], lo[keep] / k, hi[keep] / k, nr)


def _norm(v) -> float:
    return math.sqrt(float(v @ v))


def kkt_residual(Q, c, G, lo, hi, y, prepared=None, gap=False) -> tuple[float, float]:
    """Optimality of ``y`` for ``min ½‖Q y − c‖², lo ≤ G y ≤ hi``.

    Returns ``(stationarity, infeasibility)``, both dimensionless:

    - *infeasibility*: the largest violation of a row, relative to its scale
      ``max(1, |bound|, ‖y‖∞)`` after the rows are normalised to unit norm (the library's
      ``max(1, |bound|)`` rule);
    - *stationarity*: with the columns equilibrated (``S = diag(1/max(‖Q_:j‖, ‖G_:j‖))``,
      so that variables in any units count alike), the distance of the scaled gradient
      ``S Qᵀ(Q y − c)`` from the cone of the active rows' normals with multipliers of the
      right sign (non-negative least squares: dual sign and complementarity are part of it,
      only rows within ``KKT_FEAS_TOL`` of a bound may carry a multiplier), divided by
      ``max(‖Q y − c‖, 1e-8·(‖c‖ + ‖Q y‖))``.

    With ``gap=True`` complementarity is measured too: a multiplier ``μᵢ`` on a row ``sᵢ``
    short of its bound is an objective gap ``μᵢ·sᵢ``, and the NNLS also minimises
    ``‖μ∘s‖ / (‖c‖ + ‖Q y‖)`` and its residual counts it, so rows dependent to rounding
    cannot hold a point far along them with multipliers of ``‖g‖/σ``. The minimum-norm
    step asks for it (strictly convex: its optimum is unique, and a point far from it is
    wrong); a level's check does not, since on a least-squares level rows a rounding
    distance from their bounds with such multipliers also hold its exact points.

    A point with both under their tolerances (:data:`KKT_TOL`, :data:`KKT_FEAS_TOL`) is
    optimal up to an objective gap of order ``KKT_TOL²`` times the level's value in
    well-scaled directions (with ``gap``, plus the rows' gap ``Σ μᵢ·sᵢ``, under about
    ``KKT_TOL·‖Q y − c‖·(‖c‖ + ‖Q y‖)``). ``prepared`` (:func:`prepare` of the same
    ``Q, G, lo, hi``) saves the row normalisation; the verdict is the same.

    Cheap paths (same verdict): a level met to :data:`VALUE_TOL` of its scale is certified
    by its value (no column scaling, no NNLS); a gradient already under :data:`KKT_TOL`
    needs no NNLS (``μ = 0`` is a feasible multiplier).
    """
    if prepared is None:
        Gn, lon, hin = _normalise_rows(G, lo, hi)
        prepared = Prepared(Gn, lon, hin, None)
    Gn, lon, hin = prepared.Gn, prepared.lo, prepared.hi
    qy = Q @ y
    res = qy - c
    # a level met to rounding has a gradient of rounding noise: its floor is 1e-8 of the
    # level's scale ‖c‖ + ‖Q y‖, and one met to VALUE_TOL of it is certified by its value
    # (the objective is ≥ 0)
    nres = _norm(res)
    lscale = _norm(c) + _norm(qy)
    den = max(nres, 1e-8 * lscale, 1e-300)
    by_value = nres <= VALUE_TOL * max(1.0, lscale)  # the library's max(1, scale) rule
    infeas = 0.0
    if Gn.shape[0]:
        gy = Gn @ y
        ny = float(np.abs(y).max()) if y.size else 0.0
        sc = np.maximum(prepared.bscale, ny)
        # an infinite bound gives −inf here (y is finite)
        infeas = max(0.0, float((np.maximum(lon - gy, gy - hin) / sc).max()))
        if by_value:
            return 0.0, infeas  # met exactly: no column scaling, no NNLS
        S = prepared.col_scale(Q)
        gs = S * (Q.T @ res)
        # μ = 0 is a feasible multiplier: a gradient already under the tolerance certifies
        # the level without the NNLS (its residual can only be smaller)
        g0 = _norm(gs) / den
        if g0 <= KKT_TOL:
            return g0, infeas
        a_lo = gy - lon <= KKT_FEAS_TOL * sc  # False for an infinite bound
        a_hi = hin - gy <= KKT_FEAS_TOL * sc
        act = a_lo | a_hi
        if act.any():
            # g = Σ μ_i G_i, μ ≥ 0 at a lower bound, μ ≤ 0 at an upper bound (a row at
            # both, an equality, gets both columns)
            idx = np.concatenate((np.flatnonzero(a_lo), np.flatnonzero(a_hi)))
            sign = np.ones(idx.size)
            sign[int(a_lo.sum()) :] = -1.0
            B = (Gn[idx] * S).T * sign
            gmax = float(np.abs(gs).max())
            if gmax == 0.0:
                return 0.0, infeas
            from scipy.optimize import nnls

            if gap:
                # each μ_i weighted by s_i / lscale: the residual ‖(gs − Bμ, μ∘s / lscale)‖
                # / den measures the gap as the stationarity measures a move of the
                # level's scale (the LexLS humanoid's minimum-norm step: a point 8.7 from
                # the optimum, its rows 1e-13 past their bounds, was stationary with
                # μ = 1e14, a gap of 92)
                slack = np.abs(np.concatenate(((gy - lon)[a_lo], (hin - gy)[a_hi])))
                B = np.vstack((B, np.diag(slack / lscale)))
                gs = np.concatenate((gs, np.zeros(idx.size)))
            _mu, rn = nnls(B / gmax, gs / gmax, maxiter=50 * B.shape[1] + 50)
            return rn * gmax / den, infeas
        return g0, infeas
    if by_value:
        return 0.0, infeas
    return _norm(prepared.col_scale(Q) * (Q.T @ res)) / den, infeas


def pull_back(G, lo, hi, y, y_safe=None, norms=None):
    """The point of the segment from ``y_safe`` (default 0, feasible by assumption) to ``y``
    farthest along it that meets ``lo ≤ G y ≤ hi`` exactly (a ratio test on the rows ``y``
    violates: each row's half-space holds both ends of the segment otherwise)."""
    if G.shape[0] == 0:
        return y
    gy = G @ y
    # misses at the active-set backends' opening (1e-12·max(1, |bound|)) or at rounding
    # level are not violations
    if norms is None:
        norms = np.sqrt(np.einsum("ij,ij->i", G, G))
    tol = 1e-13 * norms * float(np.abs(y).max()) + PULL_TOL * (
        np.maximum(
            1.0,
            np.maximum(
                np.where(np.isfinite(lo), np.abs(lo), 0.0),
                np.where(np.isfinite(hi), np.abs(hi), 0.0),
            ),
        )
    )
    over, under = gy > hi + tol, gy < lo - tol
    if not (over.any() or under.any()):
        return y
    base = np.zeros_like(y) if y_safe is None else y_safe
    gb = G @ base
    gd = gy - gb
    t = 1.0
    if over.any():
        t = min(t, float(np.min((hi[over] - gb[over]) / gd[over])))
    if under.any():
        t = min(t, float(np.min((lo[under] - gb[under]) / gd[under])))
    return base + max(t, 0.0) * (y - base)


def active_set_ls(
    Q, c, G, lo, hi, y0, max_iter: int | None = None, prepared=None, exact_signs: bool = False
):
    """Solve ``min ½‖Q y − c‖², lo ≤ G y ≤ hi`` exactly from a feasible ``y0``.

    A primal active-set method (Nocedal & Wright, Alg. 16.3) on the least-squares form:
    each iteration solves the objective on the working set's null space in minimum-norm
    least squares (an SVD, no Hessian is formed: a semidefinite ``QᵀQ`` is fine), steps
    as far as the inactive rows allow, adds the blocking row, or, when the point is
    stationary on its working set, drops the row whose multiplier has the wrong sign.
    A multiplier counts as negative below ``−KKT_TOL·‖g‖∞``; with ``exact_signs`` below the
    rounding of the gradient only (``16·ε·k·‖Q‖·(‖|Q|·|y|‖ + ‖c‖)``, in the equilibrated
    variables), and a working set counts as solved when the step is at rounding, not when
    it gains under 1e-15 of the objective: for a damped level, whose damped directions
    have curvature ``τ²`` and gradients far under ``KKT_TOL``, so that a multiplier of
    1e-10, or a step gaining 1e-19, still moves the optimum along them by ~1. Without
    ``exact_signs`` a step gaining under 1e-15 of the objective that is not at rounding is
    still taken once per working set: on a level with a large residual (an unreachable
    posture, objective 72) a 4.5e-8 step gains only 1.8e-14.
    The working set's rank, and its multipliers, count singular values above
    :data:`AS_DEP_TOL` of the largest only: rows dependent to rounding are one constraint.
    Returns ``(y, converged)``; ``y`` is feasible whenever ``y0`` is (a row of the working
    set moves by at most ``AS_DEP_TOL`` of a step's length, in the equilibrated variables).
    """
    k = y0.shape[0]
    if prepared is None:
        Gn, lon, hin = _normalise_rows(G, lo, hi)
        S = _col_scale(Q, Gn)
    else:
        Gn, lon, hin = prepared.Gn, prepared.lo, prepared.hi
        S = prepared.col_scale(Q)
    m = Gn.shape[0]
    y = y0.astype(float).copy()
    Qs = Q * S  # work in the equilibrated variables u = y / S
    Gs = Gn * S
    u = y / S
    if max_iter is None:
        max_iter = AS_ITER * (m + k) + 10
    eq = np.isfinite(lon) & (lon == hin)
    gy = Gn @ y if m else np.zeros(0)
    sc = _row_scale(Gn, lon, hin, y) if m else np.zeros(0)
    W_lo = np.isfinite(lon) & (gy - lon <= KKT_FEAS_TOL * sc)
    W_hi = np.isfinite(hin) & (hin - gy <= KKT_FEAS_TOL * sc) & ~W_lo
    W_lo |= eq
    cn = float(np.linalg.norm(c))
    finished = False  # the current working set's sub-threshold step was taken
    for _ in range(max_iter):
        W = W_lo | W_hi
        if W.any():
            Uw, sw, Vw = svd(Gs[W], full=True)
            # rows dependent to rounding (their combination's singular value ~1e-14) are
            # one constraint: counted as more, they fill the null space and leave a point
            # "stationary" that only multipliers of ‖g‖/σ hold (the LexLS humanoid's
            # minimum-norm step from a pulled-back point: 0.2–18 from its optimum)
            rw = active_rank(sw, Gs[W].shape, AS_DEP_TOL)
            N = Vw[rw:].T
        else:
            N = np.eye(k)
        res = Qs @ u - c
        if N.shape[1]:
            K = Qs @ N
            Uk, sk, Vk = svd(K, full=False)
            rk = numerical_rank(sk, K.shape)
            step = N @ (Vk[:rk].T @ ((Uk[:, :rk].T @ -res) / sk[:rk])) if rk else np.zeros(k)
        else:
            step = np.zeros(k)
        # stationary on W when the step no longer decreases the objective measurably
        dres = Qs @ step
        gain = -(2.0 * float(res @ dres) + float(dres @ dres))
        if exact_signs:  # on a damped direction a step gaining 1e-19 can still move y
            stationary = gain <= 0.0 or float(np.abs(step).max()) <= 8.0 * _EPS * max(
                1.0, float(np.abs(u).max())
            )
        else:
            stationary = gain <= 1e-15 * max(float(res @ res), 1e-30 * cn * cn)
            if (
                stationary
                and not finished
                and float(np.abs(step).max()) > 8.0 * _EPS * max(1.0, float(np.abs(u).max()))
            ):
                # the step gains under 1e-15 of a large objective but is no rounding (a
                # residual of 8.5 hides a 4.5e-8 step, tests/core/test_talos_joint_limit_
                # oracle.py): take it, once per working set (a noisy step cannot cycle)
                stationary = False
                finished = True
        if stationary or not np.any(step):
            g = Qs.T @ res
            if not W.any():
                return u * S, True
            idx = np.flatnonzero(W)
            sign = np.where(W_lo[idx], 1.0, -1.0)
            # the multipliers on the same rank (a least-squares solve to machine precision
            # would divide g's rounding along the dependent directions by their σ)
            mu = sign * (Uw[:, :rw] @ ((Vw[:rw] @ g) / sw[:rw]))
            mu[eq[idx]] = np.inf  # equalities are never dropped
            j = int(np.argmin(mu))
            gref = max(float(np.abs(g).max()), 1e-300)
            if exact_signs:
                # the rounding of res = Qs u − c is at most k·ε·(|Qs| |u|) + ε|c| entrywise:
                # |Qs| |u|, not ‖Qs‖·‖u‖∞ (a level's slack rows do not read z, whose entries
                # at the box, 1e3, made the bound 500× its size and hid multipliers of -2e-10
                # of a level whose gains along a 3e-8 direction are ~1e-9)
                qn = float(np.linalg.norm(Qs))
                thr = 16.0 * _EPS * k * qn * (float(np.linalg.norm(np.abs(Qs) @ np.abs(u))) + cn)
            else:
                thr = KKT_TOL * gref
            if mu[j] >= -thr:
                return u * S, True
            W_lo[idx[j]] = W_hi[idx[j]] = False
            finished = False
            continue
        # ratio test on the rows outside the working set
        if m:
            gp = Gs @ step
            gu = Gs @ u
            tiny = 1e-13 * float(np.abs(step).max())
            with np.errstate(divide="ignore", invalid="ignore"):
                t_hi = np.where(~W & (gp > tiny), (hin - gu) / gp, np.inf)
                t_lo = np.where(~W & (gp < -tiny), (lon - gu) / gp, np.inf)
            t_hi = np.maximum(t_hi, 0.0)
            t_lo = np.maximum(t_lo, 0.0)
            jh, jl = int(np.argmin(t_hi)), int(np.argmin(t_lo))
            alpha = min(1.0, float(t_hi[jh]), float(t_lo[jl]))
        else:
            alpha = 1.0
        u = u + alpha * step
        if alpha < 1.0:
            finished = False
            if t_hi[jh] <= t_lo[jl]:
                W_hi[jh] = True
            else:
                W_lo[jl] = True
    return u * S, False
