"""Tasks built from a :class:`~qpcoord.Robot` at the current configuration.

The decision variable of every task here is the robot's **velocity** ``v`` (size
``robot.nv``; rad/s for revolute joints, m/s for prismatic ones, and for a free-flyer root its
linear and angular velocity in the base frame), so that ``q_next = robot.integrate(q, v, dt)``.
For the thesis arms (``nq == nv``) ``v`` is simply ``q̇``. Each task owns one
:class:`~qpcoord.Equality` or :class:`~qpcoord.Inequality` (its ``task`` attribute, with
``robot.nv`` columns) and refreshes its numbers in place with ``update(q, t, dt, reference)``,
so a stack built once is re-solved every control step.

=========================  =========================================================
:class:`KinematicTask`     base class of your own tasks: ``compute_error(q)``,
                           ``compute_jacobian(q)``; ``J v = −K e`` or a band
:class:`PositionTask`      ``J v = ẏ_ref + K (y_ref − y)`` (closed-loop IK, CLIK)
:class:`PositionBand`      ``K (y_lo − y) ≤ J v ≤ K (y_hi − y)`` (stay in a box, any level)
:class:`PostureTask`       ``v_a = K (q_ref ⊖ q)_a`` (actuated joints ``a``)
:class:`PotentialTask`     ``v = −K ∇p(q)`` (gradient descent on a potential, chapter 5)
:class:`OneFormTask`       ``ω(q) v = rate`` (a 1-form, chapter 4; default rate 0)
:class:`Limit`             base class of boxes ``lower(q) ≤ v ≤ upper(q)``: ``box(q, dt)``
:class:`JointLimits`       ``K (q_min − q)/dt ≤ v ≤ K (q_max − q)/dt`` (1-DoF joints)
:class:`VelocityLimits`    ``−v_max ≤ v ≤ v_max``
:class:`AccelerationLimits` ``v_prev − a_max dt ≤ v ≤ v_prev + a_max dt``
=========================  =========================================================

The limits are boxes on ``v``: :class:`~qpcoord.IK` merges them into the stack's
:class:`~qpcoord.Bounds` (always hard); their ``task`` (an Inequality) can also be placed at
a soft level.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from ..core.tasks import Equality, Inequality
from .braking import braking_speed
from .paths import Path
from .robot import Robot

if TYPE_CHECKING:
    from typing_extensions import Self  # typing.Self from Python 3.11

__all__ = [
    "KinematicTask",
    "PositionTask",
    "PositionBand",
    "PostureTask",
    "PotentialTask",
    "OneFormTask",
    "LMDamping",
    "Limit",
    "JointLimits",
    "VelocityLimits",
    "AccelerationLimits",
    "TASK_KINDS",
]

#: The two forms of a :class:`KinematicTask`: ``"equality"`` (``J v = −K e``) and ``"band"``
#: (``K (lower − e) ≤ J v ≤ K (upper − e)``).
TASK_KINDS = ("equality", "band")

#: Limits at least this large in magnitude mean "unlimited" (Pinocchio stores ±DBL_MAX for
#: the free-flyer and for joints without limits).
_HUGE = 1e300

#: Root joints that make a floating base (their velocity rows are not "actuated").
_FLOATING_ROOTS = ("JointModelFreeFlyer", "JointModelPlanar")


#: The attributes of a kinematic task that the native IK step holds a copy of (its kernels'
#: parameters): an assignment is validated by the task's ``_checked_parameter`` (the
#: constructor's checks and messages, where the task has them) and tells the steps the task
#: is bound to (``_bound``), which copy it again. Their arrays are read-only (a write in
#: place raises numpy's "assignment destination is read-only"): a native step would not see
#: it; assign a new array or call the task's setter.
PARAMETERS = frozenset(
    (
        "gain", "target", "target_velocity", "_target_T", "_target_t", "q_ref", "lower",
        "upper", "contact_points", "margin", "limit", "lm_damping", "offset", "band",
        "position_limits",
    )
)  # fmt: skip
_setattr = object.__setattr__


def read_only(a: np.ndarray) -> np.ndarray:
    """``a`` (an array the task owns) made read-only, returned."""
    a.flags.writeable = False
    return a


def _gain(value: object, what: str = "gain") -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{what} must be a number (1/s), got {value!r}")
    if not np.isfinite(value) or value < 0:
        raise ValueError(f"{what} must be finite and >= 0 (1/s), got {value!r}")
    return float(value)


def _lm_damping(value: object, who: str) -> float:
    """A validated ``lm_damping`` (dimensionless, finite, >= 0)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{who}: lm_damping must be a number (dimensionless), got {value!r}")
    if not np.isfinite(value) or value < 0:
        raise ValueError(
            f"{who}: lm_damping must be finite and >= 0 (dimensionless), got {value!r}"
        )
    return float(value)


def _check_dt(dt: object) -> float:
    if isinstance(dt, bool) or not isinstance(dt, (int, float, np.integer, np.floating)):
        raise ValueError(f"dt must be a number of seconds, got {dt!r}")
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be > 0 and finite (s), got {dt!r}")
    return float(dt)


def _check_robot(robot: Any, who: str) -> Robot:
    if not isinstance(robot, Robot):
        raise ValueError(f"{who}: robot must be a qpcoord.Robot, got {type(robot).__name__}")
    return robot


def _is_number(value: object) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))


def _positive_limit(value: Any, nv: int, who: str, units: str) -> np.ndarray:
    """A limit's ``limit``: ``nv`` numbers > 0 (a scalar broadcast; ``inf``, or Pinocchio's
    ``1.8e308``, for an unlimited entry, read as ``inf``)."""
    try:
        arr = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        arr = None
    if arr is not None and arr.size == 1:
        arr = np.full(nv, arr[0])
    if arr is None or arr.shape != (nv,) or not np.all(arr > 0):  # NaN is not > 0
        raise ValueError(
            f"{who}: limit must be {nv} numbers > 0 or one ({units}; inf for none), got {value!r}"
        )
    return _unlimited(arr)


def _faces(lower: Any, upper: Any, rows: int, who: str) -> tuple[np.ndarray, np.ndarray]:
    """Band faces ``(lower, upper)`` of ``rows`` entries each (scalars broadcast, ±inf
    allowed on its own side), checked ``lower ≤ upper``."""
    faces = []
    for what, value, wrong in (("lower", lower, np.inf), ("upper", upper, -np.inf)):
        try:
            arr = np.broadcast_to(np.asarray(value, dtype=float), (rows,)).copy()
        except (ValueError, TypeError):
            arr = None
        if arr is None or np.isnan(arr).any() or (arr == wrong).any():
            raise ValueError(
                f"{who} {what} must have {rows} numbers (task units, ±inf allowed), got {value!r}"
            )
        faces.append(arr)
    lo, hi = faces
    bad = np.flatnonzero(lo > hi)
    if bad.size:
        raise ValueError(f"{who}: lower > upper on row(s) {bad.tolist()}: {lo[bad]} > {hi[bad]}")
    return lo, hi


def _unlimited(values: np.ndarray) -> np.ndarray:
    """``values`` with ±DBL_MAX-like entries (|x| ≥ 1e300) read as ±inf (a copy)."""
    out = np.array(values, dtype=float)
    out[out >= _HUGE] = np.inf
    out[out <= -_HUGE] = -np.inf
    return out


def floating_base_velocity_indices(robot: Robot) -> np.ndarray:
    """Velocity indices of a floating root (free-flyer: 6, planar: 3), empty on a fixed base."""
    model = robot.model
    if model.njoints > 1 and model.parents[1] == 0:
        joint = model.joints[1]
        if joint.shortname() in _FLOATING_ROOTS:
            return np.arange(joint.idx_v, joint.idx_v + joint.nv)
    return np.zeros(0, dtype=int)


def actuated_velocity_indices(robot: Robot) -> np.ndarray:
    """Velocity indices of every joint but a floating root (all ``nv`` on a fixed base)."""
    return np.setdiff1d(np.arange(robot.nv), floating_base_velocity_indices(robot))


class KinematicTask(ABC):
    """A task on the robot's velocity ``v`` (size ``robot.nv``), refreshed every control step.

    **Writing your own task.** Subclass it, call ``super().__init__(robot, rows, ...)`` and
    implement two methods of the configuration ``q`` (shape ``(nq,)``, already validated):

    - ``compute_error(q) -> e``, shape ``(rows,)``, in task units (m, rad, …);
    - ``compute_jacobian(q) -> J``, shape ``(rows, nv)``, with ``ė = J v`` (task units per
      unit of ``v``).

    Every step the task then holds

    - ``kind="equality"`` (default): ``J v = −K e`` (the error decays at rate ``K``);
    - ``kind="band"``: ``K (lower − e) ≤ J v ≤ K (upper − e)`` (the error is kept in
      ``[lower, upper]``; outside it is pushed back at rate ``K``).

    The task is an :class:`~qpcoord.Equality` / :class:`~qpcoord.Inequality` (its ``task``
    attribute): put it at any level of an :class:`~qpcoord.IK`, beside others in a level, or
    as a hard constraint (``IK(..., constraints=[task])``).

    Built-in tasks (:class:`PositionTask`, :class:`PostureTask`, …) also override the per-step
    hook ``_refresh(q, t, dt, reference)`` (library-internal: time-dependent targets,
    feed-forward terms, no extra copies); a subclass may too, instead of the two methods.

    Parameters
    ----------
    robot : Robot
        Its ``model`` must be the IK's (``robot.with_frame(...)`` gives another default frame
        on the same model: accepted).
    rows : int
        Number of task rows (the size of ``e``).
    kind : {"equality", "band"}
    gain : float
        ``K`` (1/s), default 1; > 0 for a band.
    weight : float or array_like, shape (rows,)
        Row weights inside the level (default 1).
    lower, upper : float or array_like, shape (rows,)
        Band faces (task units; ``-inf`` / ``inf`` for a free side); only for
        ``kind="band"``.
    name : str, optional
        Used in messages and reports (default: the class name).
    lm_damping : float
        Levenberg–Marquardt damping (dimensionless, default 0): the task's level also
        minimises ``μ ‖v‖²`` with ``μ = lm_damping · Σ wᵢ eᵢ²`` (row weights ``w``; for a band,
        ``e`` is its distance outside ``[lower, upper]``), zero once the task is met. Far from
        an unreachable target it slows the motion to a stop instead of chattering at the
        speed limits. The damping rows are :attr:`lm_rows` (``nv`` rows beside the task in
        its level; in a strict hierarchy they fix the level's null space); they are zero once
        the error is below ``LM_ERROR_FLOOR`` = 1e-6 (task units). The native IK step
        computes them for a task it has a kernel for; for any other task, from its Python
        refresh.

    Raises
    ------
    TypeError
        A subclass that implements neither both methods nor ``_refresh`` is instantiated.
    ValueError
        Bad rows, kind, gain, weight, faces or lm_damping.

    Examples
    --------
    Keep a frame's height (see ``docs/custom-task.md``)::

        class Height(qc.KinematicTask):
            def __init__(self, robot, frame, z, gain=10.0):
                super().__init__(robot, 1, gain=gain, name="height")
                self.frame, self.z = frame, z

            def compute_error(self, q):
                return self.robot.frame_pose(q, self.frame)[2:3, 3] - self.z

            def compute_jacobian(self, q):
                return self.robot.frame_jacobian(q, self.frame)[2:3]
    """

    task: Equality | Inequality
    robot: Robot
    gain: float = 1.0
    kind: str = "equality"
    #: Levenberg–Marquardt damping (dimensionless): see the class docstring
    lm_damping: float = 0.0
    #: The damping rows ``√μ · I`` (an :class:`LMDamping`), ``None`` without damping
    lm_rows: LMDamping | None = None
    #: The error of the last refresh (kept rows, task units), recorded only with lm_rows
    _lm_e: np.ndarray | None = None
    #: The native IK steps' slots that hold a copy of this task's parameters
    #: (``qpcoord.kinematics.native_step``), told of every parameter write; not pickled
    _bound: tuple = ()

    def __setattr__(self, name: str, value: Any) -> None:
        if name in PARAMETERS:
            value = self._checked_parameter(name, value)
            if type(value) is np.ndarray and value.flags.writeable:
                value = read_only(value.copy())  # the caller keeps no writable alias
            _setattr(self, name, value)
            if self._bound:
                self._parameters_written()
            return
        _setattr(self, name, value)

    def _checked_parameter(self, name: str, value: Any) -> Any:
        """``value`` for the parameter ``name`` (one of :data:`PARAMETERS`) validated, in the
        form the task keeps: what an assignment, the constructor's included, stores.

        Raises the constructor's ``ValueError`` (naming the argument and the value). Here:
        ``lm_damping`` (read by the damping rows at every step); a subclass extends it for
        its own parameters (the limits: all of theirs)."""
        if name == "lm_damping":
            task = self.__dict__.get("task")
            return _lm_damping(value, type(self).__name__ if task is None else task.name)
        return value

    def _parameters_written(self) -> None:
        """Tell the bound native steps that a parameter changed (a setter that writes
        several through ``__dict__`` calls it once)."""
        for slot in self._bound:
            slot.changed()

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state.pop("_bound", None)  # the native steps of this process (rebuilt with an IK)
        return state

    def __new__(cls, *args: Any, **kwargs: Any) -> Self:
        base = KinematicTask
        if cls._refresh is base._refresh and (
            cls.compute_error is base.compute_error or cls.compute_jacobian is base.compute_jacobian
        ):
            raise TypeError(
                f"Can't instantiate {cls.__name__}: a KinematicTask subclass implements "
                "compute_error(q) -> e (rows,) and compute_jacobian(q) -> J (rows, nv)"
            )
        return super().__new__(cls)

    def __init__(
        self,
        robot: Robot,
        rows: int,
        *,
        kind: str = "equality",
        gain: float = 1.0,
        weight: ArrayLike = 1.0,
        lower: ArrayLike = -np.inf,
        upper: ArrayLike = np.inf,
        name: str | None = None,
        lm_damping: float = 0.0,
    ) -> None:
        who = name or type(self).__name__
        self.robot = _check_robot(robot, who)
        if isinstance(rows, bool) or not isinstance(rows, (int, np.integer)) or rows < 1:
            raise ValueError(f"{who}: rows must be a positive integer, got {rows!r}")
        if kind not in TASK_KINDS:
            raise ValueError(f"{who}: kind must be 'equality' or 'band', got {kind!r}")
        self.kind = kind
        self.gain = _gain(gain)
        rows = int(rows)
        zeros = np.zeros((rows, robot.nv))
        if kind == "equality":
            if np.any(np.asarray(lower) != -np.inf) or np.any(np.asarray(upper) != np.inf):
                raise ValueError(f"{who}: lower/upper are for kind='band'")
            self.task = Equality(zeros, np.zeros(rows), weight, who)
        else:
            if self.gain <= 0:
                raise ValueError(f"{who}: a band needs gain > 0 (1/s), got {gain!r}")
            self.lower, self.upper = _faces(lower, upper, rows, who)
            self.task = Inequality(zeros, -np.inf, np.inf, weight, who)
        self._init_lm(lm_damping)

    def _init_lm(self, lm_damping: float) -> None:
        """Validate ``lm_damping`` and build the damping rows (call once ``task`` exists)."""
        self.lm_damping = _lm_damping(lm_damping, self.task.name)
        self.lm_rows = LMDamping(self) if self.lm_damping > 0 else None

    def _lm_error_sq(self) -> float:
        """``Σ wᵢ eᵢ²`` of the last refresh (task units²): the error of an equality task, the
        distance outside the band of a band (read from its rows ``K (lower − e)``,
        ``K (upper − e)``)."""
        task = self.task
        if isinstance(task, Inequality):
            k = self.gain
            out = np.maximum(task.lower, 0.0) - np.minimum(task.upper, 0.0)
            return float(task.weight @ (out * out)) / (k * k)
        e = self._lm_e
        return 0.0 if e is None else float(task.weight @ (e * e))

    # -- the two methods of a user task ------------------------------------------------
    def compute_error(self, q: np.ndarray) -> np.ndarray:
        """Task error ``e(q)``, shape ``(rows,)`` (task units) at configuration ``q`` (nq,).

        The method a user task writes (with :meth:`compute_jacobian`); a task that builds
        its rows in ``_refresh`` instead has no error of this form and raises."""
        raise NotImplementedError(
            f"{type(self).__name__} builds its rows directly (_refresh): it has no "
            "compute_error; a user task must define compute_error and compute_jacobian"
        )

    def compute_jacobian(self, q: np.ndarray) -> np.ndarray:
        """Task Jacobian ``J(q)``, shape ``(rows, nv)``, with ``ė = J v``.

        The method a user task writes (with :meth:`compute_error`)."""
        raise NotImplementedError(
            f"{type(self).__name__} builds its rows directly (_refresh): it has no "
            "compute_jacobian; a user task must define compute_error and compute_jacobian"
        )

    # -- public per-step API -----------------------------------------------------------
    def set_band(self, lower: ArrayLike | None = None, upper: ArrayLike | None = None) -> None:
        """Replace the band faces (task units; ``None`` keeps a side). Only for bands."""
        if self.kind != "band":
            raise ValueError(f"{self.name}: set_band is for kind='band' tasks")
        self.lower, self.upper = _faces(
            self.lower if lower is None else lower,
            self.upper if upper is None else upper,
            self.task.shape[0],
            self.name,
        )

    def update(
        self, q: ArrayLike, t: float = 0.0, dt: float = 1e-3, reference: Path | None = None
    ) -> Equality | Inequality:
        """Refresh ``self.task`` for configuration ``q`` (nq,) at time ``t`` (s); return it.

        ``dt`` is the control period (s); ``reference`` is the run's end-effector path
        (used by tasks built without their own target).

        Raises
        ------
        ValueError
            ``q`` of the wrong size, not finite or with a non-unit quaternion (named ``q``),
            ``dt`` not positive, a user method returning a wrong shape or a non-finite value.
        """
        q = self.robot.check_configuration(q)
        return self._refresh(q, float(t), _check_dt(dt), reference)

    def _refresh(
        self, q: np.ndarray, t: float, dt: float, reference: Path | None
    ) -> Equality | Inequality:
        """:meth:`update` for an already validated ``q`` (the per-step path of IK).

        Default: ``J v = −K e`` or ``K (lower − e) ≤ J v ≤ K (upper − e)`` from
        :meth:`compute_error` and :meth:`compute_jacobian`.
        """
        e, J = self._checked(self.compute_error(q), self.compute_jacobian(q))
        k = self.gain
        task = self.task
        if isinstance(task, Equality):  # kind "equality"
            if self.lm_rows is not None:
                self._lm_e = e
            return task._assign(J, -k * e)
        with np.errstate(invalid="ignore"):  # inf − e stays inf
            return task._assign(k * (self.lower - e), k * (self.upper - e), C=J)

    def _checked(self, e: Any, J: Any) -> tuple[np.ndarray, np.ndarray]:
        rows, nv = self.task.shape
        e = np.asarray(e, dtype=float)
        if e.shape != (rows,):
            if e.size != rows:
                raise ValueError(
                    f"{self.task.label}: compute_error(q) must return {rows} values, "
                    f"got shape {e.shape}"
                )
            e = e.reshape(rows)
        J = np.asarray(J, dtype=float)
        if J.shape != (rows, nv):
            if not (J.ndim == 1 and rows == 1 and J.size == nv):
                raise ValueError(
                    f"{self.task.label}: compute_jacobian(q) must return shape ({rows}, {nv}) "
                    f"(rows, nv), got {J.shape}"
                )
            J = J.reshape(1, nv)
        if not np.isfinite(e.sum()):
            raise ValueError(f"{self.task.label}: compute_error(q) returned a non-finite value")
        return e, J

    @property
    def name(self) -> str:
        return self.task.name

    def __repr__(self) -> str:
        rows, nv = self.task.shape
        return f"{type(self).__name__}(name={self.name!r}, rows={rows}, nv={nv})"


class PositionTask(KinematicTask):
    """End-effector position tracking with a closed loop: ``J v = ẏ_ref + K (y_ref − y)``.

    The point is the robot's default frame (:meth:`~qpcoord.Robot.position`); its error is
    ``e = y − y_ref`` (m) and its Jacobian ``J = robot.jacobian(q)`` (rows × nv).

    Parameters
    ----------
    robot : Robot
    target : array_like or Path, optional
        A fixed point (m; then ``ẏ_ref = 0``) or a :class:`~qpcoord.kinematics.paths.Path`. If
        ``None``, the ``reference`` given to :meth:`update` (e.g. by
        :func:`~qpcoord.simulate`) is used.
    gain : float
        ``K`` (1/s), default 10. ``0`` gives the open-loop velocity map ``J v = ẏ_ref``
        (thesis Eq. 4.1).
    weight : float or array_like
        Row weights inside the level.
    name : str
    lm_damping : float
        Levenberg–Marquardt damping (dimensionless, default 0; see :class:`KinematicTask`).
    """

    task: Equality

    def __init__(
        self,
        robot: Robot,
        target: ArrayLike | Path | None = None,
        gain: float = 10.0,
        weight: ArrayLike = 1.0,
        name: str = "position",
        lm_damping: float = 0.0,
    ) -> None:
        super().__init__(
            _check_robot(robot, name),
            robot.m,
            gain=gain,
            weight=weight,
            name=name,
            lm_damping=lm_damping,
        )
        self.target: Path | np.ndarray | None = None
        if target is not None:
            self.set_target(target)
        self._zero = np.zeros(robot.m)

    def set_target(self, target: ArrayLike | Path) -> None:
        """Set a fixed point (m) or a :class:`~qpcoord.kinematics.paths.Path`."""
        if isinstance(target, Path):
            if target.dim != self.robot.m:
                raise ValueError(
                    f"target path is {target.dim}-D but robot {self.robot.name!r} has "
                    f"{self.robot.m} task rows"
                )
            self.target = target
            return
        y = np.array(target, dtype=float).reshape(-1)
        if y.shape != (self.robot.m,) or not np.all(np.isfinite(y)):
            raise ValueError(
                f"target must be {self.robot.m} finite coordinates (m) or a Path, got {target!r}"
            )
        self.target = y

    def reference_at(
        self, t: float, reference: Path | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(y_ref, ẏ_ref)`` (m, m/s) at time ``t`` (s)."""
        target = self.target if self.target is not None else reference
        if target is None:
            raise ValueError(
                f"{self.task.label}: no target; give target= or run it with a reference"
            )
        if isinstance(target, Path):
            if target.dim != self.robot.m:
                raise ValueError(
                    f"{self.task.label}: reference path is {target.dim}-D, the robot has "
                    f"{self.robot.m} task rows"
                )
            return target.position_velocity(t)
        if not isinstance(target, np.ndarray) or target.shape != (self.robot.m,):
            arr = np.asarray(target, dtype=float)
            if arr.shape != (self.robot.m,) or not np.all(np.isfinite(arr)):
                raise ValueError(
                    f"{self.task.label}: reference must be {self.robot.m} finite "
                    f"coordinates (m) or a Path, got {target!r}"
                )
            target = arr
        return target, self._zero

    def compute_error(
        self, q: ArrayLike, t: float = 0.0, reference: Path | None = None
    ) -> np.ndarray:
        """``e = y(q) − y_ref(t)`` (m), shape (rows,)."""
        q = self.robot.check_configuration(q)
        y_ref, _ = self.reference_at(float(t), reference)
        return self.robot.position(q) - y_ref

    def compute_jacobian(self, q: ArrayLike) -> np.ndarray:
        """``J = ∂y/∂q`` (m per unit of ``v``), shape (rows, nv)."""
        return self.robot.jacobian(q)

    def _refresh(self, q: np.ndarray, t: float, dt: float, reference: Path | None) -> Equality:
        y_ref, v_ref = self.reference_at(t, reference)
        y, J = self.robot._kinematics(q)
        if self.lm_rows is not None:
            self._lm_e = y - y_ref
        return self.task._assign(J, v_ref + self.gain * (y_ref - y))


class PositionBand(KinematicTask):
    """Keep the end effector in a box: ``K (y_lo − y) ≤ J v ≤ K (y_hi − y)`` per row.

    An :class:`~qpcoord.Inequality` task: at a soft level it is met when the levels above
    allow it (its violation is minimised, strictly below them and above the levels
    under it); as a hard constraint (``IK(..., constraints=[band])``) it always holds. With
    ``K·dt = 1`` one Euler step lands at most on the face; a point already outside is
    pushed back at rate ``K``. Its error is ``e = y`` (m), its Jacobian ``robot.jacobian(q)``.

    Parameters
    ----------
    robot : Robot
    lower, upper : array_like, shape (robot.m,)
        Box faces (m); ``-inf`` / ``inf`` for a free side (e.g. only ``z ≥ 0.2``:
        ``lower=[-inf, -inf, 0.2]``, ``upper=inf``). Scalars are broadcast.
    gain : float
        ``K`` (1/s), default 10.
    weight : float or array_like
        Row weights inside the level.
    name : str
    lm_damping : float
        Levenberg–Marquardt damping (dimensionless, default 0; see :class:`KinematicTask`).

    Raises
    ------
    ValueError
        Faces of the wrong size, NaN, or ``lower > upper`` on a row; a bad gain or
        lm_damping.
    """

    task: Inequality

    def __init__(
        self,
        robot: Robot,
        lower: ArrayLike = -np.inf,
        upper: ArrayLike = np.inf,
        gain: float = 10.0,
        weight: ArrayLike = 1.0,
        name: str = "position band",
        lm_damping: float = 0.0,
    ) -> None:
        robot = _check_robot(robot, name)
        lower, upper = _faces(lower, upper, robot.m, "PositionBand")
        super().__init__(
            robot,
            robot.m,
            kind="band",
            gain=gain,
            weight=weight,
            lower=lower,
            upper=upper,
            name=name,
            lm_damping=lm_damping,
        )

    def compute_error(self, q: ArrayLike) -> np.ndarray:
        """``e = y(q)`` (m), shape (rows,)."""
        return self.robot.position(q)

    def compute_jacobian(self, q: ArrayLike) -> np.ndarray:
        """``J = ∂y/∂q``, shape (rows, nv)."""
        return self.robot.jacobian(q)

    def _refresh(self, q: np.ndarray, t: float, dt: float, reference: Path | None) -> Inequality:
        y, J = self.robot._kinematics(q)
        k = self.gain
        with np.errstate(invalid="ignore"):  # inf − y stays inf
            return self.task._assign(k * (self.lower - y), k * (self.upper - y), C=J)


class PostureTask(KinematicTask):
    """Joint-space regulation toward ``q_ref``: ``v_a = K (q_ref ⊖ q)_a``.

    ``q_ref ⊖ q = robot.difference(q, q_ref)`` (``q_ref − q`` for a vector-space
    configuration). The rows ``a`` are the **actuated** joints: on a floating base the root's
    velocity rows (6 for a free-flyer, 3 for a planar root) are left out (the base is moved
    by the other tasks, not pulled to ``q_ref``); on a fixed base every joint (``nv`` rows,
    the task matrix is the identity). Error ``e = (q ⊖ q_ref)_a``, Jacobian the selection of
    those rows (shape ``(rows, nv)``).

    Parameters
    ----------
    robot : Robot
    q_ref : array_like, shape (nq,)
        Preferred configuration (rad, m; quaternions unit).
    gain : float
        ``K`` (1/s), default 1.
    weight : float or array_like, shape (rows,)
        Per-joint weights (``nv`` on a fixed base, ``nv − 6`` under a free-flyer).
    name : str
    lm_damping : float
        Levenberg–Marquardt damping (dimensionless, default 0; see :class:`KinematicTask`).
    """

    task: Equality

    def __init__(
        self,
        robot: Robot,
        q_ref: ArrayLike,
        gain: float = 1.0,
        weight: ArrayLike = 1.0,
        name: str = "posture",
        lm_damping: float = 0.0,
    ) -> None:
        robot = _check_robot(robot, name)
        q_ref = robot.check_configuration(q_ref, "q_ref").copy()
        self.joints = actuated_velocity_indices(robot)
        rows = int(self.joints.size)
        if rows == 0:
            raise ValueError(f"{name}: robot {robot.name!r} has no actuated joint")
        super().__init__(robot, rows, gain=gain, weight=weight, name=name)
        self.q_ref = q_ref
        self._full = rows == robot.nv
        S = np.eye(robot.nv) if self._full else np.eye(robot.nv)[self.joints]
        self.task = Equality(S, np.zeros(rows), weight, name)
        self._init_lm(lm_damping)

    def set_target(self, q_ref: ArrayLike) -> None:
        """Replace the preferred configuration ``q_ref`` (nq,)."""
        self.q_ref = self.robot.check_configuration(q_ref, "q_ref").copy()

    def compute_error(self, q: ArrayLike) -> np.ndarray:
        """``e = (q ⊖ q_ref)_a`` (rad, m), shape (rows,)."""
        d = self.robot.difference(self.q_ref, q)
        return d if self._full else d[self.joints]

    def compute_jacobian(self, q: ArrayLike) -> np.ndarray:
        """The selection of the actuated rows of the identity, shape (rows, nv)."""
        self.robot.check_configuration(q)
        return self.task.A.copy()

    def _refresh(self, q: np.ndarray, t: float, dt: float, reference: Path | None) -> Equality:
        robot = self.robot
        if robot.euclidean:
            d = self.q_ref - q
        else:
            d = pin.difference(robot.model, q, self.q_ref)
        if not self._full:
            d = d[self.joints]
        if self.lm_rows is not None:
            self._lm_e = -d
        return self.task._assign(b=self.gain * d)


class PotentialTask(KinematicTask):
    """Descend a potential: ``v = −K ∇p(q)`` (thesis chapter 5).

    A thesis task: the gradient is taken along ``v`` (size ``nv``); on a vector-space
    configuration (``nq == nv``) that is the usual ``∇p(q)``.

    Parameters
    ----------
    robot : Robot
    gradient : callable
        ``gradient(q) -> ∇p(q)``, shape (nv,), in potential units per rad. An object with
        a ``gradient`` method is accepted too.
    gain : float
        ``K`` (rad²/(s · potential unit)), default 1.
    weight : float or array_like
    name : str
    lm_damping : float
        Levenberg–Marquardt damping (dimensionless, default 0; see :class:`KinematicTask`);
        the task's "error" is the gradient ``∇p(q)``, zero at a minimum of ``p``.
    """

    task: Equality

    def __init__(
        self,
        robot: Robot,
        gradient: Any,  # q -> ∇p(q), or an object with such a .gradient
        gain: float = 1.0,
        weight: ArrayLike = 1.0,
        name: str = "potential",
        lm_damping: float = 0.0,
    ) -> None:
        fn = getattr(gradient, "gradient", gradient)
        if not callable(fn):
            raise ValueError(f"gradient must be callable (q -> ∇p(q)), got {gradient!r}")
        robot = _check_robot(robot, name)
        super().__init__(robot, robot.nv, gain=gain, weight=weight, name=name)
        self.gradient = fn
        self.task = Equality(np.eye(robot.nv), np.zeros(robot.nv), weight, name)
        self._init_lm(lm_damping)

    def _refresh(self, q: np.ndarray, t: float, dt: float, reference: Path | None) -> Equality:
        g = np.asarray(self.gradient(q), dtype=float).reshape(-1)
        if g.shape != (self.robot.nv,):
            raise ValueError(
                f"{self.task.label}: gradient(q) must return {self.robot.nv} values, "
                f"got shape {g.shape}"
            )
        if self.lm_rows is not None:
            self._lm_e = g
        return self.task._assign(b=-self.gain * g)


class OneFormTask(KinematicTask):
    """Annihilate (or prescribe) 1-forms: ``ω(q) v = rate`` (thesis chapter 4).

    A thesis task: the forms act on ``v`` (``nv`` columns; ``q̇`` when ``nq == nv``).

    Parameters
    ----------
    robot : Robot
    form : array_like, shape (k, nv), or callable
        Constant 1-forms (rows, e.g. ``ω₄ = dq₁ + dq₅`` is ``[1, 0, 0, 0, 1]``) or
        ``form(q) -> (k, nv)`` array.
    rate : float or array_like, shape (k,)
        Prescribed ``ω(q) v`` (default 0: motion stays on the leaf ``ω = 0``).
    weight : float or array_like
    name : str
    """

    task: Equality

    def __init__(
        self,
        robot: Robot,
        form: ArrayLike | Callable[[np.ndarray], ArrayLike],
        rate: ArrayLike = 0.0,
        weight: ArrayLike = 1.0,
        name: str = "one-form",
    ) -> None:
        self.robot = robot = _check_robot(robot, name)
        if callable(form):
            self.form: Callable | None = form
            q0 = np.zeros(robot.nq) if robot.euclidean else robot.neutral()
            W = np.asarray(form(q0), dtype=float)
        else:
            self.form = None
            W = np.asarray(form, dtype=float)
        if W.ndim == 1:
            W = W.reshape(1, -1)
        if W.ndim != 2 or W.shape[1] != robot.nv:
            raise ValueError(f"form must have {robot.nv} columns, got shape {W.shape}")
        self.kind = "equality"
        self.gain = 0.0
        self.task = Equality(W, rate, weight, name)
        self.rate = self.task.b.copy()

    def _refresh(self, q: np.ndarray, t: float, dt: float, reference: Path | None) -> Equality:
        if self.form is None:
            return self.task
        return self.task.update(A=self.form(q))  # validated: user code computes it


#: Error (task units, ``√(Σ wᵢ eᵢ²)``) below which a task's Levenberg–Marquardt damping rows
#: are zero: the task counts as met (the convergence the damping must not slow, 1e-6).
LM_ERROR_FLOOR = 1e-6


class LMDamping(KinematicTask):
    """The Levenberg–Marquardt damping rows of a task: ``√μ · v = 0`` on all ``nv`` rows,
    ``μ = lm_damping · Σ wᵢ eᵢ²`` from the owner's error at its last refresh.

    Built by a task constructed with ``lm_damping > 0`` (its :attr:`KinematicTask.lm_rows`);
    :class:`~qpcoord.IK` places it in the owner's level, right after it, and refreshes it
    after the owner. All rows are zero once the owner's error is below
    :data:`LM_ERROR_FLOOR` (the task is met).

    Parameters
    ----------
    owner : KinematicTask
    """

    task: Equality

    def __init__(self, owner: KinematicTask) -> None:
        self.robot = robot = owner.robot
        self.owner = owner
        self.kind = "equality"
        self.gain = 0.0
        nv = robot.nv
        self._eye = np.eye(nv)
        self._A = np.zeros((nv, nv))
        self.task = Equality(self._A, np.zeros(nv), 1.0, f"{owner.task.name} lm damping")

    @property
    def mu(self) -> float:
        """``μ = lm_damping · Σ wᵢ eᵢ²`` of the last step's rows ((task units)²; 0 below
        :data:`LM_ERROR_FLOOR`), read from them (``√μ`` on the diagonal): the same for the
        rows of a native IK step and those of :meth:`update`."""
        return float(self.task.A[0, 0]) ** 2

    def _refresh(self, q: np.ndarray, t: float, dt: float, reference: Path | None) -> Equality:
        owner = self.owner
        if owner.kind == "equality" and owner._lm_e is None:
            # a task whose own _refresh does not record its error: its compute_error
            # (validated), or a message rather than a silent zero damping
            try:
                e = owner.compute_error(q)
            except NotImplementedError:
                raise ValueError(
                    f"{owner.task.label}: lm_damping needs the task's error; define "
                    "compute_error(q) (its _refresh does not record one)"
                ) from None
            owner._lm_e, _ = owner._checked(e, np.zeros(owner.task.shape))
            mu = owner.lm_damping * owner._lm_error_sq()
            owner._lm_e = None
        else:
            mu = owner.lm_damping * owner._lm_error_sq()
        # below LM_ERROR_FLOOR the rows are zero, not tiny: in a strict hierarchy rows of any
        # positive size fix the level's null space, so rows at rounding size would switch the
        # levels below on and off from step to step around a met task
        if mu <= self.owner.lm_damping * LM_ERROR_FLOOR**2:
            mu = 0.0
        np.multiply(self._eye, np.sqrt(mu), out=self._A)
        return self.task._assign(self._A)


class Limit(KinematicTask):
    """A box ``lower(q) ≤ v ≤ upper(q)`` on the velocity (size ``nv``).

    **Writing your own limit.** Subclass it, call ``super().__init__(robot, name)`` and
    implement ``box(q, dt) -> (lower, upper)`` (each of shape ``(nv,)``, ``v`` units;
    ``-inf`` / ``inf`` where a joint is free). :class:`~qpcoord.IK` intersects every limit's
    box into its hard :class:`~qpcoord.Bounds` each step; ``task`` (an Inequality on the
    identity) holds the same box for use at a soft level. A limit that depends on the
    previous velocity overrides :meth:`record`, which the IK calls after each step.

    Parameters
    ----------
    robot : Robot
    name : str
    """

    task: Inequality

    def __init__(self, robot: Robot, name: str = "limit") -> None:
        self.robot = robot = _check_robot(robot, name)
        self.kind = "band"
        self.task = Inequality(np.eye(robot.nv), -np.inf, np.inf, name=name)

    @abstractmethod
    def box(self, q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` on ``v`` (rad/s, m/s), shape (nv,) each, at configuration
        ``q`` (nq,) for the control period ``dt`` (s)."""

    def record(self, v: np.ndarray) -> None:  # noqa: B027 - a hook, empty on purpose
        """Called by :class:`~qpcoord.IK` after each step with the velocity it returned
        (nv,). Stateless limits ignore it."""

    def _refresh(self, q: np.ndarray, t: float, dt: float, reference: Path | None) -> Inequality:
        lo, hi = self.box(q, dt)
        return self.task._assign(lo, hi)


#: Default width of :class:`JointLimits`' damped band, as a fraction of the distance a joint
#: covers in one control step at its speed limit (dimensionless): ``b = band · v_max · dt``.
LIMIT_BAND = 0.2


def _one_dof_q_index(robot: Robot) -> np.ndarray:
    """``(q index, v index)`` of each joint with one position variable per velocity
    (revolute, prismatic), shape ``(n, 2)``."""
    pairs = [
        (int(joint.idx_q), int(joint.idx_v))
        for joint in robot.model.joints[1:]
        if joint.nq == 1 and joint.nv == 1
    ]
    return np.array(pairs, dtype=int).reshape(-1, 2)


class JointLimits(Limit):
    """Joint position limits at velocity level: one Euler step ``q + dt v`` may cover
    ``s(D) = max(K D, D − (1 − K) b)`` of a joint's distance ``D`` to its limit.

    A full step toward the limit leaves ``(1 − K) min(D, b)``. Within the band ``b = band ·
    v_max · dt`` (by default a fifth of a step at the joint's speed limit ``v_max``) the box
    is a velocity damper: each step covers the fraction ``K`` of the distance, so the joint
    approaches its limit exponentially at rate ``K/dt`` (1/s) and never crosses it. From
    farther away the joint may go at full speed and stops ``(1 − K) b`` short of the limit:
    it reaches its limit as fast as with the one-step box ``v ≤ (q_max − q)/dt`` (``K =
    1``) to within the band, and where it lands near the limit still depends on where it
    comes from. That dependence is what keeps a fast task (gain near ``1/dt``) at a singular
    configuration on the limit (a folded arm's elbow) out of a two-step cycle on and off the
    limit at the speed limits: the one-step box lands a joint exactly on its limit from
    anywhere and locks that cycle (UR10 in ``benchmarks/edges.py``: 499 velocity
    reversals/s with ``K = 1``, none with the default). A fast task held on a limit by a
    target it cannot reach from there is settled by its ``lm_damping``. A configuration
    already outside a limit gets a box that moves it back by the fraction ``K`` of its
    excess per step.

    With ``band=inf`` the box is the damper ``v ≤ (K/dt)(q_max − q)`` at every distance and
    the joint decelerates at most ``(K/dt) v_max``; with a finite band it may stop from its
    speed limit within one step at the band's edge, as with ``K = 1``
    (:class:`AccelerationLimits` bound that deceleration). ``v_max`` is the robot's
    ``velocity_limit``, also beside a tighter :class:`VelocityLimits`: the band is a
    property of the joint, the same in every IK the limits are given to (for a band relative
    to a speed limit ``c · v_max``, give ``band = c · 0.2``). A joint without a speed limit
    (infinite, or Pinocchio's ``1.8e308``) has an infinite band.

    Only joints with one position variable per velocity (revolute, prismatic; ``q`` index
    ``model.joints[j].idx_q`` ↔ ``v`` index ``idx_v``) are limited. A free-flyer, planar,
    spherical or continuous joint is unlimited, and so is a side whose limit is infinite or
    ``±1.8e308`` (Pinocchio's "no limit"): its box entries are ``∓inf``.

    Parameters
    ----------
    robot : Robot
    gain : float
        ``K`` in ``(0, 1]`` (dimensionless: the fraction of its distance to the limit a joint
        within the band may cover in one step), default 0.5. ``K = 1``: the one-step box
        ``v ≤ (q_max − q)/dt`` at every distance.
    lower, upper : array_like, shape (nq,), optional
        Limits (rad, m) in ``q``'s layout; default the robot's.
    band : float
        The damped band's width as a fraction of a step at the speed limit (dimensionless,
        ``≥ 0``; default :data:`LIMIT_BAND` = 0.2): ``b = band · v_max · dt``. ``0``: the
        one-step box at every gain; ``inf``: the damper at every distance.

    Raises
    ------
    ValueError
        ``gain`` not in ``(0, 1]``, ``band`` not a number ``≥ 0``, ``lower`` or ``upper``
        not ``nq`` numbers (NaN, a wrong-signed infinity), ``lower > upper``; on
        assignment, a finite ``lower`` or ``upper`` on a joint built without a limit. The
        message names the argument and the value; a bad assignment keeps the old value.

    Attributes
    ----------
    joints : ndarray of int
        Velocity indices of the limited joints.
    band_rate : ndarray
        ``band · v_max`` of each limited joint (rad/s, m/s; order of :attr:`joints`,
        ``inf`` without a speed limit): the band is ``band_rate · dt`` (read-only, from the
        current ``band``).

    Notes
    -----
    Each parameter may be assigned later (``limits.band = 0.5``): checked as here, used from
    the next step on, by both engines. ``lower`` and ``upper`` keep the limited joints of
    the construction (:attr:`joints`).
    """

    lower: np.ndarray  # an assigned value is checked and converted (__setattr__)
    upper: np.ndarray  # an assigned value is checked and converted (__setattr__)

    def __init__(
        self,
        robot: Robot,
        gain: float = 0.5,
        lower: ArrayLike | None = None,
        upper: ArrayLike | None = None,
        band: float = LIMIT_BAND,
    ) -> None:
        super().__init__(robot, "joint limits")
        # each through _checked_parameter: the checks and messages of an assignment
        self.gain = gain
        #: the band's width as a fraction of a step at the speed limit (dimensionless)
        self.band = band
        self.lower = lower  # type: ignore[assignment]  # an ndarray: __setattr__ converts
        self.upper = upper  # type: ignore[assignment]
        bounded = np.isfinite(self.lower) | np.isfinite(self.upper)
        if robot.euclidean:
            # q and v share one layout (q index = v index): the box is computed on all of q
            self._q_index = self._v_index = None
            self.joints = np.flatnonzero(bounded)
        else:
            one_dof = _one_dof_q_index(robot)
            self._q_index = one_dof[bounded[one_dof[:, 0]], 0]
            self._v_index = one_dof[bounded[one_dof[:, 0]], 1]
            self.joints = self._v_index.copy()
        #: the speed limit of each limited joint (rad/s, m/s; order of :attr:`joints`)
        self._speed = _unlimited(robot.velocity_limit)[self.joints]

    def _checked_parameter(self, name: str, value: Any) -> Any:
        if name == "gain":
            if not _is_number(value) or not 0 < value <= 1:  # NaN is not in (0, 1]
                raise ValueError(
                    f"JointLimits: gain must be a number in (0, 1] (dimensionless), got {value!r}"
                )
            return float(value)
        if name == "band":
            if not _is_number(value) or not value >= 0:  # NaN is not >= 0
                raise ValueError(
                    "JointLimits: band must be a number >= 0 or inf (dimensionless: a "
                    f"fraction of a step at the speed limit), got {value!r}"
                )
            return float(value)
        if name == "lower" or name == "upper":
            return self._checked_side(name, value)
        return super()._checked_parameter(name, value)

    def _checked_side(self, name: str, value: Any) -> np.ndarray:
        """``lower`` or ``upper`` (``None``: the robot's) validated: ``nq`` numbers or one
        (rad, m), read with ``±1.8e308`` as unlimited, not beyond the other side; after
        construction, finite only on the joints it limits."""
        robot = self.robot
        sign = -1 if name == "lower" else 1
        given = getattr(robot, name) if value is None else value
        try:
            arr = _unlimited(robot._limit(given, None, name, sign))
        except (TypeError, ValueError) as exc:
            raise ValueError(
                f"JointLimits: {name} must be {robot.nq} numbers or one (rad, m; "
                f"{'-' if sign < 0 else ''}inf for none): {exc}; got {value!r}"
            ) from None
        other = self.__dict__.get("upper" if sign < 0 else "lower")
        if other is not None:
            lo, hi = (arr, other) if sign < 0 else (other, arr)
            bad = np.flatnonzero(lo > hi)
            if bad.size:
                raise ValueError(
                    f"JointLimits: lower > upper at q index {bad.tolist()}: "
                    f"{lo[bad]} > {hi[bad]}; got {name}={value!r}"
                )
        if "joints" in self.__dict__:  # an assignment: the limited joints are fixed
            limited = self.joints if self._q_index is None else self._q_index
            candidates = np.arange(robot.nq) if robot.euclidean else _one_dof_q_index(robot)[:, 0]
            new = np.setdiff1d(candidates[np.isfinite(arr[candidates])], limited)
            if new.size:
                raise ValueError(
                    f"JointLimits: {name} is finite at q index {new.tolist()}, joints built "
                    "without a limit (the limited joints are fixed at construction: build a "
                    f"new JointLimits), got {value!r}"
                )
        return arr

    @property
    def band_rate(self) -> np.ndarray:
        """``band · v_max`` of each limited joint (rad/s, m/s; order of :attr:`joints`,
        ``inf`` without a speed limit), from the current :attr:`band`: the band is
        ``band_rate · dt``."""
        band, rate = self.__dict__.get("_band_rate", (None, None))
        if band != self.band:  # first read, or band assigned since: computed again
            with np.errstate(invalid="ignore"):  # 0 · inf (no band, no speed limit): no band
                rate = read_only(np.nan_to_num(self.band * self._speed, nan=0.0, posinf=np.inf))
            self._band_rate = (self.band, rate)
        return rate

    @property
    def q_index(self) -> np.ndarray | None:
        """The ``q`` index of each limited joint (its ``v`` index in :attr:`joints`), or
        ``None`` on a robot whose ``q`` and ``v`` share one layout (every joint of
        :attr:`joints` is then limited at that index)."""
        return self._q_index

    def distances(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(q_max − q, q − q_min)`` of the limited joints (rad, m; order of
        :attr:`joints`, ``inf`` for a free side), at a validated ``q`` (nq,); negative
        outside a limit."""
        if self._q_index is None:
            j = self.joints
            return self.upper[j] - q[j], q[j] - self.lower[j]
        qi = self._q_index
        qq = q[qi]
        return self.upper[qi] - qq, qq - self.lower[qi]

    def box(self, q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        up, down = self.distances(q)
        nv = self.robot.nv
        lo, hi = np.full(nv, -np.inf), np.full(nv, np.inf)
        lo[self.joints] = -self._step(down, dt) / dt
        hi[self.joints] = self._step(up, dt) / dt
        return lo, hi

    def _step(self, D: np.ndarray, dt: float) -> np.ndarray:
        """The longest step ``max(K D, D − (1 − K) b)`` toward a limit at distance ``D`` (rad,
        m; order of :attr:`joints`); outside (``D < 0``) the step back ``K D``."""
        K = self.gain
        with np.errstate(invalid="ignore"):
            # fmax: inf − inf (no limit, no speed limit) is NaN, and the inf K D is the step
            return np.fmax(K * D, D - (1.0 - K) * (self.band_rate * dt))


class VelocityLimits(Limit):
    """Joint speed limits ``−v_max ≤ v ≤ v_max``.

    Parameters
    ----------
    robot : Robot
    limit : float or array_like, shape (nv,), optional
        ``v_max`` (rad/s, m/s), > 0, default the robot's ``velocity_limit`` (a floating
        base's ``±1.8e308`` entries read as unlimited). May be assigned later: checked as
        here, used from the next step on, by both engines.

    Raises
    ------
    ValueError
        ``limit`` not ``nv`` numbers ``> 0`` or one (NaN, ``≤ 0``), at construction or on
        assignment (the message names it and the value; the old value is kept).
    """

    limit: np.ndarray  # an assigned value is checked and converted (__setattr__)

    def __init__(self, robot: Robot, limit: ArrayLike | None = None) -> None:
        super().__init__(robot, "velocity limits")
        self.limit = limit  # type: ignore[assignment]  # validated and converted, as assigned
        self.task = Inequality(np.eye(robot.nv), -self.limit, self.limit, name="velocity limits")

    def _checked_parameter(self, name: str, value: Any) -> Any:
        if name == "limit":
            robot = self.robot
            given = robot.velocity_limit if value is None else value
            return _positive_limit(given, robot.nv, "VelocityLimits", "rad/s, m/s")
        return super()._checked_parameter(name, value)

    def box(self, q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        return -self.limit, self.limit


class AccelerationLimits(Limit):
    """Joint acceleration limits ``v_prev − a_max dt ≤ v ≤ v_prev + a_max dt``, braking
    before the joint position limits.

    ``v_prev`` is the velocity of the previous control step: the :class:`~qpcoord.IK` that
    holds this limit records the ``v`` it returns after every :meth:`~qpcoord.IK.step`
    (:meth:`record`); it is zero at the start (the robot at rest) and after
    :meth:`reset`. Meant for one ``step`` per control period (a real loop, or
    :func:`~qpcoord.simulate` with ``integrator="euler"``: RK4 calls the IK four times a step).

    **Braking.** A joint with a position limit also gets ``v ≤ braking_speed(q_max − q)``
    and ``v ≥ −braking_speed(q − q_min)`` (:func:`~qpcoord.kinematics.braking.braking_speed`
    with ``a_max``: the step-by-step form of ``|v| ≤ √(2 a_max d)``), so it slows down in
    time and reaches its limit without a deceleration above ``a_max``: the acceleration
    limit holds at every step, at the position limits too. Where the two cannot both hold
    (a joint already moving faster than it can brake, or outside its limit), the end of the
    box nearer to 0 is kept, as :meth:`~qpcoord.IK.refresh` does: outside a limit the joint
    moves back with the acceleration limit.

    The braking rows are computed for the gain of ``position_limits``, as for its damper
    ``v ≤ (K/dt)(q_max − q)`` at every distance (a :class:`JointLimits` box is never smaller,
    whatever its band, so the braking sequence keeps it): give the IK's own
    :class:`JointLimits` when it has another gain or other bounds, so that the joint also
    slows down for that box (braking rows for ``K = 1`` beside a damper ``K = 0.5`` let the
    joint decelerate at up to 60 rad/s² for ``a_max = 50``, dt = 1 ms).

    Parameters
    ----------
    robot : Robot
    limit : float or array_like, shape (nv,)
        ``a_max`` (rad/s², m/s²), > 0; ``inf`` for an unlimited entry (e.g. a floating base's
        six rows: ``np.r_[np.full(6, np.inf), np.full(robot.nv - 6, 20.0)]``). May be
        assigned later: checked as here, used from the next step on, by both engines.
    position_limits : "robot", JointLimits or None
        The position limits braked before, and their gain (default ``"robot"``: the
        robot's finite limits of its 1-DoF joints, as ``JointLimits(robot)``, its default
        gain 0.5: the IK's ``limits="robot"``); give the IK's own :class:`JointLimits` if it
        has another gain or other bounds; ``None``: no braking. Fixed at construction (an
        IK's native step holds the braked joints): assign the JointLimits' own ``gain``,
        ``lower``, ``upper`` instead, which the braking rows follow.

    Raises
    ------
    ValueError
        ``limit`` not ``nv`` numbers ``> 0`` or one (at construction or on assignment),
        ``position_limits`` of another kind or robot, or assigned after construction. The
        message names the argument and the value; a bad assignment keeps the old value.
    """

    limit: np.ndarray  # an assigned value is checked and converted (__setattr__)

    def __init__(self, robot: Robot, limit: ArrayLike, position_limits: Any = "robot") -> None:
        super().__init__(robot, "acceleration limits")
        # each through _checked_parameter: the checks and messages of an assignment
        self.limit = limit  # type: ignore[assignment]  # an ndarray: __setattr__ converts
        self._v_prev = np.zeros(robot.nv)
        #: The :class:`JointLimits` braked before (``None``: no braking); fixed at
        #: construction
        self.position_limits: JointLimits | None = position_limits

    def _checked_parameter(self, name: str, value: Any) -> Any:
        robot = self.robot
        if name == "limit":
            return _positive_limit(value, robot.nv, "AccelerationLimits", "rad/s², m/s²")
        if name == "position_limits":
            if "position_limits" in self.__dict__:
                # an IK's native step and start-up check hold the braked joints
                raise ValueError(
                    "AccelerationLimits: position_limits is fixed at construction (assign "
                    "the JointLimits' own gain, lower, upper; or build a new "
                    f"AccelerationLimits and IK), got {value!r}"
                )
            if isinstance(value, str) and value == "robot":
                value = JointLimits(robot)
            elif value is not None and not (
                isinstance(value, JointLimits) and value.robot.model is robot.model
            ):
                raise ValueError(
                    "AccelerationLimits: position_limits must be 'robot', a JointLimits of "
                    f"this robot or None, got {value!r}"
                )
            return value if value is not None and value.joints.size else None
        return super()._checked_parameter(name, value)

    @property
    def v_prev(self) -> np.ndarray:
        """The previous step's velocity (nv,) (rad/s, m/s): one array for the limit's life,
        written in place (assigning copies into it; a native IK step reads it)."""
        return self._v_prev

    @v_prev.setter
    def v_prev(self, value: ArrayLike) -> None:
        self._v_prev[...] = self.robot._check_velocity(value, "v_prev")

    def box(self, q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        step = self.limit * dt
        lo, hi = self._v_prev - step, self._v_prev + step
        P = self.position_limits
        if P is not None:
            j = P.joints
            a = self.limit[j]
            up, down = P.distances(q)
            hi[j] = np.minimum(hi[j], braking_speed(up, a, dt, P.gain))
            lo[j] = np.maximum(lo[j], -braking_speed(down, a, dt, P.gain))
            bad = lo > hi
            if bad.any():  # cannot brake in time, or outside the limit: the end nearer to 0
                back = np.where(np.abs(lo) < np.abs(hi), lo, hi)
                lo[bad] = hi[bad] = back[bad]
        return lo, hi

    def record(self, v: np.ndarray) -> None:
        """Keep ``v`` (nv,) as the previous step's velocity."""
        self._v_prev[...] = v

    def reset(self, v_prev: ArrayLike | None = None) -> None:
        """Start again from rest (``v_prev = 0``) or from the given velocity (nv,)."""
        if v_prev is None:
            self._v_prev[...] = 0.0
        else:
            self.v_prev = v_prev
