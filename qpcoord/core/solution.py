"""The result of a stack solve: :class:`Solution`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Solution"]


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
        the level and its KKT residual; ``Stack.solve(strict=True)`` raises instead).
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
        when ``status == "inaccurate"``, ``inaccurate`` (``{"level", "kkt_residual"}``).
    """

    x: np.ndarray
    status: str
    level_residuals: np.ndarray
    solver: str
    solve_time: float
    method: str = "hierarchical"
    info: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        res = ", ".join(f"{r:.3g}" for r in self.level_residuals)
        return (
            f"Solution(status={self.status!r}, method={self.method!r}, solver={self.solver!r}, "
            f"level_residuals=[{res}], solve_time={self.solve_time * 1e6:.1f} µs)"
        )
