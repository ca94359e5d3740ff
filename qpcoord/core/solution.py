"""The result of a stack solve: :class:`Solution`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .explain import Explanation, explain
from .polish import KKT_TOL

__all__ = ["Solution", "inaccurate"]


def inaccurate(
    level: int, residual: float, engine: str, levels: int | None = None
) -> dict[str, Any]:
    """``Solution.info["inaccurate"]`` for a level that could not be certified: its index,
    its relative KKT residual and a sentence saying why (``engine``: ``"python"``, whose
    check is the level's optimality conditions at ``x``, or ``"native"``, whose check is how
    far the level's value moved after the level was frozen). ``level == levels`` (the
    stack's level count) is the final minimum-norm step, named so."""
    if levels is not None and level >= levels:
        return {
            "level": level,
            "kkt_residual": residual,
            "reason": f"level {level} (the minimum-norm step after the {levels} levels): its "
            f"optimality conditions hold only to {residual:.3g} (relative KKT residual), "
            f"above the tolerance {KKT_TOL:g}; the levels' values are certified, x may lie "
            "elsewhere in their optimal set",
        }
    if engine == "native":
        what = f"its value moved by {residual:.3g} (relative) after the level was frozen"
    else:
        what = f"its optimality conditions hold only to {residual:.3g} (relative KKT residual)"
    return {
        "level": level,
        "kkt_residual": residual,
        "reason": f"level {level}: {what}, above the tolerance {KKT_TOL:g}; its value may "
        "depend on a rank or active-set decision within rounding (rows nearly dependent on "
        "the levels above, or a point far from the origin)",
    }


@dataclass
class Solution:
    """Result of :meth:`Stack.solve`.

    Attributes
    ----------
    x : numpy.ndarray, shape (n,)
        The solution, checked against the bounds and hard constraints.
    status : str
        ``"optimal"`` when every level's optimality conditions were checked on ``x``
        (``method="hierarchical"``: its KKT residual, see ``docs/stack.md``);
        ``"inaccurate"`` when a level could not be certified (``info["inaccurate"]`` names
        the level, its KKT residual and the reason; ``Stack.solve(strict=True)`` raises instead).
    level_residuals : numpy.ndarray, shape (levels,)
        Per level, ``√(‖√w (A x − b)‖² + ‖√w · violation(C x)‖²)`` over its tasks, in task
        units (weights included).
    solver : str
        Backend used for the QPs (the closed-form steps need none).
    solve_time : float
        Wall-clock time of the solve, in seconds.
    method : str
        ``"hierarchical"``, ``"nullspace"`` or ``"weighted"``.
    info : dict
        ``qp_calls`` (QPs actually solved), ``fallbacks`` (level QPs the requested
        backend failed on and another backend solved, e.g. ``"level 1: quadprog"``),
        ``level_ranks`` (dimensions each level fixed;
        hierarchical and nullspace methods), ``free_dofs`` (freedom left to the
        minimum-norm step; hierarchical), and for the hierarchical method ``kkt`` (the
        certified KKT residual of each level that ran a QP), ``continued`` (levels made
        exact by the active-set continuation), ``uncertified`` (``(level, residual)``) and,
        when ``status == "inaccurate"``, ``inaccurate`` (``{"level", "kkt_residual",
        "reason"}``).
    stack : Stack or None
        The stack this solves (for :meth:`explain`); ``None`` for a solution built
        elsewhere, and after pickling (the stack is not pickled with it).
    """

    x: np.ndarray
    status: str
    level_residuals: np.ndarray
    solver: str
    solve_time: float
    method: str = "hierarchical"
    info: dict = field(default_factory=dict)
    stack: Any = field(default=None, repr=False, compare=False)

    def explain(self) -> Explanation:
        """What gave way: per level and task the residual and the inequality rows active
        or violated at ``x``, by name; the hard constraints' and bounds' active rows (see
        :mod:`qpcoord.core.explain` for the tolerance). ``str()`` of the result is a
        readable report; nothing is printed.

        Reads the tasks' current numbers: call it before they are updated for the next
        solve.

        Raises
        ------
        ValueError
            The solution has no stack (built outside :meth:`Stack.solve
            <qpcoord.Stack.solve>`, or unpickled).
        """
        if self.stack is None:
            raise ValueError(
                "this Solution has no stack to explain (built outside Stack.solve, or unpickled)"
            )
        return explain(self.stack, self.x, self.level_residuals)

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["stack"] = None  # may hold a native engine, which does not pickle
        return state

    def __repr__(self) -> str:
        res = ", ".join(f"{r:.3g}" for r in self.level_residuals)
        return (
            f"Solution(status={self.status!r}, method={self.method!r}, solver={self.solver!r}, "
            f"level_residuals=[{res}], solve_time={self.solve_time * 1e6:.1f} µs)"
        )
