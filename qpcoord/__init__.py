"""qpcoord: coordination of over-actuated systems as prioritised QP stacks.

Every coordination problem (redundant arms, macro/micro dual stages, muscle-force sharing)
is posed as a stack of priority levels of linear tasks, solved once per control step::

    import qpcoord as qc
    sol = qc.solve_stack([qc.Equality(J, v), qc.Equality(np.eye(n), q_rest - q)],
                         bounds=qc.Bounds(-dq_max, dq_max))
"""

from .backends import available_solvers, default_solver, solver_versions
from .errors import InfeasibleError, SolverError
from .stack import METHODS, Solution, Stack, solve_stack
from .tasks import Bounds, Equality, Inequality

__version__ = "0.1.0"

__all__ = [
    "Bounds",
    "Equality",
    "InfeasibleError",
    "Inequality",
    "METHODS",
    "Solution",
    "SolverError",
    "Stack",
    "available_solvers",
    "default_solver",
    "solve_stack",
    "solver_versions",
]
