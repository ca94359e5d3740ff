"""A persistent fast path for stacks whose matrices do not change: :class:`PersistentQP`.

In a condensed MPC, or any control loop around a fixed linear model, the task matrices
(``A`` of every :class:`~qpcoord.Equality`, ``C`` of every :class:`~qpcoord.Inequality`, the
hard constraints) stay the same from step to step; only the right-hand sides ``b``, the
inequality limits and the bounds move. The weighted QP of such a stack (``method="weighted"``,
:mod:`qpcoord.core.methods.weighted`) then has a constant Hessian and constraint matrix, so the
backend's
workspace -- its factorisation and its working set -- can be kept between steps: this class
sets up one workspace once and, per step, only updates the linear term and the limits and
hot-starts from the previous working set. No Python-level QP assembly happens per step. The
workspace is the native weighted QP (:mod:`qpcoord.core.native_weighted`: the Hessian factored
once per set-up, a dual active set warm-started from the last working set) where the
extension is built, else (or with ``engine="python"``) one ``daqp.Model``.

The answer is the same QP as ``stack.solve(method="weighted")`` (levels weighted by
``weight_ratio**k``, soft inequalities with slacks, bounds and hard constraints hard) and is
checked like it: bounds and hard constraints to the stack's tolerance. If the backend fails,
or the matrices have changed (checked every step against the set-up copy), the step falls
back to ``stack.solve(method="weighted")`` -- recorded in ``Solution.info`` (``fallback``,
``setups``) -- so an unchecked answer is never returned.

In the parametric form (:meth:`PersistentQP.parametrize`, right-hand sides and limits affine
in a parameter ``θ``) the optimum is piecewise affine in ``θ``: affine on each *critical
region*, the set of ``θ`` with the same active constraints (Bemporad, Morari, Dua &
Pistikopoulos 2002). :meth:`PersistentQP.solve_theta` keeps a small cache of the regions it
has met (the on-line "partial enumeration" of Pannocchia, Rawlings & Wright 2007): the last
region's affine law and its KKT test -- primal feasibility of every row and the sign of every
active row's multiplier -- are one matrix-vector product each, and the QP solver is called
only when ``θ`` has left that region.
"""

from __future__ import annotations

import math
import time
from operator import attrgetter
from typing import Any, Protocol

import numpy as np
from scipy.linalg import lapack

from .backends import DEFAULT_TIME_LIMIT
from .compile import CompiledStack
from .elimination import CHECK_TOL, whiten_rows
from .errors import InfeasibleError, SolverError
from .linalg import all_finite
from .methods.weighted import _qr
from .native_weighted import NativeWeighted, resolve_weighted_engine
from .solution import Solution
from .tasks import Equality

__all__ = ["PersistentQP", "WeightedStack"]

_INF = 1e30  # daqp's infinity
_MATRIX_VERSION = attrgetter("matrix_version")

#: daqp settings of the persistent workspace: the stack's first (exact) setting, and the
#: default time limit of a solve (s; :data:`qpcoord.core.backends.DEFAULT_TIME_LIMIT`).
DAQP_SETTINGS = dict(eps_prox=0.0, primal_tol=1e-10, time_limit=DEFAULT_TIME_LIMIT)

#: Critical-region test tolerance: a cached region's law answers only if every row holds and
#: every active multiplier has its sign to this absolute margin (task units); else the QP
#: solver is called. Tighter than CHECK_TOL, so a region answer is the QP's optimum to
#: rounding, not merely feasible.
REGION_TOL = 1e-9

#: Most critical regions kept per workspace (least recently used dropped first).
REGION_CACHE = 64

#: Regions tested per step before the QP solver is called, most recently used first (a
#: trajectory that alternates between two or three active sets stays off the solver).
REGION_TRIES = 8


def _inside(v: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """``lo − CHECK_TOL·max(1,|lo|) ≤ v ≤ hi + CHECK_TOL·max(1,|hi|)`` (daqp's ±1e30 = none)."""
    if np.maximum(lo - v, v - hi).max() <= CHECK_TOL:
        return True
    return bool(
        (lo - v <= CHECK_TOL * np.maximum(1.0, np.abs(lo))).all()
        and (v - hi <= CHECK_TOL * np.maximum(1.0, np.abs(hi))).all()
    )


def _region(x0, X, r0, R) -> tuple:
    """A critical region as tested per step: ``(m, [R; X], [r0; x0])`` with ``m`` test rows
    (``r0 + R θ ≤ REGION_TOL`` inside) and the law ``x = x0 + X θ`` below them."""
    return (R.shape[0], np.ascontiguousarray(np.vstack((R, X))), np.concatenate((r0, x0)))


def _whitening(W: list, s: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The whitening of the weighted QP: ``(T, Fw)``, or ``None`` if ``T`` is singular
    (then daqp gets the formed Hessian).

    ``W`` (list of blocks) are the weighted rows, ``H[:n, :n] = WᵀW``, the first
    ``s.shape[0]`` of them the equality rows with ``f = −Wᵀ diag(s) b`` (``s``: the rows'
    ``√βₖ·√w``), the rest the regularization's ``√ε I``. With the QR of ``W`` as the
    weighted method's (:func:`qpcoord.core.methods.weighted._qr`, ``W = Q₁T``: no
    squaring, errors ~ε·cond(W) = ε·√cond(H)): ``T`` upper triangular with ``TᵀT = H``,
    and ``Fw = Q₁ᵀ diag(s)`` so that ``f_u = T⁻ᵀ f = −Fw b`` (``n × len(s)``) never goes
    through the formed ``f``."""
    if not W:
        return None
    Wm = np.vstack(W)
    if Wm.shape[0] < n:
        return None
    qr, tau = _qr(Wm)
    T = np.triu(qr[:n, :n])
    if not (np.all(np.isfinite(T)) and np.all(T.diagonal() != 0.0)):
        return None
    if s.shape[0] == 0:  # no equality row (W is the regularization's): f = 0
        return T, np.zeros((n, 0))
    E = np.zeros((Wm.shape[0], s.shape[0]))
    E[np.arange(s.shape[0]), np.arange(s.shape[0])] = s
    QtE, _work, info = lapack.dormqr("L", "T", qr, tau, E, max(1, 2 * s.shape[0]))
    if info != 0:
        return None
    return T, np.ascontiguousarray(QtE[:n])


class WeightedStack(Protocol):
    """What a :class:`PersistentQP` reads of its :class:`~qpcoord.Stack`: the compiled rows,
    the weighted method's parameters, and its general solve (the fallback)."""

    weight_ratio: float
    regularization: float

    @property
    def compiled(self) -> CompiledStack: ...

    def solve(
        self,
        solver: str | None = None,
        method: str = "hierarchical",
        *,
        engine: str | None = None,
    ) -> Solution: ...


class PersistentQP:
    """The weighted QP of a fixed-matrix :class:`~qpcoord.Stack` on a persistent workspace (native
    or daqp).

    Parameters
    ----------
    stack : Stack
        Its tasks' matrices must stay constant; their ``b``, limits and the bounds may change
        between :meth:`solve` calls (change them with ``task.update(b=...)`` or the bounds'
        ``update``).
    weight_ratio, regularization : float, optional
        Default: the stack's.
    engine : {None, "native", "python"}
        ``"native"``: the native weighted QP; ``"python"``: a daqp workspace; ``None``: native
        where built (:func:`~qpcoord.core.native_weighted.resolve_weighted_engine`).

    Raises
    ------
    ValueError
        ``stack`` is not a Stack.
    ImportError
        daqp is not installed (``engine="python"``), or ``engine="native"`` and the extension
        is not built.

    Notes
    -----
    Variables: ``x`` (n) and one slack per soft inequality row. Cost:
    ``Σ_k ρᵏ (‖A_k x − b_k‖² + ‖√w_k s_k‖²) + ε‖x‖²`` with ``ρ = weight_ratio``,
    ``ε = regularization · max(1, max diag)``, as
    :func:`qpcoord.core.methods.weighted.solve_weighted`. The native workspace adds ``ε``
    exactly where that function does (the Hessian singular on the hard equalities' null
    space), so its answer is ``stack.solve(method="weighted")``'s; the daqp workspace adds it
    where the x-space Hessian has no Cholesky factor, and is given the QP in whitened
    variables ``u = T x`` (``TᵀT = H`` from the QR of the weighted rows, as the weighted
    method's :data:`~qpcoord.core.elimination.WHITENED` path): errors ε·√cond(H), not
    ε·cond(H).
    """

    def __init__(
        self,
        stack: WeightedStack,
        weight_ratio: float | None = None,
        regularization: float | None = None,
        engine: str | None = None,
    ) -> None:
        self.engine = resolve_weighted_engine(engine, None)
        if self.engine == "python":
            import daqp
        else:
            daqp = None
        # read through WeightedStack: qpcoord.core.stack imports this module (Stack.persistent)
        if not isinstance(getattr(stack, "compiled", None), CompiledStack):
            raise ValueError(f"stack must be a qpcoord.Stack, got {type(stack).__name__}")
        self.stack = stack
        self.weight_ratio = stack.weight_ratio if weight_ratio is None else float(weight_ratio)
        self.regularization = (
            stack.regularization if regularization is None else float(regularization)
        )
        if not 0 < self.weight_ratio <= 1:
            raise ValueError(f"weight_ratio must be in (0, 1], got {self.weight_ratio!r}")
        if not self.regularization >= 0:
            raise ValueError(f"regularization must be >= 0, got {self.regularization!r}")
        self._daqp = daqp
        self.model = None
        self._nw: NativeWeighted | None = None
        self.setups = 0
        self.fallbacks = 0
        #: :meth:`solve_theta` steps answered by a cached critical region's affine law
        #: (the unconstrained region included) and by the QP solver.
        self.region_steps = 0
        self.qp_steps = 0
        self.last: Solution | None = None
        P = stack.compiled
        P.refresh()
        self._setup(P)

    # ------------------------------------------------------------------ set-up
    def _versions(self, P) -> list:
        """Matrix versions of every task (``update``/``_assign`` of a matrix or weight bump
        them): cheap change detection."""
        return list(map(_MATRIX_VERSION, self._all_tasks))

    def _setup(self, P) -> None:
        self._all_tasks = [t for L in (*P.levels, P.hard) for t in (*L.eqs, *L.ineqs)]
        n = P.n
        soft = [L for L in P.levels if L.m_in]
        mi = sum(L.m_in for L in soft)
        nv = n + mi
        H = np.zeros((nv, nv))
        F = []  # per equality task: ρᵏ Aᵀ diag(w), so that f = −Σ F_t b_t
        eq_tasks = []
        beta = 1.0
        j = n
        # the weighted rows √βₖ Aₖ (H[:n, :n] = WᵀW) and their √βₖ·√w: the daqp workspace's
        # whitening
        W, sw = [], []
        for L in P.levels:
            if L.m_eq:
                H[:n, :n] += beta * (L.Ae.T @ L.Ae)
                W.append(np.sqrt(beta) * L.Ae)
                sw += [np.sqrt(beta) * t.sqrt_weight for t in L.eqs]
                for t in L.eqs:
                    F.append(beta * (t.A.T * t.weight))
                    eq_tasks.append(t)
            if L.m_in:
                idx = np.arange(j, j + L.m_in)
                H[idx, idx] = beta * L.sw**2
                j += L.m_in
            beta *= self.weight_ratio
        # ε‖x‖² only where the levels leave H singular (its Cholesky fails): on a positive
        # definite H the QP is solved exactly, without ε's bias. (Until this was fixed the
        # line wrote into a copy -- ``H.flat[::k][:n] += ε`` -- so ε was never added and a
        # singular H sent every step to the fallback.)
        self.regularized = False
        if self.engine == "native":
            self.regularized = self._native_setup(P)
        elif lapack.dpotrf(H[:n, :n], lower=0, clean=0)[1] != 0:
            self.regularized = True
        if self.regularized:
            i = np.arange(n)
            eps = self.regularization * max(1.0, float(H.diagonal()[:n].max()))
            H[i, i] += eps
            W.append(np.sqrt(eps) * np.eye(n))
        wh = None
        if self.engine == "python":
            wh = _whitening(W, np.concatenate(sw) if sw else np.zeros(0), n)
        self._T: np.ndarray | None = None
        self._Fw: np.ndarray | None = None
        if wh is not None:
            self._T, self._Fw = wh
        self._fw_fresh = False
        hard = P.hard
        # rows after the simple bounds: hard equalities, hard inequalities, soft rows C x − s
        G = np.zeros((hard.m_eq + hard.m_in + mi, nv))
        r = 0
        if hard.m_eq:
            G[: hard.m_eq, :n] = hard.Ae
            r = hard.m_eq
        if hard.m_in:
            G[r : r + hard.m_in, :n] = hard.C
            r += hard.m_in
        j = n
        for L in soft:
            G[r : r + L.m_in, :n] = L.C
            G[r : r + L.m_in, j : j + L.m_in] = -np.eye(L.m_in)
            r += L.m_in
            j += L.m_in
        self._bounded = P.lb is not None
        self._dummy = G.shape[0] == 0 and not self._bounded
        if self._dummy:
            G = np.zeros((1, nv))  # daqp needs a constraint: an always-inactive one
        self._n, self._nv = n, nv
        # no soft inequality: the unconstrained optimum -H⁻¹f is tried first each step (a
        # Cholesky factor kept from here); it is the QP's answer whenever it meets the hard
        # rows and bounds -- exact, where daqp's LDL loses accuracy on ill-conditioned H
        self._chol = None
        self._try_unconstrained = True
        #: parametrize()'s size of θ and, by task id, (task, [(c, M) per side])
        self._pspec: tuple[int, dict[int, tuple[Any, list[tuple[Any, np.ndarray]]]]] | None = None
        #: the unconstrained optimum affine in θ: (z0, Z, e0, E)
        self._pz: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        #: the limit rows stacked: (Lb, lb0, [G; −G], scratch)
        self._fused: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._p_version: list[int] | None = None
        if mi == 0:
            cho, info = lapack.dpotrf(H, lower=0, clean=1)
            if info == 0:
                self._chol = cho
        self._F = np.hstack(F) if F else np.zeros((n, 0))
        self._eq_tasks = eq_tasks
        self._b = np.zeros(self._F.shape[1])
        self._f = np.zeros(nv)
        self._H, self._G = H, G
        # limit rows filled per step: (task, attribute pair, slice of bu/bl)
        m0 = nv if self._bounded else 0
        rows = []
        k = m0 + (1 if self._dummy else 0)
        for t in hard.eqs:
            m = t.A.shape[0]
            rows.append((t, "eq", slice(k, k + m)))
            k += m
        for t in (*hard.ineqs, *(t for L in soft for t in L.ineqs)):
            m = t.C.shape[0]
            rows.append((t, "in", slice(k, k + m)))
            k += m
        self._rows = rows
        self._bu = np.full(k, _INF)
        self._bl = np.full(k, -_INF)
        if self._dummy:
            self._bu[0], self._bl[0] = 1.0, -1.0
        self._bounds_version = None
        self._fill_limits(P)
        self._version = self._versions(P)
        # hard rows (after the simple bounds in daqp's order) for a one-matvec check
        mh = hard.m_eq + hard.m_in
        self._G_hard = G[:mh, :n] if mh else None
        h0 = m0 + (1 if self._dummy else 0)
        self._hard_slice = slice(h0, h0 + mh)
        # no slack and bounded: bounds then hard rows lead daqp's limit vectors, so one
        # stacked matrix [I; G_hard] checks them all with one matvec
        self._G_check: np.ndarray | None = None
        if mi == 0 and self._bounded:
            self._G_check = np.vstack((np.eye(n), G[:mh, :n]))
            self._check_rows = slice(0, n + mh)
        # residual rows: the equality tasks stacked (same order as self._b), with the level
        # of each task, for a one-matvec residual; inequality tasks one by one
        self._nlevels = len(P.levels)
        self._res_eq: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None
        if eq_tasks:
            lev_of = {id(t): k for k, L in enumerate(P.levels) for t in L.eqs}
            sizes = [t.A.shape[0] for t in eq_tasks]
            self._res_eq = (
                np.vstack([t.A for t in eq_tasks]),
                np.concatenate([t.sqrt_weight for t in eq_tasks]),
                np.concatenate(([0], np.cumsum(sizes)[:-1])),
                np.array([lev_of[id(t)] for t in eq_tasks]),
            )
        else:
            self._res_eq = None
        self._res_in = [(k, t) for k, L in enumerate(P.levels) for t in L.ineqs]
        self.setups += 1
        if self.engine == "native":
            return
        Hq, Gq = H, G
        T = self._T
        if T is not None:
            # daqp gets the QP in u = T x (elimination.WHITENED): the identity as u's
            # Hessian, every row (the bounds too, as rows of T⁻¹, in the same order of the
            # limit vectors) through T⁻¹; f and the answer are mapped per step
            Hq = H.copy()
            Hq[:n, :n] = np.eye(n)
            Gq = whiten_rows(np.vstack((np.eye(nv), G)) if self._bounded else G.copy(), T, n)
            self._fw = np.zeros(nv)
        model = self._daqp.Model()
        model.settings = dict(model.settings, **DAQP_SETTINGS)
        flag = model.setup(Hq, self._f, Gq, self._bu, self._bl, np.zeros(k, dtype=np.int32))
        if isinstance(flag, tuple):
            flag = flag[0]
        # a failed set-up (e.g. constraints daqp's presolve finds inconsistent) leaves no
        # workspace: every step then goes to the general path, which reports the cause
        self.model = model if flag >= 0 else None

    def _native_setup(self, P) -> bool:
        """The native workspace: its own stacked arrays (the constant matrices written once;
        per step only ``beq``, the limits and the box), the write plan of a step, and one
        solve that factors the Hessian. Returns whether ``ε`` was added (its rule)."""
        P.refresh_stacked()
        arrs = tuple(a.copy() for a in (P.Aeq, P.beq, P.C, P.clo, P.chi, P.csw, P.lbs, P.ubs))
        self._nb = arrs
        eq_plan, in_plan = [], []
        i = j = 0
        for B in (P.hard, *P.levels):
            for t in B.eqs:
                m = t.A.shape[0]
                eq_plan.append((t, slice(i, i + m), None if t.unit_weight else t.sqrt_weight))
                i += m
            for t in B.ineqs:
                m = t.C.shape[0]
                in_plan.append((t, slice(j, j + m)))
                j += m
        self._nb_plan = (eq_plan, in_plan)
        self._nb_bounds = None
        self._nw = NativeWeighted(P, self.regularization, self.weight_ratio, arrays=arrs)
        try:
            self._nw.run(P, warm=False, refactor=True)
        except (InfeasibleError, SolverError, ValueError):
            pass  # the steps report it (they fall back to the general path)
        return bool(self._nw.detail[6])

    def _native_fill(self, P) -> None:
        """Write the tasks' right-hand sides, limits and the box into the native arrays."""
        beq, clo, chi, lbs, ubs = self._nb[1], self._nb[3], self._nb[4], self._nb[6], self._nb[7]
        eq_plan, in_plan = self._nb_plan
        for t, sl, sw in eq_plan:
            if sw is None:
                beq[sl] = t.b
            else:
                np.multiply(t.b, sw, out=beq[sl])
        for t, sl in in_plan:
            clo[sl] = t.lower
            chi[sl] = t.upper
        b = P.bounds
        if self._bounded and b.version != self._nb_bounds:
            lbs[...], ubs[...] = b.resolve(self._n)
            self._nb_bounds = b.version

    def _native_step(self, P) -> np.ndarray | None:
        """One native solve on the filled arrays; the checked ``x`` (a new array) or ``None``
        (then: fall back). Sets ``_lam`` (the active rows in daqp's order) and ``_iters``."""
        nw = self._nw
        assert nw is not None  # the native engine's workspace (_setup)
        try:
            nw.run(P, warm=True, time_left=DEFAULT_TIME_LIMIT, refactor=False)
        except (InfeasibleError, SolverError, ValueError):
            self._lam = None
            return None
        self._iters = int(nw.detail[2])
        act = nw.active
        self._lam = act if self._bounded else act[self._n :]
        return nw.x.copy()

    def _fill_limits(self, P) -> None:
        bu, bl = self._bu, self._bl
        b = P.bounds
        if self._bounded and b.version != self._bounds_version:
            lo, hi = b.resolve(self._n)
            np.minimum(hi, _INF, out=bu[: self._n])
            np.maximum(lo, -_INF, out=bl[: self._n])
            self._bounds_version = b.version
        for t, kind, sl in self._rows:  # daqp reads |bound| ≥ 1e30 (inf too) as none
            if kind == "eq":
                bu[sl] = t.b
                bl[sl] = t.b
            else:
                bu[sl] = t.upper
                bl[sl] = t.lower

    # ------------------------------------------------------------------ per step
    def solve(self) -> Solution:
        """Solve with the tasks' current numbers (one control step).

        Returns
        -------
        Solution
            ``method="weighted"``; ``info``: ``persistent`` (True when the persistent
            workspace answered), ``iterations`` (daqp's; 0 when the unconstrained optimum
            was feasible), ``setups`` (workspace set-ups so far: 1 unless the matrices,
            weights or the presence of bounds changed), ``fallbacks`` (steps answered by
            ``stack.solve(method="weighted")`` so far).

        Raises
        ------
        InfeasibleError, SolverError
            As :meth:`Stack.solve` (from the fallback), if the fallback fails too.
        """
        t0 = time.perf_counter()
        x, iterations = self._solve_x()
        if x is None:
            sol = self._fallback()
        else:
            sol = Solution(
                x=x,
                status="optimal",
                level_residuals=self._nw.res.copy() if self._nw else self._residuals(x),
                solver="native" if self.engine == "native" else "daqp",
                solve_time=time.perf_counter() - t0,
                method="weighted",
                info={
                    "persistent": True,
                    "iterations": iterations,
                    "setups": self.setups,
                    "fallbacks": self.fallbacks,
                    "qp_calls": 1,
                },
            )
        self.last = sol
        return sol

    def solve_x(self) -> np.ndarray:
        """:meth:`solve` for the hot loop: only the checked ``x`` (no residuals, no
        :class:`~qpcoord.Solution`); the fallback is the same (:attr:`last` is set then)."""
        x, _ = self._solve_x()
        return self._fallback().x if x is None else x

    def _fallback(self) -> Solution:
        self.fallbacks += 1
        if self.engine == "native":
            sol = self.stack.solve(method="weighted", engine="python")
        else:
            sol = self.stack.solve(solver="daqp", method="weighted")
        sol.info.update(persistent=False, setups=self.setups, fallbacks=self.fallbacks)
        self.last = sol
        return sol

    def _solve_x(self) -> tuple[np.ndarray | None, int]:
        """Checked ``x`` from the persistent workspace, or ``None`` (then: fall back)."""
        P = self.stack.compiled
        if self._versions(P) != self._version or (P.bounds is not None) != self._bounded:
            P.refresh()
            self._setup(P)
        if self.engine == "native":
            self._native_fill(P)
            x = self._native_step(P)
            return x, (0 if x is None else self._iters)
        n = self._n
        if self._eq_tasks:
            i = 0
            b = self._b
            for t in self._eq_tasks:
                m = t.b.shape[0]
                b[i : i + m] = t.b
                i += m
            if self._T is None:
                f = self._f[:n]
                np.dot(self._F, b, out=f)
                np.negative(f, out=f)
            else:
                # whitened: f_u = T⁻ᵀ f = −Q₁ᵀ diag(s) b, not through the formed f (whose
                # rounding, ε‖F‖‖b‖, T⁻ᵀ would amplify by cond(T)); f itself is not needed
                fu = self._fw[:n]
                assert self._Fw is not None  # whitened: the map of the Python engine
                np.dot(self._Fw, b, out=fu)
                np.negative(fu, out=fu)
                self._fw_fresh = True
        self._fill_limits(P)
        return self._solve_current()

    def _unconstrained(self) -> np.ndarray | None:
        """The unconstrained optimum ``−H⁻¹f`` (no soft row: ``nv = n``), or ``None``: from
        the whitening factor where there is one (``x = −T⁻¹ f_u``, errors ~ε·cond(T)),
        else from the Cholesky factor of the formed ``H``."""
        if self._T is not None:
            z, ok = lapack.dtrtrs(self._T, self._fw, lower=0)
        else:
            z, ok = lapack.dpotrs(self._chol, self._f, lower=0)
        if ok != 0:
            return None
        return np.negative(z, out=z)

    def _solve_current(
        self, check=None, unconstrained_first: bool = True
    ) -> tuple[np.ndarray | None, int]:
        """The QP with the current ``_f``, ``_bu``, ``_bl``: unconstrained try, then daqp.

        ``check(x) -> bool`` replaces :meth:`_feasible` for daqp's answer (the parametric
        path has a cheaper, equivalent one). ``unconstrained_first=False`` skips the
        unconstrained try (the caller made it). Sets ``_lam``: daqp's multipliers, or
        ``None`` when the unconstrained optimum answered."""
        check = self._feasible if check is None else check
        n = self._n
        self._lam = None
        T = self._T
        if T is not None and not self._fw_fresh:  # the QP in u = T x: f_u = T⁻ᵀ f
            fw = self._fw
            fw[:] = self._f
            fw[:n] = lapack.dtrtrs(T, self._f[:n], lower=0, trans=1)[0]
        self._fw_fresh = False
        # consecutive steps are alike: the unconstrained optimum is tried first only when
        # the previous step had no active constraint (daqp's multipliers all zero)
        if self._chol is not None and self._try_unconstrained and unconstrained_first:
            z = self._unconstrained()
            if z is not None and self._feasible(z):
                return z, 0
        model = self.model
        if model is None:
            return None, 0
        model.update(f=self._f if T is None else self._fw, bupper=self._bu, blower=self._bl)
        y, _, flag, info = model.solve()
        if flag in (1, 2):
            if T is None:
                x = np.asarray(y[:n], dtype=float)
            else:
                x = lapack.dtrtrs(T, np.asarray(y[:n], dtype=float), lower=0)[0]
            if check(x):
                lam = info.get("lam")
                self._lam = lam
                self._try_unconstrained = lam is None or not lam.any()
                if self._try_unconstrained and self._chol is not None:
                    # nothing active: the exact unconstrained optimum is the answer
                    z = self._unconstrained()
                    if z is not None and self._feasible(z):
                        return z, 0
                return x, int(info.get("iterations", -1))
        return None, 0

    # ------------------------------------------------------------------ parametric form
    def parametrize(self, size: int, maps: dict) -> None:
        """Declare right-hand sides affine in a parameter vector ``θ`` (size ``size``).

        ``maps[task]`` is ``(c, M)`` for an :class:`~qpcoord.Equality` (``b = c + M θ``) or
        ``((c_lo, M_lo), (c_hi, M_hi))`` for an :class:`~qpcoord.Inequality` (its limits).
        The linear term and the limits of the QP then follow ``θ`` by two matrix-vector
        products per step (:meth:`solve_theta`), the form of a condensed MPC whose
        parameters are the state estimate and the reference. Tasks not in ``maps`` and the
        bounds keep the values they have now (call :meth:`parametrize` again after changing
        them; a changed matrix or bounds object is detected and handled).

        Raises
        ------
        ValueError
            A task not in the stack, or maps of the wrong shapes.
        """
        if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < 1:
            raise ValueError(f"size must be an integer >= 1, got {size!r}")
        P = self.stack.compiled
        tasks = {id(t): t for t in self._all_tasks}
        spec = {}
        for t, m in maps.items():
            if id(t) not in tasks:
                raise ValueError(f"parametrize: {getattr(t, 'label', t)!r} is not in the stack")
            parts = [m] if isinstance(t, Equality) else list(m)
            rows = t.A.shape[0] if isinstance(t, Equality) else t.C.shape[0]
            if len(parts) != (1 if isinstance(t, Equality) else 2):
                raise ValueError(f"parametrize: {t.label} needs (c, M) per limit")
            out = []
            for c, M in parts:
                c = np.broadcast_to(np.asarray(c, dtype=float), (rows,)).copy()
                M = np.asarray(M, dtype=float)
                if M.shape != (rows, size) or not np.all(np.isfinite(M)):
                    raise ValueError(
                        f"parametrize: {t.label}: M must be finite, shape {(rows, size)}, "
                        f"got {M.shape}"
                    )
                out.append((c, M))
            spec[id(t)] = (t, out)
        self._pspec = (int(size), spec)
        self._build_parametric(P)

    def _build_parametric(self, P) -> None:
        assert self._pspec is not None  # parametrize() set it
        size, spec = self._pspec
        b0 = np.zeros(self._F.shape[1])
        Bt = np.zeros((self._F.shape[1], size))
        i = 0
        for t in self._eq_tasks:
            m = t.b.shape[0]
            if id(t) in spec:
                ((c, M),) = spec[id(t)][1]
                b0[i : i + m], Bt[i : i + m] = c, M
            else:
                b0[i : i + m] = t.b
            i += m
        self._f0 = -(self._F @ b0)
        self._Ft = -(self._F @ Bt)
        # whitened (the Python engine): f_u = T⁻ᵀ f is affine in θ too, taken from the
        # whitened map F_w = T⁻ᵀ F as the per-step refresh does (no triangular solve per
        # step, and no rounding of the formed f amplified by cond(T))
        Fw = self._Fw  # set with _T: the whitened map (Python engine)
        self._fw_affine = None if Fw is None else (-(Fw @ b0), -(Fw @ Bt))
        self._fill_limits(P)
        k = self._bu.shape[0]
        self._lu0, self._ll0 = self._bu.copy(), self._bl.copy()
        self._Lu, self._Ll = np.zeros((k, size)), np.zeros((k, size))
        for t, kind, sl in self._rows:
            if id(t) not in spec:
                continue
            parts = spec[id(t)][1]
            if kind == "eq":
                ((c, M),) = parts
                self._lu0[sl] = self._ll0[sl] = c
                self._Lu[sl] = self._Ll[sl] = M
            else:
                (cl, Ml), (cu, Mu) = parts
                self._ll0[sl], self._Ll[sl] = cl, Ml
                self._lu0[sl], self._Lu[sl] = cu, Mu
        # the unconstrained optimum and its margins to the bounds and hard rows are affine
        # in θ too: z(θ) = z0 + Z θ, and [G z − u; l − G z] = e0 + E θ (one matvec each)
        self._pz = None
        if self._chol is not None and self._G_check is not None:
            Z = -lapack.dpotrs(self._chol, self._Ft, lower=0)[0]
            z0 = -lapack.dpotrs(self._chol, self._f0, lower=0)[0]  # no slack: nv = n
            sl = self._check_rows
            G = self._G_check
            with np.errstate(invalid="ignore"):
                E = np.vstack((G @ Z - self._Lu[sl], self._Ll[sl] - G @ Z))
                e0 = np.concatenate((G @ z0 - self._lu0[sl], self._ll0[sl] - G @ z0))
            self._pz = (z0, Z, e0, E)
        # bounds + hard rows are every limit row (no slack, no dummy): keep them stacked as
        # [u; −l] = lb0 + Lb θ, so that one matvec gives both and [G; −G] x − [u; −l] ≤ tol
        # checks an answer in three operations
        self._fused = None
        k = self._bu.shape[0]
        if self._G_check is not None and self._check_rows.stop == k:
            G = self._G_check
            self._fused = (
                np.vstack((self._Lu, -self._Ll)),
                np.concatenate((self._lu0, -self._ll0)),
                np.vstack((G, -G)),
                np.empty(2 * k),
            )
        # critical regions (module notes): possible when every limit row is a checked row
        # and H has a Cholesky factor; rows with l(θ) ≡ u(θ) are equalities (no sign test)
        self._regions: dict = {}
        self._free = None if self._pz is None else _region(*self._pz)  # nothing active
        self._recent: list = [self._free] if self._fused is not None and self._pz else []
        self._seen: dict = {}  # active sets met once (an ordered set)
        self._eq_rows = (
            (self._lu0 == self._ll0) & (self._Lu == self._Ll).all(axis=1)
            if self._fused is not None
            else None
        )
        self._p_version = self._version
        self._p_bounds = self._bounds_version
        if self.engine == "native":
            self._native_parametric(P, spec)

    def _native_parametric(self, P, spec: dict) -> None:
        """The native arrays affine in θ: ``beq = q0 + Q θ``, ``lo = l0 + L θ``,
        ``hi = h0 + U θ`` (tasks not in ``spec`` keep their current numbers)."""
        assert self._pspec is not None  # parametrize() set it
        size = self._pspec[0]
        self._native_fill(P)
        beq, clo, chi = self._nb[1], self._nb[3], self._nb[4]
        q0, Q = beq.copy(), np.zeros((beq.shape[0], size))
        l0, Lq = clo.copy(), np.zeros((clo.shape[0], size))
        h0, Uq = chi.copy(), np.zeros((chi.shape[0], size))
        eq_plan, in_plan = self._nb_plan
        for t, sl, sw in eq_plan:
            if id(t) in spec:
                ((c, M),) = spec[id(t)][1]
                w = np.ones(c.shape[0]) if sw is None else sw
                q0[sl], Q[sl] = w * c, w[:, None] * M
        for t, sl in in_plan:
            if id(t) in spec:
                (cl, Ml), (cu, Mu) = spec[id(t)][1]
                l0[sl], Lq[sl], h0[sl], Uq[sl] = cl, Ml, cu, Mu
        self._nb_param = (q0, Q, l0, Lq, h0, Uq)

    def _build_region(self, lam: np.ndarray):
        """The affine law and KKT test of the critical region whose active rows are
        ``lam``'s non-zero entries (daqp's sign: > 0 upper, < 0 lower), or ``None`` if the
        active rows are linearly dependent (degenerate: left to the QP solver).

        Null-space form, accurate when ``H`` is ill-conditioned: with ``G_Aᵀ = [Q₁ Q₂] R``
        (QR), the active rows ``G_A x = b_A(θ) = c + M θ`` give
        ``x = Q₁ R⁻ᵀ b_A + Q₂ y``, ``y`` minimises the cost on ``Q₂``'s span
        (``Q₂ᵀ H Q₂ y = −Q₂ᵀ (H xₚ + f)``), and the multipliers solve
        ``R ν = −Q₁ᵀ (H x + f)``; all are affine in θ. The region's test stacks every row's
        margin ``[G; −G] x − [u; −l]`` and ``−sign·ν`` of every active inequality:
        ``r0 + R θ ≤ REGION_TOL``."""
        act = np.flatnonzero(lam)
        if act.size == 0:
            return self._free
        n, k = self._n, act.size
        if k > n:
            return None
        up = lam[act] > 0
        # regions are learnt only with the limit rows stacked (_fused, _G_check, _eq_rows)
        assert self._G_check is not None and self._fused is not None
        assert self._eq_rows is not None
        GA = self._G_check[act]
        c = np.where(up, self._lu0[act], self._ll0[act])
        M = np.where(up[:, None], self._Lu[act], self._Ll[act])
        Q, Rq = np.linalg.qr(GA.T, mode="complete")
        Rq = Rq[:k]
        d = np.abs(np.diag(Rq))
        if d.min() <= 1e-9 * d.max():  # dependent active rows
            return None
        Q1, Q2 = Q[:, :k], Q[:, k:]
        T = Q1 @ np.linalg.solve(Rq.T, np.eye(k))  # x_p = T b_A
        H = self._H[:n, :n]
        xp0, Xp = T @ c, T @ M
        f0, Ft = self._f0, self._Ft
        if k < n:
            Hr = Q2.T @ H @ Q2
            Lr, info = lapack.dpotrf(Hr, lower=0, clean=1)
            if info != 0:
                return None
            y0 = -lapack.dpotrs(Lr, Q2.T @ (H @ xp0 + f0), lower=0)[0]
            Y = -lapack.dpotrs(Lr, Q2.T @ (H @ Xp + Ft), lower=0)[0]
            x0, X = xp0 + Q2 @ y0, Xp + Q2 @ Y
        else:
            x0, X = xp0, Xp
        nu0 = -np.linalg.solve(Rq, Q1.T @ (H @ x0 + f0))
        Nu = -np.linalg.solve(Rq, Q1.T @ (H @ X + Ft))
        Lb, lb0, GG, _ = self._fused
        ineq = ~self._eq_rows[act]
        sgn = np.where(up, -1.0, 1.0)[ineq]
        with np.errstate(invalid="ignore"):
            R = np.vstack((GG @ X - Lb, sgn[:, None] * Nu[ineq]))
            r0 = np.concatenate((GG @ x0 - lb0, sgn * nu0[ineq]))
        if not (np.isfinite(R).all() and np.isfinite(x0).all() and np.isfinite(X).all()):
            return None
        return _region(x0, X, r0, R)

    def _learn_region(self, lam: np.ndarray | None) -> None:
        """After a QP answer: make its critical region the one tried first next step. A
        region is built the second time its active set is met (a set met once costs
        nothing) and kept in a small LRU cache."""
        if lam is None or not lam.any():
            region = self._free
        else:
            key = np.flatnonzero(lam).tobytes() + (lam[lam != 0] > 0).tobytes()
            regions = self._regions
            if key in regions:
                region = regions.pop(key)
                regions[key] = region  # most recently used last
            elif key not in self._seen:  # first sighting: remembered, not built
                self._seen[key] = None
                if len(self._seen) > 4 * REGION_CACHE:
                    del self._seen[next(iter(self._seen))]
                return
            else:
                region = regions[key] = self._build_region(lam)
                if len(regions) > REGION_CACHE:
                    del regions[next(iter(regions))]
        if region is not None:
            self._use_region(region)

    def _use_region(self, region) -> None:
        """Put ``region`` first in the list of regions tried per step."""
        recent = self._recent
        for i, r in enumerate(recent):
            if r is region:
                del recent[i]
                break
        recent.insert(0, region)
        del recent[REGION_TRIES:]

    def solve_theta(self, theta: np.ndarray) -> np.ndarray:
        """Checked ``x`` for the parameter ``θ`` declared by :meth:`parametrize` (hot loop).

        The last step's critical region is tried first (module notes; counted in
        :attr:`region_steps`), then the QP solver, hot-started (:attr:`qp_steps`). On a
        failure the tasks are given the values ``θ`` implies and the step goes to
        ``stack.solve(method="weighted")`` (counted in :attr:`fallbacks`).
        """
        if self._pspec is None:
            raise ValueError("solve_theta: call parametrize() first")
        P = self.stack.compiled
        if self._versions(P) != self._version or (P.bounds is not None) != self._bounded:
            P.refresh()
            self._setup(P)
        if self._p_version != self._version or (
            self._bounded and P.bounds is not None and P.bounds.version != self._p_bounds
        ):
            self._build_parametric(P)
        # θ real, finite, of the declared size (one dot product); else _theta names the
        # problem (a NaN θ once went on to the fallback's proxqp for 72 s)
        try:
            d = len(theta) == self._pspec[0] and theta @ theta
            ok = isinstance(d, float) and math.isfinite(d)  # np.float64 is a float; complex not
        except (TypeError, ValueError):
            ok = False
        if not ok:
            theta = self._theta(theta, "solve_theta")  # raises unless merely huge or a list
        recent = self._recent
        for i, (m, W, w0) in enumerate(recent):
            v = W @ theta  # [test rows; x]: one matvec gives both
            v += w0
            if v[:m].max() <= REGION_TOL:  # NaN fails too
                self.region_steps += 1
                if i:
                    recent.insert(0, recent.pop(i))
                return v[m:]
        if self._fused is None and self._pz is not None and self._try_unconstrained:
            z0, Z, e0, E = self._pz
            if (E @ theta + e0).max() <= CHECK_TOL:
                self.region_steps += 1
                return z0 + Z @ theta
        if self.engine == "native":
            q0, Q, l0, Lq, h0, Uq = self._nb_param
            beq, clo, chi = self._nb[1], self._nb[3], self._nb[4]
            np.dot(Q, theta, out=beq)
            beq += q0
            if clo.shape[0]:
                np.dot(Lq, theta, out=clo)
                clo += l0
                np.dot(Uq, theta, out=chi)
                chi += h0
            x = self._native_step(P)
            if x is not None:
                self.qp_steps += 1
                if self._fused is not None and self._pz is not None:
                    self._learn_region(self._lam)
                return x
            self.write_tasks(theta)
            return self._fallback().x
        if self._fw_affine is None:
            f = self._f[: self._n]
            np.dot(self._Ft, theta, out=f)
            f += self._f0
        else:  # whitened: f_u(θ) directly (_solve_current then skips T⁻ᵀ f)
            fw0, Fwt = self._fw_affine
            fu = self._fw[: self._n]
            np.dot(Fwt, theta, out=fu)
            fu += fw0
            self._fw_fresh = True
        check = None
        if self._fused is not None:
            Lb, lb0, _, bb = self._fused
            k = self._bu.shape[0]
            np.dot(Lb, theta, out=bb)
            bb += lb0
            self._bu[:] = bb[:k]
            np.negative(bb[k:], out=self._bl)
            check = self._fused_check
        else:
            np.dot(self._Lu, theta, out=self._bu)
            self._bu += self._lu0
            np.dot(self._Ll, theta, out=self._bl)
            self._bl += self._ll0
        # the region test already covered the unconstrained optimum when there is one
        x, _ = self._solve_current(check, unconstrained_first=self._fused is None)
        if x is not None:
            self.qp_steps += 1
            if self._fused is not None and self._pz is not None:
                self._learn_region(self._lam)
            return x
        self.write_tasks(theta)
        return self._fallback().x

    def _fused_check(self, x: np.ndarray) -> bool:
        """``[G; −G] x ≤ [u; −l]`` to ``CHECK_TOL`` absolute, else the relative rule."""
        assert self._fused is not None  # called only when the rows are stacked
        _, _, GG, bb = self._fused
        return (GG @ x - bb).max() <= CHECK_TOL or self._feasible(x)

    def write_tasks(self, theta: np.ndarray) -> None:
        """Give the parametrised tasks the values ``θ`` implies (the stack can then be
        solved by any method or backend, e.g. to compare them)."""
        if self._pspec is None:
            raise ValueError("write_tasks: call parametrize() first")
        theta = self._theta(theta, "write_tasks")
        for t, parts in self._pspec[1].values():
            # the tasks' checked, version-keeping write path (their arrays are read-only)
            if isinstance(t, Equality):
                ((c, M),) = parts
                t._assign(b=c + M @ theta)
            else:
                (cl, Ml), (cu, Mu) = parts
                t._assign(cl + Ml @ theta, cu + Mu @ theta)

    def _theta(self, theta, where: str) -> np.ndarray:
        """θ as a finite float vector of the declared size, else ``ValueError``/``TypeError``
        naming it (off the hot path: called once a step has left the cached regions)."""
        if self._pspec is None:
            raise ValueError(f"{where}: call parametrize() first")
        size = self._pspec[0]
        if np.iscomplexobj(theta):
            raise TypeError(f"{where}: theta is complex; it must be real")
        try:
            arr = np.asarray(theta, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{where}: theta must be a numeric vector, got {theta!r}") from None
        if arr.shape != (size,):
            raise ValueError(
                f"{where}: theta must have shape ({size},) as declared by parametrize(), "
                f"got {np.shape(theta)}"
            )
        if not np.isfinite(arr).all():
            i = int(np.flatnonzero(~np.isfinite(arr))[0])
            raise ValueError(f"{where}: theta[{i}] = {float(arr[i])!r} is not finite")
        return arr

    def _feasible(self, x: np.ndarray) -> bool:
        """Finite, within the bounds and the hard rows to the stack's CHECK_TOL relative to
        ``max(1, |bound|)`` (:func:`qpcoord.core.tolerance.within`'s rule; an absolute
        ``CHECK_TOL`` test, stricter, is tried first)."""
        if self._G_check is not None:  # NaN or inf in x fails both tests of _inside
            sl = self._check_rows
            return _inside(self._G_check @ x, self._bl[sl], self._bu[sl])
        if not all_finite(x):
            return False
        n = self._n
        if self._bounded and not _inside(x, self._bl[:n], self._bu[:n]):
            return False
        if self._G_hard is not None:
            sl = self._hard_slice
            if not _inside(self._G_hard @ x, self._bl[sl], self._bu[sl]):
                return False
        return True

    def _residuals(self, x: np.ndarray) -> np.ndarray:
        """Per-level residual norms (as ``CompiledLevel.residual``), one matvec per kind."""
        sq = np.zeros(self._nlevels)
        if self._res_eq is not None:
            A, sw, starts, lev = self._res_eq
            b = self._b if self._eq_tasks else None
            r = sw * (A @ x - b)
            sq += np.bincount(lev, np.add.reduceat(r * r, starts), minlength=self._nlevels)
        for k, t in self._res_in:
            cx = t.C @ x
            v = t.sqrt_weight * (cx - np.clip(cx, t.lower, t.upper))
            sq[k] += float(v @ v)
        return np.sqrt(sq)
