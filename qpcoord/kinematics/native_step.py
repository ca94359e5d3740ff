"""The native IK step: one call into ``qpcoord._native`` per control step.

:class:`NativeIKStep` compiles an :class:`~qpcoord.IK` once: which kernel writes which rows
of the compiled stack's stacked arrays (the native solver's inputs), the frames the kernels
read (views of the robot's ``pinocchio.Data``, bound once), and the limit boxes. A step is
then Pinocchio's ``computeJointJacobians`` (and ``jacobianCenterOfMass`` with a CoM task) and
one native call that checks ``q``, computes each task's error and Jacobian, the intersected
limit box, and solves the strict hierarchy -- or, for ``IK(..., method="weighted")``, the
native weighted QP (:mod:`qpcoord.core.native_weighted`, ``src/native/weighted.*``) on the
same rows.

Native kernels (the same rows as the tasks' Python ``_refresh``, to rounding):

- :class:`~qpcoord.PositionTask` on a robot with a default frame (fixed target, path or the
  run's reference; a path is evaluated by the task's ``reference_at``),
- :class:`~qpcoord.FramePositionTask`, :class:`~qpcoord.FrameTask` (both errors),
  :class:`~qpcoord.OrientationTask`, :class:`~qpcoord.ComTask` (targets, feed-forward,
  masks, weights),
- :class:`~qpcoord.PostureTask` (``q_ref ⊖ q = pinocchio.difference(q, q_ref)`` on its
  joints by segments of ``src/native/integrate.hpp``: ``q_ref − q`` on 1-DoF joints, the
  angle of a continuous joint, Pinocchio's quaternion ``log3`` of a spherical joint and
  ``log6`` of a free-flyer below the root, SE(2)'s log of a planar one; a floating base's
  own rows are not in it),
- :class:`~qpcoord.RelativeFrameTask` (``e = log₆(T*⁻¹ T_ref⁻¹ T_frame)``, both frames'
  motions) and :class:`~qpcoord.JointCouplingTask` (one row; its ``offset`` is a parameter),
- :class:`~qpcoord.DampingTask` (``v = 0``; the step writes ``q`` into its ``q_hold``) and
  :class:`~qpcoord.LowAccelerationTask` (``v = v_prev``: its ``set_previous`` velocity, else
  ``difference(q_hold, q) / dt`` on the configuration manifold, ``src/native/integrate.hpp``),
- the Levenberg–Marquardt rows (:class:`~qpcoord.LMDamping`) of every task listed here with
  ``lm_damping > 0``: ``√μ I`` from the error its kernel computed at the same step (run after
  the other kernels; zero below ``LM_ERROR_FLOOR``),
- :class:`~qpcoord.PositionBand` on a robot with a default frame (inequality rows ``C``,
  ``lower``, ``upper``: the frame's position rows),
- :class:`~qpcoord.ComBand` and :class:`~qpcoord.SupportPolygon` (inequality rows ``C``,
  ``lower``, ``upper``; ``src/native/support_kernels.hpp``: the polygon's hull as
  ``frame_tasks._hull``, its ``edges`` set after each step; collinear contacts or a
  non-finite row make Python raise the task's message),
- :class:`~qpcoord.kinematics.collision.CollisionAvoidance` whose rows are native
  (:attr:`~qpcoord.kinematics.collision.CollisionAvoidance.native`): ``qpcoord._collision``'s
  kernel handed to the step as a C entry point (``src/native/rows_kernel.h``), called inside
  the native call on the step's kinematics (the broad phase, coal's distances, the rows of
  the pairs inside the influence distance; a pair outside it a zero row with lower ``-inf``,
  so the row count is the task's, one per pair),
- :class:`~qpcoord.JointLimits`, :class:`~qpcoord.VelocityLimits` and
  :class:`~qpcoord.AccelerationLimits` with its braking before the position limits
  (``src/native/braking.hpp``; its ``v_prev`` array is bound once and read at every step),
  intersected by the rule of :meth:`IK.refresh <qpcoord.IK.refresh>`.

Every other task (other bands, collision rows computed in Python, user tasks, a posture over a
joint without a native difference -- composite, mimic --, and their ``lm_damping`` rows) and
constant Equality/Inequality rows keep their Python ``_refresh``, run before the native call
and copied into the same arrays (a hybrid step); any other limit (a user's
:class:`~qpcoord.Limit`) makes the whole box Python-computed. With ``integrate=True``
(:meth:`IK.step_integrate <qpcoord.IK.step_integrate>`) the same call writes ``q_next``
(:func:`integration_plan`).

The boundary is data only (``docs/engine.md``, *The IK step*): the native step holds its own
copy of each kernel's parameters (gain, row weights, target and feed-forward, faces, contact
points, limits), set through its typed setters when a task's parameter is assigned (the task
tells the steps it is bound to: ``KinematicTask._bound``) and, for a path or the run's
reference, evaluated by ``reference_at`` before each step; it reads no task attribute while it
runs. The kernels write each task's own ``task.task`` arrays (``A``, ``b``; ``C``, ``lower``,
``upper``: bound once, as output buffers) and this module counts a new ``A`` (``C``) in its
``matrix_version``, as its ``_refresh`` would.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import IntEnum
from functools import partial
from typing import Any

import numpy as np
import pinocchio as pin

from ..core.backends import DEFAULT_TIME_LIMIT
from ..core.compile import CompiledStack
from ..core.conflict import infeasible
from ..core.errors import InfeasibleError, SolverError
from ..core.native import NativeHierarchy, load, raise_status
from ..core.native_weighted import weighted_info
from ..core.polish import KKT_TOL
from ..core.solution import Solution, inaccurate
from ..core.tasks import TASK_WRITES, Equality, _w
from .collision import CollisionAvoidance
from .frame_tasks import (
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
from .robot import Robot
from .tasks import (
    LM_ERROR_FLOOR,
    AccelerationLimits,
    JointLimits,
    KinematicTask,
    Limit,
    LMDamping,
    PositionBand,
    PositionTask,
    PostureTask,
    VelocityLimits,
)

__all__ = ["NativeIKStep", "IKStepSpec", "KERNELS", "TaskKind", "native_kind", "integration_plan"]


class TaskKind(IntEnum):
    """The native IK step's task kernels (``qpcoord._native.IKTaskKind``, the same names and
    values: ``src/native/ik_step.cpp``'s ``Kind``; ``ik_step/kernels.hxx`` evaluates each)."""

    POSITION = 0
    FRAME_POSITION = 1
    POSE = 2
    ORIENTATION = 3
    COM = 4
    POSTURE = 5
    POSE_SPLIT = 6  #: ``FrameTask(error="split")``
    COM_BAND = 7  #: an inequality (``src/native/support_kernels.hpp``)
    SUPPORT_POLYGON = 8  #: an inequality (``src/native/support_kernels.hpp``)
    POSITION_BAND = 9  #: an inequality on the default frame's position rows
    # -- the damping kernels (a task's rows from another kernel's error) --
    LM_DAMPING = 10  #: a task's Levenberg–Marquardt rows (:class:`~qpcoord.LMDamping`)
    RELATIVE_FRAME = 11  #: :class:`~qpcoord.RelativeFrameTask` (two frames)
    JOINT_COUPLING = 12  #: :class:`~qpcoord.JointCouplingTask`
    DAMPING = 13  #: :class:`~qpcoord.DampingTask` (``v = 0``; ``q_hold`` written in place)
    LOW_ACCELERATION = 14  #: :class:`~qpcoord.LowAccelerationTask` (``v = v_prev``)

    # rows another extension module computes (``src/native/rows_kernel.h``), from 32 on
    COLLISION = 32  #: an inequality: ``qpcoord._collision``'s kernel, called by the step


#: The kernel of each task class (``FrameTask(error="split")``: ``POSE_SPLIT``).
KERNELS = {
    PositionTask: TaskKind.POSITION,
    FramePositionTask: TaskKind.FRAME_POSITION,
    FrameTask: TaskKind.POSE,
    OrientationTask: TaskKind.ORIENTATION,
    ComTask: TaskKind.COM,
    PostureTask: TaskKind.POSTURE,
    ComBand: TaskKind.COM_BAND,
    SupportPolygon: TaskKind.SUPPORT_POLYGON,
    PositionBand: TaskKind.POSITION_BAND,
    RelativeFrameTask: TaskKind.RELATIVE_FRAME,
    JointCouplingTask: TaskKind.JOINT_COUPLING,
    DampingTask: TaskKind.DAMPING,
    LowAccelerationTask: TaskKind.LOW_ACCELERATION,
    CollisionAvoidance: TaskKind.COLLISION,
}
#: The limits with a kernel (exact classes: a subclass's box is Python's).
_NATIVE_LIMITS = (JointLimits, VelocityLimits, AccelerationLimits)
#: The kernels that read no frame.
_FRAMELESS = (
    TaskKind.COM, TaskKind.POSTURE, TaskKind.JOINT_COUPLING, TaskKind.DAMPING,
    TaskKind.LOW_ACCELERATION,
)  # fmt: skip
#: The kernels whose task's matrix is constant (a step writes no new ``A``).
_CONSTANT_A = (TaskKind.POSTURE, TaskKind.DAMPING, TaskKind.LOW_ACCELERATION)
#: The band kernels (Inequality rows).
_BANDS = (TaskKind.COM_BAND, TaskKind.SUPPORT_POLYGON, TaskKind.POSITION_BAND)

_F64 = np.dtype(np.float64)
_clock = time.perf_counter
_jacobians = pin.computeJointJacobians


def _f64(x: Any) -> np.ndarray:
    """``x`` as a float64 array (``x`` itself when it is one)."""
    if type(x) is np.ndarray and x.dtype == _F64:
        return x
    return np.asarray(x, dtype=float)


def _push_position(slot: _Slot) -> None:
    task = slot.task  # a PositionTask
    y = task.target
    moving = slot.moving
    if slot in moving:
        moving.remove(slot)
    if type(y) is np.ndarray and y.dtype == _F64 and y.shape == (task.robot.m,):
        slot.solver.set_target(slot.k, y, None)
    else:  # a path, the run's reference, or numbers reference_at converts: at every step
        moving.append(slot)


def _push_point(slot: _Slot) -> None:
    task = slot.task  # a FramePositionTask or a ComTask
    y, v = task.target, task.target_velocity
    if y is None:
        raise ValueError("no target")
    slot.solver.set_target(slot.k, _f64(y), v if v is None else _f64(v))


def _push_pose(slot: _Slot) -> None:
    task = slot.task  # a FrameTask: _target_T its validated 4×4 (None without a target)
    T, v = task._target_T, task.target_velocity
    if T is None:
        raise ValueError("no target")
    slot.solver.set_target(slot.k, T, v if v is None else _f64(v))


def _push_orientation(slot: _Slot) -> None:
    task = slot.task  # an OrientationTask: _target_t is R*ᵀ, what its _evaluate reads
    Rt, v = task._target_t, task.target_velocity
    if Rt is None:
        raise ValueError("no target")
    slot.solver.set_target(slot.k, Rt.T, v if v is None else _f64(v))


def _push_relative(slot: _Slot) -> None:
    T = slot.task.target  # a RelativeFrameTask's pin.SE3 (validated by its set_target)
    if T is None:
        raise ValueError("no target")
    slot.solver.set_target(slot.k, np.asarray(T.homogeneous, dtype=float), None)


def _push_coupling(slot: _Slot) -> None:
    task = slot.task  # a JointCouplingTask: (ratios, offset)
    slot.solver.set_target(slot.k, np.append(_f64(task.ratios), float(task.offset)), None)


def _push_damping(slot: _Slot) -> None:
    slot.solver.bind_hold(slot.k, slot.task._hold, None)  # a DampingTask's q_hold, one array


def _push_low_acceleration(slot: _Slot) -> None:
    task = slot.task  # a LowAccelerationTask: q_hold and v_prev (one array each)
    slot.solver.bind_hold(slot.k, task._hold, task._v_prev)
    if task._given is not None:  # set_previous: the native step's next step takes it
        slot.solver.set_previous(slot.k, task._given)
        task._given = None


def _push_posture(slot: _Slot) -> None:
    slot.solver.set_target(slot.k, _f64(slot.task.q_ref), None)


def _push_faces(slot: _Slot) -> None:
    task = slot.task  # a ComBand or a PositionBand
    slot.solver.set_faces(slot.k, _f64(task.lower), _f64(task.upper))


def _push_polygon(slot: _Slot) -> None:
    task = slot.task  # a SupportPolygon
    slot.solver.set_contacts(slot.k, _f64(task.contact_points), task.margin)


def _push_lm_damping(slot: _Slot) -> None:
    owner = slot.task.owner  # an LMDamping's task: its lm_damping, read at each assignment
    slot.solver.set_lm_damping(slot.k, float(owner.lm_damping), LM_ERROR_FLOOR**2)


def _push_joint_limits(slot: _Slot) -> None:
    lim = slot.task  # a JointLimits
    qi = lim.q_index
    if qi is None:  # all of q (q and v share one layout); an unlimited joint's band unused
        lo, hi = lim.lower, lim.upper
        band = np.full(lim.lower.shape, np.inf)
        band[lim.joints] = lim.band_rate
    else:
        lo, hi, band = lim.lower[qi], lim.upper[qi], lim.band_rate
    slot.solver.set_joint_limits(slot.k, lim.gain, _f64(lo), _f64(hi), _f64(band))


def _push_collision(slot: _Slot) -> None:
    kernel = slot.task._kernel  # a CollisionAvoidance: its qpcoord._collision kernel
    if kernel is None:
        raise ValueError("no native rows")
    slot.solver.set_rows_kernel(slot.k, kernel.entry())


def _push_velocity_limits(slot: _Slot) -> None:
    slot.solver.set_velocity_limits(slot.k, _f64(slot.task.limit))  # a VelocityLimits


def _push_acceleration_limits(slot: _Slot) -> None:
    lim = slot.task  # an AccelerationLimits: its v_prev array is bound (add_acceleration_limits)
    P = lim.position_limits
    if P is None:
        gain, lo, hi = 1.0, np.zeros(0), np.zeros(0)
    else:
        qi = _braked_q_index(P)
        gain, lo, hi = P.gain, _f64(P.lower[qi]), _f64(P.upper[qi])
    slot.solver.set_acceleration_limits(slot.k, _f64(lim.limit), gain, lo, hi)


def _braked_q_index(P: JointLimits) -> np.ndarray:
    """The q index of each joint of ``P.joints`` (its v index where q and v share one
    layout)."""
    return P.joints if P.q_index is None else P.q_index


#: How each kernel's parameters (target, faces, contact points; a collision task's kernel)
#: go to the native step.
_PUSH: dict[TaskKind, Callable[[_Slot], None]] = {
    TaskKind.POSITION: _push_position,
    TaskKind.FRAME_POSITION: _push_point,
    TaskKind.POSE: _push_pose,
    TaskKind.POSE_SPLIT: _push_pose,
    TaskKind.ORIENTATION: _push_orientation,
    TaskKind.COM: _push_point,
    TaskKind.POSTURE: _push_posture,
    TaskKind.COM_BAND: _push_faces,
    TaskKind.POSITION_BAND: _push_faces,
    TaskKind.SUPPORT_POLYGON: _push_polygon,
    TaskKind.COLLISION: _push_collision,
    TaskKind.LM_DAMPING: _push_lm_damping,
    TaskKind.RELATIVE_FRAME: _push_relative,
    TaskKind.JOINT_COUPLING: _push_coupling,
    TaskKind.DAMPING: _push_damping,
    TaskKind.LOW_ACCELERATION: _push_low_acceleration,
}


class _Slot:
    """A task bound to one kernel (``kind`` a :class:`TaskKind`) or limit (``kind`` None) of
    a native step (``solver``, index ``k``), told of every parameter write of the task (its
    ``_bound``, until the step is dropped), and what of the task the step holds (its gain;
    its weights and output arrays, by identity)."""

    __slots__ = (
        "k", "kind", "task", "solver", "moving", "push", "gain", "arrays", "set_target", "watched",
        "error",
    )  # fmt: skip

    def __init__(
        self, solver: Any, moving: list[_Slot], k: int, kind: TaskKind | None, task: Any
    ) -> None:
        self.k, self.kind, self.solver, self.moving = k, kind, solver, moving
        self.task: Any = task  # its class is the kind's (KERNELS)
        #: the tasks whose parameter writes this slot is told of: its own and those it
        #: reads (an acceleration limit's braked position limits)
        self.watched: tuple[Any, ...] = (task,)
        if kind is not None:
            self.push = _PUSH[kind]
            if kind == TaskKind.LM_DAMPING:  # told when its owner's lm_damping is assigned
                self.watched = (task, task.owner)
        elif isinstance(task, VelocityLimits):
            self.push = _push_velocity_limits
        elif isinstance(task, AccelerationLimits):
            self.push = _push_acceleration_limits
            if task.position_limits is not None:
                self.watched = (task, task.position_limits)
        else:
            self.push = _push_joint_limits
        self.gain: Any = None
        self.arrays: tuple[np.ndarray, ...] = ()
        #: what the native setter said of data it refused (None: its data is in the step)
        self.error: str | None = None
        #: ``set_target(target, velocity)`` of this kernel: a task's own set_target calls it
        #: with its validated float64 target (FrameTask: T* (4, 4), OrientationTask: R*
        #: (3, 3), FramePositionTask and ComTask: (3,)) and velocity (or None), one native
        #: call per control step
        self.set_target = partial(solver.set_target, k)
        for t in self.watched:
            t._bound = (*t._bound, self)

    def unbind(self) -> None:
        """Tell the tasks no more (its step is dropped)."""
        for t in self.watched:
            t._bound = tuple(s for s in t._bound if s is not self)

    def changed(self) -> None:
        """Copy the task's parameters (gain, target, ...) into the native step: at compile
        and whenever one is assigned. Data the kernel cannot use leaves it without a target
        (its step then raises the task's own message)."""
        try:
            if self.kind is not None:
                gain = self.task.gain
                if gain != self.gain:  # (NaN: always, and refused)
                    self.solver.set_gain(self.k, gain)
                    self.gain = gain
            self.push(self)
            self.error = None
        except (TypeError, ValueError) as exc:
            self.error = str(exc)
            if self in self.moving:
                self.moving.remove(self)
            if self.kind is None:
                self.solver.forget_limit(self.k)
            else:
                self.solver.forget_target(self.k)

    def task_arrays(self) -> tuple[np.ndarray, ...]:
        """The task's weights and output arrays (``sqrt_weight`` and ``A``, ``b`` or ``C``,
        ``lower``, ``upper``)."""
        eq = self.task.task
        if isinstance(eq, Equality):
            return eq.sqrt_weight, eq.A, eq.b
        return eq.sqrt_weight, eq.C, eq.lower, eq.upper


def native_kind(task: KinematicTask) -> TaskKind | None:
    """The native kernel of ``task`` (:data:`KERNELS`), or ``None`` if its rows are
    built by its Python ``_refresh`` (exact classes only: a subclass may change them)."""
    if type(task) is LMDamping:  # native when its owner is: its kernel reads the owner's
        return TaskKind.LM_DAMPING if native_kind(task.owner) is not None else None
    kind = KERNELS.get(type(task))
    if kind == TaskKind.COLLISION:  # its native rows (qpcoord._collision), if it has them
        assert isinstance(task, CollisionAvoidance)
        return kind if task.native else None
    if kind == TaskKind.POSITION_BAND and task.robot.frame_id is None:
        return None  # no default frame: its _refresh raises the robot's message
    if kind in _BANDS:
        return kind
    if kind is None or task.kind != "equality":
        return None
    if kind == TaskKind.POSITION and task.robot.frame_id is None:
        return None  # no default frame: its _refresh raises the robot's message
    if kind == TaskKind.POSE and isinstance(task, FrameTask) and task.error == "split":
        return TaskKind.POSE_SPLIT
    if kind == TaskKind.POSTURE and isinstance(task, PostureTask) and _posture_plan(task) is None:
        return None
    if kind == TaskKind.LOW_ACCELERATION and integration_plan(task.robot) is None:
        return None  # a joint without a native difference (planar, composite, ...)
    return kind


def _coupling_indices(task: JointCouplingTask) -> list[int]:
    """A joint coupling's q indices, then its v indices (one-DoF joints, in its order)."""
    model = task.robot.model
    joints = [model.joints[model.getJointId(name)] for name in task.joints]
    return [int(j.idx_q) for j in joints] + [int(j.idx_v) for j in joints]


def _posture_plan(task: PostureTask) -> list[int] | None:
    """A posture's difference plan (``q_ref ⊖ q`` on its joints: the segments of
    :func:`integration_plan` whose velocity rows are the task's, planar joints too), or
    ``None`` if one of its joints has no native difference (composite, mimic, ...)."""
    robot = task.robot
    if robot.euclidean:
        return [0, 0, 0, robot.nq]
    return _segments(robot, {int(j) for j in task.joints}, _DIFFERENCE_JOINTS)


#: Joints whose configuration is a vector space (``q + v dt``), by Pinocchio short name.
_VECTOR_JOINTS = frozenset(
    f"JointModel{name}"
    for name in (
        "RX", "RY", "RZ", "PX", "PY", "PZ", "HX", "HY", "HZ", "RevoluteUnaligned",
        "PrismaticUnaligned", "HelicalUnaligned", "Translation",
    )
)  # fmt: skip
#: Segment kinds of the native integrator (``src/native/integrate.hpp``) by joint short name.
_MANIFOLD_JOINTS = {
    "JointModelRUBX": 1,
    "JointModelRUBY": 1,
    "JointModelRUBZ": 1,
    "JointModelRevoluteUnboundedUnaligned": 1,
    "JointModelSpherical": 2,
    "JointModelFreeFlyer": 3,
}
#: The segment kinds of the native difference (``integrate::difference``): the integrator's
#: and the planar joint's (no native integration).
_DIFFERENCE_JOINTS = {**_MANIFOLD_JOINTS, "JointModelPlanar": 4}


def integration_plan(robot: Any) -> list[int] | None:
    """The native integrator's plan for ``robot`` (``(kind, idx_q, idx_v, size)`` per segment,
    adjacent vector-space joints merged), or ``None`` if a joint is of another type (planar,
    composite, mimic, ...): then ``q_next`` comes from :meth:`~qpcoord.Robot.integrate`.

    A robot with a vector-space configuration (``robot.euclidean``, a coordinate map
    included) is one segment ``q + v dt`` in its own coordinates, as ``Robot.integrate``."""
    if robot.euclidean:
        return [0, 0, 0, robot.nq]
    return _segments(robot, None, _MANIFOLD_JOINTS)


def _segments(robot: Any, rows: set[int] | None, kinds: dict[str, int]) -> list[int] | None:
    """The native segments of the robot's joints (all of them, or those whose first velocity
    row is in ``rows``), adjacent vector-space joints merged, the others' kind from ``kinds``
    (by short name); ``None`` if one has no native kind."""
    plan: list[int] = []
    for joint in robot.model.joints[1:]:
        name = joint.shortname()
        iq, iv = int(joint.idx_q), int(joint.idx_v)
        if rows is not None and iv not in rows:
            continue
        if name in _VECTOR_JOINTS:
            if plan and plan[-4] == 0 and plan[-3] + plan[-1] == iq and plan[-2] + plan[-1] == iv:
                plan[-1] += int(joint.nq)
            else:
                plan += [0, iq, iv, int(joint.nq)]
        elif name in kinds:
            plan += [kinds[name], iq, iv, 1]
        else:
            return None
    return plan


def _selection(task: KinematicTask, kind: TaskKind) -> list[int]:
    """Per row of the task: the axis of its full error (or the joint of a posture)."""
    if kind in (TaskKind.POSITION, TaskKind.POSITION_BAND):
        return [int(r) for r in task.robot.rows]
    if kind in (TaskKind.LM_DAMPING, TaskKind.DAMPING, TaskKind.LOW_ACCELERATION):
        return list(range(task.robot.nv))
    if isinstance(task, PostureTask):  # TaskKind.POSTURE
        return [int(j) for j in task.joints]
    if kind in _BANDS or kind == TaskKind.COLLISION:
        return list(range(task.task.shape[0]))
    assert isinstance(
        task,
        (
            FramePositionTask,
            FrameTask,
            OrientationTask,
            ComTask,
            RelativeFrameTask,
            JointCouplingTask,
        ),
    )
    return [int(r) for r in task.selected_rows]


def _frame_id(task: KinematicTask, kind: TaskKind) -> int:
    """The frame a kernel of ``kind`` reads for ``task`` (its own, or its robot's default)."""
    fid: int | None
    if isinstance(task, (FramePositionTask, FrameTask, OrientationTask, RelativeFrameTask)):
        fid = task.frame_id
    else:  # POSITION: a PositionTask, on a robot with a default frame (native_kind)
        fid = task.robot.frame_id
    assert fid is not None, kind
    return int(fid)


@dataclass(frozen=True)
class IKStepSpec:
    """Everything the native step reads of an :class:`~qpcoord.IK` (the IK builds it).

    Attributes
    ----------
    robot : Robot
        The IK's robot: its model and data are bound once.
    stack : CompiledStack
        The compiled form of the IK's stack, whose stacked arrays the native call writes.
    box : tuple of numpy.ndarray or None
        The writable ``(lower, upper)`` arrays (nv,) behind the stack's bounds (``None``: no
        limits): the native call writes the limits' box there.
    tasks : sequence of KinematicTask
        The IK's kinematic tasks (levels and constraints), each owning one task of ``stack``.
    limits : sequence of Limit
        The IK's limits, intersected into ``box``.
    refresh_limits : callable
        ``refresh_limits(q)`` writes the limits' intersected box into ``box`` for a
        validated ``q`` (the IK's rule): used when a limit has no native kernel.
    dt : float
        Control period (s).
    damping : float
        The stack's relative damping.
    weighted : bool
        The weighted QP solves (``IK(..., method="weighted")``) instead of the hierarchy.
    regularization, weight_ratio : float
        The stack's weighted-QP parameters.
    """

    robot: Robot
    stack: CompiledStack
    box: tuple[np.ndarray, np.ndarray] | None
    tasks: Sequence[KinematicTask]
    limits: Sequence[Limit]
    refresh_limits: Callable[[np.ndarray], None]
    dt: float
    damping: float
    weighted: bool
    regularization: float
    weight_ratio: float


class NativeIKStep(NativeHierarchy):
    """The compiled native step of one :class:`~qpcoord.IK` (built by the IK).

    It is a :class:`~qpcoord.core.native.NativeHierarchy` whose solver also writes the task
    rows (its status codes and messages are the same), bound to the IK's compiled stack.

    Parameters
    ----------
    spec : IKStepSpec
        What it reads of an IK with ``method="hierarchical"`` or ``"weighted"`` and no
        explicit ``solver``. ``"weighted"``: the native weighted QP solves (the stack's
        ``regularization`` and ``weight_ratio``), its rows written by the same kernels; the
        solution's ``info`` is that of
        :meth:`NativeWeighted.solve <qpcoord.core.native_weighted.NativeWeighted.solve>`.
    """

    def __init__(self, spec: IKStepSpec) -> None:  # noqa: D107 - own solver, no super().__init__
        mod = load()
        robot = spec.robot
        P = spec.stack
        self.spec = spec
        self.robot = robot
        self.P = P
        self.n = P.n
        self._mod = mod
        self._solved = False
        self.x = np.zeros(P.n)
        self.res = np.zeros(len(P.levels))
        self.stats = np.zeros((len(P.levels) + 2, 3))
        self.detail = np.zeros(8)
        self._model, self._data = robot.model, robot.data
        self._qshape = (robot.nq,)
        self._M = robot.coordinate_map
        blocks = [P.hard, *P.levels]
        unit = [v for start, stop, _, _ in robot.unit_blocks for v in (start, stop - start)]
        solver = mod.IKStep(
            robot.nq,
            robot.nv,
            [B.m_eq for B in blocks],
            [B.m_in for B in blocks],
            P.bounds is not None,
            float(spec.damping),
            float(spec.dt),
            unit,
        )
        if P.bounds is not None and spec.box is not None:
            box_lo, box_hi = spec.box
        else:
            box_lo, box_hi = np.full(P.n, -np.inf), np.full(P.n, np.inf)
        solver.bind(
            P.Aeq, P.beq, P.C, P.clo, P.chi, P.csw, P.lbs, P.ubs, box_lo, box_hi,
            self.x, self.res, self.stats, self.detail,
        )  # fmt: skip
        solver.set_jacobian(self._data.J)
        if self._M is not None:
            solver.set_coordinate_map(np.ascontiguousarray(self._M, dtype=float))
        owners = {id(t.task): t for t in spec.tasks}
        self.kernel_tasks: list[KinematicTask] = []
        self._python_tasks: list[KinematicTask] = []
        self._eq_ops: list[tuple] = []  # (task, A rows, b rows): copied every step
        self._in_ops: list[tuple] = []  # (task, C rows, lo, hi, sw)
        self.com = False
        #: per kernel (in the order added), then per limit: the task bound to it
        self._slots: list[_Slot] = []
        #: the kernels whose target moves with time (a path, the run's reference): their
        #: ``reference_at(t, reference)`` is copied in before every step
        self._moving: list[_Slot] = []
        frames: dict[int, int] = {}
        data = self._data
        #: the LM_DAMPING tasks and their first stacked row: added after the loop (an owner
        #: band's kernel comes after the equalities of its level)
        damping: list[tuple[Any, int]] = []
        i = j = 0
        for B in blocks:
            for t in B.eqs:
                m = t.A.shape[0]
                owner = owners.get(id(t))
                kind = None if owner is None else native_kind(owner)
                if owner is None or kind is None:
                    self._eq_ops.append((t, P.Aeq[i : i + m], P.beq[i : i + m]))
                    if owner is not None and owner not in self._python_tasks:
                        self._python_tasks.append(owner)
                elif kind == TaskKind.LM_DAMPING:  # added once every owner's kernel is
                    damping.append((owner, i))
                else:
                    frame = -1
                    if kind == TaskKind.COM and not self.com:  # views: computed at each step
                        solver.set_com(self._data.com[0], self._data.Jcom)
                        self.com = True
                    elif kind not in _FRAMELESS:
                        fid = _frame_id(owner, kind)
                        if fid not in frames:
                            frames[fid] = self._add_frame(solver, fid)
                        frame = frames[fid]
                    qidx: list[int] | None = []
                    if isinstance(owner, PostureTask):  # its difference's segments
                        qidx = _posture_plan(owner)
                    elif isinstance(owner, RelativeFrameTask):  # the reference frame's slot
                        ref = int(owner.reference_id)
                        if ref not in frames:
                            frames[ref] = self._add_frame(solver, ref)
                        qidx = [frames[ref]]
                    elif isinstance(owner, JointCouplingTask):  # q indices, then v indices
                        qidx = _coupling_indices(owner)
                    elif isinstance(owner, LowAccelerationTask):  # its difference's segments
                        qidx = integration_plan(owner.robot)
                    k = solver.add_task(kind, frame, _selection(owner, kind), i, qidx)
                    self._slots.append(_Slot(solver, self._moving, k, kind, owner))
                    self.kernel_tasks.append(owner)
                i += m
            for u in B.ineqs:
                m = u.C.shape[0]
                owner = owners.get(id(u))
                kind = None if owner is None else native_kind(owner)
                if owner is not None and kind == TaskKind.COLLISION and owner.robot.data is data:
                    # its kernel reads its robot's data: this step's kinematics are there
                    k = solver.add_task(kind, -1, _selection(owner, kind), j, [])
                    self._slots.append(_Slot(solver, self._moving, k, kind, owner))
                    self.kernel_tasks.append(owner)
                    j += m
                    continue
                if owner is not None and kind in _BANDS:  # the bands: natively
                    frame = -1
                    if kind == TaskKind.POSITION_BAND:
                        fid = _frame_id(owner, kind)
                        if fid not in frames:
                            frames[fid] = self._add_frame(solver, fid)
                        frame = frames[fid]
                    elif not self.com:
                        solver.set_com(self._data.com[0], self._data.Jcom)
                        self.com = True
                    slots = []
                    if isinstance(owner, SupportPolygon):  # TaskKind.SUPPORT_POLYGON
                        for fid in owner.frame_ids:
                            if fid not in frames:
                                frames[fid] = self._add_frame(solver, fid)
                            slots.append(frames[fid])
                    k = solver.add_task(kind, frame, _selection(owner, kind), j, slots)
                    self._slots.append(_Slot(solver, self._moving, k, kind, owner))
                    self.kernel_tasks.append(owner)
                    j += m
                    continue
                rows = slice(j, j + m)
                self._in_ops.append((u, P.C[rows], P.clo[rows], P.chi[rows], P.csw[rows]))
                if owner is not None and owner not in self._python_tasks:
                    self._python_tasks.append(owner)
                j += m
        kernel_of = {id(t): k for k, t in enumerate(self.kernel_tasks)}
        for owner, row0 in damping:
            kind = TaskKind.LM_DAMPING
            k = solver.add_task(
                kind, -1, _selection(owner, kind), row0, [kernel_of[id(owner.owner)]]
            )
            self._slots.append(_Slot(solver, self._moving, k, kind, owner))
            self.kernel_tasks.append(owner)
        # limits: natively when all are of _NATIVE_LIMITS, else Python's box
        self._python_limits = False
        if spec.limits:
            if all(type(lim) in _NATIVE_LIMITS for lim in spec.limits):
                for lim in spec.limits:
                    self._add_limit(solver, lim)
                solver.limits_mode = 1
            else:
                self._python_limits = True
                solver.limits_mode = 2
        self._hybrid = bool(self._python_tasks or self._eq_ops or self._in_ops)
        #: the kernels' tasks whose matrix each step writes: their ``matrix_version`` counts a
        #: new matrix per step, as their ``_assign(A, b)`` would (a posture writes only b, a
        #: damping task nothing)
        #: (their instance dicts: one item write each per step)
        self._bumps = [
            sl.task.task.__dict__
            for sl in self._slots
            if sl.kind is not None and sl.kind not in _CONSTANT_A
        ]
        for d in self._bumps:  # the class default 0 as an instance item
            d.setdefault("matrix_version", 0)
        #: the support polygons (slot, task): their ``edges`` after a step
        self._polygons = [
            (sl.k, sl.task) for sl in self._slots if sl.kind == TaskKind.SUPPORT_POLYGON
        ]
        #: ``TASK_WRITES`` when the kernels' weights and output arrays were last bound
        self._writes = -1
        self._solver = solver
        for slot in self._slots:  # a task without a target yet: named at the first step
            slot.changed()
        self._bind_arrays()
        #: q_next of the last ``step(..., integrate=True)`` (nq,), overwritten by the next one
        self.q_next = np.zeros(robot.nq)
        plan = integration_plan(robot)
        #: whether the native call integrates (every joint of a supported type)
        self.integrates = plan is not None
        if plan is not None:
            solver.set_integrator(plan, self.q_next)
        #: the weighted QP solves (``IK(..., method="weighted")``) instead of the hierarchy
        self.weighted = spec.weighted
        if self.weighted:
            ms = sum(L.m_in for L in P.levels)
            #: per row after a weighted step (as ``NativeWeighted.active``)
            self.active = np.zeros(P.n + P.hard.m_eq + P.hard.m_in + ms)
            solver.set_weighted(float(spec.regularization), float(spec.weight_ratio), self.active)
            # a kernel that writes a task's A (all but a posture's) refactors at every step;
            # without one, the tasks' matrix_version decides (as NativeWeighted.run)
            writes_a = any(native_kind(t) not in _CONSTANT_A for t in self.kernel_tasks)
            self._watched = [] if writes_a else [t for B in blocks for t in (*B.eqs, *B.ineqs)]
            self._versions: list | None = None
        #: the copy of :attr:`q_next` the last ``step(..., integrate=True)`` returned with its
        #: solution (a new array per step: :meth:`IK.step_integrate <qpcoord.IK.step_integrate>`
        #: hands it out)
        self.q_next_out: np.ndarray | None = None
        if not self.weighted:  # the strict step's answer in one call (IKStep.solve_step)
            solver.set_copies(self.x, self.res, self.q_next if plan is not None else None)
        #: the strict step of kernels only on plain coordinates (no Python rows, no Python
        #: limits, no coordinate map, no CoM): :meth:`step`'s short path
        self._plain = (
            not (self._hybrid or self._python_limits or self._M is not None or self.com)
            and not self.weighted
        )

    def __del__(self) -> None:
        for slot in getattr(self, "_slots", ()):  # the tasks no longer tell this step
            slot.unbind()

    @property
    def counters(self) -> Any:
        """The last strict-hierarchy step's counters (a copy of the extension's ``Stats``, as
        :attr:`NativeHierarchy.counters <qpcoord.core.native.NativeHierarchy.counters>`; the
        info's ``stats``)."""
        return self._solver.stats

    def _add_frame(self, solver: Any, fid: int) -> int:
        model, data = self._model, self._data
        frame = model.frames[fid]
        joint = int(frame.parentJoint)
        cols = [
            c
            for s in model.supports[joint]
            if s > 0
            for c in range(model.joints[s].idx_v, model.joints[s].idx_v + model.joints[s].nv)
        ]
        oMi = data.oMi[joint]
        placement = frame.placement
        return solver.add_frame(
            oMi.rotation,
            oMi.translation,
            np.array(placement.rotation, dtype=float),
            np.array(placement.translation, dtype=float),
            cols,
        )

    def _add_limit(self, solver: Any, lim: Limit) -> None:
        if isinstance(lim, VelocityLimits):
            i = solver.add_velocity_limits()
        elif isinstance(lim, AccelerationLimits):
            P = lim.position_limits
            qi = [] if P is None else _braked_q_index(P).tolist()
            vi = [] if P is None else P.joints.tolist()
            i = solver.add_acceleration_limits(qi, vi, lim.v_prev)
        else:
            assert isinstance(lim, JointLimits)  # the kinds with a kernel (_NATIVE_LIMITS)
            qi = lim.q_index
            if qi is None:
                i = solver.add_joint_limits([], [])
            else:  # lim.joints: the v index of each limited joint
                i = solver.add_joint_limits(qi.tolist(), lim.joints.tolist())
        self._slots.append(_Slot(solver, self._moving, i, None, lim))

    # ------------------------------------------------------------------ parameters
    def _bind_arrays(self) -> None:
        """Bind the kernels' weights and output arrays where a task holds new ones (an
        ``update(...)`` rebinds them; ``TASK_WRITES`` counts it)."""
        solver = self._solver
        for slot in self._slots:
            if slot.kind is None:
                continue
            arrays = slot.task_arrays()
            old = slot.arrays
            if old and all(a is b for a, b in zip(arrays, old, strict=True)):
                continue
            if not old or arrays[0] is not old[0]:
                solver.set_weights(slot.k, _f64(arrays[0]))
            # the task's own arrays (read-only views): the kernel writes their memory
            if len(arrays) == 3:
                solver.bind_rows(slot.k, _w(arrays[1]), _w(arrays[2]))
            else:
                solver.bind_band_rows(slot.k, *(_w(a) for a in arrays[1:]))
            slot.arrays = arrays
        self._writes = TASK_WRITES[0]

    def _inputs(self, q: np.ndarray, t: float, reference: Any) -> None:
        """Before a step: the arrays a task's ``update`` rebound (``TASK_WRITES`` moved) and
        the moving targets at time ``t`` (s), evaluated by the task's ``reference_at``
        (which raises its own message)."""
        if TASK_WRITES[0] != self._writes:
            self._bind_arrays()
        for slot in self._moving:
            task = slot.task
            assert isinstance(task, PositionTask)
            y, v = task.reference_at(t, reference)
            try:
                self._solver.set_target(slot.k, _f64(y), _f64(v))
            except (TypeError, ValueError) as exc:
                self._task_failed(task, q, t, reference, exc)

    def _task_failed(
        self, task: KinematicTask, q: np.ndarray, t: float, reference: Any, exc: Exception
    ) -> None:
        """Raise the message of ``task`` whose data its kernel cannot use: its Python
        refresh's own, else one naming it (``exc``: what the native setter said)."""
        task._refresh(q, t, self.spec.dt, reference)  # raises the task's own message
        raise ValueError(
            f"{task.task.label}: its data cannot be read by the native IK step ({exc}); use "
            "IK(..., engine='python')"
        ) from exc

    def _after_rows(self, versions: bool = True) -> None:
        """What a step's rows change on the Python side: the ``matrix_version`` of the tasks
        whose matrix the kernels wrote (``versions``), a support polygon's ``edges``."""
        if versions:
            for d in self._bumps:
                d["matrix_version"] += 1
        for k, task in self._polygons:
            task.edges = self._solver.edges(k)

    def _wrote_rows(self, code: int) -> bool:
        """Did the native call with status ``code`` write every kernel's rows?"""
        mod = self._mod
        return code != mod.IK_BAD_Q and code < mod.IK_TASK_DATA and code != mod.BAD_INPUT

    # ------------------------------------------------------------------ per step
    def step(self, q: Any, t: float, reference: Any, integrate: bool = False) -> Solution:
        """One step at configuration ``q`` (nq,) and time ``t`` (s): the IK's solution.

        With ``integrate`` (and :attr:`integrates`) the native call also writes
        ``q_next = integrate(q, v dt)`` into :attr:`q_next` (overwritten by the next step).

        Raises as :meth:`IK.step <qpcoord.IK.step>` does (``ValueError`` naming ``q`` for a
        bad configuration, the tasks' own messages, the solver's errors)."""
        t0 = _clock()
        if self._plain and type(q) is np.ndarray and q.dtype == _F64 and q.shape == self._qshape:
            # the common case in a few lines (0.2 µs of attribute reads and branches less)
            if TASK_WRITES[0] != self._writes or self._moving:
                self._inputs(q, float(t), reference)
            _jacobians(self._model, self._data, q)
            self.robot.data_changed()
            out = self._solver.solve_step(q, self._solved, DEFAULT_TIME_LIMIT, integrate, KKT_TOL)
            if type(out) is tuple and not out[2]["uncertified"]:
                for d in self._bumps:  # _after_rows inline (its common part)
                    d["matrix_version"] += 1
                if self._polygons:
                    self._after_rows(versions=False)
                self._solved = True
                x, res, info, self.q_next_out = out
                return Solution(x, "optimal", res, "native", _clock() - t0, "hierarchical", info)
            return self._answer(out, q, float(t), reference, t0)
        robot = self.robot
        if type(q) is not np.ndarray or q.dtype != _F64 or q.shape != self._qshape or self._hybrid:
            q = robot.check_configuration(q)
        t = float(t)
        if TASK_WRITES[0] != self._writes or self._moving:
            self._inputs(q, t, reference)
        if self._hybrid:  # first: a Python task may evaluate the robot elsewhere (its data)
            self._python_rows(q, t, reference)
        if self._python_limits:
            self.spec.refresh_limits(q)
        if self._M is None:
            pin.computeJointJacobians(self._model, self._data, q)
        else:
            pin.computeJointJacobians(self._model, self._data, self._M @ q)
        if self.com:
            pin.jacobianCenterOfMass(self._model, self._data, False)
        robot.data_changed()  # the robot's cached kinematics no longer match its data
        if self.weighted:
            return self._step_weighted(q, t, reference, integrate, t0)
        # one call: the step, then (x copy, res copy, info, q_next copy or None) built in C++
        out = self._solver.solve_step(q, self._solved, DEFAULT_TIME_LIMIT, integrate, KKT_TOL)
        return self._answer(out, q, t, reference, t0)

    def _answer(self, out: Any, q: np.ndarray, t: float, reference: Any, t0: float) -> Solution:
        """The :class:`~qpcoord.Solution` of ``IKStep.solve_step``'s answer ``out`` (its
        status code raised as :meth:`_fail` does); ``t0`` the step's start
        (``time.perf_counter``, s)."""
        if type(out) is int:
            self._solved = False
            if self._wrote_rows(out):
                self._after_rows()
            self._fail(out, q, t, reference)
        self._after_rows()
        self._solved = True
        x, res, info, self.q_next_out = out
        status = "optimal"
        bad = info["uncertified"]
        if bad:
            status = "inaccurate"
            k, dev = bad[0]
            info["inaccurate"] = inaccurate(k, dev, "native")
        # positional (x, status, level_residuals, solver, solve_time, method, info): 0.2 µs
        # less than by keyword
        return Solution(
            x, status, res, "native", _clock() - t0, "hierarchical", info
        )  # fmt: skip

    def _step_weighted(
        self, q: np.ndarray, t: float, reference: Any, integrate: bool, t0: float
    ) -> Solution:
        """The native call of a weighted step and its :class:`~qpcoord.Solution` (``info`` as
        :meth:`NativeWeighted.solve <qpcoord.core.native_weighted.NativeWeighted.solve>`)."""
        refactor = True
        if self._watched:
            versions = [t.matrix_version for t in self._watched]
            refactor = versions != self._versions
            self._versions = versions
        code = self._solver.step(q, self._solved, DEFAULT_TIME_LIMIT, integrate, refactor)
        if self._wrote_rows(code):
            self._after_rows()
        if code:
            self._solved = False
            self._versions = None  # the next step sets up again
            self._fail(code, q, t, reference)
        self._solved = True
        info = weighted_info(self.detail, self._solver.refactored)
        self.q_next_out = self.q_next.copy() if integrate else None
        return Solution(
            self.x.copy(), "optimal", self.res.copy(), "native", time.perf_counter() - t0,
            "weighted", info,
        )  # fmt: skip

    def _python_rows(self, q: np.ndarray, t: float, reference: Any) -> None:
        """The hybrid part: the Python tasks' ``_refresh`` and every non-native row copied
        into the stacked arrays (as ``CompiledStack.refresh_stacked``)."""
        dt = self.spec.dt
        for task in self._python_tasks:
            task._refresh(q, t, dt, reference)
        for task, A, b in self._eq_ops:
            np.multiply(task.A, task.sqrt_weight[:, None], out=A)
            np.multiply(task.b, task.sqrt_weight, out=b)
        for task, C, lo, hi, sw in self._in_ops:
            C[...] = task.C
            lo[...] = task.lower
            hi[...] = task.upper
            sw[...] = task.sqrt_weight

    def _fail(self, code: int, q: Any, t: float, reference: Any) -> None:
        try:
            self._raise_status(code, q, t, reference)
        except InfeasibleError as exc:  # the engine's words, and the rows in conflict
            P = self.P
            raise infeasible(str(exc), P, P.lbs, P.ubs).with_traceback(exc.__traceback__) from None

    def _raise_status(self, code: int, q: Any, t: float, reference: Any) -> None:
        mod = self._mod
        if code == mod.BAD_INPUT:  # a limit whose data its setter refused: named
            for slot in self._slots:
                if slot.kind is None and slot.error is not None:
                    raise ValueError(
                        f"{slot.task.task.name}: the native IK step cannot use its data "
                        f"({slot.error})"
                    )
        if code == mod.IK_BAD_Q:
            self.robot.check_configuration(q)  # names q
            raise ValueError(f"q: the native IK step rejected the configuration {q!r}")
        if code >= mod.IK_TASK_DATA:
            task = self.kernel_tasks[code - mod.IK_TASK_DATA]
            task._refresh(q, t, self.spec.dt, reference)  # raises the task's own message
            raise ValueError(
                f"{task.task.label}: its data cannot be read by the native IK step (a target "
                "or weight of an unexpected type); use IK(..., engine='python')"
            )
        if self.weighted and code != mod.TIME_LIMIT:
            raise_status(
                code,
                mod,
                self.detail,
                self.x,
                self.P,
                hard_phase="dual active set: a hard row stays {:.3g} away, relative",
                prefix="weighted QP: ",
            )
        if code == mod.TIME_LIMIT:
            raise SolverError(
                f"time limit of {DEFAULT_TIME_LIMIT:g} s reached before the solve ended: "
                "native engine: time limit reached in an active set"
            )
        self._raise(code, self.P)
