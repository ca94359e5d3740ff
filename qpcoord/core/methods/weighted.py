"""One weighted QP (``method="weighted"``): the usual fast approximation of a hierarchy.

Level ``k``'s cost (weighted equality residual plus weighted squared inequality violation)
is multiplied by ``weight_ratio**k`` (default ``1e-3``: three decades per level) and all
levels are summed into one QP. Hard constraints and bounds stay hard. Lower levels leak
into higher ones by about ``weight_ratio``; use ``method="hierarchical"`` for strict
priorities.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

from ..compile import CompiledStack
from ..elimination import Reduced

__all__ = ["solve_weighted"]

#: ``H`` counts as singular when a Cholesky pivot² is under this fraction of its largest
#: diagonal entry: rounding-level pivots (~1e-16) of a rank-deficient ``H`` pass LAPACK's
#: test and then fail quadprog's; a level weighted ``weight_ratio**4 = 1e-12`` stays above.
_SINGULAR = 1e-14


def solve_weighted(
    P: CompiledStack,
    R: Reduced,
    regularization: float,
    weight_ratio: float,
    x_warm: np.ndarray | None = None,
) -> dict:
    """Solve a compiled stack as one weighted QP into the workspace ``R`` (already reset).

    Returns solve statistics; the solution is ``R.x``.
    """
    R.hard_phase(P.hard)
    r = R.r
    x = R.x
    if r == 0:
        return {"qp_calls": R.qp_calls, "retries": R.retries, "fallbacks": R.fallbacks}
    H = np.zeros((r, r))
    f = np.zeros(r)
    soft = []
    beta = 1.0
    hdiag = 0.0  # largest diagonal entry of the x-space Hessian Σ βₖ Aₖᵀ Aₖ
    dx = None
    for L in P.levels:
        if L.m_eq:
            M = R.reduce(L.Ae)
            e = L.be - L.Ae @ x
            H += beta * (M.T @ M)
            f -= beta * (M.T @ e)
            d = beta * np.einsum("ij,ij->j", L.Ae, L.Ae)
            dx = d if dx is None else dx + d
        if L.m_in:
            soft.append((L, np.sqrt(beta)))
        beta *= weight_ratio
    if dx is not None:
        hdiag = float(dx.max())
    # ε‖x‖² only where the levels leave H singular, as PersistentQP: with ε scaled by the
    # x-space Hessian and centred on x = 0 (not on the hard phase's point, in the reduced
    # coordinates, where 1e-9·max diag pulled a last level weighted 1e-6 by ~1 %: 2e-3 in x)
    cho, info = lapack.dpotrf(H, lower=0, clean=1)
    if info != 0 or float(cho.diagonal().min()) ** 2 <= _SINGULAR * max(
        float(H.diagonal().max()), 1e-300
    ):
        eps = regularization * max(1.0, hdiag)
        H.flat[:: r + 1] += eps
        f += eps * R.project(x)
        cho, info = lapack.dpotrf(H, lower=0, clean=1)
    # unconstrained optimum first: if it violates nothing it is the QP's optimum
    if info == 0:
        z, info = lapack.dpotrs(cho, -f, lower=0)
    if info == 0:
        xc = x + R.lift(z)
        if R.feasible(xc) and all(
            (L.C @ xc <= L.hiw).all() and (L.C @ xc >= L.low).all() for L, _ in soft
        ):
            R.move_to(xc, verified=True)
            return {"qp_calls": R.qp_calls, "retries": R.retries, "fallbacks": R.fallbacks}
    mi = sum(L.m_in for L, _ in soft)
    if mi:
        C = np.vstack([L.C for L, _ in soft])
        sw = np.concatenate([b * L.sw for L, b in soft])
        Hy = np.zeros((r + mi, r + mi))
        Hy[:r, :r] = H
        Hy[r:, r:] = np.diag(sw**2)
        fy = np.concatenate((f, np.zeros(mi)))
        D = np.hstack((R.reduce(C), -np.eye(mi)))
        cx = C @ x
        dlo = np.concatenate([L.lo for L, _ in soft]) - cx
        dhi = np.concatenate([L.hi for L, _ in soft]) - cx
    else:
        Hy, fy, D, dlo, dhi = H, f, None, None, None
    y0 = None
    if x_warm is not None:
        y0 = np.zeros(Hy.shape[0])
        y0[:r] = R.project(x_warm - x)
    y = R.solve_qp(Hy, fy, D, dlo, dhi, y0, where="weighted QP")
    R.move_to(x + R.lift(y[:r]), verified=False)
    return {"qp_calls": R.qp_calls, "retries": R.retries, "fallbacks": R.fallbacks}
