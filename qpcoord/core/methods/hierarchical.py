"""Strict lexicographic hierarchy by variable elimination (``method="hierarchical"``).

Level ``k`` is solved in the null space of everything fixed above it (Kanoun et al. 2011;
Escande, Mansard & Wieber 2014):

1. its equality rows are projected, ``M = Ae Z``, and solved in closed form with the
   filtered pseudo-inverse of :mod:`qpcoord.core.linalg`; if the candidate satisfies the level's
   own inequalities, the inherited rows and the bounds, it is optimal and no QP is solved;
2. otherwise a QP in ``(z, w)`` is solved, where the slack ``w`` carries the violation of
   the level's inequality rows (``lo ≤ C x − w ≤ hi``, minimising ``Σ weightᵢ·wᵢ²``
   together with the damped equality residual), under the inherited rows and bounds;
3. the optimum is frozen: the row space of ``M`` and the violated inequality rows are
   eliminated (``Z ← Z · null(F)``), the satisfied inequality rows are inherited as
   constraints for every lower level, and the optimal slacks never change again.

After the last level the remaining freedom is spent on the minimum-norm ``x`` (subject to
the inherited rows and bounds), so a single equality level without bounds gives ``A⁺b``.

Tolerances. In a level's QP each inequality row that ``z`` can move is normalised to a
unit row in ``z`` (its slack in units of ``z``) and the objective is scaled so that the
level's largest curvature is 1; ``regularization·‖z‖²`` is added in the directions the
level's equalities leave free. A row counts as violated (and is frozen as an equality) when
its slack exceeds ``VIOLATION_TOL`` times the row's scale (``max(|bounds|, ‖Cᵢ‖·‖x‖)``); a
row below that stays an inequality whose bounds are opened to its current value, so lower
levels can never make it worse. The regularisation biases a row's violation by about
``regularization × (largest / its own curvature)``: below ``VIOLATION_TOL`` unless the
curvatures in one level spread over more than 10³ (row norms over ~30×).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import qr

from ..compile import CompiledStack
from ..elimination import MOVABLE_TOL, Reduced
from ..linalg import filtered_svd, numerical_rank, svd
from ..polish import (
    KKT_FEAS_TOL,
    KKT_TOL,
    PULL_TOL,
    active_rank,
    active_set_ls,
    kkt_residual,
    prepare,
    pull_back,
)
from ..tolerance import at_bounds

__all__ = [
    "solve_hierarchical",
    "solve_equality_chain",
    "VIOLATION_TOL",
]

#: Relative slack (to the row's scale) above which an inequality row is frozen as violated.
VIOLATION_TOL = 1e-6
#: The equality-row factors of a level without equality rows (rank 0: never read)
_NO_ROWS: np.ndarray = np.zeros((0, 0))
#: Relative distances to a bound under which the refinement takes a row as active: the
#: first guess, then a looser one for backends that stop ~1e-6 short (SCS).
ACTIVE_TOL = (1e-7, 1e-5)
#: Relative objective increase the refinement may cost over the QP's own point.
REFINE_SLACK = 1e-7
#: A level whose projected equality rows have a singular value under this fraction of the
#: largest (curvature under 1e-6 of the largest), or a damped one, is finished exactly after
#: its certificate (:class:`_Certifier`): along such a direction a point certified to
#: ``KKT_TOL`` can be far from the optimum, and the freeze passes it on.
ILL_CONDITIONED = 1e-3
_ABS_FLOOR = 1e-14
#: A certified level point farther from the origin of the level's step than this many times
#: the minimum-norm point of the level's optimal set is replaced by that point
#: (:meth:`_Certifier.near`): VIOLATION_TOL / KKT_FEAS_TOL. The lower levels' feasibility
#: and activity tolerances are ``KKT_FEAS_TOL`` relative to ``‖x‖``; beyond this ratio they
#: exceed ``VIOLATION_TOL`` of the minimum-norm point's scale, the threshold at which the
#: level's own rows were classified.
FAR_RATIO = VIOLATION_TOL / KKT_FEAS_TOL


def _independent_rank(A: np.ndarray, U: np.ndarray, s: np.ndarray, rank: int, scale: float):
    """The rank of a level's ``M = A Z`` (SVD ``U, s``, numerical rank ``rank``) without the
    directions in which the level's rows are dependent to within :data:`MOVABLE_TOL` of the
    rows they combine: a left singular vector ``uᵢ`` with ``sᵢ ≤ MOVABLE_TOL·Σⱼ|uᵢⱼ|·‖Aⱼ‖``
    is a combination of the rows that only rounding keeps (each row's projection carries an
    error of ``ε·κ`` times its own norm, so a combination's carries ``ε·κ·Σⱼ|uᵢⱼ|·‖Aⱼ‖``:
    ≤ 2e-9 of it for ``κ`` up to ``1/damping`` = 1e7). Such a direction is left to the lower
    levels, as an exactly dependent one is, instead of being damped and frozen. Two cases:
    the combination lies in the frozen rows' span (``‖Aᵀuᵢ‖`` itself is large: Talos with
    targets at 1e5, the CoM level below a support polygon that already pins the CoM froze 2
    directions of ~1e-13 and the posture level below ended 1.6 %–8 % above its optimum;
    ``tests/data/talos_extreme_feet_*.npz``), or the level's own rows nearly cancel (rows
    parallel to ~1e-10: ``‖Aᵀuᵢ‖`` is as small as ``sᵢ``; the point kept along that direction
    is set by gradients under ``KKT_TOL`` and decides the lower levels: a level below ended
    340× above its optimum). The inequality rows' :func:`_drop_dependent` applies the same
    measure (rows scaled by their own norms). Only ``sᵢ ≤ MOVABLE_TOL·scale`` can qualify
    (``Σⱼ|uᵢⱼ|·‖Aⱼ‖ ≤ ‖A‖_F = scale`` for a unit ``uᵢ``)."""
    norms = None
    for i in range(rank):
        if s[i] > MOVABLE_TOL * scale:
            continue
        if norms is None:
            norms = np.sqrt(np.einsum("ij,ij->i", A, A))
        if s[i] <= MOVABLE_TOL * float(np.abs(U[:, i]) @ norms):
            return i
    return rank


def _drop_dependent(D: np.ndarray, norms: np.ndarray) -> tuple[np.ndarray, float]:
    """The projected rows ``D`` (rows ``Cᵢ Z`` of rows of norms ``norms``) without the
    directions in which they are dependent to within :data:`MOVABLE_TOL` of their own norms:
    each row projected on the span of the pivot rows of a pivoted QR of the rows scaled to
    ``Dᵢ / ‖Cᵢ‖``, stopped at the first pivot whose distance to the span of the previous
    ones is at most ``MOVABLE_TOL`` (the per-row movable test generalised to the rows
    together). The Talos support polygon is a function of the CoM and the feet; with the
    feet frozen by an ill-conditioned level its 6 projected rows have rank 2 plus singular
    values ~1e-13, and stepping along those (the native engine: to ``y`` = 1e17) is a step
    along rounding. Returns ``(D, pivot)``: ``D`` itself when nothing is dropped, and the
    last pivot kept (one row: ``‖D₀‖ / ‖C₀‖``), under :data:`ILL_CONDITIONED` an
    ill-conditioned level (the native engine's ``drop_dependent_directions``, whose Gram
    screen proves the pivots above it without the QR)."""
    m, r = D.shape
    if m == 1 or r == 0:
        return D, float(np.linalg.norm(D[0]) / norms[0]) if r else 0.0
    Q, Rf, _ = qr(D.T / norms, mode="economic", pivoting=True)
    d = np.abs(np.diag(Rf))
    rank = int(np.argmax(d <= MOVABLE_TOL)) if (d <= MOVABLE_TOL).any() else d.size
    last = float(d[rank - 1]) if rank else 0.0
    if rank >= min(m, r):
        return D, last
    Qr = Q[:, :rank]
    return (D @ Qr) @ Qr.T, last


def _finite_abs(v: np.ndarray) -> np.ndarray:
    a = np.abs(v)
    a[~np.isfinite(a)] = 0.0
    return a


def _level_objective(A, b, z) -> float:
    """Level objective on the least-squares rows (equalities, damping, violated rows)."""
    if A is None:
        return 0.0
    res = A @ z - b
    return float(res @ res)


def _refine(R: Reduced, L, x, z0, ls_rows, ls_rhs, viol_rows):
    """Try :func:`_refine_at` with each active-set tolerance in turn (the level's
    least-squares rows stacked once)."""
    if ls_rows:
        A = ls_rows[0] if len(ls_rows) == 1 else np.vstack(ls_rows)
        b = ls_rhs[0] if len(ls_rhs) == 1 else np.concatenate(ls_rhs)
        nA = float(np.linalg.norm(A))
    else:
        A = b = None
        nA = 0.0
    before = _level_objective(A, b, z0)
    for tol in ACTIVE_TOL:
        z = _refine_at(R, L, x, z0, A, b, nA, before, viol_rows, tol)
        if z is not None:
            return z
    return None


def _refine_at(R: Reduced, L, x, z0, A, b, nA, before, viol_rows, tol):
    """Solve the level exactly on the active set of the QP's point ``x + Z z0``.

    Active inherited rows, bounds and satisfied level rows at a bound become equalities;
    the level's equality rows (with their damping rows) and its violated rows are solved
    in least squares on what remains, minimum-norm. Returns the refined ``z``, or ``None``
    if the guess is inconsistent, infeasible or no better than the QP's point.
    """
    r = z0.shape[0]
    xn0 = x + R.lift(z0)
    E, t = [], []
    if R.k:
        Cin, cl, ch = R.Cin, R.lin, R.uin
        if R.n_dependent:  # (rows that are no longer constraints: Reduced.drop_dependent)
            keep = ~R.dependent
            Cin, cl, ch = Cin[keep], cl[keep], ch[keep]
        a_lo, a_hi = at_bounds(Cin @ xn0, cl, ch, tol)
        if a_lo.any() or a_hi.any():
            act = a_lo | a_hi
            E.append(R.reduce(Cin[act]))
            t.append(np.where(a_lo, cl, ch)[act] - Cin[act] @ x)
    if R.lb is not None and R.ub is not None:
        a_lo, a_hi = at_bounds(xn0, R.lb, R.ub, tol)
        if a_lo.any() or a_hi.any():
            act = a_lo | a_hi
            E.append(R.Z[act] if R.Z is not None else np.eye(r)[act])
            t.append(np.where(a_lo, R.lb, R.ub)[act] - x[act])
    sat = ~viol_rows
    if L.m_in and sat.any():
        Cs = L.C[sat]
        a_lo, a_hi = at_bounds(Cs @ xn0, L.lo[sat], L.hi[sat], tol)
        if a_lo.any() or a_hi.any():
            act = a_lo | a_hi
            E.append(R.reduce(Cs[act]))
            t.append(np.where(a_lo, L.lo[sat], L.hi[sat])[act] - Cs[act] @ x)
    if E:
        Em = np.vstack(E)
        tv = np.concatenate(t)
        U, s, Vt = svd(Em, full=True)
        # active rows dependent to within the activity tolerance are one constraint at that
        # tolerance (polish.active_rank)
        rk = active_rank(s, Em.shape, tol)
        zp = Vt[:rk].T @ ((U[:, :rk].T @ tv) / s[:rk])
        if not np.isfinite(zp).all() or np.abs(Em @ zp - tv).max() > 1e-9 * max(
            1.0, float(np.abs(tv).max())
        ):
            return None
        N = Vt[rk:].T
    else:
        zp = np.zeros(r)
        N = np.eye(r)
    if N.shape[1] and A is not None:
        K = A @ N
        U, s, Vt = svd(K, full=False)
        rk = numerical_rank(s, K.shape, nA)
        if rk:
            # the library never prints: an overflow here is caught by the check below
            with np.errstate(all="ignore"):
                u = Vt[:rk].T @ ((U[:, :rk].T @ (b - A @ zp)) / s[:rk])
                zp = zp + N @ u
    xn = x + R.lift(zp)
    if not np.isfinite(xn.sum()) or not R.feasible(xn):
        return None
    if L.m_in and sat.any():
        c = L.C[sat] @ xn
        if not ((c <= L.hiw[sat]).all() and (c >= L.low[sat]).all()):
            return None
    after = _level_objective(A, b, zp)
    # the QP's point may sit outside the rows by the opening RELAX and gain ~RELAX from it
    if after > before + max(REFINE_SLACK, 10.0 * R.used_relax) * max(1.0, before):
        return None
    return zp


class _Certifier:
    """Certify a level's point, and make it exact where it is not.

    The level, in ``y = (z, w)`` (``w`` the slacks of its movable inequality rows, in the
    rows' own units), is ``min ½‖Q y − c‖²`` under the inherited rows, the bounds and its own
    rows ``dlo ≤ D z − w ≤ dhi``, none of them opened: ``Q`` holds the projected equality rows
    ``M``, the damping rows ``√(τ² − s²)·vᵢᵀ`` of the damped directions (the damping is
    part of the level's objective: a damped level is certified as the damped problem it
    is) and ``diag(√weight)`` on the slacks (not the QP's slacks in units of ``z``,
    ``w / ‖Dᵢ‖``: a row nearly dependent on the frozen ones, ``‖Dᵢ‖`` = 1e-9, has a slack of
    ~1e9 there, whose rounding hid the level's last multipliers from the exact finish). The
    regularisation of the QP is not: the certificate is of the level's own problem.

    :meth:`run` tries the candidate points in turn (pulled back into the rows if a backend
    left them by its tolerance), then the exact active-set continuation from the best one,
    then each fallback backend's QP point (with the continuation). Returns the first
    certified point, else the best feasible one with ``ok = False``.

    On a damped or ill-conditioned level (:data:`ILL_CONDITIONED`) a certified point is
    finished exactly too (:meth:`_exact`): a damped direction's curvature is only ``τ²``
    (1e-14 of the level's largest at the default damping), a near-singular one's ``s²``, so
    a point certified to ``KKT_TOL`` can lie far along it (anywhere in the box, damped), and
    the freeze would pass that point on to every lower level (a level below then got
    1.42 instead of the exact 3.89). The exact point, unique in the frozen directions, is
    kept if certified and no worse.
    """

    def __init__(self, R, r, rank, M, e, s, tau, Vt, mv, Dm, dlo, dhi, wdiag):
        self.R, self.r, self.mv = R, r, mv
        kdim = r + mv
        blocks, rhs = [], []
        self.exact = False  # finish certified points exactly (ILL_CONDITIONED)
        if rank:
            blocks.append(np.hstack((M, np.zeros((M.shape[0], mv)))) if mv else M)
            rhs.append(e)
            self.exact = bool(s[rank - 1] < max(tau, ILL_CONDITIONED * s[0]))
            damped = s[:rank] < tau
            if damped.any():
                gain = np.sqrt(tau * tau - s[:rank][damped] ** 2)
                Dr = gain[:, None] * Vt[:rank][damped]
                blocks.append(np.hstack((Dr, np.zeros((Dr.shape[0], mv)))) if mv else Dr)
                rhs.append(np.zeros(Dr.shape[0]))
        if mv:
            blocks.append(np.hstack((np.zeros((mv, r)), np.diag(wdiag))))
            rhs.append(np.zeros(mv))
        self.Q = np.vstack(blocks) if blocks else np.zeros((0, kdim))
        self.c = np.concatenate(rhs) if rhs else np.zeros(0)
        self.Dm, self.dlo, self.dhi = Dm, dlo, dhi
        Dy = None if not mv else np.hstack((Dm, -np.eye(mv)))
        self.G, self.lo, self.hi = R.exact_rows(kdim, Dy, dlo, dhi)
        self.prep = prepare(self.Q, self.G, self.lo, self.hi)  # once per level
        self.y_safe = self._with_slacks(np.zeros(r))

    def _with_slacks(self, z):
        if not self.mv:
            return z
        dz = self.Dm @ z
        return np.concatenate((z, dz - np.clip(dz, self.dlo, self.dhi)))

    def _feasible_point(self, z):
        y = pull_back(
            self.G, self.lo, self.hi, self._with_slacks(z), self.y_safe, norms=self.prep.norms
        )
        return self._with_slacks(y[: self.r])

    def _obj(self, y):
        d = self.Q @ y - self.c
        return float(d @ d)

    def _check(self, y):
        st, infeas = kkt_residual(self.Q, self.c, self.G, self.lo, self.hi, y, self.prep)
        return st <= KKT_TOL and infeas <= KKT_FEAS_TOL, st

    def _working_set_solve(self, y):
        """``y`` moved to the exact minimiser of the level on the rows active at ``y``
        (as equalities): the minimum-norm least-squares step in their null space, in the
        equilibrated variables. :func:`active_set_ls` stops where a step gains less than
        1e-15 of the objective; along a damped direction (curvature ``τ²``) such a step
        can still move the point by ~1e-9, which the level's freeze would pass on."""
        prep = self.prep
        S = prep.col_scale(self.Q)
        u = y / S
        Gs = prep.Gn * S
        N = None
        if prep.Gn.shape[0]:
            gy = prep.Gn @ y
            tol = KKT_FEAS_TOL * np.maximum(prep.bscale, float(np.abs(y).max()))
            W = (gy - prep.lo <= tol) | (prep.hi - gy <= tol)
            if W.any():
                _U, sw, Vw = svd(Gs[W], full=True)
                N = Vw[numerical_rank(sw, Gs[W].shape) :].T
        Qs = self.Q * S
        K = Qs if N is None else Qs @ N
        if K.shape[1] == 0:
            return y
        Uk, sk, Vk = svd(K, full=False)
        rk = numerical_rank(sk, K.shape)
        if not rk:
            return y
        du = Vk[:rk].T @ ((Uk[:, :rk].T @ (self.c - Qs @ u)) / sk[:rk])
        return (u + (du if N is None else N @ du)) * S

    def _no_worse(self, y, kkt, cand):
        """``cand`` (made feasible) if it is certified and its objective is no worse than
        ``y``'s (to rounding), else ``y``; with the kept point's KKT residual."""
        yc = self._feasible_point(cand[: self.r])
        ok, kc = self._check(yc)
        o, oc = self._obj(y), self._obj(yc)
        if ok and oc <= o + 4.0 * np.finfo(float).eps * (o + float(self.c @ self.c)):
            return yc, kc
        return y, kkt

    def _exact(self, y, kkt):
        """A certified point ``y`` of an ill-conditioned level made exact: the active-set
        continuation with the multiplier signs to rounding, then the working-set solve,
        each kept only if certified and no worse."""
        ya, _conv = active_set_ls(
            self.Q, self.c, self.G, self.lo, self.hi, y, prepared=self.prep, exact_signs=True
        )
        self.R.continued += 1
        y, kkt = self._no_worse(y, kkt, ya)
        return self._no_worse(y, kkt, self._working_set_solve(y))

    def min_norm_point(self, y):
        """The minimum-norm point (in ``z``) of the level's optimal set, from its point ``y``:
        ``min ‖z‖²`` subject to the level's rows and ``Q y' = Q y`` (the least-squares
        optimal set is where ``Q y`` takes its unique optimal value; the slacks are fixed by
        it), by :func:`active_set_ls` from ``y`` (feasible)."""
        r, mv = self.r, self.mv
        Qn = np.hstack((np.eye(r), np.zeros((r, mv)))) if mv else np.eye(r)
        qy = self.Q @ y
        G = np.vstack((self.G, self.Q))
        ym, _conv = active_set_ls(
            Qn, np.zeros(r), G, np.concatenate((self.lo, qy)), np.concatenate((self.hi, qy)), y
        )
        return ym

    def near(self, z, z_qp, x):
        """``(z, ok)``: the certified point ``z`` checked against the level's optimal set's
        minimum-norm point (:data:`FAR_RATIO`), replaced by that point if it is farther than
        the ratio allows and the replacement is certified and no worse; ``ok`` False if it
        is far and cannot be replaced.

        The certificate accepts any point of the optimal set; a point far out in it (the
        tip of a wedge of two nearly parallel active rows: a step of 1e7) is frozen
        with ``x`` and every lower level's tolerances scale with ``‖x‖``. The level's QP point
        ``z_qp`` (regularised towards ``z = 0``) is no longer than the minimum-norm point
        ``z*``; only when ``‖z‖ > FAR_RATIO · max(1, ‖x‖, ‖z_qp‖)`` is ``z*`` computed."""
        floor = max(1.0, float(np.linalg.norm(x)))
        nz = float(np.linalg.norm(z))
        if nz <= FAR_RATIO * max(floor, float(np.linalg.norm(z_qp))):
            return z, True
        y = self._with_slacks(z)
        ym = self.min_norm_point(y)
        if nz <= FAR_RATIO * max(floor, float(np.linalg.norm(ym[: self.r]))):
            return z, True
        ok, kkt = self._check(y)
        self.R.continued += 1
        yk, _ = self._no_worse(y, kkt, ym)
        if yk is y:  # ym is optimal for the far point's value of Q y: the level from there
            yc, _conv = active_set_ls(
                self.Q, self.c, self.G, self.lo, self.hi, ym, prepared=self.prep
            )
            yk, _ = self._no_worse(y, kkt, yc)
        if yk is y or float(np.linalg.norm(yk[: self.r])) > FAR_RATIO * floor:
            return z, False
        return yk[: self.r], True

    def run(self, candidates, H, f, Dy, where):
        best, best_obj, best_kkt = None, np.inf, np.inf
        for z in candidates:
            y = self._feasible_point(z)
            ok, kkt = self._check(y)
            if ok:
                if self.exact:
                    y, kkt = self._exact(y, kkt)
                return y[: self.r], True, kkt
            o = self._obj(y)
            if o < best_obj:
                best, best_obj, best_kkt = y, o, kkt
        # exact continuation from the best point, then from other backends' points
        starts = [best]
        alts = iter(self.R.alternatives())
        while starts:
            y0 = starts.pop()
            y, _conv = active_set_ls(
                self.Q, self.c, self.G, self.lo, self.hi, y0, prepared=self.prep
            )
            y = self._feasible_point(y[: self.r])
            ok, kkt = self._check(y)
            self.R.continued += 1
            if ok:
                if self.exact:
                    y, kkt = self._exact(y, kkt)
                return y[: self.r], True, kkt
            o = self._obj(y)
            if o < best_obj:
                best, best_obj, best_kkt = y, o, kkt
            for alt in alts:
                ya = self.R.solve_qp_with(alt, H, f, Dy, self.dlo, self.dhi, where)
                if ya is None:
                    continue
                self.R.fallbacks.append(f"{where}: {alt} (not certified)")
                ya = self._feasible_point(ya[: self.r])
                ok, kkt = self._check(ya)
                if ok:
                    return ya[: self.r], True, kkt
                o = self._obj(ya)
                if o < best_obj:
                    best, best_obj, best_kkt = ya, o, kkt
                starts.append(ya)
                break
        return best[: self.r], False, best_kkt


def _level_svd(L, M: np.ndarray, damping: float):
    """:func:`~qpcoord.core.linalg.filtered_svd` of a level's projected rows ``M = Ae Z``.

    A level that is exactly ``x = be`` (``L.identity``) has ``M = Z`` with orthonormal
    columns: singular values 1, ``U = M``, ``Vt = I`` — no SVD (the damping threshold
    ``τ = damping·√n`` stays below 1 unless the damping is huge).
    """
    n = L.Ae.shape[1]
    if L.identity and damping * np.sqrt(n) < 1.0:
        r = M.shape[1]
        one = np.ones(r)
        return M, one, np.eye(r), r, one, damping * float(np.sqrt(n))
    return filtered_svd(M, damping, float(np.sqrt(np.vdot(L.Ae, L.Ae))))


def solve_equality_chain(P: CompiledStack, damping: float) -> tuple[np.ndarray, dict]:
    """Closed-form lexicographic solution of a stack of equality levels, bounds ignored.

    The per-step fast path for stacks without inequality rows or hard constraints: each
    level's filtered pseudo-inverse step in the null space of the levels above, then the
    minimum-norm step. If the result satisfies the bounds it is also the solution of the
    bounded problem (every level already reaches its unconstrained optimum, and the
    remaining freedom its minimum norm); the caller checks that and otherwise runs
    :func:`solve_hierarchical`.
    """
    x = np.zeros(P.n)
    Z = None  # orthonormal basis of the remaining freedom (None: all of R^n)
    r = P.n
    ranks = []
    moved = False
    for L in P.levels:
        if r == 0:
            ranks.append(0)
            continue
        if L.identity and damping * np.sqrt(P.n) < 1.0:
            # A = I: M = Z has orthonormal columns (singular values 1, above the damping
            # threshold τ = damping·√n), so the step is Zᵀe and no SVD is needed
            e = L.be - x
            x = x + (e if Z is None else Z @ (Z.T @ e))
            ranks.append(r)
            r = 0
            continue
        A = L.Ae
        M = A if Z is None else A @ Z
        e = L.be - A @ x if moved else L.be
        scale = float(np.sqrt(np.vdot(A, A)))
        U, s, Vt, rank, g, _tau = filtered_svd(M, damping, scale)
        rank = _independent_rank(A, U, s, rank, scale)
        g = g[:rank]
        if rank:
            dz = Vt[:rank].T @ (g * (U[:, :rank].T @ e))
            x += dz if Z is None else Z @ dz
            r -= rank
            if r:  # no basis needed once the freedom is used up
                Z = Vt[rank:].T if Z is None else Z @ Vt[rank:].T
            moved = True
        ranks.append(rank)
    if r and Z is not None:
        x -= Z @ (Z.T @ x)
    elif r:
        x[:] = 0.0
    info = {
        "qp_calls": 0,
        "retries": 0,
        "fallbacks": [],
        "polished": 0,
        "level_ranks": ranks,
        "free_dofs": r,
        "continued": 0,
        "kkt": [],
        "uncertified": [],
    }
    return x, info


def _exact_on_active_rows(G, lo, hi, z, p, floor: float) -> np.ndarray | None:
    """The minimum-norm step ``min ½‖z + p‖²`` solved exactly on the rows the QP's point
    ``z`` meets to the backends' opening (:data:`~qpcoord.core.polish.PULL_TOL`), each
    held at its bound; ``None`` if that point leaves a row (beyond the opening) or is far
    (``FAR_RATIO``). The caller certifies it (a row held that should be left is not).

    The backends meet the rows only to their opening (``RELAX``, 1e-12): where active
    rows are nearly dependent in the remaining freedom (smallest singular value ``σ``),
    the opening ``δ`` buys a step ``δ/σ`` along them that shortens ``x``, which the
    native engine's exact step does not take (Panda, a frozen posture row and three speed
    bounds at ``σ`` = 1.9e-10: 3e-12 past the bounds bought 0.017 rad/s). The rows within
    ``ACTIVE_TOL`` (1e-7) instead of the opening held a row the optimum leaves on the
    LexLS humanoid, 4.3 away, and the certificate did not catch it: the opening it is."""
    a_lo, a_hi = at_bounds(G @ z, lo, hi, PULL_TOL)
    act = a_lo | a_hi
    if not act.any():
        return None
    E = G[act]
    t = np.where(a_lo, lo, hi)[act]
    U, s, Vt = svd(E, full=True)
    rk = numerical_rank(s, E.shape)
    ze = Vt[:rk].T @ ((U[:, :rk].T @ t) / s[:rk])
    N = Vt[rk:].T
    ze = ze - N @ (N.T @ (ze + p))
    if not np.isfinite(ze).all() or np.linalg.norm(ze) > FAR_RATIO * max(
        floor, float(np.linalg.norm(z))
    ):
        return None
    return ze if pull_back(G, lo, hi, ze) is ze else None


def _min_norm_step(G, lo, hi, z, p, floor: float, R: Reduced) -> tuple[np.ndarray, bool, float]:
    """The minimum-norm step ``min ½‖z + p‖²`` under the inherited rows and bounds
    (``lo ≤ G z ≤ hi``, none opened) from the QP's point ``z``, certified as a level is.

    Paths, each point certified before it is kept: the QP's point within the opening,
    finished exactly on the rows it meets to it (:func:`_exact_on_active_rows`) or as it
    is; then the active-set continuation from it (pulled back into the rows if it slipped
    through one), as it is or finished exactly on its active rows. The pull-back can land
    far from the QP's point (the LexLS humanoid's interior-point points, 1.4e-8 outside a
    row: at ``z = 0``, 0.2–18 from the optimum, on 11 rows dependent to rounding); the
    continuation goes on from there (it counts such rows as one constraint). When no point
    is certified the caller tries the fallback backends' points.
    Returns ``(z, ok, residual)``: ``ok`` False when no path's point is certified (the
    feasible one of least objective is kept)."""
    Q = np.eye(z.shape[0])
    prep = prepare(Q, G, lo, hi)
    best = None  # (objective, z, residual) of the feasible points that fail

    def certified(w, exact: bool) -> bool:
        nonlocal best
        if exact:
            w = _exact_on_active_rows(G, lo, hi, w, p, floor)
            if w is None:
                return False
        # the step is strictly convex: a certified point is its optimum (rows wrongly held
        # active, with multipliers of the wrong sign or a gap μ·s that is not small, are not)
        st, infeas = kkt_residual(Q, -p, G, lo, hi, w, prep, gap=True)
        if st <= KKT_TOL and infeas <= KKT_FEAS_TOL:
            best = (0.0, w, st)
            return True
        o = float(np.sum((w + p) ** 2))
        if best is None or o < best[0]:
            best = (o, w, st)
        return False

    zb = pull_back(G, lo, hi, z)
    if zb is z and (certified(z, True) or certified(z, False)):
        assert best is not None  # set by the check that certified
        R.continued += best[1] is not z
        return best[1], True, best[2]
    za, _conv = active_set_ls(Q, -p, G, lo, hi, zb, prepared=prep)
    za = pull_back(G, lo, hi, za)
    R.continued += 1
    ok = certified(za, False) or certified(za, True)
    assert best is not None  # certified(za, False) records its point whatever the verdict
    return best[1], ok, best[2]


def solve_hierarchical(
    P: CompiledStack,
    R: Reduced,
    damping: float,
    regularization: float,
    x_warm: np.ndarray | None = None,
) -> dict:
    """Solve a compiled stack lexicographically into the workspace ``R`` (already reset).

    Returns solve statistics; the solution is ``R.x`` and ``R``'s inherited rows are what
    it must satisfy.

    Parameters
    ----------
    P : CompiledStack
    R : Reduced
        Workspace, reset with the bounds and the solver to use for the QPs that closed
        forms cannot replace.
    damping : float
        Relative damping threshold (see :mod:`qpcoord.core.linalg`).
    regularization : float
        Relative weight of ``‖z‖²`` in directions a level does not determine.
    x_warm : ndarray, optional
        A previous solution; its projection gives each level QP a primal start.
    """
    R.hard_phase(P.hard)
    ranks = []
    for k, L in enumerate(P.levels):
        r = R.r
        x = R.x
        if r == 0:
            ranks.append(0)
            if L.m_in:  # nothing can move: the rows are kept as they are
                cx = L.C @ x
                R.inherit(L.C, np.minimum(L.lo, cx), np.maximum(L.hi, cx))
            continue
        R.drop_dependent()
        # ---- closed form for the equality rows --------------------------------------
        rank = 0
        # a level without equality rows keeps rank 0: M, e, s and Vt are then never read
        M = e = s = Vt = _NO_ROWS
        tau = 0.0
        if L.m_eq:
            M = R.reduce(L.Ae)
            e = L.be - L.Ae @ x
            U, s, Vt, rank, g, tau = _level_svd(L, M, damping)
            if rank and not L.identity:
                rank = _independent_rank(L.Ae, U, s, rank, float(np.sqrt(np.vdot(L.Ae, L.Ae))))
                g = g[:rank]
            if rank:
                xc = x + R.lift(Vt[:rank].T @ (g * (U[:, :rank].T @ e)))
            else:
                xc = x
        else:
            xc = x
        if R.feasible(xc) and (
            not L.m_in or ((L.C @ xc <= L.hiw).all() and (L.C @ xc >= L.low).all())
        ):
            R.move_to(xc, verified=True)
            if rank:
                R.restrict(Vt[rank:].T)
            R.inherit(L.C, L.lo, L.hi)
            ranks.append(rank)
            continue
        # ---- QP with slacks --------------------------------------------------------
        # Only rows that z can move get a slack; each is normalised to a unit row in z
        # (slack w̃ in units of z, violation = ‖Dᵢ‖·w̃ᵢ) so that the QP stays well scaled
        # whatever the rows' units.
        curv = []
        if rank:
            d = np.maximum(s[:rank] ** 2, tau * tau)
            curv.append(d)
        mv = 0
        rows_pivot = 1.0  # the moving rows' last kept pivot (_drop_dependent)
        dlo: np.ndarray | None
        dhi: np.ndarray | None
        if L.m_in:
            D = R.reduce(L.C)
            dn = np.sqrt(np.einsum("ij,ij->i", D, D))
            cn = np.sqrt(np.einsum("ij,ij->i", L.C, L.C))
            movable = dn > MOVABLE_TOL * cn
            mv = int(movable.sum())
            if mv:
                idx = np.flatnonzero(movable)
                D[idx], rows_pivot = _drop_dependent(D[idx], cn[idx])
                dn[idx] = np.sqrt(np.einsum("ij,ij->i", D[idx], D[idx]))
                # each row scaled to a unit row in z (slack in units of z), unless a
                # combination of them is nearly dependent on the frozen rows: then by its own
                # norm (a row with ‖Dᵢ‖ = 1e-9‖Cᵢ‖ has a slack ~1e9 in units of z, next to
                # box rows met to 1e-11 at a vertex: every backend called that infeasible)
                dm = dn[idx] if rows_pivot >= ILL_CONDITIONED else cn[idx]
                Dm = D[idx] / dm[:, None]
                cx = L.C[idx] @ x
                dlo = (L.lo[idx] - cx) / dm
                dhi = (L.hi[idx] - cx) / dm
                wcurv = (L.sw[idx] * dm) ** 2
                curv.append(wcurv)
        # objective scaled so the level's largest curvature is 1; the regularisation is
        # relative to it (active-set backends lose accuracy below ~1e-10, measured)
        cmax = max(float(c.max()) for c in curv) if curv else 1.0
        eps = regularization
        kdim = r + mv
        H = np.zeros((kdim, kdim))
        f = np.zeros(kdim)
        if rank:
            dd = np.full(r, eps)
            dd[:rank] = d / cmax
            H[:r, :r] = (Vt.T * dd) @ Vt
            f[:r] = -(M.T @ e) / cmax
        else:
            H[:r, :r] = eps * np.eye(r)
        Dy: np.ndarray | None = None
        if mv:
            H[r:, r:] = np.diag(wcurv / cmax)
            Dy = np.hstack((Dm, -np.eye(mv)))
        else:
            dlo = dhi = None
        y0 = None
        if x_warm is not None:
            y0 = np.zeros(kdim)
            y0[:r] = R.project(x_warm - x)
        where = f"level {k}"
        y = R.solve_qp(H, f, Dy, dlo, dhi, y0, where=where)
        z = y[:r]
        xn = x + R.lift(z)
        F = [Vt[:rank]] if rank else []
        viol_rows = np.zeros(L.m_in, dtype=bool)
        vscale = np.zeros(L.m_in)
        if mv:
            w = y[r:] * dm  # violation, units of C x
            xscale = max(float(np.abs(x).max()), float(np.abs(xn).max()))
            scale = np.maximum(
                np.maximum(_finite_abs(L.lo[idx]), _finite_abs(L.hi[idx])), cn[idx] * xscale
            )
            viol_rows[idx[np.abs(w) > VIOLATION_TOL * scale + _ABS_FLOOR]] = True
            vscale[idx] = scale
        # exact refinement on the QP's active set (removes the backend's tolerance and
        # the regularisation's bias before the level is frozen)
        ls_rows, ls_rhs = [], []
        if rank:
            ls_rows.append(M)
            ls_rhs.append(e)
            damped = s[:rank] < tau
            if damped.any():
                gain = np.sqrt(tau * tau - s[:rank][damped] ** 2)
                ls_rows.append(gain[:, None] * Vt[:rank][damped])
                ls_rhs.append(np.zeros(int(damped.sum())))
        if viol_rows.any():
            Cv = L.C[viol_rows]
            cxv = Cv @ xn
            target = np.where(cxv > L.hi[viol_rows], L.hi[viol_rows], L.lo[viol_rows])
            swv = L.sw[viol_rows]
            ls_rows.append(swv[:, None] * D[viol_rows])
            ls_rhs.append(swv * (target - Cv @ x))
        # also for exact backends: their optimum carries the regularisation's ~1e-9 bias
        zp = _refine(R, L, x, z, ls_rows, ls_rhs, viol_rows)
        if zp is not None:
            R.polished += 1
        # ---- certification: the level's KKT conditions at the point kept -------------
        cert = _Certifier(
            R,
            r,
            rank,
            M,
            e,
            s,
            tau,
            Vt,
            mv,
            D[idx] if mv else None,
            dlo * dm if mv else None,
            dhi * dm if mv else None,
            L.sw[idx] if mv else None,
        )
        if mv and rows_pivot < ILL_CONDITIONED:
            # moving rows with a combination within ILL_CONDITIONED of the frozen rows' span
            # (a row parallel to them to 1e-8: its violation falls by ~1e-8 of itself across
            # the whole box, under KKT_TOL; the QP's regularised point stopped short of the
            # box, where the lower levels are decided): finished exactly, as the native engine
            cert.exact = True
        z_qp = z
        z, ok, kkt = cert.run([zp, z] if zp is not None else [z], H, f, Dy, where)
        if ok:
            z, ok = cert.near(z, z_qp, x)
        R.certificates.append(kkt)
        if not ok:
            R.uncertified.append((k, kkt))
        xn = x + R.lift(z)
        if mv:
            # classify on the kept point's own violation (a row the QP's tolerance left
            # violated but the exact point satisfies is not frozen)
            cxk = L.C[idx] @ xn
            gap = np.maximum(L.lo[idx] - cxk, cxk - L.hi[idx])
            viol_rows[:] = False
            viol_rows[idx[gap > VIOLATION_TOL * vscale[idx] + _ABS_FLOOR]] = True
        R.move_to(xn, verified=False)
        fscale = 1.0  # rows of Vt are unit vectors
        if viol_rows.any():
            F.append(D[viol_rows])  # (the rows' projections as the level solved them)
            fscale = max(fscale, float(np.linalg.norm(L.C[viol_rows])))
        if L.m_in:
            # rows kept as inequalities are inherited with their bounds opened to the
            # current value: a violation under the threshold may stay, never grow
            keep = ~viol_rows
            cxn = L.C[keep] @ R.x
            R.inherit(L.C[keep], np.minimum(L.lo[keep], cxn), np.maximum(L.hi[keep], cxn))
        if len(F) == 1 and rank and not viol_rows.any():
            R.restrict(Vt[rank:].T)  # null(Vt[:rank]) is its orthonormal complement
        elif F:
            R.freeze(np.vstack(F) if len(F) > 1 else F[0], fscale)
        ranks.append(r - R.r)
    # ---- remaining freedom: minimum-norm x ----------------------------------------
    r = R.r
    if r:
        R.drop_dependent()
        x = R.x
        if R.Z is None:
            xc = np.zeros(P.n)
        else:
            xc = x - R.Z @ (R.Z.T @ x)
        if R.feasible(xc):
            R.move_to(xc, verified=True)
        else:
            y0 = None if x_warm is None else R.project(x_warm - x)
            p = R.project(x)
            z = R.solve_qp(np.eye(r), p, y0=y0, where="minimum-norm step")
            # never let the step slip through a row a level above kept (an opened QP)
            G, lo, hi = R.exact_rows(r)
            if R.Z is not None and R.lb is not None and R.ub is not None:
                # the bounds are the last rows, Z's own: a variable the levels froze to
                # rounding (‖Zᵢ‖ ≤ MOVABLE_TOL, Reduced.drop_dependent's rule for a row of
                # norm 1) is no row of the step; normalised, its rounding reads as a
                # violation of 0.4 (LexLS humanoid, bounds as a box). The final check
                # holds its bound.
                keep = np.ones(G.shape[0], dtype=bool)
                keep[G.shape[0] - P.n :] = np.einsum("ij,ij->i", R.Z, R.Z) > MOVABLE_TOL**2
                if not keep.all():
                    G, lo, hi = G[keep], lo[keep], hi[keep]
            floor = max(1.0, float(np.linalg.norm(x)))
            z, ok, kkt = _min_norm_step(G, lo, hi, z, p, floor, R)
            # then each fallback backend's QP point, as a level's
            for alt in R.alternatives() if not ok else ():
                za = R.solve_qp_with(alt, np.eye(r), p, where="minimum-norm step")
                if za is None:
                    continue
                R.fallbacks.append(f"minimum-norm step: {alt} (not certified)")
                za, ok, ka = _min_norm_step(G, lo, hi, za, p, floor, R)
                if ok:
                    z, kkt = za, ka
                    break
            if not ok:  # reported as the level after the last one
                R.uncertified.append((len(P.levels), kkt))
            R.move_to(x + R.lift(z), verified=False)
    return {
        "qp_calls": R.qp_calls,
        "retries": R.retries,
        "fallbacks": R.fallbacks,
        "polished": R.polished,
        "level_ranks": ranks,
        "free_dofs": r,
        "continued": R.continued,
        "kkt": R.certificates,
        "uncertified": R.uncertified,
    }
