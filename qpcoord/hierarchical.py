"""Strict lexicographic hierarchy by variable elimination (``method="hierarchical"``).

Level ``k`` is solved in the null space of everything fixed above it (Kanoun et al. 2011;
Escande, Mansard & Wieber 2014):

1. its equality rows are projected, ``M = Ae Z``, and solved in closed form with the
   filtered pseudo-inverse of :mod:`qpcoord.linalg`; if the candidate satisfies the level's
   own inequalities, the inherited rows and the bounds, it is optimal and no QP is solved;
2. otherwise a QP in ``(z, w)`` is solved, where the slack ``w`` carries the violation of
   the level's inequality rows (``lo ≤ C x − w ≤ hi``, minimising ``Σ wᵢ·weightᵢ·wᵢ``
   together with the damped equality residual), under the inherited rows and bounds;
3. the optimum is frozen: the row space of ``M`` and the violated inequality rows are
   eliminated (``Z ← Z · null(F)``), the satisfied inequality rows are inherited as
   constraints for every lower level, and the optimal slacks never change again.

After the last level the remaining freedom is spent on the minimum-norm ``x`` (subject to
the inherited rows and bounds), so a single equality level without bounds gives ``A⁺b``.
"""

from __future__ import annotations

import numpy as np

from .linalg import filtered_svd
from .problem import CompiledStack
from .reduced import FEAS_TOL, Reduced, within

__all__ = ["solve_hierarchical"]

#: Relative threshold above which an inequality row's optimal slack counts as a violation
#: that is frozen as an equality for the lower levels.
VIOLATION_TOL = 1e-9


def solve_hierarchical(
    P: CompiledStack,
    solver: str,
    damping: float,
    regularization: float,
    x_warm: np.ndarray | None = None,
) -> tuple[np.ndarray, Reduced, dict]:
    """Solve a compiled stack lexicographically.

    Returns ``(x, reduced, info)``: the solution, the final elimination state (its
    inherited rows are what the returned ``x`` must satisfy) and solve statistics.

    Parameters
    ----------
    P : CompiledStack
    solver : str
        Backend for the QPs that closed forms cannot replace.
    damping : float
        Relative damping threshold (see :mod:`qpcoord.linalg`).
    regularization : float
        Weight of ``‖z‖²`` in directions a level does not determine (keeps each QP strictly
        convex; dimensionless, relative to a unit-weight task).
    x_warm : ndarray, optional
        A previous solution; its projection gives each level QP a primal start.
    """
    R = Reduced(P.n, P.lb, P.ub, solver)
    R.hard_phase(P.hard)
    ranks = []
    for k, L in enumerate(P.levels):
        where = f"level {k}"
        r = R.r
        x = R.x
        if r == 0:
            ranks.append(0)
            R.inherit(L.C, L.lo, L.hi)
            continue
        # ---- closed form for the equality rows --------------------------------------
        if L.m_eq:
            M = R.reduce(L.Ae)
            e = L.be - L.Ae @ x
            U, s, Vt, rank, g = filtered_svd(M, damping)
            tau = damping * s[0] if rank else 0.0
            z = Vt[:rank].T @ (g * (U[:, :rank].T @ e))
            xc = x + R.lift(z)
        else:
            rank = 0
            Vt = None
            xc = x
        ok = R.feasible(xc)
        if ok and L.m_in:
            ok = within(L.C @ xc, L.lo, L.hi, FEAS_TOL)
        if ok:
            R.move_to(xc)
            if rank:
                R.restrict(Vt[rank:].T)
            R.inherit(L.C, L.lo, L.hi)
            ranks.append(rank)
            continue
        # ---- QP with slacks --------------------------------------------------------
        mi = L.m_in
        kdim = r + mi
        H = np.zeros((kdim, kdim))
        f = np.zeros(kdim)
        if rank:
            d = np.full(r, regularization)
            d[:rank] = np.maximum(s[:rank] ** 2, tau * tau)
            H[:r, :r] = (Vt.T * d) @ Vt
            f[:r] = -(M.T @ e)
        else:
            H[:r, :r] = regularization * np.eye(r)
        if mi:
            H[r:, r:] = np.diag(L.sw**2)
            D = np.hstack((R.reduce(L.C), -np.eye(mi)))
            cx = L.C @ x
            dlo, dhi = L.lo - cx, L.hi - cx
        else:
            D = dlo = dhi = None
        y0 = None
        if x_warm is not None:
            y0 = np.zeros(kdim)
            dx = x_warm - x
            y0[:r] = dx if R.Z is None else R.Z.T @ dx
        y = R.solve_qp(H, f, D, dlo, dhi, y0, where=where)
        z, w = y[:r], y[r:]
        R.move_to(x + R.lift(z))
        F = [Vt[:rank]] if rank else []
        if mi:
            scale = np.maximum(1.0, np.maximum(np.abs(np.where(np.isfinite(L.lo), L.lo, 0.0)),
                                               np.abs(np.where(np.isfinite(L.hi), L.hi, 0.0))))
            viol = np.abs(w) > VIOLATION_TOL * scale
            if viol.any():
                F.append(D[viol, :r])
            keep = ~viol
            R.inherit(L.C[keep], L.lo[keep], L.hi[keep])
        if F:
            R.freeze(np.vstack(F) if len(F) > 1 else F[0])
        ranks.append(r - R.r)
    # ---- remaining freedom: minimum-norm x ----------------------------------------
    r = R.r
    if r:
        x = R.x
        if R.Z is None:
            xc = np.zeros(P.n) if R.lb is None else np.clip(np.zeros(P.n), R.lb, R.ub)
            if not R.feasible(xc):
                xc = None
        else:
            xc = x - R.Z @ (R.Z.T @ x)
            if not R.feasible(xc):
                xc = None
        if xc is not None:
            R.x = xc
        else:
            f = x.copy() if R.Z is None else R.Z.T @ x
            y0 = None
            if x_warm is not None:
                dx = x_warm - x
                y0 = dx if R.Z is None else R.Z.T @ dx
            z = R.solve_qp(np.eye(r), f, y0=y0, where="minimum-norm step")
            R.move_to(x + R.lift(z))
    info = {"qp_calls": R.qp_calls, "level_ranks": ranks, "free_dofs": r}
    return R.x, R, info
