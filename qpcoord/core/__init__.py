"""The prioritised QP stack: tasks, compilation, the three methods, backends, the per-step path.

The lowest layer of qpcoord: it knows nothing about robots, plants or studies.

========================  ==============================================================
module                    holds
========================  ==============================================================
``tasks``                 :class:`Equality`, :class:`Inequality`, :class:`Bounds`
``compile``               the stacked, compiled form of a stack (rows per level)
``stack``                 :class:`Stack`, :func:`solve_stack`, :data:`METHODS`
``solution``              :class:`Solution`
``explain``               :class:`~qpcoord.core.explain.Explanation` (``Solution.explain()``)
``conflict``              :class:`~qpcoord.core.conflict.ConflictRow`, the named conflict
``methods.hierarchical``  lexicographic (strict) levels
``methods.nullspace``     the classic projection formula (thesis Def. 5.4)
``methods.weighted``      one QP, levels weighted by decades
``elimination``           the ``x = x̄ + Z z`` state the methods share
``polish``                active-set polish of an approximate QP point
``backends``              QP backends, fallbacks, :func:`available_solvers`
``persistent``            :class:`~qpcoord.core.persistent.PersistentQP`, the per-step path
``linalg``                filtered SVD, null spaces, numerical rank
``tolerance``             the tolerance rules every check uses
``errors``                :class:`InfeasibleError`, :class:`SolverError`, ...
========================  ==============================================================
"""

from .backends import available_solvers, default_solver, solver_versions
from .errors import AlgorithmicSingularity, InfeasibleError, SolverError
from .solution import Solution
from .stack import METHODS, Stack, solve_stack
from .tasks import Bounds, Equality, Inequality

__all__ = [
    "METHODS",
    "AlgorithmicSingularity",
    "Bounds",
    "Equality",
    "InfeasibleError",
    "Inequality",
    "Solution",
    "SolverError",
    "Stack",
    "available_solvers",
    "default_solver",
    "solve_stack",
    "solver_versions",
]
