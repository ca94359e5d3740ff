"""Per-step differential inverse kinematics on a prioritised stack.

:class:`IK` builds one :class:`~qpcoord.Stack` over the robot's velocity ``v`` (size
``robot.nv``; ``q̇`` in rad/s for the thesis arms, where ``nq == nv``) from kinematic tasks
(:mod:`qpcoord.kinematics.tasks`) and re-solves it every control step; the next configuration
is ``robot.integrate(q, v, dt)`` (on the configuration manifold: a floating base's quaternion
stays unit):

>>> import numpy as np, qpcoord as qc
>>> arm = qc.robots.load("planar_3r")
>>> ee = qc.PositionTask(arm, target=[1.5, 1.0], gain=10.0)
>>> ik = qc.IK(arm, [ee, qc.PostureTask(arm, [0.0, 0.5, 1.0])], dt=0.01)
>>> qdot, sol = ik.step(np.array([0.1, 0.6, 1.2]))

Limits (:class:`~qpcoord.JointLimits`, :class:`~qpcoord.VelocityLimits`,
:class:`~qpcoord.kinematics.tasks.AccelerationLimits`, or your own
:class:`~qpcoord.kinematics.tasks.Limit`) are boxes on ``v``; they are merged into one hard
:class:`~qpcoord.Bounds` (by default the robot's own finite position and speed limits).

Tasks may be built on ``robot`` or on another :class:`~qpcoord.Robot` of the same Pinocchio
model (``robot.with_frame("elbow")``: several frames of one robot in one IK).

:func:`ik_step` is the one-call form; :func:`inverse_kinematics` solves the position IK
``ζ(q) = y`` from a start configuration (Gauss–Newton with minimum-norm steps).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from ..core.conflict import renamed
from ..core.errors import InfeasibleError
from ..core.linalg import filtered_svd
from ..core.native import resolve_engine
from ..core.native_weighted import resolve_weighted_engine
from ..core.stack import METHODS, Solution, Stack
from ..core.tasks import Bounds, Equality, Inequality
from .native_step import IKStepSpec, NativeIKStep
from .paths import Path
from .robot import Robot
from .startup import StartCheck
from .tasks import JointLimits, KinematicTask, Limit, VelocityLimits, _check_dt

__all__ = ["IK", "IKTask", "ik_step", "inverse_kinematics", "DEFAULT_IK_DAMPING"]

#: What an IK level or constraint holds: kinematic tasks (refreshed every step) and constant
#: rows on the velocity
IKTask = KinematicTask | Equality | Inequality

#: Default relative damping of the IK stacks: a singular value below ``1e-4 · s₀`` is
#: damped, so no joint speed exceeds ``‖task error‖ / (1e-4 s₀)``.
DEFAULT_IK_DAMPING = 1e-4


def _default_limits(robot: Robot) -> list[Limit]:
    """The robot's finite joint position limits and speed limits (floating-base and
    ±1.8e308 entries are unlimited)."""
    limits: list[Limit] = []
    joint_limits = JointLimits(robot)
    if joint_limits.joints.size:
        limits.append(joint_limits)
    speed = VelocityLimits(robot)
    if np.any(np.isfinite(speed.limit)):
        limits.append(speed)
    return limits


def _joint_of_velocity(model: Any, i: int) -> str:
    """The name of the joint whose velocity ``v[i]`` is (``"name[k]"``: its ``k``-th of
    several)."""
    for j in range(1, model.njoints):
        first, size = model.joints[j].idx_v, model.joints[j].nv
        if first <= i < first + size:
            return model.names[j] + (f"[{i - first}]" if size > 1 else "")
    return ""


def _same_robot(task_robot: object, robot: Robot) -> bool:
    return task_robot is robot or getattr(task_robot, "model", None) is robot.model


def _other_robot(what: str, robot: Robot, task_robot: object) -> str:
    other = getattr(task_robot, "name", type(task_robot).__name__)
    return (
        f"{what} belongs to another robot ({other!r}: another Pinocchio model than "
        f"{robot.name!r}'s); build it on this robot or on robot.with_frame(...), which "
        "shares the model"
    )


class IK:
    """A differential-IK stack for one robot, built once and stepped every control period.

    Parameters
    ----------
    robot : Robot
    levels : sequence
        Priority levels, highest first. Each item is a task or a list of tasks; a task is a
        :class:`~qpcoord.kinematics.tasks.KinematicTask` (refreshed every step; built on
        ``robot`` or on a robot sharing its Pinocchio model) or a constant
        :class:`~qpcoord.Equality` / :class:`~qpcoord.Inequality` with ``nv`` columns.
    dt : float
        Control period (s): used by :class:`~qpcoord.JointLimits` (look-ahead) and
        :class:`~qpcoord.kinematics.tasks.AccelerationLimits`.
    limits : "robot", sequence of Limit, or None
        Hard boxes on ``v``. ``"robot"`` (default): the robot's finite position limits
        (:class:`~qpcoord.JointLimits`, revolute and prismatic joints) and speed limits
        (:class:`~qpcoord.VelocityLimits`). Add an acceleration limit with
        ``limits=[qc.JointLimits(robot), qc.VelocityLimits(robot),
        AccelerationLimits(robot, a_max)]``.
    constraints : sequence, optional
        Hard tasks (kinematic or constant), e.g. a 1-form that must hold exactly.
    method : {"hierarchical", "nullspace", "weighted"}
        Stack method (default strict priorities).
    solver : str, optional
        QP backend (default: the fastest installed).
    damping : float
        Relative singular-value damping of the stack (default :data:`DEFAULT_IK_DAMPING`).
    regularization, weight_ratio : float
        Passed to :class:`~qpcoord.Stack`.
    fallback : bool
        Passed to :class:`~qpcoord.Stack`: solve a level QP the backend failed on with
        another backend (reported in ``Solution.info["fallbacks"]``).
    engine : {None, "native", "python"}
        ``"native"``: the native IK step (:mod:`qpcoord.kinematics.native_step`): task rows,
        limit box and strict hierarchy (``method="weighted"``: the native weighted QP) in
        one compiled call per step (tasks without a native kernel keep their Python
        refresh). ``"python"``: the tasks' Python refresh and the Python engine of
        :meth:`Stack.solve <qpcoord.Stack.solve>`. ``None`` (default): as
        :meth:`Stack.solve`'s rule -- native where it is built and applies
        (``method="hierarchical"`` or ``"weighted"``, no ``solver``), else Python (one
        warning per process if it is not built).
    outside_limits : {"recover", "raise"}
        A first step (or a step after :meth:`reset`) whose ``q`` is outside a position limit
        (more than :data:`~qpcoord.kinematics.startup.OUTSIDE_TOLERANCE`, rad or m):
        ``"recover"`` (default) lets the limits bring the joints back (within the speed and
        acceleration limits) and reports ``Solution.info["outside_limits"]`` (joint name ->
        signed excess, rad or m) at each step until they are back;
        ``"raise"``: :class:`~qpcoord.kinematics.startup.OutsideLimitsError` naming them.

    Attributes
    ----------
    v_prev : numpy.ndarray, shape (nv,)
        Velocity returned by the last :meth:`step` (zero before the first, and after
        :meth:`reset`): the ``v_prev`` of acceleration limits.
    """

    def __init__(
        self,
        robot: Robot,
        levels: Sequence[IKTask | Sequence[IKTask]],
        dt: float,
        limits: Literal["robot"] | Sequence[Limit] | None = "robot",
        constraints: Sequence[IKTask] | None = None,
        method: str = "hierarchical",
        solver: str | None = None,
        damping: float = DEFAULT_IK_DAMPING,
        regularization: float = 1e-9,
        weight_ratio: float = 1e-3,
        fallback: bool = True,
        engine: str | None = None,
        outside_limits: str = "recover",
    ) -> None:
        if method not in METHODS:
            raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
        if not isinstance(robot, Robot):
            raise ValueError(f"robot must be a qpcoord.Robot, got {type(robot).__name__}")
        self.robot = robot
        self.dt = _check_dt(dt)
        self.method = method
        self.solver = solver
        if isinstance(limits, str):
            if limits != "robot":
                raise ValueError(
                    f"limits must be 'robot', a list of limits or None, got {limits!r}"
                )
            limits = _default_limits(robot)
        limits = list(limits or [])
        for lim in limits:
            if not isinstance(lim, Limit):
                raise ValueError(
                    "limits must be JointLimits/VelocityLimits objects (or other Limit "
                    f"subclasses), got {lim!r}"
                )
            if not _same_robot(lim.robot, robot):
                raise ValueError(_other_robot(f"limit {lim.task.name!r}", robot, lim.robot))
        if method == "nullspace" and limits:
            raise ValueError(
                "method='nullspace' takes no inequalities: pass limits=None (the robot's "
                "limits are used by default)"
            )
        self.limits = limits
        #: the start-up check of the position limits (``outside_limits``)
        self.start_check = StartCheck(robot, limits, outside_limits)
        self._dynamic: list[KinematicTask] = []
        stack_levels = [self._collect(level, f"levels[{i}]") for i, level in enumerate(levels)]
        stack_constraints = self._collect(list(constraints or []), "constraints")
        # limits that keep state across steps (acceleration limits): told the step's v
        self._recorders = [
            lim
            for lim in [*limits, *self._dynamic]
            if isinstance(lim, Limit) and type(lim).record is not Limit.record
        ]
        self.v_prev = np.zeros(robot.nv)
        self.bounds = Bounds(np.full(robot.nv, -np.inf), np.full(robot.nv, np.inf), "limits")
        self.stack = Stack(
            stack_levels,
            bounds=self.bounds if limits else None,
            regularization=regularization,
            damping=damping,
            constraints=stack_constraints or None,
            weight_ratio=weight_ratio,
            fallback=fallback,
        )
        self.last: Solution | None = None
        #: ``"native"`` (the native IK step) or ``"python"``: the engine this IK uses
        if method == "weighted":
            self.engine = resolve_weighted_engine(engine, solver)
        else:
            self.engine = resolve_engine(engine, method, solver)
        self._engine_arg = engine
        self._native: NativeIKStep | None = None
        if self.engine == "native":
            self._native = NativeIKStep(self._native_spec())

    def __getstate__(self) -> dict:
        """Pickling (e.g. a sweep's worker): the native step holds views of the robot's
        Pinocchio data and is rebuilt on unpickling (its warm start is lost)."""
        state = self.__dict__.copy()
        state["_native"] = None
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        if self.engine == "native":
            self._native = NativeIKStep(self._native_spec())

    def _native_spec(self) -> IKStepSpec:
        """What the native step reads of this IK (its stack's arrays are bound once)."""
        return IKStepSpec(
            robot=self.robot,
            stack=self.stack.compiled,
            box=self.bounds._writable() if self.limits else None,
            tasks=tuple(self._dynamic),
            limits=tuple(self.limits),
            refresh_limits=self._refresh_limits,
            dt=self.dt,
            damping=self.stack.damping,
            weighted=self.method == "weighted",
            regularization=self.stack.regularization,
            weight_ratio=self.stack.weight_ratio,
        )

    def _collect(self, level: IKTask | Sequence[IKTask], where: str) -> list[Equality | Inequality]:
        items = level if isinstance(level, (list, tuple)) else [level]
        out: list[Equality | Inequality] = []
        nv = self.robot.nv
        for task in items:
            if isinstance(task, KinematicTask):
                if not _same_robot(task.robot, self.robot):
                    raise ValueError(
                        _other_robot(f"{where}: task {task.name!r}", self.robot, task.robot)
                    )
                if task.task.shape[1] != nv:
                    raise ValueError(
                        f"{where}: task {task.name!r} has {task.task.shape[1]} columns, the "
                        f"robot {nv} velocity variables (nv)"
                    )
                if task.lm_rows is not None and where == "constraints":
                    raise ValueError(
                        f"{where}: task {task.name!r} has lm_damping={task.lm_damping:g}; a "
                        "hard constraint is not damped (damping rows there would hold v = 0): "
                        "build it with lm_damping=0 or put it at a level"
                    )
                self._dynamic.append(task)
                out.append(task.task)
                if task.lm_rows is not None:  # refreshed after its task, in its level
                    self._dynamic.append(task.lm_rows)
                    out.append(task.lm_rows.task)
            elif isinstance(task, (Equality, Inequality)):
                if task.shape[1] != nv:
                    raise ValueError(
                        f"{where}: {task.label} has {task.shape[1]} columns, the robot "
                        f"{nv} velocity variables (nv)"
                    )
                out.append(task)
            else:
                raise ValueError(
                    f"{where}: expected kinematic tasks, Equality or Inequality, got {task!r}"
                )
        return out

    def refresh(self, q: np.ndarray, t: float = 0.0, reference: Path | None = None) -> None:
        """Update every task and the bounds for a validated configuration ``q`` (rad)
        (float array of shape (nq,)) at time ``t`` (s).

        The limits' boxes are intersected. Where they do not meet (a joint outside its
        position limit pushed back faster than its speed limit allows, or a position limit
        that needs a harder brake than an acceleration limit allows), the end nearer to 0
        is kept: the speed limit, and the position limit, win."""
        for task in self._dynamic:
            task._refresh(q, t, self.dt, reference)
        self._refresh_limits(q)

    def _refresh_limits(self, q: np.ndarray) -> None:
        """The limits' boxes intersected into the stack's bounds (see :meth:`refresh`)."""
        if self.limits:
            # written straight into the stack's Bounds (the writable arrays behind its
            # read-only lower/upper), then marked changed
            lo, hi = self.bounds._writable()
            first, *rest = self.limits
            a, b = first.box(q, self.dt)
            np.copyto(lo, a)
            np.copyto(hi, b)
            for lim in rest:
                a, b = lim.box(q, self.dt)
                np.maximum(lo, a, out=lo)
                np.minimum(hi, b, out=hi)
            # outside a joint limit the box that pushes back may lie beyond the speed
            # limit: the boxes do not meet, and the speed limit (which contains 0) wins:
            # move back at full speed, i.e. take the end nearer to 0
            bad = lo > hi
            if bad.any():
                back = np.where(np.abs(lo) < np.abs(hi), lo, hi)
                lo[bad] = hi[bad] = back[bad]
            self.bounds._touch()

    def step(
        self,
        q: ArrayLike,
        t: float = 0.0,
        reference: Path | None = None,
        warm_start: Solution | ArrayLike | None = None,
    ) -> tuple[np.ndarray, Solution]:
        """Solve one control step.

        Parameters
        ----------
        q : array_like, shape (nq,)
            Current configuration (rad, m; unit quaternions), checked by
            :meth:`~qpcoord.Robot.check_configuration` (``ValueError`` naming ``q``).
        t : float
            Time (s), for tasks that follow a path.
        reference : Path, optional
            End-effector path for position tasks built without a target.
        warm_start : Solution or array, optional
            Previous step's solution (default: the last one of this IK).

        Returns
        -------
        v : numpy.ndarray, shape (nv,)
            Velocity (rad/s, m/s): ``q_next = robot.integrate(q, v, dt)``.
        solution : Solution
            The stack's solution: ``status``, ``level_residuals``, ``info`` (with
            ``engine="python"``, ``info["level_ranks"]`` shows a rank loss near a
            singularity).
        """
        outside = self.start_check.check(q) if self.start_check.pending else None
        try:
            if self._native is not None:
                if warm_start is not None:
                    self.stack._warm(warm_start)  # validated; the engine keeps its working sets
                sol = self._native.step(q, t, reference)
            else:
                q = self.robot.check_configuration(q)
                self.refresh(q, t, reference)
                sol = self.stack.solve(
                    solver=self.solver,
                    method=self.method,
                    warm_start=self.last if warm_start is None else warm_start,
                    engine=self._engine_arg,
                )
        except InfeasibleError as exc:
            raise self._named(exc, q) from None
        sol.stack = self.stack  # the native step's Solution: for sol.explain()
        if outside:
            sol.info["outside_limits"] = outside
        self.last = sol
        v = sol.x
        self.v_prev[...] = v
        for lim in self._recorders:
            lim.record(v)
        return v, sol

    def step_integrate(
        self,
        q: ArrayLike,
        t: float = 0.0,
        reference: Path | None = None,
        warm_start: Solution | ArrayLike | None = None,
    ) -> tuple[np.ndarray, np.ndarray, Solution]:
        """One control step and the configuration it leads to: ``(q_next, v, solution)``.

        The same step as :meth:`step` (same arguments, same ``v`` and ``solution``) followed
        by ``q_next = robot.integrate(q, v, dt)`` with this IK's ``dt`` (s). On the native
        engine the integration is done inside the native call, on the configuration
        manifold as ``pinocchio.integrate`` (revolute, prismatic, helical and translation
        joints ``q + v dt``; continuous joints on their circle; spherical and free-flyer
        joints through the SO(3) / SE(3) exponential, quaternions renormalised); a model
        with another joint type (planar, composite, mimic) falls back to
        :meth:`~qpcoord.Robot.integrate`, as does the Python engine.

        Returns
        -------
        q_next : numpy.ndarray, shape (nq,)
            Configuration after ``dt`` (a new array).
        v : numpy.ndarray, shape (nv,)
            Velocity (rad/s, m/s), as :meth:`step`.
        solution : Solution
        """
        native = self._native
        if native is not None and native.integrates and not self.start_check.pending:
            if warm_start is not None:
                self.stack._warm(warm_start)
            try:
                sol = native.step(q, t, reference, True)
            except InfeasibleError as exc:
                raise self._named(exc, q) from None
            sol.stack = self.stack  # for sol.explain()
            self.last = sol
            v = sol.x
            self.v_prev[...] = v
            for lim in self._recorders:
                lim.record(v)
            q_next = native.q_next_out
            assert q_next is not None  # written by an integrating step
            return q_next, v, sol
        v, sol = self.step(q, t, reference, warm_start)
        return self.robot.integrate(q, v, self.dt), v, sol

    def _named(self, exc: InfeasibleError, q: ArrayLike) -> InfeasibleError:
        """``exc`` with each bound of its conflict named by the limit that sets that side of
        the box at ``q`` (the nearest side value; the other side where the IK kept the end
        nearer to 0, see :meth:`refresh`) and by the joint of that velocity. The IK's hard
        tasks are named by their own task names already."""
        if not any(r.is_bound for r in exc.conflict):
            return exc
        q = self.robot.check_configuration(q)
        boxes = [(lim.task.name, *lim.box(q, self.dt)) for lim in self.limits]
        rows = []
        for r in exc.conflict:
            if r.is_bound:
                side = 1 if r.kind == "lower bound" else 2
                gap = [(abs(b[s][r.row] - r.bound), s != side, b[0]) for b in boxes for s in (1, 2)]
                joint = _joint_of_velocity(self.robot.model, r.row)
                r = replace(r, task=min(gap)[2] if gap else r.task, joint=joint)
            rows.append(r)
        return renamed(exc, tuple(rows))

    def reset(self, v_prev: ArrayLike | None = None) -> None:
        """Forget the previous step: ``v_prev`` (and that of the acceleration limits) back to
        zero, or to the given velocity (nv,); no warm start for the next solve; the next
        steps check ``q`` against the position limits again (``outside_limits``)."""
        v = np.zeros(self.robot.nv) if v_prev is None else self.robot._check_velocity(v_prev)
        self.v_prev[...] = v
        for lim in self._recorders:
            lim.record(v)
        self.last = None
        self.start_check.reset()

    def velocity(self, q: ArrayLike, t: float = 0.0, reference: Path | None = None) -> np.ndarray:
        """Velocity ``v`` (nv,) at ``(q, t)``: the scheme interface used by :func:`simulate`."""
        return self.step(q, t, reference)[0]


def ik_step(
    robot: Robot,
    q: ArrayLike,
    levels: Sequence[IKTask | Sequence[IKTask]],
    dt: float,
    solver: str | None = None,
    t: float = 0.0,
    **options: Any,
) -> tuple[np.ndarray, Solution]:
    """Build an :class:`IK` and solve one step (convenience; a control loop keeps the IK).

    ``options`` go to :class:`IK` (``limits``, ``constraints``, ``method``, ``damping``…).
    Returns ``(v, solution)`` with ``v`` (nv,) in rad/s.
    """
    return IK(robot, levels, dt, solver=solver, **options).step(q, t)


def inverse_kinematics(
    robot: Robot,
    target: ArrayLike,
    q0: ArrayLike,
    tol: float = 1e-12,
    max_iter: int = 200,
    max_step: float = 0.5,
) -> np.ndarray:
    """Configuration ``q`` with ``ζ(q) = target``, closest to ``q0`` (locally).

    Two phases (filtered pseudo-inverse, step norm capped at ``max_step`` rad): Gauss–Newton
    minimum-norm steps ``q ← q + J⁺ (target − ζ(q))`` until the target is reached, then
    projected steps ``q ← q + J⁺ (target − ζ(q)) + (I − J⁺J)(q0 − q)`` that slide along the
    self-motion toward ``q0``. At convergence ``q − q0`` is orthogonal to the self-motion, so
    ``q`` is a local minimum of ``‖q − q0‖`` among configurations that reach ``target``
    (otherwise the on-target configuration closest to ``q0`` met is returned). A singular
    configuration met in the first phase is left by a fixed 0.01 rad step. Joint limits are
    not enforced. On a floating base (``nq ≠ nv``) the steps are velocities of size ``nv``
    applied with :meth:`~qpcoord.Robot.integrate`, and distances are
    :meth:`~qpcoord.Robot.difference` norms.

    Parameters
    ----------
    robot : Robot
    target : array_like, shape (rows,)
        End-effector position (m).
    q0 : array_like, shape (nq,)
        Start configuration (rad).
    tol : float
        Stop when ``‖ζ(q) − target‖ ≤ tol · max(1, ‖target‖)`` (m) and the null-space part
        of ``q0 − q`` is below ``1e3 · tol`` (rad).
    max_iter : int
    max_step : float
        Largest joint step per iteration (rad).

    Raises
    ------
    ValueError
        Bad arguments, or the target is not reached (out of reach, or a singularity).
    """
    q_ref = robot.check_configuration(q0, "q0").copy()
    y_target = np.asarray(target, dtype=float).reshape(-1)
    if y_target.shape != (robot.m,) or not np.all(np.isfinite(y_target)):
        raise ValueError(f"target must be {robot.m} finite coordinates (m), got {target!r}")
    goal = tol * max(1.0, float(np.linalg.norm(y_target)))

    # a fixed small kick out of a singular configuration (e.g. a stretched arm, where
    # minimum-norm steps keep it stretched forever)
    kick = 1e-2 * np.where(np.arange(robot.nv) % 2 == 0, 1.0, -1.0) / np.sqrt(robot.nv)
    if robot.euclidean:

        def toward(q: np.ndarray, q1: np.ndarray) -> np.ndarray:
            return q1 - q

        def advance(q: np.ndarray, dq: np.ndarray) -> np.ndarray:
            return q + dq

    else:

        def toward(q: np.ndarray, q1: np.ndarray) -> np.ndarray:
            return robot.difference(q, q1)

        def advance(q: np.ndarray, dq: np.ndarray) -> np.ndarray:
            return robot.integrate(q, dq, 1.0)

    def step(q: np.ndarray, toward_q0: bool) -> tuple[float, float, np.ndarray]:
        y, J = robot._kinematics(q)
        e = y_target - y
        U, s_, Vt, rank, g, _tau = filtered_svd(J, 1e-6)
        if not toward_q0 and (rank < robot.m or s_[rank - 1] < 1e-6 * s_[0]):
            return float(np.linalg.norm(e)), 0.0, kick
        dq = Vt[:rank].T @ (g * (U[:, :rank].T @ e))
        drift = np.zeros(robot.nv)
        if toward_q0:
            N = Vt[rank:]  # rows: orthonormal basis of the self-motion directions
            drift = N.T @ (N @ toward(q, q_ref))
            dq = dq + drift
        norm = float(np.linalg.norm(dq))
        if norm > max_step:
            dq *= max_step / norm
        return float(np.linalg.norm(e)), float(np.linalg.norm(drift)), dq

    # phase 1: reach the target by minimum-norm steps
    q = q_ref.copy()
    err = np.inf
    for _ in range(max_iter):
        err, _, dq = step(q, False)
        if err <= goal:
            break
        q = advance(q, dq)
    if err <= goal:
        # phase 2: slide along the self-motion toward q0, staying on the target; keep the
        # on-target configuration closest to q0 seen
        best, best_d = q.copy(), float(np.linalg.norm(toward(q_ref, q)))
        for _ in range(max_iter):
            err, drift, dq = step(q, True)
            if err <= goal:
                d = float(np.linalg.norm(toward(q_ref, q)))
                if d < best_d:
                    best, best_d = q.copy(), d
                if drift <= 1e3 * tol:
                    break
            q = advance(q, dq)
        return best
    raise ValueError(
        f"inverse_kinematics: target {y_target.tolist()} not reached from q0 "
        f"(residual {err:.3g} m after {max_iter} iterations; out of reach or singular)"
    )
