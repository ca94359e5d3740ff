"""Dense QP backends: one entry point, a dict of backends.

Every QP qpcoord solves internally has the form::

    minimise    ½ yᵀ H y + fᵀ y
    subject to  lo ≤ G y ≤ hi        (two-sided rows; ±inf allowed)
                lb ≤ y ≤ ub          (optional box)

with ``H`` symmetric positive definite (the stack adds regularisation to make it so).
:func:`solve_dense_qp` dispatches on the solver name. ``daqp``, ``quadprog`` and ``proxqp``
are called directly (no conversion layer: a small control-loop QP costs ≈ 10–60 µs less
than through :func:`qpsolvers.solve_qp`, see ``benchmarks/README.md``); every other backend
that :mod:`qpsolvers` can import goes through :func:`qpsolvers.solve_problem` with tight
tolerances.

Quiet and bounded
-----------------
No backend writes to stdout or stderr: every one gets its verbosity option (``verbose=False``;
HiGHS also ``output_flag=False``; OSQP runs without its own polishing, whose "Polishing not
needed" line ignores ``verbose``, the stack polishes every non-active-set point itself), and
HiGHS's banner, which its constructor prints once per process before any option can be set, is
sent to ``/dev/null`` at file-descriptor level the first time qpcoord creates a HiGHS object.

Every QP runs under a deadline (:func:`deadline`, set by :meth:`qpcoord.Stack.solve`'s
``time_limit``): :func:`solve_dense_qp` refuses to start a QP after it, and passes the time left
to each backend -- daqp ``time_limit`` (its iterations; its set-up, ``O(m n²)``, is not
counted), HiGHS ``time_limit``, OSQP ``time_limit``, Clarabel ``time_limit``, SCS
``time_limit_secs``. proxqp has no time limit: it runs in chunks of iterations, each sized to
the time left from the previous chunk's measured speed. quadprog and piqp cannot be stopped
once started: they are refused when an estimate of their cost (:func:`_estimate`,
conservative) exceeds the time left, and piqp's iteration cap is sized to it.
"""

from __future__ import annotations

import contextvars
import math
import os
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from importlib import metadata

import numpy as np

from .tolerance import within

__all__ = [
    "QPResult",
    "available_solvers",
    "default_solver",
    "solver_versions",
    "solve_dense_qp",
    "check_solver",
    "deadline",
    "time_left",
    "DEFAULT_TIME_LIMIT",
]

#: Time limit (s) of a solve when none is given (``Stack.solve(time_limit=None)``): generous
#: for any control step (those take micro- to milliseconds); ``time_limit=math.inf`` lifts it.
DEFAULT_TIME_LIMIT = 10.0

#: Absolute ``time.perf_counter()`` by which the current solve must end (``None``: no limit).
#: A context variable: each thread (and each asyncio task) has its own.
_DEADLINE: contextvars.ContextVar[float | None] = contextvars.ContextVar(
    "qpcoord_deadline", default=None
)


class deadline:  # noqa: N801 (a context manager used like a function)
    """Run the enclosed QPs under a time limit of ``seconds`` (``None``/``inf``: none).

    Nested limits keep the earlier deadline. Used by :meth:`qpcoord.Stack.solve`::

        with deadline(0.01):
            ...  # every solve_dense_qp call here gets the time left
    """

    __slots__ = ("_at", "_token")

    def __init__(self, seconds: float | None) -> None:
        at = None
        if seconds is not None and seconds != math.inf:
            at = time.perf_counter() + seconds
        outer = _DEADLINE.get()
        if outer is not None and (at is None or outer < at):
            at = outer
        self._at = at
        self._token: contextvars.Token[float | None] | None = None

    @property
    def at(self) -> float | None:
        """The absolute deadline (``time.perf_counter()`` clock), or ``None``."""
        return self._at

    def expired(self) -> bool:
        """Has the deadline passed?"""
        return self._at is not None and time.perf_counter() >= self._at

    def __enter__(self) -> deadline:
        self._token = _DEADLINE.set(self._at)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._token is not None:
            _DEADLINE.reset(self._token)


def check_time_limit(time_limit) -> float:
    """Validate a ``time_limit`` argument (s): ``None`` gives :data:`DEFAULT_TIME_LIMIT`,
    ``math.inf`` no limit; anything else must be a positive number (``ValueError``)."""
    if time_limit is None:
        return DEFAULT_TIME_LIMIT
    if isinstance(time_limit, bool) or not isinstance(
        time_limit, (int, float, np.integer, np.floating)
    ):
        raise ValueError(f"time_limit must be a number of seconds or None, got {time_limit!r}")
    value = float(time_limit)
    if not value > 0:  # NaN too
        raise ValueError(f"time_limit must be > 0 seconds, got {time_limit!r}")
    return value


OK, INFEASIBLE, FAILED = 0, 1, 2

#: Preference order for the default solver: fastest first on small dense QPs
#: (measured in ``benchmarks/stack_bench.py``).
_PREFERENCE = ("daqp", "quadprog", "proxqp", "piqp", "clarabel", "highs", "osqp", "scs", "cvxopt")

#: Distribution that provides each qpsolvers backend (for version reports).
_DISTRIBUTION = {
    "daqp": "daqp",
    "quadprog": "quadprog",
    "proxqp": "proxsuite",
    "osqp": "osqp",
    "clarabel": "clarabel",
    "piqp": "piqp",
    "highs": "highspy",
    "scs": "scs",
    "cvxopt": "cvxopt",
    "ecos": "ecos",
    "gurobi": "gurobipy",
    "mosek": "mosek",
    "qpalm": "qpalm",
    "qpoases": "qpoases",
    "qpswift": "qpSWIFT",
    "hpipm": "hpipm_python",
    "jaxopt_osqp": "jaxopt",
    "kvxopt": "kvxopt",
    "sip": "sip-python",
}

#: Accuracy settings passed to the generic (qpsolvers) path. Our stacks need ~1e-9.
_GENERIC_SETTINGS: dict[str, dict] = {
    # 1e-10 did not converge on a 3-variable level QP; 1e-9 plus the exact refinement does
    "osqp": dict(eps_abs=1e-9, eps_rel=1e-9, max_iter=200_000, polishing=False, verbose=False),
    "clarabel": dict(tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10, verbose=False),
    "piqp": dict(eps_abs=1e-10, eps_rel=1e-10, verbose=False),
    # a first-order method: reaching 1e-10 can take 10⁵ iterations (a hard control step
    # cost 2.5 s in the benchmark); capping it at 2·10⁴ left level optima 2e-6 off
    "scs": dict(eps_abs=1e-10, eps_rel=1e-10, max_iters=500_000, verbose=False),
    # HiGHS drops Hessian entries ≤ small_matrix_value (default 1e-9): our regularisation
    # small_matrix_value at its lower limit; iteration and time caps: its QP solver ran for
    # minutes on some degenerate level QPs
    "highs": dict(
        small_matrix_value=1e-12,
        qp_iteration_limit=20_000,
        time_limit=2.0,
        output_flag=False,
        log_to_console=False,
    ),
    "cvxopt": dict(show_progress=False),
}

#: Name of each generic backend's time-limit setting (seconds).
_TIME_OPTION = {
    "osqp": "time_limit",
    "clarabel": "time_limit",
    "highs": "time_limit",
    "scs": "time_limit_secs",
}


@dataclass
class QPResult:
    """Outcome of one dense QP solve.

    Attributes
    ----------
    y : numpy.ndarray or None
        Primal solution (``None`` unless ``code == OK``).
    code : int
        ``0`` solved, ``1`` declared infeasible by the backend, ``2`` other failure.
    message : str
        Backend status text, for error messages.
    """

    y: np.ndarray | None
    code: int
    message: str
    exact: bool = False  # solved to round-off (active-set backend at tight tolerances)


def available_solvers() -> list[str]:
    """Names of the QP backends that import here (qpsolvers names, e.g. ``"daqp"``).

    Returns
    -------
    list of str
        Sorted by qpcoord's preference (fastest on small dense QPs first).
    """
    import qpsolvers

    names = list(qpsolvers.available_solvers)
    rank = {name: i for i, name in enumerate(_PREFERENCE)}
    return sorted(names, key=lambda s: (rank.get(s, len(rank)), s))


def default_solver() -> str:
    """The solver used when none is named: the first of :func:`available_solvers`."""
    names = available_solvers()
    if not names:
        raise RuntimeError(
            "no QP backend is installed: install qpcoord's dependencies (daqp, quadprog, proxsuite)"
        )
    return names[0]


def solver_versions() -> dict[str, str]:
    """Installed version of each available backend's distribution (``"?"`` if unknown)."""
    out = {}
    for name in available_solvers():
        dist = _DISTRIBUTION.get(name, name)
        try:
            out[name] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[name] = "?"
    return out


def check_solver(solver: str | None) -> str:
    """Resolve ``None`` to the default and validate a solver name (``ValueError`` if unknown)."""
    if solver is None:
        return default_solver()
    if not isinstance(solver, str):
        raise ValueError(f"solver must be a string, got {solver!r}")
    names = available_solvers()
    if solver not in names:
        raise ValueError(f"unknown or uninstalled solver {solver!r}; installed: {', '.join(names)}")
    return solver


def _meets_rows(G, lo, hi, lb, ub, y, tol: float) -> bool:
    """Does ``y`` meet ``lo ≤ G y ≤ hi`` and the box to ``tol`` (relative)?"""
    return within(G @ y, lo, hi, tol) and (lb is None or within(y, lb, ub, tol))


def as_rows(G, lo, hi, lb, ub, k):
    """Two-sided rows and box as one-sided ``G y ≤ h`` rows (finite entries only)."""
    rows, rhs = [], []
    fl, fh = np.isfinite(lo), np.isfinite(hi)
    if fh.any():
        rows.append(G[fh])
        rhs.append(hi[fh])
    if fl.any():
        rows.append(-G[fl])
        rhs.append(-lo[fl])
    if lb is not None:
        # finite box entries become rows: backends disagree on infinite box entries
        eye = np.eye(k)
        bu, bl = np.isfinite(ub), np.isfinite(lb)
        if bu.any():
            rows.append(eye[bu])
            rhs.append(ub[bu])
        if bl.any():
            rows.append(-eye[bl])
            rhs.append(-lb[bl])
    if not rows:
        return None, None
    return np.vstack(rows), np.concatenate(rhs)


def _left(at: float | None) -> float | None:
    """Seconds left before the deadline ``at`` (``None``: no deadline)."""
    return None if at is None else at - time.perf_counter()


def time_left() -> float | None:
    """Seconds left before the current solve's :class:`deadline` (``None``: no limit); for
    the solves qpcoord runs outside :func:`solve_dense_qp` (the hard phase's LP)."""
    return _left(_DEADLINE.get())


def _out_of_time(solver: str, left: float) -> QPResult:
    return QPResult(None, FAILED, f"{solver}: time limit reached ({left:.3g} s left)")


#: Seconds per ``n²·(n + m)`` of quadprog's dual active-set method, an upper estimate
#: (measured 1.2e-9…2.6e-9 on dense QPs of n = m = 300…1600, one BLAS thread).
_QUADPROG_RATE = 5e-9


def _estimate(solver: str, n: int, m: int) -> float:
    """Upper estimate (s) of an uninterruptible backend's run on ``n`` variables and ``m``
    rows: quadprog's whole solve; piqp's one interior-point iteration."""
    if solver == "quadprog":
        return 1e-3 + _QUADPROG_RATE * n * n * (n + m)
    return 1e-4 + 1e-9 * (n + m) ** 3  # piqp: one factorisation of the KKT matrix


_highs_primed = False


def _prime_highs() -> None:
    """Create one HiGHS object with stdout and stderr sent to /dev/null at file-descriptor
    level: HiGHS prints its banner from the constructor, once per process, before any option
    can be set. Later objects print nothing (``output_flag=False``)."""
    global _highs_primed
    if _highs_primed:
        return
    _highs_primed = True
    import ctypes

    import highspy

    saved = []
    try:
        for stream in (sys.stdout, sys.stderr):
            if stream is not None:
                stream.flush()
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            for fd in (1, 2):
                saved.append((fd, os.dup(fd)))
                os.dup2(devnull, fd)
            highspy.Highs()
            try:  # the banner may sit in the C library's buffer: flush it into /dev/null
                ctypes.CDLL(None).fflush(None)
            except (OSError, AttributeError):
                pass
        finally:
            for fd, keep in saved:
                os.dup2(keep, fd)
                os.close(keep)
            os.close(devnull)
    except OSError:  # no usable file descriptors (embedded interpreter): nothing to hide
        highspy.Highs()


# --------------------------------------------------------------------------------------
# Direct backends
# --------------------------------------------------------------------------------------


#: Tried in order until daqp reports success. Degenerate level QPs (a point pinned by
#: more active rows than free directions) made daqp report infeasibility with tight
#: tolerances; a stronger proximal term, then daqp's defaults, solve them. The stack
#: refines every level QP's answer on its active set, so the looser tries cost no accuracy
#: when they find the right active set.
_DAQP_SETTINGS: tuple[dict[str, float], ...] = (
    dict(eps_prox=1e-6, eta_prox=1e-12, primal_tol=1e-10),
    dict(eps_prox=1e-4, eta_prox=1e-12, primal_tol=1e-10),
    dict(),
    # Last: a proximal term of the Hessian's own scale (times max diag H, see _solve_daqp).
    # daqp recovers its primal iterate through (H + eps_prox·I)⁻¹ times multipliers of the
    # slacks' scale: on a level QP whose z-block is only the 1e-9 regularisation that is
    # ~1e6 × O(1) with eps_prox = 1e-6, the iterate is ~2e-9 off the exact vertex, a row the
    # optimum meets (3e-10 margin) looks violated by more than primal_tol, is added, the
    # working set turns singular and the singular step declares infeasibility (a kept case:
    # tests/data/daqp_false_infeasible_qp.npz). With eps_prox ≥ 1e-2 the iterate's error is
    # ~1e-15: measured, 17 of the 19 level QPs daqp failed on in 40 000 random stacks solved.
    dict(eps_prox=0.1, eta_prox=1e-12, primal_tol=1e-10),
)
#: daqp's exit flag when its ``time_limit`` stopped it.
_DAQP_TIME_LIMIT = -7


def _solve_daqp(H, f, G, lo, hi, lb, ub, y0):
    at = _DEADLINE.get()
    import daqp

    n = H.shape[0]
    if lb is not None:
        bupper = np.concatenate((ub, hi))
        blower = np.concatenate((lb, lo))
    else:
        bupper, blower = hi, lo
    if G.shape[0] == 0 and lb is None:
        # daqp needs at least one constraint: an always-inactive bound row.
        G = np.zeros((1, n))
        bupper = np.array([1.0])
        blower = np.array([-1.0])
    # daqp treats |bound| >= 1e30 as infinite
    bupper = np.minimum(bupper, 1e30)
    blower = np.maximum(blower, -1e30)
    sense = np.zeros(bupper.shape[0], dtype=np.int32)
    # proximal-point outer iterations keep daqp exact on the nearly singular Hessians of
    # a hierarchy's levels (eigenvalues ~ regularization); without them it declared some
    # feasible level QPs infeasible (12 of 200 random 3-level stacks, measured). Its
    # default primal tolerance (1e-6) let level optima miss their rows by 6e-7, and its
    # default proximal stopping (eta_prox) left level optima 2e-3 off in x.
    attempt = 0
    verdict = None  # the flag of the last attempt before the proximal one of the H's scale
    for attempt, settings in enumerate(_DAQP_SETTINGS):  # noqa: B007 (used after the loop)
        left = _left(at)
        if left is not None:
            if left <= 0:
                return _out_of_time("daqp", left)
            settings = dict(settings, time_limit=left)  # seconds of iterations
        if attempt == len(_DAQP_SETTINGS) - 1:  # relative to the Hessian's scale
            if verdict != -1:  # only for an "infeasible" verdict (the QPs above)
                break
            scale = max(float(np.abs(H.diagonal()).max()), 1e-300)
            settings = dict(settings, eps_prox=settings["eps_prox"] * scale)
        if y0 is None:
            x, _, flag, _ = daqp.solve(H, f, G, bupper, blower, sense, **settings)
        else:
            x, _, flag, _ = daqp.solve(H, f, G, bupper, blower, sense, primal_start=y0, **settings)
        if flag in (1, 2):
            break
        if flag == _DAQP_TIME_LIMIT:
            return QPResult(None, FAILED, "daqp: time limit reached (exitflag -7)")
        if attempt < len(_DAQP_SETTINGS) - 1:
            verdict = flag
    if flag not in (1, 2) and verdict is not None:
        flag = verdict  # the proximal attempt failed too: the earlier attempts' verdict
    if flag in (1, 2):
        return QPResult(np.asarray(x, dtype=float), OK, f"daqp exitflag {flag}", attempt == 0)
    if flag == -1:
        return QPResult(None, INFEASIBLE, "daqp: infeasible (exitflag -1)")
    return QPResult(None, FAILED, f"daqp exitflag {flag}")


def _solve_quadprog(H, f, G, lo, hi, lb, ub, y0):
    at = _DEADLINE.get()
    import quadprog

    n = H.shape[0]
    left = _left(at)
    if left is not None:
        need = _estimate("quadprog", n, G.shape[0] + (0 if lb is None else 2 * n))
        if need > left:
            # quadprog cannot be interrupted: do not start what may not end in time
            return QPResult(
                None,
                FAILED,
                f"quadprog: not started, it cannot be interrupted and may need ~{need:.3g} s "
                f"({left:.3g} s left before the time limit)",
            )
    # rows with lo == hi are equalities (quadprog's dual method called the two opposite
    # inequalities of such a row inconsistent); quadprog takes them first (meq)
    eq = np.isfinite(lo) & (lo == hi)
    if eq.any():
        Gq, hq = as_rows(G[~eq], lo[~eq], hi[~eq], lb, ub, n)
        C = G[eq].T if Gq is None else np.hstack((G[eq].T, -Gq.T))
        b = lo[eq] if hq is None else np.concatenate((lo[eq], -hq))
        meq = int(eq.sum())
    else:
        Gq, hq = as_rows(G, lo, hi, lb, ub, n)
        # quadprog wants Cᵀ y ≥ b
        C = np.zeros((n, 0)) if Gq is None else -Gq.T
        b = np.zeros(0) if hq is None else -hq
        meq = 0
    try:
        x = quadprog.solve_qp(H, -f, C, b, meq)[0]
    except ValueError as exc:
        text = str(exc)
        if "inconsistent" in text:
            return QPResult(None, INFEASIBLE, f"quadprog: {text}")
        return QPResult(None, FAILED, f"quadprog: {text}")
    return QPResult(np.asarray(x, dtype=float), OK, "quadprog solved", True)


#: Most proxqp iterations per QP (1e5 took ~5 s on a 1-variable QP).
_PROXQP_MAX_ITER = 10_000


def _proxqp_run(qp, proxqp, at, y0, n: int, m: int) -> None:
    """``qp.solve()`` in chunks of iterations that fit the time left before ``at`` (proxqp
    has no time limit of its own). The first chunk is all of ``_PROXQP_MAX_ITER`` unless a
    generous per-iteration estimate says it would not fit; each next chunk is sized from the
    measured speed and resumes from the previous chunk's state."""
    st = qp.settings
    if at is None:
        st.max_iter = _PROXQP_MAX_ITER
        if y0 is None:
            qp.solve()
        else:
            qp.solve(y0, None, None)
        return
    # ``max_iter`` counts outer iterations; each may run up to ``max_iter_in`` (1500) inner
    # ones (measured: 10 000 outer iterations, 11.9 million inner, 96 s on a 2-variable
    # level QP of the campaign). Every chunk is sized for that worst case, to half the time
    # left: the first from a generous estimate per inner iteration, the next ones from the
    # measured one.
    generous = 1e-5 + 2e-9 * (n + m) * n  # measured 8e-6 s on n = 2, m = 6
    per_iter = int(st.max_iter_in) * generous
    done = 0
    first = True
    while True:
        left = at - time.perf_counter()
        if left <= 0:
            return
        chunk = int(min(_PROXQP_MAX_ITER - done, max(10, 0.5 * left / per_iter)))
        st.max_iter = chunk
        t0 = time.perf_counter()
        if first and y0 is not None:
            qp.solve(y0, None, None)
        elif first:
            qp.solve()
        else:
            st.initial_guess = proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
            qp.solve()
        first = False
        info = qp.results.info
        done += max(1, int(info.iter_ext))
        if info.status != proxqp.QPSolverOutput.PROXQP_MAX_ITER_REACHED:
            return
        if done >= _PROXQP_MAX_ITER:
            return
        # the worst case stays the bound: the first outer iterations were measured at
        # 3 inner ones each, later ones at 1 250 (the 96 s case above); a measured inner
        # iteration faster than the generous estimate never shrinks it (a cheap chunk
        # said nothing about the expensive ones: 11–13 s solves under a 10 s limit)
        per_inner = max((time.perf_counter() - t0) / max(1, int(info.iter)), generous)
        per_iter = int(st.max_iter_in) * per_inner


def _solve_proxqp(H, f, G, lo, hi, lb, ub, y0):
    at = _DEADLINE.get()
    from proxsuite import proxqp

    n = H.shape[0]
    m = G.shape[0]
    box = lb is not None
    qp = proxqp.dense.QP(n, 0, m, box)
    st = qp.settings
    st.eps_abs = 1e-10
    st.eps_rel = 0.0
    # the default infeasibility threshold (1e-4) declared feasible level QPs infeasible
    st.eps_primal_inf = 1e-9
    st.eps_dual_inf = 1e-9
    st.max_iter = _PROXQP_MAX_ITER
    st.verbose = False
    if y0 is not None:
        st.initial_guess = proxqp.InitialGuess.WARM_START
    C = G if m else None
    lo_c = np.maximum(lo, -1e20) if m else None
    hi_c = np.minimum(hi, 1e20) if m else None
    if box:
        qp.init(H, f, None, None, C, lo_c, hi_c, np.maximum(lb, -1e20), np.minimum(ub, 1e20))
    else:
        qp.init(H, f, None, None, C, lo_c, hi_c)
    _proxqp_run(qp, proxqp, at, y0, n, m + n * box)
    res = qp.results
    status = res.info.status
    if status == proxqp.QPSolverOutput.PROXQP_PRIMAL_INFEASIBLE:
        left = _left(at)
        if left is not None and left <= 0:
            return _out_of_time("proxqp", left)
        # proxqp 0.8 declared feasible, nearly degenerate level QPs infeasible; its
        # closest-feasible mode solves them (a feasible problem's solution is unchanged)
        st.primal_infeasibility_solving = True
        st.initial_guess = proxqp.InitialGuess.EQUALITY_CONSTRAINED_INITIAL_GUESS
        if box:
            qp.init(H, f, None, None, C, lo_c, hi_c, np.maximum(lb, -1e20), np.minimum(ub, 1e20))
        else:
            qp.init(H, f, None, None, C, lo_c, hi_c)
        _proxqp_run(qp, proxqp, at, None, n, m + n * box)
        res = qp.results
        status = res.info.status
    name = str(status).split(".")[-1]
    if status in (
        proxqp.QPSolverOutput.PROXQP_SOLVED,
        proxqp.QPSolverOutput.PROXQP_SOLVED_CLOSEST_PRIMAL_FEASIBLE,
    ):
        return QPResult(np.array(res.x, dtype=float).reshape(n), OK, name)
    if status in (
        proxqp.QPSolverOutput.PROXQP_PRIMAL_INFEASIBLE,
        proxqp.QPSolverOutput.PROXQP_DUAL_INFEASIBLE,
    ):
        return QPResult(None, INFEASIBLE, f"proxqp: {name}")
    if status == proxqp.QPSolverOutput.PROXQP_MAX_ITER_REACHED:
        x = np.array(res.x, dtype=float).reshape(n)
        if np.all(np.isfinite(x)) and _meets_rows(G, lo, hi, lb, ub, x, 1e-7):
            return QPResult(x, OK, "proxqp: max_iter reached, point accepted")
        left = _left(at)
        if left is not None and left <= 0:
            return _out_of_time("proxqp", left)
    return QPResult(None, FAILED, f"proxqp: {name}")


#: Backends whose "almost solved" answers are accepted at our tight tolerances (the
#: point must still satisfy the QP's rows to 1e-7, and the stack re-checks it).
_ALMOST_OK = frozenset({"clarabel", "scs", "osqp"})


def _generic_once(name, H, f, G, lo, hi, lb, ub, y0, at=None) -> QPResult:
    import qpsolvers

    k = H.shape[0]
    Gq, hq = as_rows(G, lo, hi, lb, ub, k)
    opts = _GENERIC_SETTINGS.get(name, {})
    left = _left(at)
    if left is not None:
        if left <= 0:
            return _out_of_time(name, left)
        opts = dict(opts)
        key = _TIME_OPTION.get(name)
        if key is not None:
            opts[key] = min(opts.get(key, math.inf), left)
        elif name == "piqp":  # no time limit: cap its iterations instead
            per_iter = _estimate("piqp", k, 0 if Gq is None else Gq.shape[0])
            if per_iter > left:
                return _out_of_time(name, left)
            opts["max_iter"] = int(min(250, left / per_iter))
    if name == "highs":
        _prime_highs()
    Hq = H
    if name not in qpsolvers.dense_solvers:
        from scipy import sparse

        Hq = sparse.csc_matrix(H)
        Gq = None if Gq is None else sparse.csc_matrix(Gq)
    problem = qpsolvers.Problem(Hq, f, Gq, hq)
    try:
        with warnings.catch_warnings():
            # e.g. osqp 1.x's PendingDeprecationWarning about raise_error
            warnings.simplefilter("ignore")
            sol = qpsolvers.solve_problem(problem, solver=name, initvals=y0, **opts)
    except Exception as exc:  # backends raise a zoo of exception types
        return QPResult(None, FAILED, f"{name}: {type(exc).__name__}: {exc}")
    x = sol.x
    if x is None or x.shape != (k,) or not np.all(np.isfinite(x)):
        left = _left(at)
        if left is not None and left <= 0:
            return _out_of_time(name, left)
        return QPResult(None, FAILED, f"{name}: no solution found")
    if sol.found:
        return QPResult(np.asarray(x, dtype=float), OK, f"{name} solved")
    if name in _ALMOST_OK and _meets_rows(G, lo, hi, lb, ub, x, 1e-7):
        return QPResult(np.asarray(x, dtype=float), OK, f"{name}: almost solved, accepted")
    return QPResult(None, FAILED, f"{name}: no solution found")


def _solve_generic(name: str):
    def solve(H, f, G, lo, hi, lb, ub, y0):
        at = _DEADLINE.get()
        res = _generic_once(name, H, f, G, lo, hi, lb, ub, y0, at)
        if res.code == OK or name != "highs":
            return res
        # HiGHS 1.15 returned NaN for free variables (our slacks) of some QPs; with every
        # variable boxed it solves them. The box is far outside any step qpcoord asks for,
        # and a solution touching it is rejected.
        k = H.shape[0]
        finite = np.concatenate((lo[np.isfinite(lo)], hi[np.isfinite(hi)], f))
        big = 1e6 * max(1.0, float(np.abs(finite).max()) if finite.size else 1.0)
        lb2 = np.full(k, -big) if lb is None else np.where(np.isfinite(lb), lb, -big)
        ub2 = np.full(k, big) if ub is None else np.where(np.isfinite(ub), ub, big)
        res = _generic_once(name, H, f, G, lo, hi, lb2, ub2, y0, at)
        if res.code == OK and np.abs(res.y).max() >= 0.99 * big:
            return QPResult(None, FAILED, f"{name}: solution reached the artificial box")
        return res

    return solve


_DIRECT: dict[str, Callable] = {
    "daqp": _solve_daqp,
    "quadprog": _solve_quadprog,
    "proxqp": _solve_proxqp,
}


def solve_dense_qp(
    solver: str,
    H: np.ndarray,
    f: np.ndarray,
    G: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    lb: np.ndarray | None = None,
    ub: np.ndarray | None = None,
    y0: np.ndarray | None = None,
) -> QPResult:
    """Solve one dense QP with the named backend.

    Parameters
    ----------
    solver : str
        A name from :func:`available_solvers` (not checked here: hot path).
    H : ndarray, shape (k, k)
        Symmetric positive-definite Hessian.
    f : ndarray, shape (k,)
        Linear term.
    G : ndarray, shape (m, k)
        Constraint rows (``m`` may be 0).
    lo, hi : ndarray, shape (m,)
        Row bounds, ±inf allowed.
    lb, ub : ndarray, shape (k,), optional
        Box on ``y`` (both or neither), ±inf allowed.
    y0 : ndarray, shape (k,), optional
        Warm start (primal guess) where the backend accepts one.

    Returns
    -------
    QPResult
        The solution is returned unchecked here; :class:`~qpcoord.Stack` checks it. Under a
        :class:`deadline` that has passed, or that the backend hit, ``code`` is ``FAILED``
        and ``message`` says "time limit reached".
    """
    at = _DEADLINE.get()
    if at is not None and time.perf_counter() >= at:
        return _out_of_time(solver, at - time.perf_counter())
    fn = _DIRECT.get(solver)
    if fn is None:
        fn = _solve_generic(solver)
    res = fn(H, f, G, lo, hi, lb, ub, y0)
    if res.code == OK and (res.y is None or not all(math.isfinite(v) for v in res.y)):
        return QPResult(None, FAILED, f"{solver} returned a non-finite solution")
    return res
