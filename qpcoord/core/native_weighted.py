"""The native weighted QP: adapter of ``qpcoord._native.Weighted`` (``src/native/weighted.*``).

``method="weighted"`` (:mod:`qpcoord.core.methods.weighted`) is one convex QP: level ``k``'s
weighted equality residual and squared inequality violation (slacks) multiplied by
``weight_ratio**k``, hard constraints and bounds hard, ``ε‖x‖²`` added (centred on ``x = 0``)
only where the levels leave the Hessian singular. The native engine solves the same QP --
the same elimination of the hard equalities, the same singularity rule, so the same optimum
(unique: the Hessian is positive definite once ``ε`` is added where needed) -- with a dense
Goldfarb–Idnani dual active set (``src/native/qp.hpp``, the method of quadprog) on buffers
sized once: no allocation per call after the first. The Hessian's factor and the constraint
rows are rebuilt only when a task's matrix or weight changed (``matrix_version``) or the
first time; otherwise a call recomputes the linear term and the limits and starts from the
previous call's working set (a *warm start*: when that set is still optimal, no iteration).

The extension is loaded by :mod:`qpcoord.core.native` (:func:`~qpcoord.core.native.load`);
:func:`resolve_weighted_engine` is the engine rule of ``Stack.solve(method="weighted")``.
"""

from __future__ import annotations

from operator import attrgetter

import numpy as np

from . import native
from .compile import CompiledStack

__all__ = ["available", "resolve_weighted_engine", "NativeWeighted"]

_MATRIX_VERSION = attrgetter("matrix_version")


def available() -> bool:
    """Is the native weighted QP built (the extension loads and has ``Weighted``)?"""
    return native.available() and hasattr(native.load(), "Weighted")


def resolve_weighted_engine(engine: str | None, solver: str | None) -> str:
    """The engine of a ``method="weighted"`` solve: ``"native"`` or ``"python"``.

    ``engine=None`` means the native engine where it is built and no explicit ``solver`` was
    asked for (as :func:`qpcoord.core.native.resolve_engine` for ``"hierarchical"``: a
    missing extension falls back to Python with that module's one warning per process).

    Raises
    ------
    ValueError
        Unknown engine, or ``engine="native"`` with an explicit ``solver``.
    NativeUnavailableError
        ``engine="native"`` and the extension (or its weighted QP) is not built.
    """
    if engine is None:
        if solver is not None or native.DEFAULT_ENGINE == "python":
            return "python"
        if native.resolve_engine(None, "hierarchical", None) == "native" and available():
            return "native"
        return "python"
    if engine not in native.ENGINES:
        raise ValueError(
            f"unknown engine {engine!r}; choose one of {', '.join(native.ENGINES)} or None"
        )
    if engine == "native":
        if solver is not None:
            raise ValueError(
                f"solver={solver!r} is not supported by the native engine (it has its own exact "
                "active-set solver); leave solver=None or use engine='python'"
            )
        native.load()
        if not available():
            raise native.NativeUnavailableError(
                "the built native engine has no weighted QP (a stale build): rebuild it "
                "(pip install -e .), or use engine='python'"
            )
    return engine


def weighted_info(detail: np.ndarray, refactored: bool) -> dict:
    """The ``Solution.info`` of a native weighted call from its ``detail`` array: ``engine``,
    ``iterations``, ``warm_start_hit``, ``regularized``, ``active_rows``, ``qp_calls``, and
    ``refactored`` (whether the Hessian was factored again in that call). Shared by
    :class:`NativeWeighted` and the weighted native IK step."""
    d = detail.tolist()
    return {
        "engine": "native",
        "iterations": int(d[2]),
        "warm_start_hit": bool(d[5]),
        "regularized": bool(d[6]),
        "active_rows": int(d[7]),
        "qp_calls": 1 if d[2] or d[5] else 0,
        "refactored": refactored,
    }


class NativeWeighted:
    """The native weighted QP of one compiled stack: structure and buffers built once.

    Bound once to the compiled stack's stacked arrays (as
    :class:`~qpcoord.core.native.NativeHierarchy`: :meth:`solve` copies the tasks' numbers
    into them natively, ``src/native/refresh.hpp``, and calls
    :meth:`CompiledStack.refresh_stacked <qpcoord.core.compile.CompiledStack.refresh_stacked>`
    only for data that copy does not take) or to arrays of the caller's (``arrays``:
    ``PersistentQP`` keeps its own and fills them), and to its own outputs.

    Parameters
    ----------
    P : CompiledStack
    regularization : float
        ``ε`` relative to ``max(1, max diag)`` of the x-space Hessian (added only where it is
        singular).
    weight_ratio : float
        Weight of each level relative to the one above.
    arrays : tuple of 8 ndarrays, optional
        ``(Aeq, beq, C, lo, hi, sw, lb, ub)`` laid out as ``P``'s stacked arrays
        (C-contiguous float64; default: ``P``'s own).
    """

    def __init__(
        self,
        P: CompiledStack,
        regularization: float,
        weight_ratio: float,
        arrays: tuple | None = None,
    ) -> None:
        mod = native.load()
        blocks = [P.hard, *P.levels]
        self.n = P.n
        self.x = np.zeros(P.n)
        self.res = np.zeros(len(P.levels))
        self.detail = np.zeros(8)
        ms = sum(L.m_in for L in P.levels)
        #: per row after a solve: bounds (n), hard equalities, hard inequalities, soft rows;
        #: −1 lower side active, +1 upper (hard equalities +1), else 0
        self.active = np.zeros(P.n + P.hard.m_eq + P.hard.m_in + ms)
        self._solver = mod.Weighted(
            P.n,
            [B.m_eq for B in blocks],
            [B.m_in for B in blocks],
            P.bounds is not None,
            float(regularization),
            float(weight_ratio),
        )
        own = arrays is None
        if arrays is None:
            arrays = (P.Aeq, P.beq, P.C, P.clo, P.chi, P.csw, P.lbs, P.ubs)
        self._solver.bind(*arrays, self.x, self.res, self.detail, self.active)
        # on P's own arrays, solve() refreshes them natively (src/native/refresh.hpp, as
        # NativeHierarchy's step), refresh_stacked only for data it does not copy
        self._P = P if own else None
        if own:
            self._solver.set_tasks(P, *P._task_rows)
        self._refresh = self._solver.refresh
        self._mod = mod
        self._tasks = [t for B in blocks for t in (*B.eqs, *B.ineqs)]
        self._versions: list | None = None
        self._solved = False

    def changed(self) -> bool:
        """Has a task's matrix or weight changed since the last set-up (``matrix_version``)?"""
        return list(map(_MATRIX_VERSION, self._tasks)) != self._versions

    def run(
        self,
        P: CompiledStack,
        warm: bool = True,
        time_left: float | None = None,
        refactor: bool | None = None,
    ) -> int:
        """One native call on the bound arrays' current numbers (no refresh); returns 0 or
        raises as :meth:`solve`. ``refactor=None``: when :meth:`changed`."""
        if refactor is None:
            versions = list(map(_MATRIX_VERSION, self._tasks))
            refactor = versions != self._versions
            self._versions = versions
        code = self._solver.run(
            self._solved and warm, np.inf if time_left is None else time_left, refactor
        )
        if code:
            self._solved = False
            self._versions = None  # the next call sets up again
            self._raise(code, P)
        self._solved = True
        return code

    def solve(
        self, P: CompiledStack, warm: bool = True, time_left: float | None = None
    ) -> tuple[np.ndarray, np.ndarray, dict]:
        """Solve with the tasks' current numbers (read into ``P``'s stacked arrays here).

        ``warm=False`` ignores the stored working set (a cold solve, for benchmarks);
        ``time_left`` (s, ``None``: no limit) bounds the active-set iterations.

        Returns
        -------
        x : ndarray, shape (n,)
            A new array.
        residuals : ndarray, shape (levels,)
            A new array: each level's value at ``x``.
        info : dict
            ``engine``, ``iterations`` (active-set iterations), ``warm_start_hit`` (the
            stored working set was optimal), ``regularized`` (``ε`` was added),
            ``active_rows`` (size of the final working set), ``qp_calls`` (1, or 0 when the
            unconstrained optimum answered), ``refactored``.

        Raises
        ------
        ValueError
            A task's matrix changed shape, a NaN or wrong-sided infinity in a task or the
            bounds (naming it).
        InfeasibleError
            Inconsistent hard equalities, or hard rows and bounds with no common point (the
            Python engine's messages).
        SolverError
            Iteration or time limit, a non-finite result, or a result that fails the check
            of the bounds and hard rows.
        """
        # the tasks' numbers into the stacked arrays in one native pass; the Python refresh
        # for data it does not copy (not float64 of the task's shape, the levels aliasing
        # their tasks' arrays), which converts, broadcasts or raises naming the task
        if P is not self._P or not self._refresh():
            P.refresh_stacked()
        versions = list(map(_MATRIX_VERSION, self._tasks))
        refactor = versions != self._versions
        self.run(P, warm, time_left, refactor=refactor)  # on an error: raises, set up again
        self._versions = versions
        return self.x.copy(), self.res.copy(), weighted_info(self.detail, refactor)

    def forget(self) -> None:
        """Drop the stored working set (the next solve starts cold)."""
        self._solver.forget()

    def _raise(self, code: int, P: CompiledStack) -> None:
        native.raise_status(
            code,
            self._mod,
            self.detail,
            self.x,
            P,
            hard_phase="dual active set: a hard row stays {:.3g} away, relative",
            prefix="weighted QP: ",
        )
