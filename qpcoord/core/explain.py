"""What gave way: :meth:`Solution.explain() <qpcoord.Solution.explain>`.

Per level and task of a solved stack: each task's residual at the returned ``x``, whether it
is met, and its inequality rows that are active (at a bound) or violated (beyond it), by
name; the same for the hard constraints and the bounds (active rows only: they hold). A
level that could not be met shows which of its rows gave way, and the active rows above it
(hard rows, bounds, inequalities of higher levels) show what held it back.

A row is *at* a bound when it is within ``CHECK_TOL · max(1, |bound|, ‖row‖·‖x‖)`` of it
(:data:`~qpcoord.core.elimination.CHECK_TOL`, relative, the tolerance every returned ``x``
is checked to; ``‖row‖·‖x‖`` is the size of the row's rounding), *beyond* it further out; an
equality row is met within the same tolerance of its target.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .elimination import CHECK_TOL

__all__ = ["RowState", "TaskState", "LevelState", "Explanation", "explain"]


@dataclass(frozen=True)
class RowState:
    """One inequality row (or bound) active or violated at ``x``.

    Attributes
    ----------
    row : int
        Row index within the task; for a bound, the index of the variable in ``x``.
    side : str
        ``"lower"`` or ``"upper"``: the bound the row is at or beyond.
    bound : float
        That bound (the task's ``lower`` / ``upper``, or the box's; the row's units).
    value : float
        ``C_i x`` (or ``x[row]``), same units.
    violation : float
        How far beyond the bound the value is (same units, ≥ 0; 0 for an active row that
        holds).
    """

    row: int
    side: str
    bound: float
    value: float
    violation: float

    @property
    def violated(self) -> bool:
        """Is the row beyond its bound by more than the tolerance (the module's rule)?"""
        return self.violation > 0.0

    def __str__(self) -> str:
        sign = "≥" if self.side == "lower" else "≤"
        state = f"violated by {self.violation:.3g}" if self.violated else "active"
        return f"row {self.row} ({sign} {self.bound:.6g}) {state}"


@dataclass(frozen=True)
class TaskState:
    """One task at ``x``.

    Attributes
    ----------
    task : str
        The task's label (kind and name, e.g. ``"Inequality 'band'"``), or the bounds'.
    residual : float
        ``‖A x − b‖`` for an equality, ``‖violation(C x)‖`` for an inequality, in the
        task's units, weights not applied (the level value of
        :attr:`Solution.level_residuals <qpcoord.Solution.level_residuals>` applies them).
    met : bool
        Every row met (the module's tolerance rule).
    rows : tuple of RowState
        Inequality rows (or bounds) active or violated, in row order.
    """

    task: str
    residual: float
    met: bool
    rows: tuple[RowState, ...]

    def __str__(self) -> str:
        head = f"{self.task}: residual {self.residual:.3g}" + ("" if self.met else " (not met)")
        return head + "".join(f"\n  {r}" for r in self.rows)


@dataclass(frozen=True)
class LevelState:
    """One priority level at ``x``.

    Attributes
    ----------
    level : int
        Its index (0: the highest priority).
    value : float
        The level's value as the solve returned it (weights applied; task units).
    met : bool
        Every task of the level met.
    tasks : tuple of TaskState
        Its tasks, equalities first then inequalities (the stack's order).
    """

    level: int
    value: float
    met: bool
    tasks: tuple[TaskState, ...]

    def __str__(self) -> str:
        head = f"level {self.level}: value {self.value:.3g}" + ("" if self.met else " (not met)")
        return head + "".join("\n  " + str(t).replace("\n", "\n  ") for t in self.tasks)


@dataclass(frozen=True)
class Explanation:
    """The state of a solved stack at its ``x``: what :meth:`Solution.explain()
    <qpcoord.Solution.explain>` returns.

    Attributes
    ----------
    levels : tuple of LevelState
        One per priority level, highest first.
    constraints : tuple of TaskState
        The hard constraints (always met: their active rows).
    bounds : TaskState or None
        The box on ``x`` (its active entries), ``None`` without bounds.
    """

    levels: tuple[LevelState, ...]
    constraints: tuple[TaskState, ...]
    bounds: TaskState | None

    @property
    def unmet(self) -> tuple[LevelState, ...]:
        """The levels that could not be met."""
        return tuple(L for L in self.levels if not L.met)

    def __str__(self) -> str:
        parts = [str(L) for L in self.levels]
        if self.constraints:
            parts.append(
                "constraints:"
                + "".join("\n  " + str(t).replace("\n", "\n  ") for t in self.constraints)
            )
        if self.bounds is not None:
            parts.append(str(self.bounds))
        return "\n".join(parts)


def _rows(values, lower, upper, size) -> tuple[tuple[RowState, ...], np.ndarray]:
    """The rows at or beyond a bound and every row's violation (0 inside)."""
    with np.errstate(invalid="ignore"):  # ±inf bounds: never at them
        tol_lo = CHECK_TOL * np.maximum(np.maximum(1.0, np.abs(lower)), size)
        tol_hi = CHECK_TOL * np.maximum(np.maximum(1.0, np.abs(upper)), size)
        below, above = lower - values, values - upper
    at_lo = np.isfinite(lower) & (below >= -tol_lo)
    at_hi = np.isfinite(upper) & (above >= -tol_hi) & ~at_lo
    miss = np.where(below > tol_lo, below, 0.0) + np.where(above > tol_hi, above, 0.0)
    out = []
    for i in np.flatnonzero(at_lo | at_hi):
        side, bound = ("lower", lower[i]) if at_lo[i] else ("upper", upper[i])
        out.append(RowState(int(i), side, float(bound), float(values[i]), float(miss[i])))
    return tuple(out), miss


def _task(t, x: np.ndarray, xnorm: float) -> TaskState:
    """The state of one Equality or Inequality at ``x``."""
    M = t.A if hasattr(t, "A") else t.C
    size = np.linalg.norm(M, axis=1) * xnorm  # each row's rounding scale
    v = M @ x
    if hasattr(t, "A"):
        r = v - t.b
        tol = CHECK_TOL * np.maximum(np.maximum(1.0, np.abs(t.b)), size)
        return TaskState(t.label, float(np.linalg.norm(r)), bool(np.all(np.abs(r) <= tol)), ())
    rows, miss = _rows(v, t.lower, t.upper, size)
    return TaskState(t.label, float(np.linalg.norm(miss)), not miss.any(), rows)


def explain(stack, x: np.ndarray, level_values: np.ndarray) -> Explanation:
    """The :class:`Explanation` of ``stack`` (a :class:`~qpcoord.Stack`) at ``x`` (its
    solution) with the level values the solve returned; reads the tasks' and bounds'
    current numbers."""
    x = np.asarray(x, dtype=float)
    xnorm = float(np.linalg.norm(x))
    P = stack._compiled
    levels = []
    for k, L in enumerate(P.levels):
        tasks = tuple(_task(t, x, xnorm) for t in (*L.eqs, *L.ineqs))
        levels.append(LevelState(k, float(level_values[k]), all(t.met for t in tasks), tasks))
    constraints = tuple(_task(t, x, xnorm) for t in (*P.hard.eqs, *P.hard.ineqs))
    bounds = None
    if P.bounds is not None:
        lb, ub = P.bounds.resolve(P.n)
        rows, miss = _rows(x, lb, ub, np.abs(x))
        bounds = TaskState(P.bounds.label, float(np.linalg.norm(miss)), not miss.any(), rows)
    return Explanation(tuple(levels), constraints, bounds)
