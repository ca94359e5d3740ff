"""qpcoord: coordination of over-actuated systems as prioritised QP stacks.

Every coordination problem (redundant arms, macro/micro dual stages, muscle-force sharing)
is posed as a stack of priority levels of linear tasks, solved once per control step::

    import qpcoord as qc
    sol = qc.solve_stack([qc.Equality(J, v), qc.Equality(np.eye(n), q_rest - q)],
                         bounds=qc.Bounds(-dq_max, dq_max))
"""

from . import robots
from ._version import __version__ as __version__
from .coordination import geometry, potentials, schemes, task_manifold

# ``qc.analysis`` (closure errors, Poincaré sections, periods) is the module
# qpcoord.coordination.periodicity under its public name; there is no qpcoord/analysis.py.
from .coordination import periodicity as analysis
from .core.backends import available_solvers, default_solver, solver_versions
from .core.errors import AlgorithmicSingularity, InfeasibleError, SolverError
from .core.stack import METHODS, Solution, Stack, solve_stack
from .core.tasks import Bounds, Equality, Inequality
from .kinematics import paths
from .kinematics.collision import Box, Capsule, CollisionAvoidance, Obstacle, Sphere
from .kinematics.frame_tasks import (
    ComBand,
    ComTask,
    DampingTask,
    FramePositionTask,
    FrameTask,
    JointCouplingTask,
    LowAccelerationTask,
    OrientationTask,
    RelativeFrameTask,
    SupportPolygon,
)
from .kinematics.ik import IK, ik_step, inverse_kinematics
from .kinematics.robot import Robot
from .kinematics.simulation import Trajectory, simulate
from .kinematics.startup import OutsideLimitsError
from .kinematics.tasks import (
    AccelerationLimits,
    JointLimits,
    KinematicTask,
    Limit,
    OneFormTask,
    PositionBand,
    PositionTask,
    PostureTask,
    PotentialTask,
    VelocityLimits,
)

__all__ = [
    "Box",
    "Capsule",
    "CollisionAvoidance",
    "Obstacle",
    "Sphere",
    "AccelerationLimits",
    "KinematicTask",
    "Limit",
    "ComBand",
    "ComTask",
    "DampingTask",
    "FramePositionTask",
    "FrameTask",
    "JointCouplingTask",
    "LowAccelerationTask",
    "OrientationTask",
    "RelativeFrameTask",
    "SupportPolygon",
    "AlgorithmicSingularity",
    "Bounds",
    "Equality",
    "IK",
    "InfeasibleError",
    "Inequality",
    "JointLimits",
    "METHODS",
    "OneFormTask",
    "OutsideLimitsError",
    "PositionBand",
    "PositionTask",
    "PostureTask",
    "PotentialTask",
    "Robot",
    "Solution",
    "SolverError",
    "Stack",
    "Trajectory",
    "analysis",
    "ddl",
    "hysteresis",
    "musculo",
    "reproduce",
    "sweep",
    "geometry",
    "VelocityLimits",
    "available_solvers",
    "default_solver",
    "ik_step",
    "inverse_kinematics",
    "paths",
    "potentials",
    "robots",
    "schemes",
    "simulate",
    "solve_stack",
    "solver_versions",
    "task_manifold",
    "viz",
]

#: Names imported on first use -> their module (``qc.ddl`` pulls in scipy.signal: ~1.4 s).
_LAZY = {
    "ddl": "qpcoord.ddl",
    "hysteresis": "qpcoord.hysteresis",
    "musculo": "qpcoord.musculo",
    "reproduce": "qpcoord.studies.reproduce",
    "sweep": "qpcoord.studies.sweep",
    "viz": "qpcoord.kinematics.viz",
}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return importlib.import_module(_LAZY[name])
    raise AttributeError(f"module 'qpcoord' has no attribute {name!r}")
