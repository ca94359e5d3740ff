"""One weighted QP (``method="weighted"``): the usual fast approximation of a hierarchy.

Level ``k``'s cost (weighted equality residual plus weighted squared inequality violation)
is multiplied by ``weight_ratio**k`` (default ``1e-3``: three decades per level) and all
levels are summed into one QP. Hard constraints and bounds stay hard. Lower levels leak
into higher ones by about ``weight_ratio``; use ``method="hierarchical"`` for strict
priorities.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack, solve_triangular

from ..compile import CompiledStack
from ..elimination import WHITENED, Reduced
from ..errors import SolverError

__all__ = ["solve_weighted"]

#: ``H = WᵀW`` (``W``: the levels' equality rows in ``z``, row ``i`` of level ``k`` scaled by
#: ``√(weight_ratioᵏ)``) counts as singular when a diagonal entry² of the triangular factor
#: ``R`` of a Householder QR of ``W`` (``RᵀR = H``: the same numbers as ``H``'s Cholesky pivots)
#: is at most this fraction of ``H``'s largest diagonal entry (``W``'s largest squared column
#: norm), i.e. ``|Rₖₖ| ≤ 1e-7·max‖W col‖`` (units of ``W``: residual per unit ``z``); or when
#: ``W`` has fewer rows than ``z`` has entries. ``R`` is computed from ``W`` itself, not from
#: ``H``: a rank-deficient ``W`` gives ``|Rₖₖ|`` at rounding, ~1e-16·‖W‖, 9 decades under the
#: threshold, where the Cholesky pivots of the formed ``H`` carry its rounding ~√ε·‖W‖ = 1.5e-8
#: ·‖W‖ (a factor ~7 under it: 1–5 of 50 exactly singular ``H`` passed as regular).
#: A level weighted ``weight_ratio**4 = 1e-12`` (unit rows: ``|Rₖₖ|² ≈ 1e-12``) is regular.
#: The native engine (``src/native/weighted.cpp``) applies the same rule to its own QR.
_SINGULAR = 1e-14


def _qr(W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """LAPACK's Householder QR of ``W`` (``dgeqrf``: ``R`` on and above the diagonal)."""
    qr, tau, _work, info = lapack.dgeqrf(W)
    if info != 0:
        raise ValueError(f"dgeqrf: illegal argument {-info}")
    return qr, tau


def _lstsq(qr: np.ndarray, tau: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """The least-squares solution ``R⁻¹ g`` from :func:`_qr`'s factors, ``g = (Qᵀ rhs)[:r]``:
    returns ``(z, g, info)``."""
    r = qr.shape[1]
    qtc, _work, info = lapack.dormqr("L", "T", qr, tau, rhs, max(1, 2 * r))
    if info != 0:
        return rhs[:r], rhs[:r], info
    z, info = lapack.dtrtrs(qr[:r, :r], qtc[:r], lower=0)
    return z, qtc[:r], info


def _singular(W: np.ndarray, r: int) -> tuple[bool, tuple[np.ndarray, np.ndarray] | None]:
    """The decision of :data:`_SINGULAR` on the stacked weighted rows ``W`` (m × r), with
    :func:`_qr`'s factors of ``W`` (``None`` when it has fewer rows than columns)."""
    if W.shape[0] < r:
        return True, None
    hmax = max(float(np.einsum("ij,ij->j", W, W).max()), 1e-300)
    qr, tau = _qr(W)
    d = np.abs(qr.diagonal()[:r])
    return bool(not np.all(np.isfinite(d)) or float(d.min()) ** 2 <= _SINGULAR * hmax), (qr, tau)


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
        return _stats(R, False)
    H = np.zeros((r, r))
    f = np.zeros(r)
    soft = []
    beta = 1.0
    hdiag = 0.0  # largest diagonal entry of the x-space Hessian Σ βₖ Aₖᵀ Aₖ
    dx = None
    W, c = [], []  # the weighted rows √βₖ Mₖ (H = WᵀW) and their targets √βₖ eₖ
    for L in P.levels:
        if L.m_eq:
            M = R.reduce(L.Ae)
            e = L.be - L.Ae @ x
            W.append(np.sqrt(beta) * M)
            c.append(np.sqrt(beta) * e)
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
    # the decision on the R of W's QR (no squaring); the unconstrained optimum is the
    # least-squares solution of W z = c from that QR (with ε: of [W; √ε I] z = [c; −√ε Zᵀx̄]),
    # not H⁻¹f: forming H and f costs ~ε_machine·cond(H) in z, the QR ε_machine·cond(W) =
    # ε_machine·√cond(H) (the Talos weighted IK: cond(H) ~ 1e12), and with ε along H's null
    # space ε_machine‖W‖²/ε (2e-7)
    Wm = np.vstack(W) if W else np.zeros((0, r))
    cm = np.concatenate(c) if c else np.zeros(0)
    regularized, fac = _singular(Wm, r)
    if regularized:
        eps = regularization * max(1.0, hdiag)
        zc = R.project(x)
        H.flat[:: r + 1] += eps
        f += eps * zc
        se = np.sqrt(eps)
        fac = _qr(np.vstack((Wm, se * np.eye(r))))
        cm = np.concatenate((cm, -se * zc))
    assert fac is not None  # _singular's factors, or those of the regularised rows
    z, g, info = _lstsq(*fac, cm)
    if info == 0:
        xc = x + R.lift(z)
        if R.feasible(xc) and all(
            (L.C @ xc <= L.hiw).all() and (L.C @ xc >= L.low).all() for L, _ in soft
        ):
            R.move_to(xc, verified=True)
            return _stats(R, regularized)
    # the QP in u = T z (T the triangular factor above, TᵀT = H): ½‖u‖² − gᵀu, the
    # identity as u's Hessian; the rows in z become rows in u through T⁻¹ (solve_qp's T);
    # for the dual active-set backends (WHITENED), the others get the formed H.
    # Its errors are ε_machine·cond(T) = ε_machine·√cond(H), not ε_machine·cond(H) as
    # with the formed H (the Talos / Panda weighted IK at weight_ratio 1e-3: x within
    # 2e-3 of the optimum before; a zero pivot, info ≠ 0, keeps the formed H)
    T = np.triu(fac[0][:r, :r]) if info == 0 and R.solver in WHITENED else None
    mi = sum(L.m_in for L, _ in soft)
    D = dlo = dhi = sw2 = None
    if mi:
        C = np.vstack([L.C for L, _ in soft])
        sw2 = np.concatenate([b * L.sw for L, b in soft]) ** 2
        D = np.hstack((R.reduce(C), -np.eye(mi)))
        cx = C @ x
        dlo = np.concatenate([L.lo for L, _ in soft]) - cx
        dhi = np.concatenate([L.hi for L, _ in soft]) - cx
    z0 = None if x_warm is None else R.project(x_warm - x)
    if T is not None:
        try:
            u = _solve_qp(R, np.eye(r), -g, sw2, D, dlo, dhi, None if z0 is None else T @ z0, T)
        except SolverError:
            # no whitened backend solved it: the QP in z, with the formed H and every
            # fallback, as for the other backends
            u = None
        if u is not None:
            R.move_to(x + R.lift(solve_triangular(T, u, lower=False)), verified=False)
            return _stats(R, regularized)
    z = _solve_qp(R, H, f, sw2, D, dlo, dhi, z0, None)
    R.move_to(x + R.lift(z), verified=False)
    return _stats(R, regularized)


def _solve_qp(
    R: Reduced,
    Hz: np.ndarray,
    fz: np.ndarray,
    sw2: np.ndarray | None,
    D: np.ndarray | None,
    dlo: np.ndarray | None,
    dhi: np.ndarray | None,
    v0: np.ndarray | None,
    T: np.ndarray | None,
) -> np.ndarray:
    """The weighted QP in ``v = (z or u = T z, w)``: ``½vᵀHzv + fzᵀv`` plus the squared
    violations ``Σ sw2·w²`` of the soft rows ``dlo ≤ D (z, w) ≤ dhi``; returns ``v[:r]``."""
    r = Hz.shape[0]
    if sw2 is None:
        Hy, fy = Hz, fz
    else:
        mi = sw2.shape[0]
        Hy = np.zeros((r + mi, r + mi))
        Hy[:r, :r] = Hz
        Hy[r:, r:] = np.diag(sw2)
        fy = np.concatenate((fz, np.zeros(mi)))
    y0 = None
    if v0 is not None:
        y0 = np.zeros(Hy.shape[0])
        y0[:r] = v0
    return R.solve_qp(Hy, fy, D, dlo, dhi, y0, where="weighted QP", T=T)[:r]


def _stats(R: Reduced, regularized: bool) -> dict:
    """Solve statistics; ``regularized``: was ``ε‖x‖²`` added (:data:`_SINGULAR`)?"""
    return {
        "qp_calls": R.qp_calls,
        "retries": R.retries,
        "fallbacks": R.fallbacks,
        "regularized": regularized,
    }
