"""One weighted QP (``method="weighted"``): the usual fast approximation of a hierarchy.

Level ``k``'s cost (weighted equality residual plus weighted squared inequality violation)
is multiplied by ``weight_ratio**k`` (default ``1e-3``: three decades per level) and all
levels are summed into one QP. Hard constraints and bounds stay hard. Lower levels leak
into higher ones by about ``weight_ratio``; use ``method="hierarchical"`` for strict
priorities.
"""

from __future__ import annotations

import numpy as np

from .problem import CompiledStack
from .reduced import FEAS_TOL, Reduced, within

__all__ = ["solve_weighted"]


def solve_weighted(
    P: CompiledStack,
    solver: str,
    regularization: float,
    weight_ratio: float,
    x_warm: np.ndarray | None = None,
) -> tuple[np.ndarray, Reduced, dict]:
    """Solve a compiled stack as one weighted QP. Returns ``(x, reduced, info)``."""
    R = Reduced(P.n, P.lb, P.ub, solver)
    R.hard_phase(P.hard)
    r = R.r
    x = R.x
    if r == 0:
        return x, R, {"qp_calls": R.qp_calls}
    H = np.zeros((r, r))
    f = np.zeros(r)
    Cs, los, his, sws = [], [], [], []
    beta = 1.0
    for L in P.levels:
        if L.m_eq:
            M = R.reduce(L.Ae)
            e = L.be - L.Ae @ x
            H += beta * (M.T @ M)
            f -= beta * (M.T @ e)
        if L.m_in:
            Cs.append(L.C)
            los.append(L.lo)
            his.append(L.hi)
            sws.append(np.sqrt(beta) * L.sw)
        beta *= weight_ratio
    H.flat[:: r + 1] += regularization
    # unconstrained optimum first: if it violates nothing it is the QP's optimum
    try:
        cho = np.linalg.cholesky(H)
        z = np.linalg.solve(cho.T, np.linalg.solve(cho, -f))
        xc = x + R.lift(z)
        ok = R.feasible(xc)
        if ok and Cs:
            for C, lo, hi in zip(Cs, los, his, strict=True):
                if not within(C @ xc, lo, hi, FEAS_TOL):
                    ok = False
                    break
    except np.linalg.LinAlgError:
        ok = False
    if ok:
        return xc, R, {"qp_calls": R.qp_calls}
    mi = sum(C.shape[0] for C in Cs)
    if mi:
        C = np.vstack(Cs)
        sw = np.concatenate(sws)
        Hy = np.zeros((r + mi, r + mi))
        Hy[:r, :r] = H
        Hy[r:, r:] = np.diag(sw**2)
        fy = np.concatenate((f, np.zeros(mi)))
        D = np.hstack((R.reduce(C), -np.eye(mi)))
        cx = C @ x
        dlo, dhi = np.concatenate(los) - cx, np.concatenate(his) - cx
    else:
        Hy, fy, D, dlo, dhi = H, f, None, None, None
    y0 = None
    if x_warm is not None:
        y0 = np.zeros(Hy.shape[0])
        dx = x_warm - x
        y0[:r] = dx if R.Z is None else R.Z.T @ dx
    y = R.solve_qp(Hy, fy, D, dlo, dhi, y0, where="weighted QP")
    return x + R.lift(y[:r]), R, {"qp_calls": R.qp_calls}
