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
warm-started from the working set the same level ended with at the previous call; when that
set misses (its point breaks a row, or a multiplier has the wrong sign), the active set starts
from it made feasible (the ratio test from the feasible cold start towards its point on the
rows without slack, each slack its row's violation, the stored rows still tight and the
blocking row as working set) instead of cold; so do the minimum-norm step and the hard
constraints' phase-1 (least violation inside the box), which decides infeasibility. The QR of
the working set is updated as rows enter (a reflector) and leave (Givens downdate); a level's
closed form uses a QR of its projected equalities when no singular value can be damped, the
SVD otherwise.

This module is the only place that imports the extension. :func:`resolve_engine` decides
which engine a :meth:`Stack.solve <qpcoord.Stack.solve>` call uses.
"""

from __future__ import annotations

import importlib
import os
import warnings
from types import ModuleType
from typing import NoReturn

import numpy as np

from .compile import CompiledStack
from .errors import InfeasibleError, SolverError
from .polish import KKT_TOL

__all__ = [
    "ENGINES",
    "DEFAULT_ENGINE",
    "NativeUnavailableError",
    "VARIANTS",
    "ISA_ENV",
    "available",
    "load",
    "variant",
    "built_variants",
    "import_variant",
    "cpu_level",
    "resolve_engine",
    "NativeHierarchy",
    "raise_status",
]

#: The engines :meth:`Stack.solve` offers.
ENGINES = ("native", "python")
#: What ``engine=None`` means where the native engine applies (method ``"hierarchical"``, no
#: explicit ``solver``): the native engine where it is built, else Python with one warning.
DEFAULT_ENGINE = "native"
#: Name of the extension module (the baseline build: plain x86-64, or another architecture).
MODULE = "qpcoord._native"
#: The builds of the extension (the same sources, CMakeLists.txt), lowest level first:
#: variant name -> (module, the x86-64 ISA level it needs: 1 baseline, 3 AVX2/FMA/BMI2...).
VARIANTS = {
    "baseline": (MODULE, 1),
    "x86-64-v3": ("qpcoord._native_x86_64_v3", 3),
}
#: The environment variable that picks a variant (read at the first :func:`load`): one of
#: :data:`VARIANTS`, or ``auto`` / unset for the highest-level build this CPU supports.
ISA_ENV = "QPCOORD_NATIVE_ISA"
#: The interface version this module speaks (``ABI_VERSION`` of the extension).
ABI_VERSION = 17

_INF = float("inf")


class NativeUnavailableError(ImportError):
    """``engine="native"`` was asked for but the extension is not built."""


_module: ModuleType | None = None
_load_error: str | None = None
_warned = False


def _import_module(name: str) -> ModuleType:
    """Import one build of the extension by its module name."""
    return importlib.import_module(name)


def _requested() -> str | None:
    """The variant :data:`ISA_ENV` asks for; ``None`` when unset, empty or ``"auto"``.

    Raises
    ------
    ValueError
        An unknown value (naming the variable and the value).
    """
    value = os.environ.get(ISA_ENV, "").strip()
    if value in ("", "auto"):
        return None
    if value not in VARIANTS:
        raise ValueError(
            f"{ISA_ENV}={value!r} is not a native engine variant; choose one of "
            f"{', '.join(VARIANTS)} or auto (or leave it unset)"
        )
    return value


def cpu_level() -> int:
    """The highest x86-64 ISA level (1 = baseline, 2, 3, 4) the running CPU and OS support,
    as the baseline build measures it (CPUID and XGETBV, ``src/native/cpu_isa.hpp``); 1 off
    x86-64.

    Raises
    ------
    NativeUnavailableError
        The baseline build is missing or cannot be loaded.
    """
    try:
        base = _import_module(MODULE)
    except ImportError as exc:
        raise NativeUnavailableError(f"the native engine ({MODULE}) is not built ({exc})") from exc
    level = getattr(base, "x86_64_level", None)
    return int(level()) if level is not None else 1  # a build without the check: baseline


def _checked_variant(name: str) -> ModuleType:
    """The module of variant ``name`` after the CPU check; :class:`NativeUnavailableError`
    if it is not built, cannot be loaded or is stale (another interface or ISA)."""
    level = cpu_level()
    if VARIANTS[name][1] > level:
        raise ValueError(
            f"the native engine variant {name!r} needs x86-64 level {VARIANTS[name][1]}, this "
            f"CPU and OS support level {level}: it would stop the process on an illegal "
            f"instruction; use {ISA_ENV}=baseline or auto"
        )
    module = VARIANTS[name][0]
    try:
        mod = _import_module(module)
    except ImportError as exc:
        raise NativeUnavailableError(f"{module} is not built or cannot be loaded ({exc})") from exc
    abi, isa = getattr(mod, "ABI_VERSION", None), getattr(mod, "ISA", "baseline")
    if abi != ABI_VERSION or isa != name:
        raise NativeUnavailableError(
            f"{module} is stale (interface {abi}, ISA {isa!r}; this qpcoord needs interface "
            f"{ABI_VERSION}, ISA {name!r}): rebuild it (pip install -e .)"
        )
    return mod


def _import() -> ModuleType:
    """Import the extension: the variant :data:`ISA_ENV` names, else the best built variant
    the CPU supports, else the baseline (a separate function so that tests can simulate the
    extension's absence).

    A variant that is not built or is stale falls back to the baseline, silently unless
    :data:`ISA_ENV` asked for it (then one ``RuntimeWarning``).

    Raises
    ------
    ImportError
        The baseline build is missing or cannot be loaded.
    ValueError
        :data:`ISA_ENV` holds an unknown value, or names a variant this CPU cannot run.
    """
    requested = _requested()
    base = _import_module(MODULE)
    if requested == "baseline":
        return base
    level = cpu_level()
    if requested is None:
        candidates = [v for v, (_, need) in VARIANTS.items() if 1 < need <= level]
        candidates.reverse()  # the highest level first
    else:
        candidates = [requested]
    for name in candidates:
        try:
            return _checked_variant(name)
        except NativeUnavailableError as exc:
            if requested is not None:
                warnings.warn(
                    f"{ISA_ENV}={requested}: {exc}; using the baseline build ({MODULE})",
                    RuntimeWarning,
                    stacklevel=2,
                )
    return base


def load() -> ModuleType:
    """The extension module; :class:`NativeUnavailableError` (an ``ImportError``) if it is
    not built (no C++ compiler or Eigen at install time) or cannot be loaded.

    The first call chooses the build (:func:`variant`): ``QPCOORD_NATIVE_ISA``
    (:data:`ISA_ENV`) if set, else the highest-level build the running CPU supports.

    Raises
    ------
    NativeUnavailableError
        No usable build.
    ValueError
        ``QPCOORD_NATIVE_ISA`` holds an unknown value or a variant this CPU cannot run.
    """
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
    if getattr(mod, "ABI_VERSION", None) != ABI_VERSION:
        _load_error = (
            f"the built extension speaks interface {getattr(mod, 'ABI_VERSION', None)}, "
            f"this qpcoord needs {ABI_VERSION}: a stale build"
        )
        raise NativeUnavailableError(
            f"the native engine (qpcoord._native) is out of date ({_load_error}): rebuild it "
            "(pip install -e .), or use engine='python'"
        )
    _module = mod
    return mod


def available() -> bool:
    """Is the native engine built and loadable?"""
    try:
        load()
    except NativeUnavailableError:
        return False
    return True


def variant() -> str | None:
    """The build of the native engine in use: ``"baseline"`` (``qpcoord._native``, plain
    x86-64 or another architecture) or ``"x86-64-v3"`` (``qpcoord._native_x86_64_v3``: AVX2,
    FMA, BMI2); ``None`` if the native engine is not available. Loads the engine."""
    if not available():
        return None
    return str(getattr(_module, "ISA", "baseline"))


def built_variants() -> tuple[str, ...]:
    """The variants that are built, current and runnable on this CPU, lowest level first
    (for tests and benchmarks that compare them; :func:`load` picks one of them); empty if
    the native engine is not available."""
    if not available():
        return ()
    names = []
    for name in VARIANTS:
        try:
            import_variant(name)
        except (NativeUnavailableError, ValueError):
            continue
        names.append(name)
    return tuple(names)


def import_variant(name: str) -> ModuleType:
    """The module of one variant of :data:`VARIANTS`, whatever :func:`load` chose (to
    compare the builds in one process: the adapters take the module from :func:`load`, so a
    test swaps ``_module``).

    Raises
    ------
    ValueError
        ``name`` is not a variant, or this CPU cannot run it.
    NativeUnavailableError
        It is not built, cannot be loaded or is stale.
    """
    if name not in VARIANTS:
        raise ValueError(
            f"name={name!r} is not a native engine variant; choose one of {', '.join(VARIANTS)}"
        )
    if name == "baseline":
        try:
            mod = _import_module(MODULE)
        except ImportError as exc:
            raise NativeUnavailableError(f"{MODULE} is not built ({exc})") from exc
        if getattr(mod, "ABI_VERSION", None) != ABI_VERSION:
            raise NativeUnavailableError(f"{MODULE} is stale: rebuild it (pip install -e .)")
        return mod
    return _checked_variant(name)


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
                stacklevel=3,  # the caller of Stack.solve
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

    The solver is bound once to the compiled stack's stacked arrays, to its tasks and to its
    own output arrays: each :meth:`solve` is one native call with three scalars
    (``Hierarchy.step``) that copies the tasks' numbers into the stacked arrays (as
    :meth:`CompiledStack.refresh_stacked
    <qpcoord.core.compile.CompiledStack.refresh_stacked>`, ``src/native/refresh.hpp``),
    solves, and returns copies of ``x`` and the level values with the info dict. A task whose
    data is not a float64 array of its shape (another dtype or byte order, a broadcast), or
    levels pointing at their tasks' arrays after a Python-engine solve, make that call hand
    the refresh back to ``refresh_stacked`` (which converts, broadcasts or raises the message
    naming the task) before the solve. The call also checks the data (finite, no wrong-sided
    infinity), checks the returned ``x`` (bounds, hard rows: as ``Stack._check``) and computes
    the level values; the solver keeps each level's final working set and tries it first at
    the next call (warm start).

    Parameters
    ----------
    P : CompiledStack
    damping : float
        Relative damping threshold (see :mod:`qpcoord.core.linalg`).
    """

    def __init__(self, P: CompiledStack, damping: float) -> None:
        mod = load()
        blocks = [P.hard, *P.levels]
        self.n = P.n
        self.x = np.zeros(P.n)
        self.res = np.zeros(len(P.levels))
        self.stats = np.zeros((len(P.levels) + 2, 3))
        self.detail = np.zeros(8)
        self._solver = mod.Hierarchy(
            P.n,
            [B.m_eq for B in blocks],
            [B.m_in for B in blocks],
            P.bounds is not None,
            float(damping),
        )
        self._solver.bind(
            P.Aeq, P.beq, P.C, P.clo, P.chi, P.csw, P.lbs, P.ubs,
            self.x, self.res, self.stats, self.detail,
        )  # fmt: skip
        self._solver.set_tasks(P, *P._task_rows, self.x, self.res)
        self._run = self._solver.run
        self._step = self._solver.step
        self._P = P
        self._damping = float(damping)
        self._mod = mod
        self._solved = False

    def solve(
        self, P: CompiledStack, warm: bool = True, time_left: float | None = None
    ) -> tuple[np.ndarray, np.ndarray, dict]:
        """Solve with the tasks' current numbers (read into ``P``'s stacked arrays here).

        ``P`` is the compiled stack this solver was built on. ``warm=False`` ignores the
        stored working sets (a cold solve, for benchmarks); ``time_left`` (s, ``None``: no
        limit) bounds the active-set iterations.

        Returns
        -------
        x : ndarray, shape (n,)
            A new array (the solution).
        residuals : ndarray, shape (levels,)
            A new array: each level's value at ``x``.
        info : dict
            ``engine``, ``active_set_iterations`` (per level), ``hard_iterations``,
            ``min_norm_iterations``, ``warm_start_hits`` (stages whose stored working set
            was optimal), ``warm_start_seeded`` (stages — hard phase, levels, minimum-
            norm step — whose stored working set missed and seeded the active set's start),
            ``closed_form_levels``, ``qp_calls``
            (stages solved by the active set rather than a closed form: the Python
            engine's count of QP calls),
            ``uncertified`` (``[(level, deviation)]`` when a level's value at ``x`` moved
            from the one it was frozen with by more than ``KKT_TOL`` relative to
            ``max(1, value, scale)``, ``scale`` the level's ``‖b‖ + ‖A‖_F·‖x‖`` (inequality
            rows: their nearer bound, weighted), the size of its value's rounding: the
            lower levels left its optimal set by more than rounding), ``stats`` (the
            call's counters: a ``Stats`` whose attributes count how often each path and
            cache was taken, e.g. ``freeze_memo_hits``, ``downdates``; they describe the
            work, never the answer; a copy, as :attr:`counters`).

        Raises
        ------
        ValueError
            A task's matrix changed shape, a NaN or wrong-sided infinity in a task or the
            bounds (naming it).
        InfeasibleError
            Inconsistent hard equalities, or hard rows and bounds with no common point.
        SolverError
            An active-set solve did not converge or ran out of time, the result is not
            finite, or it fails the check of the bounds and hard rows.
        """
        warm = self._solved and warm
        left = _INF if time_left is None else time_left
        if P is self._P:
            # one native call: the tasks' numbers into the stacked arrays (as
            # refresh_stacked), the solve, x and res copied, the info dict
            out = self._step(warm, left, KKT_TOL)
            if out.__class__ is tuple:
                self._solved = True
                return out
            code = out
            if code == self._mod.REFRESH_IN_PYTHON:  # a task's data is not float64 of its
                P.refresh_stacked()  # shape, or the levels alias their tasks: converts/raises
                code = self._run(warm, left)
        else:
            P.refresh_stacked()
            code = self._run(warm, left)
        if code:
            self._solved = False  # the stored working sets may be from another problem
            self._raise(code, P)
        self._solved = True
        return self.x.copy(), self.res.copy(), self._solver.info(KKT_TOL)

    @property
    def counters(self):
        """The last call's counters (a copy of the extension's ``Stats``: how often each path
        and cache was taken, e.g. ``freeze_memo_hits``, ``downdates``; they describe the
        work, never the answer)."""
        return self._solver.stats

    def _raise(self, code: int, P: CompiledStack) -> None:
        k = int(self.detail[2])
        where = (
            "the hard constraints"
            if k == 0
            else ("the minimum-norm step" if k == len(P.levels) + 1 else f"level {k - 1}")
        )
        raise_status(
            code,
            self._mod,
            self.detail,
            self.x,
            P,
            hard_phase="least-violation phase: no point within {:.3g} of them, relative",
            stage=f" of {where}",
        )


def raise_status(
    code: int,
    mod: ModuleType,
    d: np.ndarray,
    x: np.ndarray,
    P: CompiledStack,
    hard_phase: str,
    stage: str = "",
    prefix: str = "",
) -> NoReturn:
    """Raise the exception of a native engine's non-zero status ``code`` with the Python
    engine's messages (shared by the strict hierarchy and the weighted QP). An
    :class:`InfeasibleError` carries no conflict: the entry points a user calls
    (``Stack.solve``, the IK step) name it (:func:`~qpcoord.core.conflict.infeasible`), so a
    caller that falls back (``PersistentQP``) pays no conflict search.

    ``d`` is the engine's ``detail`` array (0: residual of the hard equalities, 1: relative
    violation of the hard part, 3/4: which check failed and where), ``x`` its output array.
    ``hard_phase`` describes the engine's infeasibility detection (a format string for
    ``d[1]``); ``stage`` (e.g. ``" of level 2"``) and ``prefix`` (e.g. ``"weighted QP: "``)
    complete the iteration- and time-limit messages.
    """
    if code == mod.BAD_INPUT:
        P.check_finite()  # names the NaN/inf (task or bounds) that reached the arrays
        raise ValueError(f"native engine rejected the data (status {code})")
    if code == mod.INFEASIBLE_EQ:
        names = ", ".join(t.label for t in P.hard.eqs)
        raise InfeasibleError(
            f"hard equality constraints are inconsistent ({names}): "
            f"least-squares residual {d[0]:.3g}",
        )
    if code == mod.INFEASIBLE_HARD and np.isinf(d[1]):
        raise InfeasibleError(
            "constraints: the hard equalities fix x completely and it violates the bounds "
            "or hard inequalities",
        )
    if code == mod.INFEASIBLE_HARD:
        raise InfeasibleError(
            "constraints: bounds and hard constraints are inconsistent (native engine's "
            + hard_phase.format(d[1])
            + ")",
        )
    if code == mod.NOT_CONVERGED:
        raise SolverError(f"{prefix}native engine: the active set{stage} did not converge")
    if code == mod.TIME_LIMIT:
        raise SolverError(f"{prefix}native engine: time limit reached in the active set{stage}")
    if code == mod.NON_FINITE:
        raise SolverError("native engine produced a non-finite solution")
    if code == mod.CHECK_FAILED:  # the messages of Stack._check
        lb, ub = P.lb, P.ub
        if d[3] == 1 and lb is not None and ub is not None:  # (only a stack with bounds)
            i = int(d[4])
            raise SolverError(
                f"backend 'native' returned x[{i}] = {x[i]!r} outside the bounds "
                f"[{lb[i]!r}, {ub[i]!r}]"
            )
        if d[3] == 2:
            raise SolverError(
                "backend 'native' returned a point violating the hard equalities "
                f"(residual {d[4]:.3g})"
            )
        raise SolverError("backend 'native' returned a point violating the hard inequalities")
    raise SolverError(f"native engine: unknown status {code}")
