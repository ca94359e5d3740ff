"""Tasks built from a :class:`~qpcoord.Robot` at the current configuration.

The decision variable of every task here is the **joint velocity** ``q̇`` (rad/s for
revolute joints). Each task owns one :class:`~qpcoord.Equality` or
:class:`~qpcoord.Inequality` (its ``task`` attribute) and refreshes its numbers in place
with ``update(q, t, dt, reference)``, so a stack built once is re-solved every control step.

=====================  =============================================================
:class:`PositionTask`  ``J q̇ = ẏ_ref + K (y_ref − y)`` (closed-loop IK, CLIK)
:class:`PositionBand`  ``K (y_lo − y) ≤ J q̇ ≤ K (y_hi − y)`` (stay in a box, any level)
:class:`PostureTask`   ``q̇ = K (q_ref − q)``
:class:`PotentialTask` ``q̇ = −K ∇p(q)`` (gradient descent on a potential, chapter 5)
:class:`OneFormTask`   ``ω(q) q̇ = rate`` (a 1-form, chapter 4; default rate 0)
:class:`JointLimits`   ``K (q_min − q)/dt ≤ q̇ ≤ K (q_max − q)/dt``
:class:`VelocityLimits` ``−v_max ≤ q̇ ≤ v_max``
=====================  =============================================================

The two limits are boxes on ``q̇``: :class:`~qpcoord.IK` merges them into the stack's
:class:`~qpcoord.Bounds` (always hard); their ``task`` (an Inequality) can also be placed at
a soft level.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable

import numpy as np

from ..core.tasks import Equality, Inequality
from .paths import Path
from .robot import Robot

__all__ = [
    "KinematicTask",
    "PositionTask",
    "PositionBand",
    "PostureTask",
    "PotentialTask",
    "OneFormTask",
    "JointLimits",
    "VelocityLimits",
    "Limit",
]


def _gain(value, what: str = "gain") -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{what} must be a number (1/s), got {value!r}")
    if not np.isfinite(value) or value < 0:
        raise ValueError(f"{what} must be finite and >= 0 (1/s), got {value!r}")
    return float(value)


def _check_dt(dt) -> float:
    if isinstance(dt, bool) or not isinstance(dt, (int, float, np.integer, np.floating)):
        raise ValueError(f"dt must be a number of seconds, got {dt!r}")
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be > 0 and finite (s), got {dt!r}")
    return float(dt)


class KinematicTask(ABC):
    """Base class: a task whose numbers depend on the configuration ``q`` and time ``t``.

    Subclasses set ``self.task`` (an :class:`Equality` or :class:`Inequality` on ``q̇``)
    in ``__init__`` and refresh it in :meth:`update`.
    """

    task: Equality | Inequality
    robot: Robot

    def update(self, q, t: float = 0.0, dt: float = 1e-3, reference=None):
        """Refresh ``self.task`` for configuration ``q`` (rad) at time ``t`` (s); return it.

        ``dt`` is the control period (s); ``reference`` is the run's end-effector path
        (used by tasks built without their own target).

        Raises
        ------
        ValueError
            ``q`` of the wrong size or not finite, ``dt`` not positive.
        """
        q = self.robot.check_configuration(q)
        return self._refresh(q, float(t), _check_dt(dt), reference)

    @abstractmethod
    def _refresh(self, q: np.ndarray, t: float, dt: float, reference):
        """:meth:`update` for an already validated ``q`` (the per-step path of IK)."""

    @property
    def name(self) -> str:
        return self.task.name


class PositionTask(KinematicTask):
    """End-effector position tracking with a closed loop: ``J q̇ = ẏ_ref + K (y_ref − y)``.

    Parameters
    ----------
    robot : Robot
    target : array_like or Path, optional
        A fixed point (m; then ``ẏ_ref = 0``) or a :class:`~qpcoord.kinematics.paths.Path`. If
        ``None``, the ``reference`` given to :meth:`update` (e.g. by
        :func:`~qpcoord.simulate`) is used.
    gain : float
        ``K`` (1/s), default 10. ``0`` gives the open-loop velocity map ``J q̇ = ẏ_ref``
        (thesis Eq. 4.1).
    weight : float or array_like
        Row weights inside the level.
    name : str
    """

    def __init__(
        self, robot: Robot, target=None, gain: float = 10.0, weight=1.0, name: str = "position"
    ) -> None:
        self.robot = robot
        self.gain = _gain(gain)
        self.target = None
        if target is not None:
            self.set_target(target)
        self.task = Equality(np.zeros((robot.m, robot.nq)), np.zeros(robot.m), weight, name)
        self._zero = np.zeros(robot.m)

    def set_target(self, target) -> None:
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

    def reference_at(self, t: float, reference=None) -> tuple[np.ndarray, np.ndarray]:
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

    def _refresh(self, q, t, dt, reference) -> Equality:
        y_ref, v_ref = self.reference_at(t, reference)
        y, J = self.robot._kinematics(q)
        return self.task._assign(J, v_ref + self.gain * (y_ref - y))


class PositionBand(KinematicTask):
    """Keep the end effector in a box: ``K (y_lo − y) ≤ J q̇ ≤ K (y_hi − y)`` per row.

    An :class:`~qpcoord.Inequality` task: at a soft level it is met when the levels above
    allow it (its violation is minimised, strictly below them and above the levels
    under it); as a hard constraint (``IK(..., constraints=[band])``) it always holds. With
    ``K·dt = 1`` one Euler step lands at most on the face; a point already outside is
    pushed back at rate ``K``.

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

    Raises
    ------
    ValueError
        Faces of the wrong size, NaN, or ``lower > upper`` on a row; a bad gain.
    """

    def __init__(
        self,
        robot: Robot,
        lower=-np.inf,
        upper=np.inf,
        gain: float = 10.0,
        weight=1.0,
        name: str = "position band",
    ) -> None:
        self.robot = robot
        self.gain = _gain(gain)
        m = robot.m
        faces = []
        for what, value in (("lower", lower), ("upper", upper)):
            try:
                arr = np.broadcast_to(np.asarray(value, dtype=float), (m,)).copy()
            except (ValueError, TypeError):
                arr = None
            if arr is None or np.isnan(arr).any():
                raise ValueError(
                    f"PositionBand {what} must have {m} numbers (m, ±inf allowed), got {value!r}"
                )
            faces.append(arr)
        self.lower, self.upper = faces
        bad = np.flatnonzero(self.lower > self.upper)
        if bad.size:
            raise ValueError(
                f"PositionBand: lower > upper on row(s) {bad.tolist()}: "
                f"{self.lower[bad]} > {self.upper[bad]}"
            )
        self.task = Inequality(np.zeros((m, robot.nq)), -np.inf, np.inf, weight, name)

    def _refresh(self, q, t, dt, reference) -> Inequality:
        y, J = self.robot._kinematics(q)
        k = self.gain
        with np.errstate(invalid="ignore"):  # inf − y stays inf
            return self.task._assign(k * (self.lower - y), k * (self.upper - y), C=J)


class PostureTask(KinematicTask):
    """Joint-space regulation ``q̇ = K (q_ref − q)``.

    Parameters
    ----------
    robot : Robot
    q_ref : array_like, shape (nq,)
        Preferred configuration (rad).
    gain : float
        ``K`` (1/s), default 1.
    weight : float or array_like
        Per-joint weights.
    name : str
    """

    def __init__(self, robot: Robot, q_ref, gain: float = 1.0, weight=1.0, name="posture"):
        self.robot = robot
        self.q_ref = robot.check_configuration(q_ref, "q_ref").copy()
        self.gain = _gain(gain)
        self.task = Equality(np.eye(robot.nq), np.zeros(robot.nq), weight, name)

    def _refresh(self, q, t, dt, reference) -> Equality:
        return self.task._assign(b=self.gain * (self.q_ref - q))


class PotentialTask(KinematicTask):
    """Descend a potential: ``q̇ = −K ∇p(q)`` (thesis chapter 5).

    Parameters
    ----------
    robot : Robot
    gradient : callable
        ``gradient(q) -> ∇p(q)``, shape (nq,), in potential units per rad. An object with
        a ``gradient`` method is accepted too.
    gain : float
        ``K`` (rad²/(s · potential unit)), default 1.
    weight : float or array_like
    name : str
    """

    def __init__(self, robot: Robot, gradient, gain: float = 1.0, weight=1.0, name="potential"):
        fn = getattr(gradient, "gradient", gradient)
        if not callable(fn):
            raise ValueError(f"gradient must be callable (q -> ∇p(q)), got {gradient!r}")
        self.robot = robot
        self.gradient = fn
        self.gain = _gain(gain)
        self.task = Equality(np.eye(robot.nq), np.zeros(robot.nq), weight, name)

    def _refresh(self, q, t, dt, reference) -> Equality:
        g = np.asarray(self.gradient(q), dtype=float).reshape(-1)
        if g.shape != (self.robot.nq,):
            raise ValueError(
                f"{self.task.label}: gradient(q) must return {self.robot.nq} values, "
                f"got shape {g.shape}"
            )
        return self.task._assign(b=-self.gain * g)


class OneFormTask(KinematicTask):
    """Annihilate (or prescribe) 1-forms: ``ω(q) q̇ = rate`` (thesis chapter 4).

    Parameters
    ----------
    robot : Robot
    form : array_like, shape (k, nq), or callable
        Constant 1-forms (rows, e.g. ``ω₄ = dq₁ + dq₅`` is ``[1, 0, 0, 0, 1]``) or
        ``form(q) -> (k, nq)`` array.
    rate : float or array_like, shape (k,)
        Prescribed ``ω(q) q̇`` (default 0: motion stays on the leaf ``ω = 0``).
    weight : float or array_like
    name : str
    """

    def __init__(self, robot: Robot, form, rate=0.0, weight=1.0, name: str = "one-form"):
        self.robot = robot
        if callable(form):
            self.form: Callable | None = form
            W = np.asarray(form(np.zeros(robot.nq)), dtype=float)
        else:
            self.form = None
            W = np.asarray(form, dtype=float)
        if W.ndim == 1:
            W = W.reshape(1, -1)
        if W.ndim != 2 or W.shape[1] != robot.nq:
            raise ValueError(f"form must have {robot.nq} columns, got shape {W.shape}")
        self.task = Equality(W, rate, weight, name)
        self.rate = self.task.b.copy()

    def _refresh(self, q, t, dt, reference) -> Equality:
        if self.form is None:
            return self.task
        return self.task.update(A=self.form(q))  # validated: user code computes it


class Limit(KinematicTask):
    """A box ``lower(q) ≤ q̇ ≤ upper(q)``: :meth:`box` gives it, ``task`` holds it."""

    @abstractmethod
    def box(self, q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` on ``q̇`` (rad/s) at configuration ``q`` (rad), period ``dt`` (s)."""

    def _refresh(self, q, t, dt, reference) -> Inequality:
        lo, hi = self.box(q, dt)
        return self.task._assign(lo, hi)


class JointLimits(Limit):
    """Joint position limits at velocity level: ``K (q_min − q)/dt ≤ q̇ ≤ K (q_max − q)/dt``.

    With ``K = 1`` one Euler step ``q + dt q̇`` lands at most on the limit; ``K < 1`` slows
    the approach. A configuration already outside a limit gets a box that pushes it back.

    Parameters
    ----------
    robot : Robot
    gain : float
        ``K`` in ``(0, 1]``, default 1.
    lower, upper : array_like, optional
        Limits (rad); default the robot's.
    """

    def __init__(self, robot: Robot, gain: float = 1.0, lower=None, upper=None):
        self.robot = robot
        self.gain = _gain(gain)
        if not 0 < self.gain <= 1:
            raise ValueError(f"JointLimits gain must be in (0, 1], got {gain!r}")
        self.lower = robot.lower if lower is None else robot._limit(lower, None, "lower", -1)
        self.upper = robot.upper if upper is None else robot._limit(upper, None, "upper", 1)
        if np.any(self.lower > self.upper):
            raise ValueError("JointLimits: lower > upper")
        n = robot.nq
        self.task = Inequality(np.eye(n), -np.inf, np.inf, name="joint limits")

    def box(self, q, dt):
        k = self.gain / dt
        # lower ≤ upper, so lo ≤ hi; outside a limit both have the sign that moves back
        return k * (self.lower - q), k * (self.upper - q)


class VelocityLimits(Limit):
    """Joint speed limits ``−v_max ≤ q̇ ≤ v_max``.

    Parameters
    ----------
    robot : Robot
    limit : float or array_like, optional
        ``v_max`` (rad/s), default the robot's ``velocity_limit``.
    """

    def __init__(self, robot: Robot, limit=None):
        self.robot = robot
        v = robot.velocity_limit if limit is None else robot._limit(limit, None, "limit", 1)
        if np.any(v <= 0):
            raise ValueError(f"VelocityLimits: limit must be > 0 (rad/s), got {v}")
        self.limit = v
        self.task = Inequality(np.eye(robot.nq), -v, v, name="velocity limits")

    def box(self, q, dt):
        return -self.limit, self.limit
