"""The native engine: loader and adapter of the compiled strict-hierarchy solver.

``qpcoord._native`` (C++17 + Eigen, ``src/native/``, built by scikit-build-core at
``pip install`` when a C++ compiler is present) solves ``method="hierarchical"`` stacks with
the same semantics as :mod:`qpcoord.core.methods.hierarchical`: bounds and hard constraints
always hold, level ``k`` minimises its weighted equality residual and inequality violation
over the optimal set of the levels above (exact, lexicographic), then the minimum-norm ``x``.
Damping of near-singular levels follows :mod:`qpcoord.core.linalg` (``Stack(damping=...)``).

Algorithm: variable elimination. Per level, the damped closed form of the projected
equalities is tried first; if it breaks a row, an exact primal active-set least-squares solve
in ``(z, w)`` (``w`` the slacks of the level's inequality rows) runs from a feasible start,
warm-started from the working set the same level ended with at the previous call. The hard
constraints get a phase-1 (least violation inside the box) that decides infeasibility.

This module is the only place that imports the extension. :func:`resolve_engine` decides
which engine a :meth:`Stack.solve <qpcoord.Stack.solve>` call uses.
"""

from __future__ import annotations

import importlib
import warnings
from types import ModuleType

import numpy as np

from .compile import CompiledStack
from .errors import InfeasibleError, SolverError

__all__ = [
    "ENGINES",
    "DEFAULT_ENGINE",
    "NativeUnavailableError",
    "available",
    "load",
    "resolve_engine",
    "NativeHierarchy",
]

#: The engines :meth:`Stack.solve` offers.
ENGINES = ("native", "python")
#: What ``engine=None`` means where the native engine applies. "python" for now: the native
#: engine is opt-in (``engine="native"``) until every test of the suite passes with it.
DEFAULT_ENGINE = "python"
#: Name of the extension module.
MODULE = "qpcoord._native"


class NativeUnavailableError(ImportError):
    """``engine="native"`` was asked for but the extension is not built."""


_module: ModuleType | None = None
_load_error: str | None = None
_warned = False


def _import() -> ModuleType:
    """Import the extension (a separate function so that tests can simulate its absence)."""
    return importlib.import_module(MODULE)


def load() -> ModuleType:
    """The extension module; :class:`NativeUnavailableError` (an ``ImportError``) if it is
    not built (no C++ compiler or Eigen at install time) or cannot be loaded."""
    global _module, _load_error
    if _module is not None:
        return _module
    try:
        mod = _import()
    except ImportError as exc:
        _load_error = str(exc)
        raise NativeUnavailableError(
            "the native engine (qpcoord._native) is not built: reinstall qpcoord with a C++17 "
            f"compiler present (pip install -e .), or use engine='python' ({exc})"
        ) from exc
    _module = mod
    return mod


def available() -> bool:
    """Is the native engine built and loadable?"""
    try:
        load()
    except NativeUnavailableError:
        return False
    return True


def resolve_engine(engine: str | None, method: str, solver: str | None) -> str:
    """The engine a solve uses: ``"native"`` or ``"python"``.

    ``engine=None`` means :data:`DEFAULT_ENGINE` where the native engine applies (method
    ``"hierarchical"``, no explicit ``solver``), else the Python engine; a default that is
    native but not built falls back to Python with one warning per process.

    Raises
    ------
    ValueError
        Unknown engine, or ``engine="native"`` with a method or solver it does not support
        (naming the argument).
    NativeUnavailableError
        ``engine="native"`` and the extension is not built.
    """
    global _warned
    if engine is None:
        if DEFAULT_ENGINE == "python" or method != "hierarchical" or solver is not None:
            return "python"
        if available():
            return "native"
        if not _warned:
            _warned = True
            warnings.warn(
                "qpcoord's native engine is not built (no C++ compiler or Eigen when qpcoord "
                "was installed); using the Python engine. Reinstall with a compiler to build "
                f"it, or pass engine='python' to silence this ({_load_error})",
                RuntimeWarning,
                stacklevel=4,
            )
        return "python"
    if engine not in ENGINES:
        raise ValueError(f"unknown engine {engine!r}; choose one of {', '.join(ENGINES)} or None")
    if engine == "native":
        if method != "hierarchical":
            raise ValueError(
                f"method={method!r} is not supported by the native engine (it solves "
                "method='hierarchical'); use engine='python'"
            )
        if solver is not None:
            raise ValueError(
                f"solver={solver!r} is not supported by the native engine (it has its own exact "
                "active-set solver); leave solver=None or use engine='python'"
            )
        load()
    return engine


class NativeHierarchy:
    """The native solver of one compiled stack: structure and buffers built once.

    Each :meth:`solve` copies the levels' current numbers into preallocated stacked arrays
    and makes one native call; the solver keeps each level's final working set and tries it
    first at the next call (warm start).

    Parameters
    ----------
    P : CompiledStack
    damping : float
        Relative damping threshold (see :mod:`qpcoord.core.linalg`).
    """

    def __init__(self, P: CompiledStack, damping: float) -> None:
        mod = load()
        blocks = [P.hard, *P.levels]
        self._blocks = blocks
        meq = [B.m_eq for B in blocks]
        mins = [B.m_in for B in blocks]
        n = P.n
        self.n = n
        self._eq = np.cumsum([0, *meq])
        self._in = np.cumsum([0, *mins])
        self.Aeq = np.zeros((int(self._eq[-1]), n))
        self.beq = np.zeros(int(self._eq[-1]))
        self.C = np.zeros((int(self._in[-1]), n))
        self.lo = np.zeros(int(self._in[-1]))
        self.hi = np.zeros(int(self._in[-1]))
        self.sw = np.ones(int(self._in[-1]))
        self.lb = np.full(n, -np.inf)
        self.ub = np.full(n, np.inf)
        self.x = np.zeros(n)
        self.stats = np.zeros((len(P.levels) + 2, 3))
        self.detail = np.zeros(4)
        self._solver = mod.Hierarchy(n, meq, mins, P.bounds is not None, float(damping))
        self._mod = mod
        self._solved = False

    def solve(self, P: CompiledStack, warm: bool = True) -> tuple[np.ndarray, dict]:
        """Solve with the numbers ``P`` holds (already refreshed and checked finite).

        ``warm=False`` ignores the stored working sets (a cold solve, for benchmarks).

        Returns
        -------
        x : ndarray, shape (n,)
            A new array (the solution).
        info : dict
            ``engine``, ``active_set_iterations`` (per level), ``hard_iterations``,
            ``min_norm_iterations``, ``warm_start_hits`` (stages whose stored working set
            was optimal), ``closed_form_levels``.

        Raises
        ------
        InfeasibleError
            Inconsistent hard equalities, or hard rows and bounds with no common point.
        SolverError
            An active-set solve did not converge or the result is not finite.
        """
        for j, B in enumerate(self._blocks):
            e0, e1 = self._eq[j], self._eq[j + 1]
            if e1 > e0:
                self.Aeq[e0:e1] = B.Ae
                self.beq[e0:e1] = B.be
            i0, i1 = self._in[j], self._in[j + 1]
            if i1 > i0:
                self.C[i0:i1] = B.C
                self.lo[i0:i1] = B.lo
                self.hi[i0:i1] = B.hi
                self.sw[i0:i1] = B.sw
        if P.lb is not None:
            self.lb[:] = P.lb
            self.ub[:] = P.ub
        mod = self._mod
        code = self._solver.solve(
            self.Aeq,
            self.beq,
            self.C,
            self.lo,
            self.hi,
            self.sw,
            self.lb,
            self.ub,
            self._solved and warm,
            self.x,
            self.stats,
            self.detail,
        )
        if code != mod.OK:
            self._solved = False  # the stored working sets may be from another problem
            self._raise(code, P)
        self._solved = True
        st = self.stats
        info = {
            "engine": "native",
            "hard_iterations": int(st[0, 0]),
            "active_set_iterations": [int(v) for v in st[1:-1, 0]],
            "min_norm_iterations": int(st[-1, 0]),
            "warm_start_hits": int(st[:, 1].sum()),
            "closed_form_levels": [int(k) for k in np.flatnonzero(st[1:-1, 2])],
            "uncertified": [],
        }
        return self.x.copy(), info

    def _raise(self, code: int, P: CompiledStack) -> None:
        mod = self._mod
        d = self.detail
        if code == mod.INFEASIBLE_EQ:
            names = ", ".join(t.label for t in P.hard.eqs)
            raise InfeasibleError(
                f"hard equality constraints are inconsistent ({names}): "
                f"least-squares residual {d[0]:.3g}"
            )
        if code == mod.INFEASIBLE_HARD and np.isinf(d[1]):
            raise InfeasibleError(
                "constraints: the hard equalities fix x completely and it violates the bounds "
                "or hard inequalities"
            )
        if code == mod.INFEASIBLE_HARD:
            raise InfeasibleError(
                "constraints: bounds and hard constraints are inconsistent (native engine's "
                f"least-violation phase: no point within {d[1]:.3g} of them, relative)"
            )
        if code == mod.NOT_CONVERGED:
            k = int(d[2])
            where = (
                "the hard constraints"
                if k == 0
                else ("the minimum-norm step" if k == len(P.levels) + 1 else f"level {k - 1}")
            )
            raise SolverError(f"native engine: the active set of {where} did not converge")
        if code == mod.NON_FINITE:
            raise SolverError("native engine produced a non-finite solution")
        P.check_finite()  # names a NaN/inf that reached the tasks' arrays
        raise ValueError(f"native engine rejected the data (status {code})")
