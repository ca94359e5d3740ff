"""Which hard rows conflict: the rows :attr:`InfeasibleError.conflict
<qpcoord.InfeasibleError.conflict>` names.

Once an engine has decided that the hard part of a stack (bounds and hard constraints) has no
common point, :func:`infeasible` builds the error it raises: the engine's message, and the
smallest set of hard rows found that cannot hold together, each with its violation at the
point that violates them least. The search reads the tasks' own numbers and the box the
engine solved with, so both engines name the same rows.

Method (an elastic LP and a deletion filter, Chinneck & Dravnieks 1991):

1. A row of the hard part is a hard equality row, a hard inequality row (both sides) or a
   bounded entry of ``x``. If the hard equalities alone have no common point, only they are
   searched.
2. The elastic LP ``min t`` subject to every row met to ``t·max(1, |bound|)`` (the library's
   relative rule, the LP the Python engine decides infeasibility with) is solved by HiGHS's
   dual simplex; the rows with a non-zero multiplier at its (basic) optimum carry a Farkas
   certificate of infeasibility: at most ``n + 1`` rows (``n`` variables) that still cannot
   hold together.
3. The support of a basic optimal multiplier is an extreme ray of ``{y ≥ 0 : Aᵀy = 0}``,
   hence irreducible (Gleeson & Ryan 1990): it is kept as is when its rows have rank one
   less than their number (every proper subset then has independent rows, so a common
   point). Otherwise (near-dependent rows, or a support that is not a vertex's) a deletion
   filter runs over those rows, bounds first, then inequalities, then equalities: a row is
   dropped when the others still have no common point (elastic optimum above ``tol``).
   Either way what is left is irreducible: dropping any one of its rows makes the rest
   consistent. It is not necessarily the smallest such set (finding that is NP-hard).
4. The least-violation point of the rows left (the elastic LP over them alone): each row's
   violation there, in its own units.

Cost: usually two LPs (HiGHS, ``scipy.optimize.linprog``) and one SVD of at most
``(n + 1) × n``; at most ``n + 5`` LPs when the filter runs, the first two over every hard
row, the others over at most ``n + 1`` rows; only on the error path. Under a solve's
time limit (:func:`~qpcoord.core.backends.time_left`) the filter stops when the time is up
and the rows kept so far (still in conflict, perhaps not irreducible) are named; the LPs
outside the filter (at most four) run to their end.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .backends import time_left
from .compile import CompiledStack
from .elimination import INFEAS_TOL
from .errors import InfeasibleError

__all__ = ["ConflictRow", "find_conflict", "infeasible", "renamed"]

#: HiGHS's primal and dual feasibility tolerances in the elastic LPs (its smallest values).
_LP_TOL = 1e-10
#: Multipliers below this fraction of the largest are zero (the certificate's support).
_SUPPORT_TOL = 1e-9

#: Singular values (of the conflict's unit rows) below this fraction of the largest count
#: as zero in the irreducibility test: conservative, near-dependent rows are filtered.
_RANK_TOL = 1e-6

_EQ, _IN, _BOUND = 0, 1, 2  # kinds of candidate rows, in the order they are listed


@dataclass(frozen=True)
class ConflictRow:
    """One hard row of a conflict (:attr:`InfeasibleError.conflict
    <qpcoord.InfeasibleError.conflict>`).

    Attributes
    ----------
    task : str
        Name of the hard task the row belongs to; for a bound, the name of the
        :class:`~qpcoord.Bounds` (in an :class:`~qpcoord.IK`: the name of the limit that
        sets this side of the box, e.g. ``"velocity limits"``).
    row : int
        Row index within the task; for a bound, the index of the variable in ``x``.
    kind : str
        ``"equality"`` (``A_i x = b_i``), ``"lower"`` / ``"upper"`` (the side of an
        inequality row ``lower_i ≤ C_i x ≤ upper_i`` that gives way), or ``"lower bound"`` /
        ``"upper bound"`` (a side of the box on ``x[row]``).
    bound : float
        What the row asks for: ``b_i``, the inequality's or the box's side that gives way
        (the row's units: the task's ``b`` / ``lower`` / ``upper``, or ``x``'s).
    value : float
        The row's value (``A_i x``, ``C_i x`` or ``x[row]``, same units) at the point that
        violates the conflict's rows least (the largest violation relative to
        ``max(1, |bound|)`` is minimised).
    violation : float
        How far the row is missed at that point (same units, ≥ 0: ``|value − bound|`` for
        a row of an irreducible conflict).
    joint : str
        For a bound in an :class:`~qpcoord.IK`: the joint whose velocity ``x[row]`` is
        (``"name[k]"`` for coordinate ``k`` of a joint with several); else ``""``.
    """

    task: str
    row: int
    kind: str
    bound: float
    value: float
    violation: float
    joint: str = ""

    @property
    def is_bound(self) -> bool:
        """Is the row a side of the box on ``x``?"""
        return self.kind.endswith("bound")

    def __str__(self) -> str:
        sign = {"equality": "=", "lower": "≥", "upper": "≤"}[self.kind.split()[0]]
        where = f"x[{self.row}]" if self.is_bound else f"row {self.row}"
        joint = f" (joint {self.joint!r})" if self.joint else ""
        return (
            f"{self.task!r} {where}{joint}: {sign} {self.bound:.6g} missed by {self.violation:.3g}"
        )


def _candidates(P: CompiledStack, lb: np.ndarray | None, ub: np.ndarray | None):
    """Every hard row as ``lo ≤ M x ≤ hi``: ``(M, lo, hi, kind, task, row)`` (rows with
    two infinite sides left out). Task rows are read from the tasks (both engines keep them
    current); ``lb``/``ub`` (``None``: no box) is the box the engine solved with."""
    n = P.n
    mats: list[np.ndarray] = []
    los: list[np.ndarray] = []
    his: list[np.ndarray] = []
    kinds: list[int] = []
    tasks: list[str] = []
    rows: list[int] = []
    hard: list[tuple[int, Any, np.ndarray, np.ndarray, np.ndarray]]
    hard = [(_EQ, t, t.A, t.b, t.b) for t in P.hard.eqs]
    hard += [(_IN, t, t.C, t.lower, t.upper) for t in P.hard.ineqs]
    for kind, t, A, low, high in hard:
        m = A.shape[0]
        mats.append(A)
        los.append(low)
        his.append(high)
        kinds += [kind] * m
        tasks += [t.name or t.label] * m
        rows += range(m)
    if lb is not None:
        lb, ub = np.asarray(lb, dtype=float), np.asarray(ub, dtype=float)
        mats.append(np.eye(n))
        los.append(lb)
        his.append(ub)
        name = P.bounds.name if P.bounds is not None else "bounds"
        kinds += [_BOUND] * n
        tasks += [name] * n
        rows += range(n)
    if not mats:
        return np.zeros((0, n)), np.zeros(0), np.zeros(0), [], [], []
    M = np.vstack(mats)
    lo, hi = np.concatenate(los), np.concatenate(his)
    keep = np.isfinite(lo) | np.isfinite(hi)
    idx = np.flatnonzero(keep)
    return (
        M[idx],
        lo[idx],
        hi[idx],
        [kinds[i] for i in idx],
        [tasks[i] for i in idx],
        [rows[i] for i in idx],
    )


def _elastic(M, lo, hi, rows, timed: bool = False):
    """The elastic LP over ``rows``: ``(t, x, multipliers per row)``, ``t`` recomputed at
    the LP's ``x`` as the largest relative violation; ``None`` if HiGHS did not finish
    (a failure, or with ``timed`` the solve's time limit)."""
    from scipy.optimize import linprog

    rows = np.asarray(rows, dtype=int)
    n = M.shape[1]
    Mr, low, high = M[rows], lo[rows], hi[rows]
    up, dn = np.flatnonzero(np.isfinite(high)), np.flatnonzero(np.isfinite(low))
    A = np.vstack((Mr[up], -Mr[dn]))
    b = np.concatenate((high[up], -low[dn]))
    s = np.maximum(1.0, np.abs(b))
    A, b = A / s[:, None], b / s
    options = {"primal_feasibility_tolerance": _LP_TOL, "dual_feasibility_tolerance": _LP_TOL}
    left = time_left() if timed else None
    if left is not None:
        if left <= 0.0:
            return None
        options["time_limit"] = left
    cost = np.zeros(n + 1)
    cost[n] = 1.0
    res = linprog(
        cost,
        A_ub=np.hstack((A, -np.ones((A.shape[0], 1)))),
        b_ub=b,
        bounds=[(None, None)] * n + [(0.0, None)],
        method="highs-ds",  # dual simplex: a basic optimum, whose multipliers' support is small
        options=options,
    )
    if res.status != 0 or res.x is None:
        return None
    x = np.asarray(res.x[:n], dtype=float)
    t = max(0.0, float((A @ x - b).max()))
    mult = np.zeros(len(rows))
    marg = np.abs(np.asarray(res.ineqlin.marginals, dtype=float))
    np.add.at(mult, np.concatenate((up, dn)), marg)
    return t, x, mult


def _irreducible(rows: np.ndarray) -> bool:
    """Do ``rows`` (in conflict) have rank ``len(rows) − 1``, every other singular value
    above :data:`_RANK_TOL` of the largest (rows scaled to unit norm)? Then no proper
    subset can conflict (its rows are independent). Near-dependent rows fail the test and
    go through the deletion filter."""
    k = rows.shape[0]
    if k > rows.shape[1] + 1:
        return False
    unit = rows / np.maximum(np.linalg.norm(rows, axis=1), np.finfo(float).tiny)[:, None]
    s = np.linalg.svd(unit, compute_uv=False)
    return k - 1 <= s.size and int(np.count_nonzero(s > _RANK_TOL * s[0])) == k - 1


def find_conflict(
    P: CompiledStack, lb: np.ndarray | None, ub: np.ndarray | None, tol: float = INFEAS_TOL
) -> tuple[ConflictRow, ...]:
    """The hard rows of compiled stack ``P`` found in conflict (see the module's method).

    Parameters
    ----------
    P : CompiledStack
        Its hard tasks (current numbers) and bounds' name.
    lb, ub : numpy.ndarray or None
        The box on ``x`` the engine solved with (``±inf`` entries unbounded; ``None``: none).
    tol : float
        Relative violation above which rows have no common point (default the engines'
        infeasibility tolerance, :data:`~qpcoord.core.elimination.INFEAS_TOL`).

    Returns
    -------
    tuple of ConflictRow
        Equalities, then inequalities, then bounds, each in its task's row order; empty if
        the rows are consistent to ``tol`` by this LP or it did not finish in time.
    """
    M, lo, hi, kinds, tasks, rows = _candidates(P, lb, ub)
    every = list(range(len(kinds)))
    if not every:
        return ()
    eqs = [i for i in every if kinds[i] == _EQ]
    lp = None
    if eqs and len(eqs) < len(every):
        lp = _elastic(M, lo, hi, eqs)
        if lp is None:
            return ()
        if lp[0] > tol:
            every = eqs  # the equalities alone have no common point: the conflict is theirs
        else:
            lp = None
    if lp is None:
        lp = _elastic(M, lo, hi, every)
        if lp is None or lp[0] <= tol:
            return ()
    mult = lp[2]
    big = float(mult.max())
    keep = [every[j] for j in np.flatnonzero(mult > _SUPPORT_TOL * big)] if big > 0 else []
    if keep != every:
        lp = _elastic(M, lo, hi, keep) if keep else None
        if lp is None or lp[0] <= tol:
            keep = every  # the multipliers did not carry the certificate: filter every row
            lp = None
    # deletion filter: bounds first, then inequalities, then equalities (each kept row is
    # needed: without it the others have a common point); not needed when the rows have
    # rank len(keep) − 1: every proper subset then has independent rows, so a common point
    order = [] if _irreducible(M[keep]) else sorted(keep, key=lambda i: (-kinds[i], i))
    for i in order:
        trial = [j for j in keep if j != i]
        test = _elastic(M, lo, hi, trial, timed=True) if trial else None
        if test is None and trial:
            break  # time is up: the rows kept still conflict
        if test is not None and test[0] > tol:
            keep, lp = trial, None
    if lp is None or len(lp[2]) != len(keep):
        lp = _elastic(M, lo, hi, keep)  # the least-violation point of the rows kept
        if lp is None:
            return ()
    x = lp[1]
    out = []
    for i in keep:
        v = float(M[i] @ x)
        if kinds[i] == _EQ:
            kind, bound = "equality", float(lo[i])
        elif v < lo[i] or (v <= hi[i] and v - lo[i] <= hi[i] - v):
            kind, bound = "lower", float(lo[i])
        else:
            kind, bound = "upper", float(hi[i])
        if kinds[i] == _BOUND:
            kind += " bound"
        # a row of an irreducible conflict is missed at that point; one kept because the
        # filter ran out of time may hold there (violation 0)
        miss = abs(v - bound) if kind == "equality" else max(0.0, lo[i] - v, v - hi[i])
        out.append(ConflictRow(tasks[i], rows[i], kind, bound, v, float(miss)))
    return tuple(out)


def describe(conflict: tuple[ConflictRow, ...]) -> str:
    """The conflict as the message's last part (``""`` when none was found)."""
    if not conflict:
        return ""
    return "; rows in conflict (each missed at the point that misses them least): " + ", ".join(
        str(r) for r in conflict
    )


def infeasible(
    message: str, P: CompiledStack, lb: np.ndarray | None, ub: np.ndarray | None
) -> InfeasibleError:
    """The :class:`InfeasibleError` an engine raises when the hard part of ``P`` has no
    common point: ``message`` (the engine's own words) followed by the rows
    :func:`find_conflict` names, which it carries as ``conflict``."""
    try:
        conflict = find_conflict(P, lb, ub)
    except (ValueError, np.linalg.LinAlgError) as exc:  # never hide the engine's error
        return InfeasibleError(f"{message}; the rows in conflict could not be isolated ({exc})")
    if not conflict:
        return InfeasibleError(
            f"{message}; the rows in conflict could not be isolated (the elastic LP finds "
            f"them consistent to {INFEAS_TOL:g}, relative, or ran out of time)"
        )
    return InfeasibleError(message + describe(conflict), conflict=conflict)


def renamed(exc: InfeasibleError, conflict: tuple[ConflictRow, ...]) -> InfeasibleError:
    """``exc`` with its conflict's rows replaced by ``conflict`` (the same rows named by a
    caller that knows more, e.g. an :class:`~qpcoord.IK` naming its limits and joints),
    in the message too."""
    message = str(exc)
    said = describe(exc.conflict)
    if said and message.endswith(said):
        message = message[: -len(said)]
    out = InfeasibleError(message + describe(conflict), conflict=conflict)
    return out.with_traceback(exc.__traceback__)
