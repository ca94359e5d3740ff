"""Variable elimination state shared by the stack methods.

The decision variable is parameterised as ``x = x̄ + Z z`` where ``Z`` (n × r, orthonormal
columns, ``None`` meaning the identity) spans the freedom left by everything fixed so far,
and ``x̄`` is the current solution. Inequality rows that must keep holding (bounds, hard
inequalities, satisfied rows of higher levels) are *inherited*: every later QP sees them as
constraints on ``z``. Because ``x̄`` satisfies all of them, ``z = 0`` is always feasible for a
later level, so a strict hierarchy cannot become spuriously infeasible.

One :class:`Reduced` workspace belongs to a compiled stack and is reset at every solve: the
inherited-row buffers are allocated once (the per-step hot path).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg import solve_triangular

from .backends import OK, as_rows, available_solvers, solve_dense_qp, time_left
from .errors import InfeasibleError, SolverError
from .linalg import all_finite, null_space, numerical_rank, svd
from .polish import polish
from .tolerance import widen, within

__all__ = ["Reduced", "FEAS_TOL", "CHECK_TOL", "MOVABLE_TOL", "within", "widen"]

#: Relative tolerance under which a closed-form candidate counts as feasible
#: (``row ≤ hi + FEAS_TOL·max(1, |hi|)``).
FEAS_TOL = 1e-9
#: Relative tolerance of the final check of every returned ``x`` against the hard
#: constraints and inherited rows; beyond it a :class:`SolverError` is raised.
CHECK_TOL = 1e-6
#: A level row, or combination of a level's rows, whose projection on the remaining freedom
#: is at most this fraction of its own norm lies in the frozen rows' span to rounding of the
#: freeze (``eps·κ`` of the frozen levels, ≤ 2e-9 for ``κ`` up to ``1/damping`` = 1e7 at the
#: default damping): it moves nothing and is left as dependent (the native engine's
#: ``kMovableTol``; the single-row case is the movable test of the level's inequality rows,
#: and an inherited level row that becomes such a row is no longer a constraint:
#: :meth:`Reduced.drop_dependent`).
MOVABLE_TOL = 1e-9
#: Relative opening of inherited rows and bounds in the QPs of lower levels, per backend:
#: active-set backends resolve a point pinned by active rows exactly; the others need a
#: feasible set at least as wide as their tolerances (proxqp and highs reported
#: "infeasible" on 1e-12-wide sets that daqp and quadprog solved).
RELAX = {"daqp": 1e-12, "quadprog": 1e-12}
RELAX_DEFAULT = 1e-8
#: Backends tried, in order, when the requested one fails on a level QP that is feasible
#: by construction (``z = 0`` meets every row; slacks are free). Measured case: at a
#: point pinned by four joint-speed bounds whose cone in ``z`` is pointed (a Panda IK
#: step), daqp 0.11 reported "infeasible" with every setting, quadprog solved it exactly.
#: clarabel (interior point, time-limited) ends the chain: on a level QP of a stack with
#: columns scaled 10^±3 (campaign var_scaled 1043) quadprog and proxqp said "infeasible"
#: and daqp returned a point 1e-3 outside; clarabel solved it and the level was certified.
FALLBACKS = ("quadprog", "daqp", "proxqp", "clarabel")
#: Backends given a QP in whitened variables (``solve_qp(..., T=...)``): the dual active-set
#: methods, which factor the Hessian (the identity there) and meet active rows exactly. On
#: the DDL MPC's weighted QP (cond(H) ≈ 1.5e9) whitening took daqp's x from 7.5e-10 to
#: 8e-12 of the native engine's; clarabel (interior point), whose tolerances are relative to
#: the rows' scale, went from 4e-11 to 7.9e-4 on the rows scaled by ``T⁻¹``: the others get
#: the formed Hessian.
WHITENED = frozenset({"daqp", "quadprog"})


def whiten_rows(G: np.ndarray, T: np.ndarray, r: int) -> np.ndarray:
    """Rows of a QP in ``z`` written in ``u = T z``: ``G[:, :r] ← G[:, :r] T⁻¹``, in place.

    ``T`` (``r × r``) is upper triangular and non-singular; the columns after ``r`` (slacks)
    are unchanged. ``G[:, :r] T⁻¹ = (T⁻ᵀ G[:, :r]ᵀ)ᵀ``: one triangular solve, no inverse
    formed. Used by :meth:`Reduced.solve_qp` (``T=``) and the persistent daqp workspace
    (:class:`qpcoord.core.persistent.PersistentQP`). Returns ``G``.
    """
    if G.shape[0]:
        G[:, :r] = solve_triangular(T, G[:, :r].T, trans="T", lower=False).T
    return G


def _miss(G, lo, hi, lb, ub, y) -> float:
    """Largest relative violation ``(row − bound)/max(1, |bound|)`` of a QP point
    (``inf`` for a non-finite point; infinite bounds never count)."""
    if not all_finite(y):
        return np.inf
    worst = 0.0
    pairs = [(G @ y, lo, hi)] if G.shape[0] else []
    if lb is not None:
        pairs.append((y, lb, ub))
    for v, low, high in pairs:
        # |bound| capped at 1e300: an infinite bound gives ∓inf here, never NaN
        below = (low - v) / np.maximum(1.0, np.minimum(np.abs(low), 1e300))
        above = (v - high) / np.maximum(1.0, np.minimum(np.abs(high), 1e300))
        worst = max(worst, float(below.max()), float(above.max()))
    return worst


#: Relative violation (``max(1, |bound|)`` rule) under which the hard part counts as
#: feasible: the optimum of the elastic LP of :func:`_lp_violation`. Far above rounding of
#: a point met exactly (a box of width 0 at 1e3 with a hard equality through it: ~1e-16),
#: far below anything :data:`CHECK_TOL` would let pass.
INFEAS_TOL = 1e-9
#: HiGHS's primal and dual feasibility tolerances in that LP (its smallest allowed values).
_LP_TOL = 1e-10


def _lp_violation(G, lo, hi, lb, ub):
    """Smallest uniform relative violation of ``lo ≤ G y ≤ hi, lb ≤ y ≤ ub``.

    The elastic LP ``min t`` over ``(y, t ≥ 0)`` with every one-sided row divided by
    ``max(1, |bound|)`` (the library's tolerance rule) and opened by ``t``, solved by HiGHS
    (``scipy.optimize.linprog``) with the solve's time left (:func:`deadline`). The LP
    always has a solution, so the answer does not depend on HiGHS's absolute tolerances:
    a box 1.6e-8 wide at 1e3, or of width 0 on a hard equality, is feasible to rounding
    (``t`` ~1e-16), and HiGHS's own feasibility test (absolute 1e-7 by default, 1e-10 at
    best) called such sets infeasible.

    Returns ``(t, y)`` with ``t`` recomputed at the LP's point ``y``, or ``(None, None)`` when
    the LP did not finish (time limit).
    """
    from scipy.optimize import linprog

    k = G.shape[1]
    A, b = as_rows(G, lo, hi, lb, ub, k)  # the box as rows too
    if A is None:
        return 0.0, np.zeros(k)
    s = np.maximum(1.0, np.abs(b))
    A = A / s[:, None]
    b = b / s
    m = A.shape[0]
    options = {"primal_feasibility_tolerance": _LP_TOL, "dual_feasibility_tolerance": _LP_TOL}
    left = time_left()
    if left is not None:
        if left <= 0.0:
            return None, None
        options["time_limit"] = left
    cost = np.zeros(k + 1)
    cost[k] = 1.0
    res = linprog(
        cost,
        A_ub=np.hstack((A, -np.ones((m, 1)))),
        b_ub=b,
        bounds=[(None, None)] * k + [(0.0, None)],
        method="highs",
        options=options,
    )
    if res.status != 0 or res.x is None:
        return None, None
    y = np.asarray(res.x[:k], dtype=float)
    return max(0.0, float((A @ y - b).max())), y


#: Active-set backends that certify infeasibility exactly and fast.
_CERTIFYING = frozenset({"daqp", "quadprog"})


class Reduced:
    """Current solution ``x̄``, null-space basis ``Z`` and inherited inequality rows.

    Parameters
    ----------
    n : int
        Number of variables.
    capacity : int
        Most inherited rows a solve can collect (hard inequalities plus every level's).
    fallback : bool
        Retry a level QP the backend failed on with :data:`FALLBACKS` (see there).
    """

    def __init__(self, n: int, capacity: int, fallback: bool = True) -> None:
        self.n = n
        self.fallback = fallback
        self._C = np.empty((capacity, n))
        self._lo = np.empty(capacity)
        self._hi = np.empty(capacity)
        self._low = np.empty(capacity)  # widened by FEAS_TOL, for the closed-form test
        self._high = np.empty(capacity)
        self._dependent = np.zeros(capacity, dtype=bool)
        self.reset(None, None, "")

    def reset(self, lb: np.ndarray | None, ub: np.ndarray | None, solver: str) -> Reduced:
        """Start a new solve at ``x̄ = 0`` with the full freedom."""
        self.x = np.zeros(self.n)
        self.Z: np.ndarray | None = None
        self.k = 0
        self.k_hard = 0  # the hard rows come first among the inherited rows
        self.n_dependent = 0
        self.lb, self.ub = lb, ub
        if lb is not None and ub is not None:
            self.lbw, self.ubw = widen(lb, ub, FEAS_TOL)
        self.solver = solver
        self.relax = RELAX.get(solver, RELAX_DEFAULT)
        self.used_relax = self.relax
        self.qp_calls = 0
        self.retries = 0
        self.fallbacks: list[str] = []
        self._in_fallback = False
        self.polished = 0
        self.continued = 0  # levels made exact by the active-set continuation
        self.certificates: list[float] = []  # KKT residual of each level that ran a QP
        self.uncertified: list[tuple[int, float]] = []  # (level, KKT residual)
        self.verified = True  # x̄ passed the feasibility test (no QP output since)
        self._asm: tuple[Any, ...] | None = (
            None  # (kdim, D, k, Z, T, G): the last QP matrix built by _assemble
        )
        return self

    # -- inherited rows -----------------------------------------------------------------
    @property
    def Cin(self) -> np.ndarray:
        """Inherited rows (k × n)."""
        return self._C[: self.k]

    @property
    def dependent(self) -> np.ndarray:
        """Mask of the inherited rows that are no longer constraints (:meth:`drop_dependent`)."""
        return self._dependent[: self.k]

    def drop_dependent(self) -> None:
        """Stop imposing the inherited level rows whose projection ``Cᵢ Z`` is at most
        :data:`MOVABLE_TOL` of ``‖Cᵢ‖``: they lie in the frozen rows' span to rounding of the
        freeze, constant as far as the remaining freedom can tell, and the direction of their
        projection is rounding (a half-space through ``x̄`` with that normal would decide the
        lower levels by rounding; the native engine's ``add_inherited_rows`` skips them).
        Projections only shrink as ``Z`` does: a row once dropped stays dropped. The hard
        rows are kept (the final check holds them)."""
        k0, k = self.k_hard, self.k
        if k <= k0 or self.Z is None:
            return
        C = self._C[k0:k]
        Cz = C @ self.Z
        dep = np.sqrt(np.einsum("ij,ij->i", Cz, Cz)) <= MOVABLE_TOL * np.sqrt(
            np.einsum("ij,ij->i", C, C)
        )
        self._dependent[k0:k] |= dep
        self.n_dependent = int(self._dependent[:k].sum())

    @property
    def lin(self) -> np.ndarray:
        """Lower bounds of the inherited rows."""
        return self._lo[: self.k]

    @property
    def uin(self) -> np.ndarray:
        """Upper bounds of the inherited rows."""
        return self._hi[: self.k]

    def inherit(self, C: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
        """Add inequality rows (x-space) that every later level must keep satisfied."""
        m = C.shape[0]
        if m == 0:
            return
        k = self.k
        self._C[k : k + m] = C
        self._lo[k : k + m] = lo
        self._hi[k : k + m] = hi
        self._dependent[k : k + m] = False
        self._low[k : k + m], self._high[k : k + m] = widen(lo, hi, FEAS_TOL)
        self.k = k + m

    # -- parameterisation -------------------------------------------------------------
    @property
    def r(self) -> int:
        """Remaining degrees of freedom."""
        return self.n if self.Z is None else self.Z.shape[1]

    def reduce(self, M: np.ndarray) -> np.ndarray:
        """``M Z`` (rows in x-space to rows in z-space)."""
        return M if self.Z is None else M @ self.Z

    def lift(self, z: np.ndarray) -> np.ndarray:
        """``Z z`` (a z-space step to x-space)."""
        return z if self.Z is None else self.Z @ z

    def project(self, v: np.ndarray) -> np.ndarray:
        """``Zᵀ v`` (an x-space vector to z-space coordinates)."""
        return v if self.Z is None else self.Z.T @ v

    def restrict(self, basis: np.ndarray) -> None:
        """Keep only the z-directions spanned by ``basis`` (r × r', orthonormal columns)."""
        self.Z = basis if self.Z is None else self.Z @ basis

    def freeze(self, F: np.ndarray, scale: float = 0.0) -> None:
        """Fix the z-space rows ``F z`` at their current values (restrict to null(F));
        ``scale`` is the size of the rows before projection (see :func:`null_space`)."""
        if F.shape[0]:
            self.restrict(null_space(F, scale))

    def move_to(self, x: np.ndarray, verified: bool) -> None:
        """Set ``x̄``, snapped into the bounds: that removes a backend's ~1e-12 overshoot,
        which would make ``z = 0`` infeasible for the next level, and a closed form's
        ``FEAS_TOL`` one, so a returned ``x`` never leaves its box."""
        if self.lb is not None and self.ub is not None:
            x = np.minimum(np.maximum(x, self.lb), self.ub)
        self.x = x
        self.verified = verified

    # -- checks ---------------------------------------------------------------------
    def feasible(self, x: np.ndarray) -> bool:
        """Does ``x`` satisfy the bounds and inherited rows (to ``FEAS_TOL``, relative)?"""
        if self.lb is not None and not ((x <= self.ubw).all() and (x >= self.lbw).all()):
            return False
        k = self.k
        if k:
            c = self._C[:k] @ x
            return bool((c <= self._high[:k]).all() and (c >= self._low[:k]).all())
        return True

    # -- QP in z (plus optional slack block) -------------------------------------------
    def _relax(self, bound: np.ndarray) -> np.ndarray | float:
        """``RELAX·max(1, |bound|)``: opens the inherited rows by a hair so that a point
        pinned by more active rows than free directions is not a degenerate vertex (daqp
        declared such QPs infeasible). Bounds are snapped back after the solve."""
        if self.relax == 0.0:
            return 0.0
        return self.relax * np.maximum(1.0, np.abs(bound))

    def _assemble(self, kdim: int, D, dlo, dhi, T: np.ndarray | None = None):
        """Constraint rows of a QP in ``y = (z, w)`` (``kdim`` entries, ``w`` unbounded).

        With ``T`` (``r × r``, upper triangular, non-singular) the QP is in ``y = (u, w)``,
        ``u = T z``: every row's ``z`` part is multiplied by ``T⁻¹`` and bounds on ``z``
        become rows (see :meth:`solve_qp`).

        The inherited rows dropped as dependent (:meth:`drop_dependent`) are left out.
        The matrix depends only on ``(kdim, D, k, Z, T)`` and the dropped rows; it is kept
        and reused while those are the same (a level's QP, its retries, polish and
        certificate share it), only the bounds are recomputed."""
        r = self.r
        x = self.x
        Cin, cl, ch = self.Cin, self.lin, self.uin
        if self.n_dependent:
            keep = ~self.dependent
            Cin, cl, ch = Cin[keep], cl[keep], ch[keep]
        k = Cin.shape[0]
        box_rows = self.lb is not None and (self.Z is not None or T is not None)
        c = self._asm
        if (
            c is not None
            and c[0] == kdim
            and c[1] is D
            and c[2] == self.k
            and c[3] is self.Z
            and c[4] is T
            and c[5] == self.n_dependent
        ):
            G = c[6]
        else:
            blocks = []
            if D is not None and D.shape[0]:
                blocks.append(D)
            if k:
                Cz = self.reduce(Cin)
                if kdim > r:
                    Cz = np.hstack((Cz, np.zeros((k, kdim - r))))
                blocks.append(Cz)
            if box_rows:
                Z = self.Z if self.Z is not None else np.eye(r)
                Zr = Z if kdim == r else np.hstack((Z, np.zeros((Z.shape[0], kdim - r))))
                blocks.append(Zr)
            if not blocks:
                G = np.zeros((0, kdim))
            else:
                G = blocks[0] if len(blocks) == 1 else np.vstack(blocks)
            if T is not None and G.shape[0]:
                G = whiten_rows(G.copy() if len(blocks) == 1 else G, T, r)
            self._asm = (kdim, D, self.k, self.Z, T, self.n_dependent, G)
        los, his = [], []
        if D is not None and D.shape[0]:
            los.append(dlo)
            his.append(dhi)
        if k:
            cx = Cin @ x
            # x̄ meets these rows up to the previous solve's tolerance; never ask for more
            # than z = 0 already gives, so the QP stays feasible by construction
            los.append(np.minimum(cl - cx, 0.0) - self._relax(cl))
            his.append(np.maximum(ch - cx, 0.0) + self._relax(ch))
        lb = ub = None
        if self.lb is not None and self.ub is not None:
            if self.Z is None and T is None:
                lb = np.full(kdim, -np.inf)
                ub = np.full(kdim, np.inf)
                lb[:r] = np.minimum(self.lb - x, 0.0) - self._relax(self.lb)
                ub[:r] = np.maximum(self.ub - x, 0.0) + self._relax(self.ub)
            else:
                los.append(np.minimum(self.lb - x, 0.0) - self._relax(self.lb))
                his.append(np.maximum(self.ub - x, 0.0) + self._relax(self.ub))
        if not los:
            return G, np.zeros(0), np.zeros(0), lb, ub
        if len(los) == 1:
            return G, los[0], his[0], lb, ub
        return G, np.concatenate(los), np.concatenate(his), lb, ub

    def exact_rows(self, kdim: int, D=None, dlo=None, dhi=None):
        """The QP's rows in ``y = (z, w)`` without any opening, the bounds as rows too:
        ``(G, lo, hi)`` with ``y = 0`` feasible (what certification checks against)."""
        keep = self.relax
        self.relax = 0.0
        try:
            G, lo, hi, lb, ub = self._assemble(kdim, D, dlo, dhi)
        finally:
            self.relax = keep
        if lb is not None:
            fin = np.isfinite(lb) | np.isfinite(ub)
            if fin.any():
                E = np.eye(kdim)[fin]
                G = np.vstack((G, E)) if G.shape[0] else E
                lo = np.concatenate((lo, lb[fin]))
                hi = np.concatenate((hi, ub[fin]))
        return G, lo, hi

    def solve_qp(
        self,
        H: np.ndarray,
        f: np.ndarray,
        D: np.ndarray | None = None,
        dlo: np.ndarray | None = None,
        dhi: np.ndarray | None = None,
        y0: np.ndarray | None = None,
        where: str = "",
        T: np.ndarray | None = None,
    ) -> np.ndarray:
        """Solve ``min ½yᵀHy + fᵀy`` over ``y = (z, w)`` with the inherited rows and bounds
        on ``x̄ + Z z`` and the extra rows ``dlo ≤ D y ≤ dhi``; ``w`` (``len(y) − r`` slack
        entries) is unbounded. Returns ``y``; raises :class:`SolverError` on failure.

        With ``T`` (``r × r``, upper triangular, non-singular) the QP's variables are
        ``y = (u, w)`` with ``u = T z``: ``H``, ``f`` and ``y0`` are given in them, ``D``
        (and every inherited row and bound) in ``z``, and the returned ``y`` is in ``u``.
        The weighted method passes the triangular factor of its weighted rows, so that its
        QP has the identity as ``u``'s Hessian (errors ~ε·cond(T), not ε·cond(TᵀT))."""
        kdim = H.shape[0]
        G, lo, hi, lb, ub = self._assemble(kdim, D, dlo, dhi, T)
        opened = self.relax
        self.qp_calls += 1
        res = solve_dense_qp(self.solver, H, f, G, lo, hi, lb, ub, y0)
        if res.code != OK and y0 is not None:
            # a warm start can mislead an active-set backend: once more from cold
            self.qp_calls += 1
            res = solve_dense_qp(self.solver, H, f, G, lo, hi, lb, ub, None)
        if res.code != OK and (self.k or self.lb is not None):
            # a point pinned by more active rows than free directions leaves a feasible
            # set as thin as the opening; some backends call that infeasible: open it
            # 100× wider once (the final check allows for it)
            self.retries += 1
            keep = self.relax
            self.relax = keep * 100.0
            G, lo, hi, lb, ub = self._assemble(kdim, D, dlo, dhi, T)
            self.relax = keep
            self.used_relax = max(self.used_relax, keep * 100.0)
            opened = keep * 100.0
            self.qp_calls += 1
            res = solve_dense_qp(self.solver, H, f, G, lo, hi, lb, ub, None)
        if res.code != OK:
            y = self._fallback(H, f, D, dlo, dhi, where, T)
            if y is not None:
                return y
            raise SolverError(f"{where}: backend {self.solver!r} failed: {res.message}")
        y = res.y
        if y is None or not all_finite(y):  # (an OK result carries its y)
            raise SolverError(f"{where}: backend {self.solver!r} returned a non-finite solution")
        miss = _miss(G, lo, hi, lb, ub, y)
        if miss > CHECK_TOL:
            # a point outside the QP's own rows is a failure of the backend: the next
            # backend gets the QP (a stretched Panda IK: daqp 4.9e-6 outside, every step)
            y = self._fallback(H, f, D, dlo, dhi, where, T)
            if y is not None:
                return y
            raise SolverError(
                f"{where}: backend {self.solver!r} returned a point that violates its QP's "
                f"constraints by {miss:.3g} (relative)"
            )
        if res.exact:
            return y
        # polish against the unopened rows: the point lands exactly on the true bounds
        keep = self.relax
        self.relax = 0.0
        G, lo, hi, lb, ub = self._assemble(kdim, D, dlo, dhi, T)
        self.relax = keep
        return polish(H, f, G, lo, hi, lb, ub, y, obj_slack=10.0 * opened)

    def alternatives(self) -> list[str]:
        """Installed backends of :data:`FALLBACKS` other than the requested one (empty with
        ``fallback=False``)."""
        if not self.fallback:
            return []
        installed = set(available_solvers())
        return [s for s in FALLBACKS if s != self.solver and s in installed]

    def solve_qp_with(self, solver: str, H, f, D=None, dlo=None, dhi=None, where: str = ""):
        """:meth:`solve_qp` with another backend (no further fallback); ``None`` if it
        fails. Used when a level's answer could not be certified."""
        keep_solver, keep_relax, keep_fb = self.solver, self.relax, self._in_fallback
        self.solver = solver
        self.relax = RELAX.get(solver, RELAX_DEFAULT)
        self.used_relax = max(self.used_relax, self.relax)
        self._in_fallback = True
        try:
            return self.solve_qp(H, f, D, dlo, dhi, None, where)
        except SolverError:
            return None
        finally:
            self.solver, self.relax, self._in_fallback = keep_solver, keep_relax, keep_fb

    def _fallback(self, H, f, D, dlo, dhi, where: str, T=None) -> np.ndarray | None:
        """Solve a level QP the requested backend failed on with the next backend of
        :data:`FALLBACKS` that is installed; recorded in ``self.fallbacks``."""
        if self._in_fallback or not self.fallback:
            return None
        installed = set(available_solvers())
        keep_solver, keep_relax = self.solver, self.relax
        self._in_fallback = True
        try:
            for alt in FALLBACKS:
                if (
                    alt == keep_solver
                    or alt not in installed
                    or (T is not None and alt not in WHITENED)
                ):
                    continue
                self.solver = alt
                self.relax = RELAX.get(alt, RELAX_DEFAULT)
                self.used_relax = max(self.used_relax, self.relax)
                try:
                    y = self.solve_qp(H, f, D, dlo, dhi, None, where, T)
                except SolverError:
                    continue
                self.fallbacks.append(f"{where}: {alt}")
                return y
        finally:
            self.solver, self.relax = keep_solver, keep_relax
            self._in_fallback = False
        return None

    def hard_phase(self, hard, where: str = "constraints") -> None:
        """Satisfy the hard constraints and bounds; start at the min-norm feasible point.

        Raises
        ------
        InfeasibleError
            Inconsistent hard equalities, or no point satisfies hard rows and bounds.
        """
        if hard.m_eq:
            Ae, be = hard.Ae, hard.be
            U, s, Vt = svd(Ae, full=True)
            rank = numerical_rank(s, Ae.shape)
            x = Vt[:rank].T @ ((U[:, :rank].T @ be) / s[:rank])
            res = Ae @ x - be
            scale = max(1.0, float(np.max(np.abs(be))))
            if float(np.max(np.abs(res))) > CHECK_TOL * scale:
                names = ", ".join(t.label for t in hard.eqs)
                raise InfeasibleError(
                    f"hard equality constraints are inconsistent ({names}): "
                    f"least-squares residual {np.linalg.norm(res):.3g}"
                )
            self.x = x
            self.restrict(Vt[rank:].T)
        self.inherit(hard.C, hard.lo, hard.hi)
        self.k_hard = self.k
        if (self.lb is None and not self.k) or self.feasible(self.x):
            return
        if self.lb is not None and self.ub is not None and self.Z is None and not self.k:
            self.x = np.minimum(np.maximum(self.x, self.lb), self.ub)
            return
        r = self.r
        if r == 0:
            raise InfeasibleError(
                f"{where}: the hard equalities fix x completely and it violates the bounds "
                "or hard inequalities"
            )
        x = self.x
        G, lo, hi, lb, ub = self._assemble(r, None, None, None)
        # the start point need not be feasible here: use the true row bounds
        if self.k:
            cx = self._C[: self.k] @ x
            lo[: self.k] = self._lo[: self.k] - cx
            hi[: self.k] = self._hi[: self.k] - cx
        if self.lb is not None and self.ub is not None:
            if self.Z is None:
                lb, ub = self.lb - x, self.ub - x
            else:
                lo[self.k :] = self.lb - x
                hi[self.k :] = self.ub - x
        lp_t = None
        if self.solver not in _CERTIFYING:
            # backends behind qpsolvers cannot say "infeasible" and proxqp needed 50–260 s
            # to give up on a 2-variable infeasible hard part: decide it first with an LP
            lp_t = self._lp_check(G, lo, hi, lb, ub, where, "")
        self.qp_calls += 1
        res = solve_dense_qp(self.solver, np.eye(r), self.project(x), G, lo, hi, lb, ub, None)
        y = res.y if res.code == OK else None
        if y is not None and not np.all(np.isfinite(y)):
            raise SolverError(f"{where}: backend {self.solver!r} returned a non-finite point")
        if y is not None and self._hard_ok(x + self.lift(y)):
            self.move_to(x + self.lift(y), verified=False)
            return
        # the backend failed, called the hard part infeasible or returned a point outside
        # it: an "infeasible" is only believed when an LP confirms it (proxqp, quadprog and
        # the LP's own absolute tolerances called feasible sets 1.6e-8 wide infeasible)
        if lp_t is None:
            lp_t = self._lp_check(G, lo, hi, lb, ub, where, f"{res.message}; ")
        # consistent (to INFEAS_TOL): the set is thinner than the backend's tolerances;
        # open it by a hair, relative to the true bounds, then try the other backends
        y = self._hard_retry(r, x, G, lo, hi, lb, ub, lp_t)
        if y is None:
            if res.code == OK:
                raise SolverError(
                    f"{where}: backend {self.solver!r} returned a point violating the hard "
                    "constraints, which an LP feasibility test shows are consistent"
                )
            raise SolverError(
                f"{where}: backend {self.solver!r} failed ({res.message}) on hard "
                "constraints that an LP feasibility test shows are consistent"
            )
        self.move_to(x + self.lift(y), verified=False)

    def _hard_ok(self, xn: np.ndarray) -> bool:
        """Does ``xn`` meet the bounds and hard rows to :data:`CHECK_TOL`?"""
        return bool(
            all_finite(xn)
            and (self.lb is None or self.ub is None or within(xn, self.lb, self.ub, CHECK_TOL))
            and within(self.Cin @ xn, self.lin, self.uin, CHECK_TOL)
        )

    def _lp_check(self, G, lo, hi, lb, ub, where: str, said: str) -> float:
        """:func:`_lp_violation` of the hard part; raises :class:`InfeasibleError` above
        :data:`INFEAS_TOL`, :class:`SolverError` when the LP ran out of time."""
        t, _y = _lp_violation(G, lo, hi, lb, ub)
        if t is None:
            raise SolverError(
                f"{where}: the LP feasibility test of the hard constraints did not finish "
                "(time limit reached)"
            )
        if t > INFEAS_TOL:
            raise InfeasibleError(
                f"{where}: bounds and hard constraints are inconsistent ({said}confirmed by an "
                f"LP feasibility test: no point within {t:.3g} of them, relative)"
            )
        return t

    def _hard_retry(self, r, x, G, lo, hi, lb, ub, t):
        """Points for a consistent hard part a backend failed on: the requested backend and
        then :data:`FALLBACKS` (unless ``fallback=False``), each with the rows and box opened
        by ``δ·max(1, |bound|)`` (``δ`` its :data:`RELAX`, at least ``10·t``, then ×100). The
        first point meeting the hard part to :data:`CHECK_TOL` is returned, else ``None``."""
        k = self.k
        olo, ohi = self._lo[:k], self._hi[:k]  # the true bounds set the opening's scale
        if self.lb is not None and self.Z is not None:
            olo, ohi = np.concatenate((olo, self.lb)), np.concatenate((ohi, self.ub))
        slo, shi = np.maximum(1.0, np.abs(olo)), np.maximum(1.0, np.abs(ohi))
        if lb is not None:
            blo, bhi = np.maximum(1.0, np.abs(self.lb)), np.maximum(1.0, np.abs(self.ub))
        solvers = [self.solver] + [s for s in self.alternatives() if s != self.solver]
        f = self.project(x)
        for solver in solvers:
            base = max(RELAX.get(solver, RELAX_DEFAULT), 10.0 * t)
            for delta in (base, 100.0 * base):
                lb2 = ub2 = None
                if lb is not None:
                    lb2, ub2 = lb - delta * blo, ub + delta * bhi
                self.qp_calls += 1
                self.retries += 1
                res = solve_dense_qp(
                    solver, np.eye(r), f, G, lo - delta * slo, hi + delta * shi, lb2, ub2, None
                )
                if res.code == OK and self._hard_ok(x + self.lift(res.y)):
                    if solver != self.solver:
                        self.fallbacks.append(f"constraints: {solver}")
                    return res.y
        return None
