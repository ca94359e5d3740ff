"""The prioritised QP stack: :class:`Stack`, :class:`Solution` and :func:`solve_stack`."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from functools import cached_property
from math import isfinite
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .backends import DEFAULT_TIME_LIMIT, check_solver, check_time_limit, deadline, time_left
from .compile import CompiledStack, compile_stack
from .conflict import infeasible
from .elimination import CHECK_TOL, FEAS_TOL, Reduced
from .errors import InfeasibleError, SolverError
from .linalg import all_finite
from .methods.hierarchical import solve_equality_chain, solve_hierarchical
from .methods.nullspace import check_equality_only, solve_nullspace
from .methods.weighted import solve_weighted
from .native import NativeHierarchy, resolve_engine
from .native_weighted import NativeWeighted, resolve_weighted_engine
from .persistent import PersistentQP
from .polish import KKT_TOL
from .solution import Solution, inaccurate
from .tasks import Bounds, Equality, Inequality
from .tolerance import within

__all__ = ["Stack", "Solution", "solve_stack", "METHODS", "Level"]

#: One priority level: a task, or a list of tasks whose squared residuals add up
Level = Equality | Inequality | Sequence[Equality | Inequality]

#: The solve methods a :class:`Stack` offers.
METHODS = ("hierarchical", "nullspace", "weighted")


def _limit_error(limit: float, exc: SolverError) -> SolverError:
    """The error of a solve whose backend failed once its time limit of ``limit`` s passed."""
    return SolverError(
        f"time limit of {limit:g} s reached before the solve ended "
        f"(time_limit=...; math.inf lifts it): {exc}"
    )


def _call_native(
    native: NativeHierarchy | NativeWeighted, P: CompiledStack, limit: float
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """``native.solve(P, time_left=...)`` (a :class:`~qpcoord.core.native.NativeHierarchy` or
    :class:`~qpcoord.core.native_weighted.NativeWeighted`) with the solve's time limit
    ``limit`` (s) or, if earlier, an enclosing solve's deadline; a native error raised once
    that time has passed is the time-limit error. Returns ``(x, level values, info)``."""
    left = time_left()  # an enclosing solve's deadline (None: none)
    limit_now = left if left is not None and left < limit else limit
    t1 = time.perf_counter()
    try:
        return native.solve(P, time_left=limit_now)
    except SolverError as exc:
        if "time limit" in str(exc) or time.perf_counter() - t1 >= limit_now:
            raise _limit_error(limit, exc) from exc
        raise


_INF = math.inf


def _check_options(regularization: object, damping: object, weight_ratio: object) -> None:
    """``ValueError`` naming the first of a :class:`Stack`'s numeric options that is not a
    finite number in its range (``damping`` may be 0, the others must be positive)."""
    for name, value, lo_ok in (
        ("regularization", regularization, False),
        ("damping", damping, True),
        ("weight_ratio", weight_ratio, False),
    ):
        if not (type(value) is float and isfinite(value)) and (
            isinstance(value, bool)
            or not isinstance(value, (int, float, np.floating, np.integer))
            or not np.isfinite(value)
        ):
            raise ValueError(f"{name} must be a finite number, got {value!r}")
        if value < 0 or (value == 0 and not lo_ok):
            raise ValueError(f"{name} must be {'>= 0' if lo_ok else '> 0'}, got {value!r}")


class Stack:
    """A prioritised stack of tasks, solved once per control step.

    Parameters
    ----------
    levels : sequence
        ``levels[0]`` is the highest priority. Each item is a task
        (:class:`~qpcoord.Equality` / :class:`~qpcoord.Inequality`) or a list of tasks that
        share the level (their squared residuals add up).
    bounds : Bounds, optional
        Box on ``x``, always hard.
    regularization : float
        Weight of ``‖x‖²``-type terms that keep every QP strictly convex in directions a
        level leaves free (default ``1e-9``, relative to a unit-weight task). It does not bias
        the strict hierarchy: every level is certified on its own problem without it (a
        point it biased is made exact by an active-set continuation), and those directions
        are handed to lower levels and finally to the minimum-norm step.
    damping : float
        Relative singular-value threshold ``τ/s₀`` under which a level's directions are
        damped rather than inverted exactly (default ``1e-7``; see :mod:`qpcoord.core.linalg`):
        gains are ``1/s`` above ``τ`` and ``s/τ²`` below, so no step exceeds ``‖e‖/τ``.
    constraints : sequence of tasks, optional
        Hard constraints: must hold exactly (to ``1e-6`` relative). Inconsistent hard
        constraints or bounds raise :class:`~qpcoord.InfeasibleError`.
    weight_ratio : float
        Cost ratio between consecutive levels for ``method="weighted"`` (default ``1e-3``).
    fallback : bool
        If the backend fails on a level QP (such QPs are feasible by construction, so a
        claimed infeasibility is the backend's failure), solve that QP with the next of
        quadprog, daqp, proxqp instead (default ``True``); reported in
        ``Solution.info["fallbacks"]``. ``False`` raises :class:`~qpcoord.SolverError`
        (use it to compare backends).

    Notes
    -----
    The stack keeps references to its tasks. Change their numbers with ``task.update(...)``
    (same shapes) and call :meth:`solve` again: the structure is validated once and the
    buffers are reused (the per-step hot path).
    """

    def __init__(
        self,
        levels: Sequence[Level],
        bounds: Bounds | None = None,
        regularization: float = 1e-9,
        damping: float = 1e-7,
        constraints: Sequence[Equality | Inequality] | None = None,
        weight_ratio: float = 1e-3,
        fallback: bool = True,
    ) -> None:
        if not isinstance(fallback, bool):
            raise ValueError(f"fallback must be True or False, got {fallback!r}")
        if not (  # the common case (Python floats in range) without _check_options
            type(regularization) is float
            and type(damping) is float
            and type(weight_ratio) is float
            and 0.0 < regularization < _INF
            and 0.0 <= damping < _INF
            and 0.0 < weight_ratio < _INF
        ):
            _check_options(regularization, damping, weight_ratio)
        self._compiled = compile_stack(levels, bounds, constraints)
        self.regularization = float(regularization)
        self.damping = float(damping)
        self.weight_ratio = float(weight_ratio)
        self._solvers: dict[str | None, str] = {}  # resolved solver names (resolving costs ~0.1 ms)
        self._fallback = fallback
        self._chain_missed = False
        self._native: NativeHierarchy | None = None  # built at the first native solve
        self._native_weighted: NativeWeighted | None = None  # the first native weighted solve

    @cached_property
    def _work(self) -> Reduced:
        """The Python engine's workspace, built at its first use (a native solve never
        needs it)."""
        return Reduced(self._compiled.n, self._compiled.capacity, self._fallback)

    @property
    def compiled(self) -> CompiledStack:
        """The stack's compiled form: its levels' stacked rows and the bounds, the arrays the
        engines read (refreshed from the tasks at each solve; read-only use)."""
        return self._compiled

    @property
    def n(self) -> int:
        """Number of decision variables."""
        return self._compiled.n

    @property
    def num_levels(self) -> int:
        """Number of priority levels (hard constraints not counted)."""
        return len(self._compiled.levels)

    @property
    def levels(self) -> list[list[Equality | Inequality]]:
        """The tasks of each level (equalities first, then inequalities)."""
        return [L.eqs + L.ineqs for L in self._compiled.levels]

    def solve(
        self,
        solver: str | None = None,
        method: str = "hierarchical",
        warm_start: Solution | ArrayLike | None = None,
        strict: bool = False,
        *,
        time_limit: float | None = None,
        engine: str | None = None,
    ) -> Solution:
        """Solve the stack with the tasks' current numbers.

        Parameters
        ----------
        solver : str, optional
            QP backend name from :func:`~qpcoord.available_solvers` (default: the fastest
            installed, ``daqp`` when present).
        method : {"hierarchical", "nullspace", "weighted"}
            Strict lexicographic priorities, the classic projection formula (equalities
            only), or one weighted QP.
        warm_start : Solution or array_like, optional
            The previous step's solution (or its ``x``); gives the QPs a primal start.
        strict : bool
            Raise :class:`~qpcoord.SolverError` instead of returning a solution whose
            ``status`` is ``"inaccurate"`` (a level whose optimality conditions could not be
            certified, ``method="hierarchical"``). The native engine is exact (each level's
            active set ends only on a working set whose multipliers have the right signs);
            its own check is that every level keeps, at the returned ``x``, the value it was
            frozen with (to ``KKT_TOL`` relative to ``max(1, value, scale)``, the level's scale
            ``‖b‖ + ‖A‖_F·‖x‖``, the size of its value's rounding): ``"inaccurate"`` /
            ``SolverError`` if not.
        time_limit : float, optional
            Bound (s) on the whole solve, fallbacks included: no QP starts after it and
            each backend gets the time left (``None``: ``DEFAULT_TIME_LIMIT`` = 10 s of
            :mod:`qpcoord.core.backends`; ``math.inf``: no limit). The linear algebra
            between QPs is not interrupted. The native engine checks it at every active-set
            iteration (the same ``SolverError`` message).
        engine : {None, "native", "python"}
            ``"native"``: the compiled solver of :mod:`qpcoord.core.native` (method
            ``"hierarchical"``; ``"weighted"``: :mod:`qpcoord.core.native_weighted`; no
            ``solver``; warm-started from the previous call's
            working sets). ``"python"``: the methods of :mod:`qpcoord.core.methods`. ``None``:
            :data:`qpcoord.core.native.DEFAULT_ENGINE` where the native engine applies, else
            Python (one warning per process if the default is native but not built).

        Returns
        -------
        Solution

        Raises
        ------
        ValueError
            Unknown method, solver or engine, bad warm start, inequalities with
            ``"nullspace"``, bad ``time_limit``, a non-finite number in a task or the bounds
            (naming it), ``engine="native"`` with another method or an explicit solver.
        NativeUnavailableError
            ``engine="native"`` but the extension is not built (an ``ImportError``).
        InfeasibleError
            Bounds and hard constraints are inconsistent.
        SolverError
            A backend failed or returned a point that violates the hard constraints, or
            the time limit was reached; with ``strict=True`` also a level that could not be
            certified.
        """
        t0 = time.perf_counter()
        limit = DEFAULT_TIME_LIMIT if time_limit is None else check_time_limit(time_limit)
        if strict is not True and strict is not False:
            raise ValueError(f"strict must be True or False, got {strict!r}")
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
        try:
            if method == "weighted" and resolve_weighted_engine(engine, solver) == "native":
                return self._solve_native_weighted(t0, warm_start, limit)
            if resolve_engine(engine, method, solver) == "native":
                return self._solve_native(t0, warm_start, strict, limit)
        except InfeasibleError as exc:  # the engine's words, and the rows in conflict
            P = self._compiled
            raise infeasible(str(exc), P, P.lbs, P.ubs).with_traceback(exc.__traceback__) from None
        # every QP the Python engine starts gets the time left (backends.deadline); a backend
        # failure once it has passed is a SolverError that says so
        with deadline(limit) as budget:
            try:
                return self._solve_python(t0, solver, method, warm_start, strict)
            except InfeasibleError as exc:  # the engine's words, and the rows in conflict
                P = self._compiled
                err = infeasible(str(exc), P, P.lb, P.ub)
                raise err.with_traceback(exc.__traceback__) from None
            except SolverError as exc:
                if budget.expired() or "time limit" in str(exc):
                    raise _limit_error(limit, exc) from exc
                raise

    def _solve_python(
        self,
        t0: float,
        solver: str | None,
        method: str,
        warm_start: Solution | ArrayLike | None,
        strict: bool,
    ) -> Solution:
        """:meth:`solve` with the Python engine (under the solve's deadline)."""
        P = self._compiled
        P.refresh()
        x_warm = self._warm(warm_start)
        if method == "nullspace":
            check_equality_only(P)
            x, info = solve_nullspace(P, self.damping)
            used = "none"
            R = None
        else:
            known = self._solvers.get(solver)
            used = known if known is not None else check_solver(solver)
            self._solvers[solver] = used
            R = None
            # equality levels only: try the closed-form chain first, unless it missed the
            # bounds at the previous step (consecutive control steps are alike; a miss
            # costs the chain's time on top of the general path's)
            if method == "hierarchical" and P.equalities_only and not self._chain_missed:
                x, info = solve_equality_chain(P, self.damping)
                if P.lb is not None and P.ub is not None:
                    if not within(x, P.lb, P.ub, FEAS_TOL):
                        R = self._reset(used)
                        self._chain_missed = True
                    else:  # met to FEAS_TOL: snapped, a returned x never leaves its box
                        np.clip(x, P.lb, P.ub, out=x)
            else:
                R = self._reset(used)
        if R is not None:
            if method == "hierarchical":
                info = solve_hierarchical(P, R, self.damping, self.regularization, x_warm)
                if not info["qp_calls"]:
                    self._chain_missed = False  # closed forms sufficed: chain next time
            else:
                info = solve_weighted(P, R, self.regularization, self.weight_ratio, x_warm)
            x = R.x
        if R is not None or method != "hierarchical" or not P.equalities_only:
            self._check(x, R, used)
        elif not all_finite(x):  # bounds met to FEAS_TOL already; no hard rows
            P.check_finite()  # names a NaN/inf that reached the tasks' arrays
            raise SolverError("the closed-form solution is not finite")
        residuals = np.array([L.residual(x) for L in P.levels])
        status = "optimal"
        bad = info.get("uncertified")
        if bad:
            status = "inaccurate"
            k, kkt = bad[0]
            info["inaccurate"] = inaccurate(k, kkt, "python", len(P.levels))
            if strict:
                step = " (the minimum-norm step)" if k >= len(P.levels) else ""
                raise SolverError(
                    f"level {k}{step}: the answer could not be certified optimal (KKT residual "
                    f"{kkt:.3g}, relative; tolerance {KKT_TOL:g}) with backend {used!r}"
                    + (" or its fallbacks" if self._work.fallback else "")
                )
        return Solution(
            x=x,
            status=status,
            level_residuals=residuals,
            solver=used,
            solve_time=time.perf_counter() - t0,
            method=method,
            info=info,
            stack=self,
        )

    def _solve_native(
        self, t0: float, warm_start: Solution | ArrayLike | None, strict: bool, limit: float
    ) -> Solution:
        """``method="hierarchical"`` with the native engine. The native call checks the data
        (finite), the returned ``x`` (bounds and hard rows, as :meth:`_check`) and computes
        the level values: no per-call Python pass over the levels here (the wrapper writes
        the tasks' numbers straight into the stacked arrays the native call reads). The time
        limit goes to the native call as seconds (the earlier of ``limit`` and an enclosing
        solve's deadline); no deadline object is built (the native engine starts no QP)."""
        P = self._compiled
        if warm_start is not None:
            self._warm(warm_start)  # validated; the engine warm-starts from its working sets
        native = self._native
        if native is None:
            native = self._native = NativeHierarchy(P, self.damping)
        x, residuals, info = _call_native(native, P, limit)
        status = "optimal"
        bad = info["uncertified"]
        if bad:
            status = "inaccurate"
            k, dev = bad[0]
            info["inaccurate"] = inaccurate(k, dev, "native")
            if strict:
                raise SolverError(
                    f"level {k}: the answer could not be certified optimal (its value moved "
                    f"by {dev:.3g}, relative, after it was frozen; tolerance {KKT_TOL:g}) "
                    "with backend 'native'"
                )
        # positional (x, status, level_residuals, solver, solve_time, method, info), as the
        # native IK step: 0.2 µs less than by keyword
        return Solution(
            x, status, residuals, "native", time.perf_counter() - t0, "hierarchical", info, self
        )

    def _solve_native_weighted(
        self, t0: float, warm_start: Solution | ArrayLike | None, limit: float
    ) -> Solution:
        """``method="weighted"`` with the native engine (:mod:`qpcoord.core.native_weighted`):
        the same QP, checked in the native call (data finite; bounds and hard rows at ``x``)."""
        P = self._compiled
        if warm_start is not None:
            self._warm(warm_start)  # validated; the engine warm-starts from its working set
        if self._native_weighted is None:
            self._native_weighted = NativeWeighted(P, self.regularization, self.weight_ratio)
        x, residuals, info = _call_native(self._native_weighted, P, limit)
        return Solution(
            x=x,
            status="optimal",
            level_residuals=residuals,
            solver="native",
            solve_time=time.perf_counter() - t0,
            method="weighted",
            info=info,
            stack=self,
        )

    def persistent(
        self,
        weight_ratio: float | None = None,
        regularization: float | None = None,
        engine: str | None = None,
    ) -> PersistentQP:
        """A :class:`~qpcoord.core.persistent.PersistentQP` on this stack: its weighted QP on one
        workspace kept across control steps (the native weighted QP where built, else daqp;
        ``engine="python"``: daqp; the tasks' matrices must stay fixed; a change is detected
        and rebuilds the workspace)."""
        return PersistentQP(
            self, weight_ratio=weight_ratio, regularization=regularization, engine=engine
        )

    def _reset(self, solver: str) -> Reduced:
        """The workspace for a solve with QPs, after checking that no NaN or wrong-sided
        infinity is in the data (``ValueError`` naming the task): nothing non-finite reaches
        a backend. The closed-form paths check their result instead (cheaper)."""
        P = self._compiled
        P.check_finite()
        return self._work.reset(P.lb, P.ub, solver)

    def _warm(self, warm_start: Solution | ArrayLike | None) -> np.ndarray | None:
        if warm_start is None:
            return None
        if isinstance(warm_start, Solution) and warm_start.x.shape == (self.n,):
            return warm_start.x  # a checked solution: finite, float, right length
        x = warm_start.x if isinstance(warm_start, Solution) else warm_start
        try:
            x = np.asarray(x, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(
                f"warm_start must be a Solution or an array, got {warm_start!r}"
            ) from None
        if x.shape[0] != self.n or not np.all(np.isfinite(x)):
            raise ValueError(
                f"warm_start must be a finite array of {self.n} values, got shape {x.shape}"
            )
        return x

    def _check(self, x: np.ndarray, R: Reduced | None, solver: str) -> None:
        """Never return an unchecked x: finite, bounds, hard rows, inherited rows."""
        P = self._compiled
        if not all_finite(x):
            P.check_finite()  # names a NaN/inf that reached the tasks' arrays
            raise SolverError(f"backend {solver!r} produced a non-finite solution")
        if R is not None and R.verified and not P.hard.m_eq:
            return  # x passed the (stricter) closed-form feasibility test after the last QP
        # snapped into the bounds: met exactly
        if P.lb is not None and P.ub is not None and not within(x, P.lb, P.ub, CHECK_TOL):
            i = int(np.argmax(np.maximum(P.lb - x, x - P.ub)))
            raise SolverError(
                f"backend {solver!r} returned x[{i}] = {x[i]!r} outside the bounds "
                f"[{P.lb[i]!r}, {P.ub[i]!r}]"
            )
        H = P.hard
        if H.m_eq:
            res = H.Ae @ x - H.be
            scale = max(1.0, float(np.max(np.abs(H.be))))
            if float(np.max(np.abs(res))) > CHECK_TOL * scale:
                raise SolverError(
                    f"backend {solver!r} returned a point violating the hard equalities "
                    f"(residual {np.linalg.norm(res):.3g})"
                )
        if H.m_in and not within(H.C @ x, H.lo, H.hi, CHECK_TOL):
            raise SolverError(
                f"backend {solver!r} returned a point violating the hard inequalities"
            )
        tol = CHECK_TOL if R is None else CHECK_TOL + (len(P.levels) + 1) * R.used_relax
        kept = slice(None) if R is None or not R.n_dependent else ~R.dependent
        if R is not None and R.k and not within(R.Cin[kept] @ x, R.lin[kept], R.uin[kept], tol):
            raise SolverError(
                f"backend {solver!r} returned a point that breaks an inequality a higher "
                "level had satisfied"
            )

    def __repr__(self) -> str:
        sizes = ", ".join(f"{L.m_eq}eq+{L.m_in}in" for L in self._compiled.levels)
        return f"Stack(n={self.n}, levels=[{sizes}], bounds={self._compiled.bounds is not None})"


def solve_stack(
    levels: Sequence[Level],
    bounds: Bounds | None = None,
    solver: str | None = None,
    method: str = "hierarchical",
    time_limit: float | None = None,
    engine: str | None = None,
    **options: Any,
) -> Solution:
    """Build a :class:`Stack` and solve it once (function form of :meth:`Stack.solve`).

    ``options`` go to :class:`Stack` (``regularization``, ``damping``, ``constraints``,
    ``weight_ratio``); ``time_limit`` (s) and ``engine`` to :meth:`Stack.solve`.
    """
    stack = Stack(levels, bounds=bounds, **options)
    return stack.solve(solver=solver, method=method, time_limit=time_limit, engine=engine)
