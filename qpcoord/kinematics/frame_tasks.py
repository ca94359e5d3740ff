"""Frame, centre-of-mass, support-polygon and joint-space tasks of a whole robot.

Every task here is a :class:`~qpcoord.kinematics.tasks.KinematicTask` whose decision
variable is the joint velocity ``v`` (size ``robot.nv``: on a floating base its first six
entries are the base's twist in the base frame, see :class:`~qpcoord.Robot`). Each task has

- ``compute_error(q)`` -- the task error ``e(q)`` (m, rad) for the current target, or the
  measured quantity of a band;
- ``compute_jacobian(q)`` -- ``J = ∂e/∂q`` against ``v``, shape ``(rows, nv)``, so that
  along ``q(t)`` with velocity ``v``: ``ė = J v``;
- ``update(q, t, dt, reference)`` -- refreshes its :class:`~qpcoord.Equality` /
  :class:`~qpcoord.Inequality` (``task`` attribute) in place and returns it.

An equality task's rows are ``J v = −K e(q)`` (``K`` the gain, 1/s, plus a feed-forward
velocity when a target moves): one step of length ``dt`` multiplies the error by about
``1 − K dt``. A band's rows are ``K (lower − e) ≤ J v ≤ K (upper − e)`` (``e`` the measured
quantity, ±inf for a free side): inside the band the rows do not bind; outside, the
quantity is pushed back at rate ``K``. Any of them can sit at any priority level, inside a
level with others, or be a hard constraint.

======================== ==============================================================
:class:`FrameTask`       pose of a frame: ``e = log₆(T*⁻¹ T)`` (SE(3) log, in the frame)
:class:`FramePositionTask` ``e = p − p*`` (origin of a frame, world axes, m)
:class:`OrientationTask` ``e = log₃(R*ᵀ R)`` (SO(3) log, in the frame, rad)
:class:`RelativeFrameTask` pose of ``frame`` in ``reference_frame``, SE(3) log
:class:`ComTask`         ``e = c − c*`` (centre of mass, world axes, m)
:class:`ComBand`         ``lower ≤ c ≤ upper`` (box on the CoM, an inequality)
:class:`SupportPolygon`  CoM ground projection inside the contacts' convex hull
:class:`JointCouplingTask` ``e = Σ rᵢ qᵢ − offset`` (joints moving together)
:class:`DampingTask`     ``v = 0`` (all ``nv`` rows, floating base included)
:class:`LowAccelerationTask` ``v = v_prev`` (all ``nv`` rows)
======================== ==============================================================

Conventions
-----------
*SE(3) error.* :class:`FrameTask` uses the error of Pink: ``E = T*⁻¹ T`` is the frame's
pose seen from the target, ``e = log₆(E)`` (linear part first, then angular) is a twist
expressed **in the frame** (at convergence the frame and target axes coincide), and
``J = Jlog₆(E) · J_local`` with ``J_local`` Pinocchio's ``LOCAL`` frame Jacobian: moving
``q`` along ``v`` moves the frame by the body twist ``J_local v`` and ``E`` by the same
right-multiplied twist, whose effect on ``log₆`` is exactly ``Jlog₆(E)``. The position
part of ``log₆`` is not ``p − p*`` while the orientation error is not zero (it is
``V(θ)⁻¹ R*ᵀ(p − p*)``), but ``e = 0`` exactly when ``T = T*``. :class:`OrientationTask` is
the same on SO(3) (``Jlog₃``); :class:`FramePositionTask` is the plain world-axes difference.

*Masks.* A task's ``mask`` keeps some of its rows: a boolean array with one entry per row,
or a string of axis names separated by spaces, commas or ``+``: ``"x"``, ``"y"``, ``"z"``
(translation) and ``"rx"``, ``"ry"``, ``"rz"`` (rotation; aliases ``"roll"``, ``"pitch"``,
``"yaw"``), ``"position"`` (= ``"x y z"``) and ``"orientation"`` (= ``"rx ry rz"``); a run of
letters ``"xy"`` means ``"x y"``. On :class:`OrientationTask` ``"x"``, ``"y"``, ``"z"`` mean
the rotation axes. The axes are those the error is expressed in: the frame's own axes for
:class:`FrameTask`, :class:`OrientationTask` and :class:`RelativeFrameTask` (so ``"yaw"`` is
the rotation about the frame's z, world yaw for a level frame), the world axes for
:class:`FramePositionTask` and :class:`ComTask`; ``FrameTask(..., error="split")`` measures
translation in the target's axes. E.g. keep a foot at its height and level:
``FrameTask(robot, "left_sole_link", T, mask="z roll pitch")`` (with roll and pitch held,
the ``z`` row of ``log₆`` is the height along the target's z); for a translation mask
without the rotation rows use ``error="split"`` (see :class:`FrameTask`).
"""

from __future__ import annotations

import re
from abc import abstractmethod
from collections.abc import Sequence
from math import isfinite
from typing import Any

import numpy as np
import pinocchio as pin

from ..core import native
from ..core.tasks import Equality, Inequality
from .robot import Robot
from .tasks import KinematicTask, read_only

__all__ = [
    "FrameTask",
    "FramePositionTask",
    "OrientationTask",
    "RelativeFrameTask",
    "ComTask",
    "ComBand",
    "SupportPolygon",
    "JointCouplingTask",
    "DampingTask",
    "LowAccelerationTask",
    "RIGID_TOLERANCE",
]

#: Largest deviation accepted for a rigid transform: ``max |RᵀR − I|``, ``|det R − 1|`` and
#: the last row's deviation from ``[0, 0, 0, 1]`` (dimensionless).
RIGID_TOLERANCE = 1e-6

_F64 = np.dtype(np.float64)
_POSE_AXES = ("x", "y", "z", "rx", "ry", "rz")
_POSITION_AXES = ("x", "y", "z")
_ROTATION_AXES = ("rx", "ry", "rz")
_ALIASES = {
    "roll": ("rx",),
    "pitch": ("ry",),
    "yaw": ("rz",),
    "position": ("x", "y", "z"),
    "translation": ("x", "y", "z"),
    "orientation": ("rx", "ry", "rz"),
    "rotation": ("rx", "ry", "rz"),
}


# ---------------------------------------------------------------------------------------
# validation helpers
# ---------------------------------------------------------------------------------------


def _number(value: Any, what: str, unit: str, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{what} must be a number ({unit}), got {value!r}")
    value = float(value)
    if not np.isfinite(value) or value < 0 or (positive and value == 0):
        sign = "> 0" if positive else ">= 0"
        raise ValueError(f"{what} must be finite and {sign} ({unit}), got {value!r}")
    return value


def _gain(value: Any, what: str = "gain") -> float:
    return _number(value, what, "1/s")


def _vector(value: Any, size: int, what: str, unit: str) -> np.ndarray:
    if type(value) is np.ndarray:
        copy = _native_finite_copy()
        if copy is not None:  # check and copy in one native call (0.2 µs less, timeit)
            out = np.empty(size)
            if copy(value, out):
                return out
        elif value.shape == (size,) and value.dtype == _F64 and isfinite(sum(value.tolist())):
            return value.copy()  # else (NaN, inf or an overflow): the checks below
    try:
        arr = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be {size} numbers ({unit}), got {value!r}") from None
    if arr.shape != (size,):
        raise ValueError(f"{what} must be {size} numbers ({unit}), got shape {np.shape(value)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be finite ({unit}), got {arr}")
    return arr


def _rotation(R: np.ndarray, what: str) -> None:
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > RIGID_TOLERANCE:
        raise ValueError(
            f"{what}: rotation part is not orthonormal (max |RᵀR − I| = {err:.3g} > "
            f"{RIGID_TOLERANCE:g}); not a rigid transform"
        )
    det = float(np.linalg.det(R))
    if abs(det - 1.0) > RIGID_TOLERANCE:
        raise ValueError(
            f"{what}: rotation part has det = {det:.9g} (must be 1: a reflection is not a "
            "rigid transform)"
        )


def _rigid_fast(value: Any) -> pin.SE3 | None:
    """:func:`_as_se3` of a float64 4×4 array in a few scalar operations, or ``None`` when
    the checks do not all pass (or ``value`` is of another kind): then :func:`_as_se3`'s full
    path runs and raises its message. The same tests (finite, last row, ``max |RᵀR − I|``,
    ``det R``) against :data:`RIGID_TOLERANCE`, by the native extension where it is built
    (``spatial_rigid_ok``: the same scalar expressions; ``timeit`` on an identity, one BLAS
    thread: 0.14 µs against 1.2 µs for :func:`_rigid_ok`), else by
    :func:`_rigid_ok`."""
    if type(value) is not np.ndarray or value.shape != (4, 4) or value.dtype != _F64:
        return None
    check = _native_rigid()
    if not (_rigid_ok(value) if check is None else check(value, RIGID_TOLERANCE)):
        return None
    return pin.SE3(value)


#: ``[module, spatial_rigid_ok, spatial_rigid_copy, spatial_finite_copy]``: the extension's
#: functions, keyed on the module object :func:`qpcoord.core.native.load` holds
#: (``native._module``; ``None`` when the engine is not built), so a build swapped
#: afterwards (``QPCOORD_NATIVE_ISA`` and a fresh ``load()``, a test's ``native._module``) is
#: followed at the next call.
_RIGID: list = [object(), None, None, None]


def _rigid_lookup() -> list:
    """Fill :data:`_RIGID` from the module ``load()`` holds (choosing it if none is)."""
    mod = native._module
    if mod is None and native.available():  # not loaded yet: load() chooses the build
        mod = native._module
    _RIGID[:] = [
        mod,
        getattr(mod, "spatial_rigid_ok", None),
        getattr(mod, "spatial_rigid_copy", None),
        getattr(mod, "spatial_finite_copy", None),
    ]
    return _RIGID


def _native_rigid() -> Any:
    """The extension's rigid-transform check of the loaded build, or ``None`` if it is not
    built (one identity test per call, looked up again only when the build changed)."""
    c = _RIGID
    return c[1] if native._module is c[0] else _rigid_lookup()[1]


def _native_rigid_copy() -> Any:
    """The extension's check-and-copy of a 4×4 rigid transform (``spatial_rigid_copy``:
    :func:`_native_rigid`'s checks, then the copy into a C-contiguous 4×4 output) of the
    loaded build, or ``None`` if it is not built (as :func:`_native_rigid`)."""
    c = _RIGID
    return c[2] if native._module is c[0] else _rigid_lookup()[2]


def _native_finite_copy() -> Any:
    """The extension's check-and-copy of a float64 vector (``spatial_finite_copy``: the
    copy into an output of the same length when the entries' sum is finite) of the loaded
    build, or ``None`` if it is not built (as :func:`_native_rigid`)."""
    c = _RIGID
    return c[3] if native._module is c[0] else _rigid_lookup()[3]


def _rigid_ok(value: np.ndarray) -> bool:
    """The checks of :func:`_rigid_fast` on a float64 4×4 array, in Python scalars."""
    (a, b, c, x), (d, e, f, y), (g, h, i, z), (l0, l1, l2, l3) = value.tolist()
    if not isfinite(a + b + c + x + d + e + f + y + g + h + i + z + l0 + l1 + l2 + l3):
        return False
    if max(abs(l0), abs(l1), abs(l2), abs(l3 - 1.0)) > RIGID_TOLERANCE:
        return False
    return _is_rotation(a, b, c, d, e, f, g, h, i)


def _is_rotation(a: float, b: float, c: float, d: float, e: float, f: float, g: float,
                 h: float, i: float) -> bool:  # fmt: skip
    """The checks of :func:`_rotation` on the 9 entries of ``R`` (row-major), as scalars."""
    tol = RIGID_TOLERANCE
    gram = max(
        abs(a * a + d * d + g * g - 1.0),
        abs(b * b + e * e + h * h - 1.0),
        abs(c * c + f * f + i * i - 1.0),
        abs(a * b + d * e + g * h),
        abs(a * c + d * f + g * i),
        abs(b * c + e * f + h * i),
    )
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    return gram <= tol and abs(det - 1.0) <= tol


def _as_se3(value: Any, what: str = "target") -> pin.SE3:
    """A validated rigid transform from a 4×4 array or a ``pin.SE3``."""
    fast = _rigid_fast(value)
    if fast is not None:
        return fast
    if isinstance(value, pin.SE3):
        T = np.array(value.homogeneous, dtype=float)
    else:
        try:
            T = np.array(value, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(
                f"{what} must be a 4×4 homogeneous matrix or a pinocchio.SE3, got {value!r}"
            ) from None
        if T.shape != (4, 4):
            raise ValueError(
                f"{what} must be a 4×4 homogeneous matrix or a pinocchio.SE3, got shape {T.shape}"
            )
    if not np.all(np.isfinite(T)):
        raise ValueError(f"{what} contains NaN or inf: {T.tolist()}")
    last = float(np.abs(T[3] - (0.0, 0.0, 0.0, 1.0)).max())
    if last > RIGID_TOLERANCE:
        raise ValueError(f"{what}: last row must be [0, 0, 0, 1], got {T[3].tolist()}")
    _rotation(T[:3, :3], what)
    return pin.SE3(T[:3, :3].copy(), T[:3, 3].copy())


def _as_rotation(value: Any, what: str = "target") -> np.ndarray:
    """A validated 3×3 rotation from a 3×3 array, a 4×4 transform or a ``pin.SE3``."""
    if type(value) is np.ndarray and value.shape == (3, 3) and value.dtype == _F64:
        rows = value.tolist()
        flat = [*rows[0], *rows[1], *rows[2]]
        if isfinite(sum(flat)) and _is_rotation(*flat):
            return value.copy()
    if isinstance(value, pin.SE3) or np.shape(value) == (4, 4):
        return np.array(_as_se3(value, what).rotation, dtype=float)
    try:
        R = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(
            f"{what} must be a 3×3 rotation, a 4×4 rigid transform or a pinocchio.SE3, "
            f"got {value!r}"
        ) from None
    if R.shape != (3, 3):
        raise ValueError(
            f"{what} must be a 3×3 rotation, a 4×4 rigid transform or a pinocchio.SE3, "
            f"got shape {R.shape}"
        )
    if not np.all(np.isfinite(R)):
        raise ValueError(f"{what} contains NaN or inf: {R.tolist()}")
    _rotation(R, what)
    return R


def _parse_mask(mask: Any, axes: tuple[str, ...], what: str = "mask") -> np.ndarray:
    """Boolean selection of ``len(axes)`` rows from a bool array or an axis string."""
    n = len(axes)
    if mask is None:
        return np.ones(n, dtype=bool)
    if isinstance(mask, str):
        # a letter is a translation axis where the task has one, else a rotation axis
        letters = {c: c if c in axes else f"r{c}" for c in "xyz" if c in axes or f"r{c}" in axes}
        chosen: set[str] = set()
        tokens = [t for t in re.split(r"[\s,+]+", mask.strip().lower()) if t]
        for token in tokens:
            if token in axes:
                chosen.add(token)
            elif token in _ALIASES and set(_ALIASES[token]) <= set(axes):
                chosen.update(_ALIASES[token])
            elif token and all(c in letters for c in token):
                chosen.update(letters[c] for c in token)
            else:
                names = [*axes, *(k for k, v in _ALIASES.items() if set(v) <= set(axes))]
                raise ValueError(
                    f"{what}: unknown axis {token!r} in {mask!r}; axes are: {', '.join(names)}"
                )
        sel = np.array([a in chosen for a in axes], dtype=bool)
    else:
        try:
            arr = np.asarray(mask)
        except (TypeError, ValueError):
            arr = None
        if arr is None or arr.shape != (n,) or arr.dtype.kind not in "bi":
            raise ValueError(
                f"{what} must be {n} booleans (rows {', '.join(axes)}) or a string of axis "
                f"names, got {mask!r}"
            )
        if arr.dtype.kind == "i" and not np.isin(arr, (0, 1)).all():
            raise ValueError(f"{what} must hold booleans (or 0/1), got {mask!r}")
        sel = arr.astype(bool)
    if not sel.any():
        raise ValueError(f"{what} selects no row: {mask!r}")
    return sel


def _frame_id(robot: Robot, frame: Any, what: str) -> int:
    if isinstance(frame, bool) or not isinstance(frame, (str, int, np.integer)):
        raise ValueError(f"{what} must be a frame name (str), got {frame!r}")
    return robot.frame_index(frame, what)


def _check_robot(robot: Any) -> Robot:
    if not isinstance(robot, Robot):
        raise ValueError(f"robot must be a qpcoord.Robot, got {type(robot).__name__}")
    return robot


def _jacobian(robot: Robot, fid: int, ref: Any) -> np.ndarray:
    """Frame Jacobian (6, nv) from the cached kinematics, in the robot's coordinates."""
    J = pin.getFrameJacobian(robot.model, robot.data, fid, ref)
    return robot._mapped(np.asarray(J).reshape(6, robot.nv))


# ---------------------------------------------------------------------------------------
# equality tasks: J v = −K e (+ feed-forward)
# ---------------------------------------------------------------------------------------


class _ErrorTask(KinematicTask):
    """Shared machinery: ``_evaluate(q) -> (e, J, ff)`` over all rows, a row selection."""

    task: Equality

    robot: Robot
    gain: float
    _sel: np.ndarray  # indices of the kept rows

    def _init_equality(self, robot: Robot, rows: int, sel: np.ndarray, weights, name: str):
        self._sel = np.flatnonzero(sel)
        self._all = self._sel.size == rows
        w = np.broadcast_to(np.asarray(weights, dtype=float), (rows,))[self._sel]
        self.task = Equality(
            np.zeros((self._sel.size, robot.nv)), np.zeros(self._sel.size), w, name
        )

    @property
    def selected_rows(self) -> np.ndarray:
        """The indices of the full error's rows this task keeps (its ``mask``), in order."""
        return self._sel

    @abstractmethod
    def _evaluate(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``(e, J, ff)`` over all rows for a validated ``q``: the error (task units), its
        Jacobian against ``v`` and the target's feed-forward velocity (or ``None``)."""

    def compute_error(self, q: Any) -> np.ndarray:
        """Task error ``e(q)`` of the kept rows (m for translation, rad for rotation)."""
        e = self._evaluate(self.robot.check_configuration(q))[0]
        return e.copy() if self._all else e[self._sel]

    def compute_jacobian(self, q: Any) -> np.ndarray:
        """``∂e/∂q`` against the velocity ``v``, shape (rows, nv): ``ė = J v``."""
        J = self._evaluate(self.robot.check_configuration(q))[1]
        return J.copy() if self._all else J[self._sel]

    def _no_target(self) -> ValueError:
        return ValueError(
            f"{self.task.label}: no target; call set_target(...) or "
            "set_target_from_configuration(q)"
        )

    def _refresh(self, q: np.ndarray, t: float, dt: float, reference: Any) -> Equality:
        e, J, ff = self._evaluate(q)
        if self.lm_rows is not None:
            self._lm_e = e.copy() if self._all else e[self._sel]
        b = -self.gain * e
        if ff is not None:
            b += ff
        if self._all:
            return self.task._assign(J, b)
        return self.task._assign(J[self._sel], b[self._sel])


class FrameTask(_ErrorTask):
    """Pose of a frame on SE(3): ``J v = −K log₆(T*⁻¹ T) + feed-forward``.

    The error ``e = log₆(T*⁻¹ T)`` (linear part in m, angular part in rad) is expressed in
    the frame; ``J = Jlog₆(T*⁻¹ T) · J_local`` (see the module's *Conventions*).

    Parameters
    ----------
    robot : Robot
    frame : str
        Name of the controlled frame (any frame of the model).
    target : array_like (4, 4) or pinocchio.SE3, optional
        Desired pose of the frame in the world (rotation, metres). ``None``: set it later
        with :meth:`set_target` or :meth:`set_target_from_configuration` (an update without
        a target raises ``ValueError``).
    gain : float
        ``K`` (1/s), default 1; ``K dt = 1`` removes the error in one step to first order.
    position_weight, orientation_weight : float
        Weights of the three translation rows (1/m²) and the three rotation rows (1/rad²)
        inside the level (the squared residual is multiplied by them). ``0`` drops those
        rows (a position-only or orientation-only task); not both.
    mask : str or array_like of 6 bool, optional
        Rows kept, among ``x y z rx ry rz`` (see the module's *Masks*); default all.
    error : {"se3", "split"}
        ``"se3"`` (default): ``e = log₆(T*⁻¹ T)``, in the frame's axes. ``"split"``:
        ``e = (R*ᵀ (p − p*), log₃(R*ᵀ R))``, the position error in the **target's** axes
        (m) and the orientation error in the frame's (rad), with
        ``J = (R*ᵀ R J_local,lin ; Jlog₃ J_local,ang)``. Both are zero exactly at the
        target. Use ``"split"`` with a mask that keeps translation rows but not every
        rotation row: a translation row of ``log₆`` is the displacement along that axis
        only once the rotation error is zero (its linear part is ``V(θ)⁻¹ R*ᵀ (p − p*)``),
        so ``mask="z"`` under ``"se3"`` does not hold the frame's height while it turns.
    name : str, optional
        Default ``"frame <frame>"``.
    lm_damping : float
        Levenberg–Marquardt damping (dimensionless, default 0): the level also minimises
        ``lm_damping · Σ wᵢ eᵢ² · ‖v‖²`` (see :class:`~qpcoord.KinematicTask`).

    Raises
    ------
    ValueError
        Unknown frame (close names listed), a target that is not a rigid transform or not
        finite, a negative or non-finite gain or weight, a mask selecting no row, an
        unknown ``error``.
    """

    def __init__(
        self,
        robot: Robot,
        frame: str,
        target: Any = None,
        gain: float = 1.0,
        position_weight: float = 1.0,
        orientation_weight: float = 1.0,
        mask: Any = None,
        name: str | None = None,
        error: str = "se3",
        lm_damping: float = 0.0,
    ) -> None:
        self.robot = _check_robot(robot)
        self.frame = frame
        self.frame_id = _frame_id(robot, frame, "frame")
        if error not in ("se3", "split"):
            raise ValueError(f"error must be 'se3' or 'split', got {error!r}")
        self.error = error
        self.gain = _gain(gain)
        self.position_weight = _number(position_weight, "position_weight", "1/m²")
        self.orientation_weight = _number(orientation_weight, "orientation_weight", "1/rad²")
        sel = _parse_mask(mask, _POSE_AXES)
        weights = np.repeat([self.position_weight, self.orientation_weight], 3)
        sel &= weights > 0
        if not sel.any():
            raise ValueError(
                "position_weight and orientation_weight are 0 on every row the mask keeps: "
                "the task would have no row"
            )
        self.mask = sel.copy()
        self._init_equality(robot, 6, sel, weights, name or f"frame {frame}")
        self._init_lm(lm_damping)
        #: the validated target pose as a 4×4 (rotation, m), written in place by set_target;
        #: ``_target_T`` is this array once a target is set (the native IK step copies it)
        self._pose = np.eye(4)
        self._target_T: np.ndarray | None = None
        self._target_se3: pin.SE3 | None = None  # ``target``, built on first read
        self._target_inv_se3: pin.SE3 | None = None  # ``_target_inv``, built on first read
        self.target_velocity: np.ndarray | None = None
        if target is not None:
            self.set_target(target)

    @property
    def target(self) -> pin.SE3 | None:
        """The desired pose (``pin.SE3``, world, m), ``None`` before a target is set.

        A new object after each :meth:`set_target` (built on its first read from the stored
        4×4: a control loop that never reads it does not pay for it); assigning it is
        :meth:`set_target` with the current ``target_velocity`` (``None`` removes the
        target)."""
        if self._target_se3 is None and self._target_T is not None:
            self._target_se3 = pin.SE3(self._target_T)
        return self._target_se3

    @target.setter
    def target(self, value: Any) -> None:
        if value is None:
            self._target_T = self._target_se3 = self._target_inv_se3 = None
        else:
            self.set_target(value, self.target_velocity)

    @property
    def _target_inv(self) -> pin.SE3 | None:
        """``target.inverse()`` (``None`` without a target), built on first read."""
        if self._target_inv_se3 is None and self._target_T is not None:
            target = self.target
            assert target is not None  # built from _target_T
            self._target_inv_se3 = target.inverse()
        return self._target_inv_se3

    def set_target(self, target: Any, velocity: Any = None) -> None:
        """Set the desired pose (4×4 array or ``pin.SE3``; rotation, m).

        Parameters
        ----------
        target : array_like (4, 4) or pinocchio.SE3
            Pose of the frame in the world.
        velocity : array_like (6,), optional
            Feed-forward twist of a moving target, expressed in the target frame (m/s then
            rad/s): the rows become ``J v = −K e + Jlog₆(E) Ad(E⁻¹) ν*``. Default zero.

        Raises
        ------
        ValueError
            Not a rigid transform (wrong shape, rotation not orthonormal within
            :data:`RIGID_TOLERANCE`, det ≠ 1, last row not ``[0, 0, 0, 1]``), NaN/inf.
        """
        nu = None if velocity is None else _vector(velocity, 6, "velocity", "m/s, rad/s")
        copy = _native_rigid_copy()
        if (
            copy is not None
            and type(target) is np.ndarray
            and copy(target, RIGID_TOLERANCE, self._pose)
        ):  # a float64 4×4 checked and copied in one native call: no pin.SE3 built here
            se3 = None
        else:
            se3 = _as_se3(target, "target")  # the full checks and messages
            self._pose[...] = se3.homogeneous
        # written to the instance dict, the bound native steps told once (not four
        # KinematicTask.__setattr__ calls: set_target runs every control step)
        d = self.__dict__
        d["_target_se3"] = se3
        d["_target_T"] = self._pose
        d["_target_inv_se3"] = None
        d["target_velocity"] = nu if nu is None else read_only(nu)
        for slot in self._bound:  # the native IK steps holding a copy: the new target
            slot.set_target(self._pose, nu)

    def set_target_from_configuration(self, q: Any) -> None:
        """Set the target to the frame's pose at configuration ``q`` (hold it there)."""
        q = self.robot.check_configuration(q)
        self.robot._update(q, 1)
        T = pin.updateFramePlacement(self.robot.model, self.robot.data, self.frame_id)
        self.set_target(T.copy())

    def _evaluate(self, q):
        if self._target_inv is None:
            raise self._no_target()
        robot = self.robot
        robot._update(q, 1)
        oMf = pin.updateFramePlacement(robot.model, robot.data, self.frame_id)
        E = self._target_inv * oMf
        if self.error == "split":
            return self._split(E, _jacobian(robot, self.frame_id, pin.LOCAL))
        Jlog = pin.Jlog6(E)
        J = Jlog @ _jacobian(robot, self.frame_id, pin.LOCAL)
        ff = None
        if self.target_velocity is not None:
            ff = Jlog @ (E.inverse().action @ self.target_velocity)
        return np.asarray(pin.log6(E).vector), J, ff

    def _split(self, E: pin.SE3, J_local: np.ndarray):
        """``error="split"``: ``E = T*⁻¹ T`` gives ``R*ᵀ(p − p*) = E.translation`` and
        ``R*ᵀ R = E.rotation``; the frame's linear velocity in the target's axes is
        ``E.rotation · J_local,lin v``."""
        R = E.rotation
        Jlog = pin.Jlog3(R)
        e = np.concatenate([E.translation, pin.log3(R)])
        J = np.vstack([R @ J_local[:3], Jlog @ J_local[3:]])
        ff = None
        if self.target_velocity is not None:
            # the target moving by its body twist ν* = (u, w): d(R*ᵀ(p − p*))/dt =
            # −[w]× R*ᵀ(p − p*) − u, and dlog₃(R*ᵀR)/dt = −Jlog₃ Rᵀ w
            u, w = self.target_velocity[:3], self.target_velocity[3:]
            ff = np.concatenate([np.cross(w, E.translation) + u, Jlog @ (R.T @ w)])
        return e, J, ff


class FramePositionTask(_ErrorTask):
    """Position of a frame's origin: ``J v = −K (p − p*) + ṗ*``, world axes (m).

    Parameters
    ----------
    robot : Robot
    frame : str
        Name of the frame.
    target : array_like (3,), optional
        Desired origin in the world (m); ``None``: set it later.
    gain : float
        ``K`` (1/s), default 1.
    weight : float
        Row weight inside the level (1/m²), default 1.
    mask : str or array_like of 3 bool, optional
        World axes kept (``"z"``, ``"xy"``, …); default all.
    name : str, optional
        Default ``"position <frame>"``.
    lm_damping : float
        Levenberg–Marquardt damping (dimensionless, default 0): the level also minimises
        ``lm_damping · Σ wᵢ eᵢ² · ‖v‖²`` (see :class:`~qpcoord.KinematicTask`).

    Raises
    ------
    ValueError
        Unknown frame, a target that is not 3 finite numbers, bad gain, weight or mask.
    """

    def __init__(
        self,
        robot: Robot,
        frame: str,
        target: Any = None,
        gain: float = 1.0,
        mask: Any = None,
        weight: float = 1.0,
        name: str | None = None,
        lm_damping: float = 0.0,
    ) -> None:
        self.robot = _check_robot(robot)
        self.frame = frame
        self.frame_id = _frame_id(robot, frame, "frame")
        self.gain = _gain(gain)
        w = _number(weight, "weight", "1/m²", positive=True)
        self.mask = _parse_mask(mask, _POSITION_AXES)
        self._init_equality(robot, 3, self.mask, w, name or f"position {frame}")
        self._init_lm(lm_damping)
        self.target: np.ndarray | None = None
        self.target_velocity: np.ndarray | None = None
        if target is not None:
            self.set_target(target)

    def set_target(self, target: Any, velocity: Any = None) -> None:
        """Set the desired origin ``p*`` (m, world) and optionally its velocity (m/s)."""
        y = _vector(target, 3, "target", "m")
        v = None if velocity is None else _vector(velocity, 3, "velocity", "m/s")
        d = self.__dict__  # the bound native steps told once, below
        d["target"], d["target_velocity"] = read_only(y), v if v is None else read_only(v)
        for slot in self._bound:  # the native IK steps holding a copy: the new target
            slot.set_target(y, v)

    def set_target_from_configuration(self, q: Any) -> None:
        """Set the target to the frame's origin at configuration ``q``."""
        self.set_target(self.robot.frame_pose(q, self.frame_id)[:3, 3])

    def _evaluate(self, q):
        if self.target is None:
            raise self._no_target()
        robot = self.robot
        robot._update(q, 1)
        oMf = pin.updateFramePlacement(robot.model, robot.data, self.frame_id)
        J = _jacobian(robot, self.frame_id, pin.LOCAL_WORLD_ALIGNED)[:3]
        return oMf.translation - self.target, J, self.target_velocity


class OrientationTask(_ErrorTask):
    """Orientation of a frame on SO(3): ``J v = −K log₃(R*ᵀ R) + feed-forward`` (rad).

    ``e = log₃(R*ᵀ R)`` is expressed in the frame, ``J = Jlog₃(R*ᵀ R) · J_local[3:]``.

    Parameters
    ----------
    robot : Robot
    frame : str
        Name of the frame.
    target : array_like (3, 3), array_like (4, 4) or pinocchio.SE3, optional
        Desired orientation (a rotation matrix, or the rotation of a rigid transform);
        ``None``: set it later.
    gain : float
        ``K`` (1/s), default 1.
    mask : str or array_like of 3 bool, optional
        Rotation axes kept, in the frame's axes (``"yaw"``, ``"rz"``, ``"roll pitch"``, or
        ``"z"``, ``"xy"``); default all.
    weight : float
        Row weight inside the level (1/rad²), default 1.
    name : str, optional
        Default ``"orientation <frame>"``.
    lm_damping : float
        Levenberg–Marquardt damping (dimensionless, default 0): the level also minimises
        ``lm_damping · Σ wᵢ eᵢ² · ‖v‖²`` (see :class:`~qpcoord.KinematicTask`).

    Raises
    ------
    ValueError
        Unknown frame, a target that is not a rotation (not orthonormal within
        :data:`RIGID_TOLERANCE`, det ≠ 1) or not finite, bad gain, weight or mask.
    """

    def __init__(
        self,
        robot: Robot,
        frame: str,
        target: Any = None,
        gain: float = 1.0,
        mask: Any = None,
        weight: float = 1.0,
        name: str | None = None,
        lm_damping: float = 0.0,
    ) -> None:
        self.robot = _check_robot(robot)
        self.frame = frame
        self.frame_id = _frame_id(robot, frame, "frame")
        self.gain = _gain(gain)
        w = _number(weight, "weight", "1/rad²", positive=True)
        self.mask = _parse_mask(mask, _ROTATION_AXES)
        self._init_equality(robot, 3, self.mask, w, name or f"orientation {frame}")
        self._init_lm(lm_damping)
        self.target: np.ndarray | None = None
        self._target_t: np.ndarray | None = None
        self.target_velocity: np.ndarray | None = None
        if target is not None:
            self.set_target(target)

    def set_target(self, target: Any, velocity: Any = None) -> None:
        """Set the desired rotation; ``velocity``: the target's angular velocity in the
        target frame (rad/s), a feed-forward ``Jlog₃(E) Eᵀ ω*``."""
        R = _as_rotation(target, "target")
        w = None if velocity is None else _vector(velocity, 3, "velocity", "rad/s")
        d = self.__dict__  # the bound native steps told once, below
        d["target"], d["_target_t"] = read_only(R), read_only(R.T.copy())
        d["target_velocity"] = w if w is None else read_only(w)
        for slot in self._bound:  # the native IK steps holding a copy: the new target
            slot.set_target(R, w)

    def set_target_from_configuration(self, q: Any) -> None:
        """Set the target to the frame's orientation at configuration ``q``."""
        self.set_target(self.robot.frame_pose(q, self.frame_id)[:3, :3])

    def _evaluate(self, q):
        if self._target_t is None:
            raise self._no_target()
        robot = self.robot
        robot._update(q, 1)
        oMf = pin.updateFramePlacement(robot.model, robot.data, self.frame_id)
        E = self._target_t @ oMf.rotation
        Jlog = pin.Jlog3(E)
        J = Jlog @ _jacobian(robot, self.frame_id, pin.LOCAL)[3:]
        ff = None if self.target_velocity is None else Jlog @ (E.T @ self.target_velocity)
        return np.asarray(pin.log3(E)), J, ff


class RelativeFrameTask(_ErrorTask):
    """Pose of ``frame`` in ``reference_frame`` on SE(3) (e.g. one hand relative to the other).

    With ``T_rel = T_ref⁻¹ T_frame`` and the target ``T*``: ``e = log₆(T*⁻¹ T_rel)``
    expressed in ``frame`` and ``J = Jlog₆(E) (J_frame − Ad(T_frame⁻¹ T_ref) J_ref)`` (both
    ``LOCAL`` Jacobians): the motion of either frame counts.

    Parameters
    ----------
    robot : Robot
    frame, reference_frame : str
        The controlled frame and the frame its pose is measured in.
    target : array_like (4, 4) or pinocchio.SE3, optional
        Desired pose of ``frame`` in ``reference_frame`` (rotation, m); ``None``: set later.
    gain : float
        ``K`` (1/s), default 1.
    position_weight, orientation_weight : float
        As in :class:`FrameTask`.
    mask : str or array_like of 6 bool, optional
        Rows kept among ``x y z rx ry rz`` (axes of ``frame``).
    name : str, optional
    lm_damping : float
        Levenberg–Marquardt damping (dimensionless, default 0): the level also minimises
        ``lm_damping · Σ wᵢ eᵢ² · ‖v‖²`` (see :class:`~qpcoord.KinematicTask`).

    Raises
    ------
    ValueError
        Unknown frame (naming ``frame`` or ``reference_frame``), the two frames equal, a
        bad target, gain, weight or mask.
    """

    def __init__(
        self,
        robot: Robot,
        frame: str,
        reference_frame: str,
        target: Any = None,
        gain: float = 1.0,
        position_weight: float = 1.0,
        orientation_weight: float = 1.0,
        mask: Any = None,
        name: str | None = None,
        lm_damping: float = 0.0,
    ) -> None:
        self.robot = _check_robot(robot)
        self.frame, self.reference_frame = frame, reference_frame
        self.frame_id = _frame_id(robot, frame, "frame")
        self.reference_id = _frame_id(robot, reference_frame, "reference_frame")
        if self.frame_id == self.reference_id:
            raise ValueError(f"reference_frame must differ from frame ({frame!r})")
        self.gain = _gain(gain)
        self.position_weight = _number(position_weight, "position_weight", "1/m²")
        self.orientation_weight = _number(orientation_weight, "orientation_weight", "1/rad²")
        sel = _parse_mask(mask, _POSE_AXES)
        weights = np.repeat([self.position_weight, self.orientation_weight], 3)
        sel &= weights > 0
        if not sel.any():
            raise ValueError(
                "position_weight and orientation_weight are 0 on every row the mask keeps: "
                "the task would have no row"
            )
        self.mask = sel.copy()
        self._init_equality(robot, 6, sel, weights, name or f"{frame} in {reference_frame}")
        self._init_lm(lm_damping)
        self.target: pin.SE3 | None = None
        self._target_inv: pin.SE3 | None = None
        if target is not None:
            self.set_target(target)

    def set_target(self, target: Any) -> None:
        """Set the desired pose of ``frame`` in ``reference_frame`` (4×4 or ``pin.SE3``)."""
        T = _as_se3(target, "target")
        self.target, self._target_inv = T, T.inverse()

    def set_target_from_configuration(self, q: Any) -> None:
        """Set the target to the relative pose at configuration ``q``."""
        q = self.robot.check_configuration(q)
        self.set_target(self._relative(q).copy())

    def _relative(self, q: np.ndarray) -> pin.SE3:
        robot = self.robot
        robot._update(q, 1)
        oMf = pin.updateFramePlacement(robot.model, robot.data, self.frame_id)
        oMr = pin.updateFramePlacement(robot.model, robot.data, self.reference_id)
        return oMr.actInv(oMf)

    def _evaluate(self, q):
        if self._target_inv is None:
            raise self._no_target()
        robot = self.robot
        rMf = self._relative(q)
        E = self._target_inv * rMf
        Jf = _jacobian(robot, self.frame_id, pin.LOCAL)
        Jr = _jacobian(robot, self.reference_id, pin.LOCAL)
        J = pin.Jlog6(E) @ (Jf - rMf.inverse().action @ Jr)
        return np.asarray(pin.log6(E).vector), J, None


class ComTask(_ErrorTask):
    """Centre of mass: ``J_com v = −K (c − c*) + ċ*`` (world axes, m).

    Parameters
    ----------
    robot : Robot
        A robot with mass.
    target : array_like (3,), optional
        Desired CoM in the world (m); ``None``: set it later.
    gain : float
        ``K`` (1/s), default 1.
    mask : str or array_like of 3 bool, optional
        World axes kept (e.g. ``"xy"``: only the ground projection); default all.
    weight : float
        Row weight inside the level (1/m²), default 1.
    name : str
    lm_damping : float
        Levenberg–Marquardt damping (dimensionless, default 0): the level also minimises
        ``lm_damping · Σ wᵢ eᵢ² · ‖v‖²`` (see :class:`~qpcoord.KinematicTask`).

    Raises
    ------
    ValueError
        A massless robot, a target that is not 3 finite numbers, bad gain, weight or mask.
    """

    def __init__(
        self,
        robot: Robot,
        target: Any = None,
        gain: float = 1.0,
        mask: Any = None,
        weight: float = 1.0,
        name: str = "com",
        lm_damping: float = 0.0,
    ) -> None:
        self.robot = _check_robot(robot)
        if robot.mass <= 0:
            raise ValueError(f"robot {robot.name!r} has no mass: its CoM is undefined")
        self.gain = _gain(gain)
        w = _number(weight, "weight", "1/m²", positive=True)
        self.mask = _parse_mask(mask, _POSITION_AXES)
        self._init_equality(robot, 3, self.mask, w, name)
        self._init_lm(lm_damping)
        self.target: np.ndarray | None = None
        self.target_velocity: np.ndarray | None = None
        if target is not None:
            self.set_target(target)

    def set_target(self, target: Any, velocity: Any = None) -> None:
        """Set the desired CoM ``c*`` (m, world) and optionally its velocity (m/s)."""
        y = _vector(target, 3, "target", "m")
        v = None if velocity is None else _vector(velocity, 3, "velocity", "m/s")
        d = self.__dict__  # the bound native steps told once, below
        d["target"], d["target_velocity"] = read_only(y), v if v is None else read_only(v)
        for slot in self._bound:  # the native IK steps holding a copy: the new target
            slot.set_target(y, v)

    def set_target_from_configuration(self, q: Any) -> None:
        """Set the target to the CoM at configuration ``q``."""
        self.set_target(self.robot.com(q))

    def _evaluate(self, q):
        if self.target is None:
            raise self._no_target()
        robot = self.robot
        robot._com_update(q)
        J = robot._mapped(np.asarray(robot.data.Jcom).reshape(3, robot.nv))
        return robot.data.com[0] - self.target, J, self.target_velocity


# ---------------------------------------------------------------------------------------
# bands (inequalities): K (lower − e) ≤ J v ≤ K (upper − e)
# ---------------------------------------------------------------------------------------


class _BandTask(KinematicTask):
    robot: Robot
    gain: float

    @abstractmethod
    def _evaluate(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(y, J)`` for a validated ``q``: the banded quantity (task units) and its
        Jacobian against ``v``."""

    task: Inequality

    def compute_error(self, q: Any) -> np.ndarray:
        """The measured quantity ``e(q)`` of every row (m)."""
        return self._evaluate(self.robot.check_configuration(q))[0].copy()

    def compute_jacobian(self, q: Any) -> np.ndarray:
        """``∂e/∂q`` against the velocity ``v``, shape (rows, nv)."""
        return self._evaluate(self.robot.check_configuration(q))[1].copy()


class ComBand(_BandTask):
    """Box on the centre of mass: ``K (lower − c) ≤ J_com v ≤ K (upper − c)`` (an inequality).

    Inside the box the rows do not bind; with ``K dt ≤ 1`` one Euler step lands at most on
    a face (to first order); a CoM outside is pushed back at rate ``K``.

    Parameters
    ----------
    robot : Robot
        A robot with mass.
    lower, upper : float or array_like (3,)
        Faces of the box in the world (m); ``-inf`` / ``inf`` for a free side; scalars
        broadcast.
    gain : float
        ``K`` (1/s), default 10.
    weight : float
        Weight of the squared violation at a soft level (1/m²), default 1.
    name : str
    lm_damping : float
        Levenberg–Marquardt damping (dimensionless, default 0): the level also minimises
        ``lm_damping · Σ wᵢ eᵢ² · ‖v‖²`` (see :class:`~qpcoord.KinematicTask`).

    Raises
    ------
    ValueError
        Faces not 3 numbers, NaN, ``+inf`` in ``lower`` or ``-inf`` in ``upper``,
        ``lower > upper``, a bad gain or weight, a massless robot.
    """

    def __init__(
        self,
        robot: Robot,
        lower: Any = -np.inf,
        upper: Any = np.inf,
        gain: float = 10.0,
        weight: float = 1.0,
        name: str = "com band",
        lm_damping: float = 0.0,
    ) -> None:
        self.robot = _check_robot(robot)
        if robot.mass <= 0:
            raise ValueError(f"robot {robot.name!r} has no mass: its CoM is undefined")
        self.gain = _gain(gain)
        w = _number(weight, "weight", "1/m²", positive=True)
        self.set_box(lower, upper)
        self.task = Inequality(np.zeros((3, robot.nv)), -np.inf, np.inf, w, name)
        self._init_lm(lm_damping)

    def set_box(self, lower: Any = -np.inf, upper: Any = np.inf) -> None:
        """Replace the box faces (m, world; ±inf allowed)."""
        faces = []
        for what, value, bad in (("lower", lower, np.inf), ("upper", upper, -np.inf)):
            try:
                arr = np.broadcast_to(np.asarray(value, dtype=float), (3,)).copy()
            except (TypeError, ValueError):
                arr = None
            if arr is None or np.isnan(arr).any() or (arr == bad).any():
                raise ValueError(
                    f"{what} must be 3 numbers (m; -inf allowed in lower, inf in upper), "
                    f"got {value!r}"
                )
            faces.append(arr)
        lo, hi = faces
        if np.any(lo > hi):
            i = int(np.flatnonzero(lo > hi)[0])
            raise ValueError(f"lower > upper on axis {'xyz'[i]}: {lo[i]} > {hi[i]} (m)")
        self.lower, self.upper = lo, hi

    def _evaluate(self, q):
        robot = self.robot
        robot._com_update(q)
        J = robot._mapped(np.asarray(robot.data.Jcom).reshape(3, robot.nv))
        return robot.data.com[0], J

    def _refresh(self, q, t, dt, reference) -> Inequality:
        c, J = self._evaluate(q)
        k = self.gain
        # c is finite: ±inf − c stays ±inf (no NaN)
        return self.task._assign(k * (self.lower - c), k * (self.upper - c), C=J)


def _hull(points: np.ndarray) -> list[int]:
    """Counter-clockwise convex hull of 2-D points (Andrew's monotone chain), indices.

    Collinear points on an edge are dropped; fewer than 3 indices means a degenerate hull.
    """
    pts = points.tolist()
    order = sorted(range(len(pts)), key=lambda i: (pts[i][0], pts[i][1]))

    def chain(indices) -> list[int]:
        out: list[int] = []
        for i in indices:
            px, py = pts[i]
            while len(out) >= 2:
                (ox, oy), (ax, ay) = pts[out[-2]], pts[out[-1]]
                if (ax - ox) * (py - oy) - (ay - oy) * (px - ox) > 0:
                    break
                out.pop()
            out.append(i)
        return out

    return chain(order)[:-1] + chain(reversed(order))[:-1]


class SupportPolygon(_BandTask):
    """CoM ground projection inside the contacts' convex hull shrunk by ``margin``.

    The contact points are the origins of ``contact_frames`` (or the points
    ``contact_points`` attached to each of them, e.g. the corners of a sole); their
    projections on the world ``(x, y)`` plane (gravity along ``−z``) span a convex polygon,
    recomputed at every update. For each hull edge ``i`` (outward unit normal ``nᵢ``, a
    vertex ``aᵢ``) the measured quantity is the signed distance
    ``eᵢ = nᵢᵀ (c_xy − aᵢ)`` (m, negative inside) and the row is

    ``Jᵢ v ≤ K (−margin − eᵢ)``, i.e. ``nᵢᵀ c_xy ≤ dᵢ − margin`` with ``dᵢ = nᵢᵀ aᵢ``.

    ``Jᵢ = ∂eᵢ/∂q`` is exact: it includes the motion of the contacts (the edge's vertices and
    normal); when the contacts are held by a higher level it reduces to ``nᵢᵀ J_com,xy``.
    The task has one row per contact point (the most edges a hull can have); rows of
    absent edges are ``0 ≤ 0 · v ≤ 0`` placeholders with infinite bounds.

    Parameters
    ----------
    robot : Robot
        A robot with mass.
    contact_frames : sequence of str
        Frames in contact with the ground.
    margin : float
        Distance (m) the CoM projection keeps from every edge, default 0.
    gain : float
        ``K`` (1/s), default 10.
    contact_points : array_like (k, 3), optional
        Points (m) in each contact frame's coordinates, the same for every frame (e.g. the
        four corners of a sole ``[(±L/2, ±W/2, 0)]``); default the frame origin.
    weight : float
        Weight of the squared violation at a soft level (1/m²), default 1.
    name : str
    lm_damping : float
        Levenberg–Marquardt damping (dimensionless, default 0): the level also minimises
        ``lm_damping · Σ wᵢ eᵢ² · ‖v‖²`` (see :class:`~qpcoord.KinematicTask`).

    Raises
    ------
    ValueError
        An unknown frame (close names listed), fewer than 3 contact points, a negative or
        non-finite margin or gain, bad contact points; at an update, contact points whose
        ground projections are collinear (no polygon).
    """

    def __init__(
        self,
        robot: Robot,
        contact_frames: Sequence[str],
        margin: float = 0.0,
        gain: float = 10.0,
        contact_points: Any = None,
        weight: float = 1.0,
        name: str = "support polygon",
        lm_damping: float = 0.0,
    ) -> None:
        self.robot = _check_robot(robot)
        if robot.mass <= 0:
            raise ValueError(f"robot {robot.name!r} has no mass: its CoM is undefined")
        if isinstance(contact_frames, str) or not isinstance(contact_frames, Sequence):
            raise ValueError(
                f"contact_frames must be a list of frame names, got {contact_frames!r}"
            )
        self.contact_frames = list(contact_frames)
        self.frame_ids = [
            _frame_id(robot, f, f"contact_frames[{i}]") for i, f in enumerate(contact_frames)
        ]
        if len(set(self.frame_ids)) != len(self.frame_ids):
            raise ValueError(f"contact_frames has a repeated frame: {self.contact_frames}")
        self.margin = _number(margin, "margin", "m")
        self.gain = _gain(gain)
        w = _number(weight, "weight", "1/m²", positive=True)
        pts: np.ndarray
        if contact_points is None:
            pts = np.zeros((1, 3))
        else:
            bad_points = ValueError(
                f"contact_points must be a (k, 3) array of points (m), got {contact_points!r}"
            )
            try:
                pts = np.array(contact_points, dtype=float)
            except (TypeError, ValueError):
                raise bad_points from None
            if pts.ndim == 1 and pts.size == 3:
                pts = pts.reshape(1, 3)
            if pts.ndim != 2 or pts.shape[1] != 3 or not len(pts):
                raise bad_points
            if not np.all(np.isfinite(pts)):
                raise ValueError(f"contact_points must be finite (m), got {pts.tolist()}")
        self.contact_points = pts
        self.rows = len(self.frame_ids) * len(pts)
        if self.rows < 3:
            raise ValueError(
                f"contact_frames: {self.rows} contact point(s) span no polygon; give at least 3 "
                "(more frames, or contact_points=... e.g. the corners of each sole)"
            )
        self.task = Inequality(np.zeros((self.rows, robot.nv)), -np.inf, np.inf, w, name)
        self._init_lm(lm_damping)
        self._e = np.zeros(self.rows)
        self._J = np.zeros((self.rows, robot.nv))
        self._lower = np.full(self.rows, -np.inf)
        self._upper = np.full(self.rows, np.inf)
        #: number of hull edges at the last evaluation (the rows ``[:edges]`` are live)
        self.edges = 0

    def contact_positions(self, q: Any) -> np.ndarray:
        """World positions (m) of every contact point, shape (rows, 3)."""
        q = self.robot.check_configuration(q)
        return self._contacts(q, jacobians=False)[0].copy()

    def _contacts(self, q: np.ndarray, jacobians: bool = True):
        robot = self.robot
        robot._update(q, 1)
        P = np.empty((self.rows, 3))
        Js = np.empty((self.rows, 2, robot.nv)) if jacobians else None
        k = len(self.contact_points)
        for f, fid in enumerate(self.frame_ids):
            oMf = pin.updateFramePlacement(robot.model, robot.data, fid)
            # world-axes offsets R o (k, 3), summed term by term ((o_x R₀ + o_y R₁) + o_z R₂):
            # a matmul's order of summation depends on the BLAS; this one is reproducible, so
            # the native kernel (src/native/support_kernels.hpp) finds the same hull vertices
            R, o = oMf.rotation, self.contact_points
            offsets = (o[:, 0:1] * R[:, 0] + o[:, 1:2] * R[:, 1]) + o[:, 2:3] * R[:, 2]
            P[f * k : (f + 1) * k] = oMf.translation + offsets
            if Js is not None:  # jacobians
                J = _jacobian(robot, fid, pin.LOCAL_WORLD_ALIGNED)
                Jv, Jw = J[:3], J[3:]
                rx, ry, rz = offsets[:, 0:1], offsets[:, 1:2], offsets[:, 2:3]
                # velocity of the point o + r: v_o + ω × r = J_v v − [r]× J_ω v
                Js[f * k : (f + 1) * k, 0] = Jv[0] - (ry * Jw[2] - rz * Jw[1])
                Js[f * k : (f + 1) * k, 1] = Jv[1] - (rz * Jw[0] - rx * Jw[2])
        return P, Js

    def _evaluate(self, q):
        robot = self.robot
        P, Js = self._contacts(q)
        robot._com_update(q)
        c = robot.data.com[0][:2]
        Jc = robot._mapped(np.asarray(robot.data.Jcom).reshape(3, robot.nv))[:2]
        pts = P[:, :2]
        hull = _hull(pts)
        h = len(hull)
        if h < 3:
            raise ValueError(
                f"{self.task.label}: the ground projections of the contact points of "
                f"{self.contact_frames} are collinear: they span no polygon"
            )
        ia = np.array(hull)
        ib = np.roll(ia, -1)
        A = pts[ia]
        T = pts[ib] - A
        L = np.hypot(T[:, 0], T[:, 1])
        U = T / L[:, None]
        N = np.column_stack([U[:, 1], -U[:, 0]])  # outward normals of a counter-clockwise hull
        D = c - A
        e, J = self._e, self._J
        e[:] = 0.0
        J[h:] = 0.0
        e[:h] = (N * D).sum(axis=1)
        # e = nᵀ(c − a): de = nᵀ(dc − da) + (c − a)ᵀ dn, dn = u uᵀ R dt / L where R t =
        # (t_y, −t_x), so (c − a)ᵀ dn = s (u_x dt_y − u_y dt_x) with s = uᵀ(c − a) / L
        s = ((U * D).sum(axis=1) / L)[:, None]
        Ja, dT = Js[ia], Js[ib] - Js[ia]
        J[:h] = (
            N[:, 0:1] * (Jc[0] - Ja[:, 0])
            + N[:, 1:2] * (Jc[1] - Ja[:, 1])
            + s * (U[:, 0:1] * dT[:, 1] - U[:, 1:2] * dT[:, 0])
        )
        self.edges = h
        return e, J

    def _refresh(self, q, t, dt, reference) -> Inequality:
        e, J = self._evaluate(q)
        h = self.edges
        self._upper[:] = np.inf
        self._upper[:h] = self.gain * (-self.margin - e[:h])
        return self.task._assign(self._lower, self._upper, C=J)


# ---------------------------------------------------------------------------------------
# joint space
# ---------------------------------------------------------------------------------------


class JointCouplingTask(_ErrorTask):
    """Joints moving together: ``e = Σᵢ rᵢ qᵢ − offset``, one row ``Σᵢ rᵢ vᵢ = −K e``.

    ``q_a = r q_b`` (a mimic joint, a differential) is ``joints=["a", "b"]``,
    ``ratios=[1, −r]``; ``q_a + q_b = π/2`` is ``ratios=[1, 1], offset=π/2``.

    Parameters
    ----------
    robot : Robot
    joints : sequence of str
        Names of one-DoF joints (revolute or prismatic; ``nq = nv = 1`` each).
    ratios : sequence of float
        Coefficients ``rᵢ`` (dimensionless for joints of one kind), not all zero.
    gain : float
        ``K`` (1/s), default 1.
    offset : float
        Constant of the relation (rad or m), default 0. :meth:`set_offset_from_configuration`
        takes the value at a configuration (keep the current relation).
    weight : float
        Row weight inside the level, default 1.
    name : str
    lm_damping : float
        Levenberg–Marquardt damping (dimensionless, default 0): the level also minimises
        ``lm_damping · Σ wᵢ eᵢ² · ‖v‖²`` (see :class:`~qpcoord.KinematicTask`).

    Raises
    ------
    ValueError
        An unknown joint (close names listed), a joint with more than one DoF, a repeated
        joint, ratios of the wrong length, non-finite or all zero, a bad gain or offset, a
        robot with a ``coordinate_map``.
    """

    def __init__(
        self,
        robot: Robot,
        joints: Sequence[str],
        ratios: Sequence[float],
        gain: float = 1.0,
        offset: float = 0.0,
        weight: float = 1.0,
        name: str = "joint coupling",
        lm_damping: float = 0.0,
    ) -> None:
        import difflib

        self.robot = _check_robot(robot)
        if robot.coordinate_map is not None:
            raise ValueError(
                f"robot {robot.name!r} has a coordinate_map: joint names do not index its q"
            )
        if isinstance(joints, str) or not isinstance(joints, Sequence) or len(joints) < 1:
            raise ValueError(f"joints must be a list of joint names, got {joints!r}")
        model = robot.model
        names = list(model.names)[1:]
        self.joints = list(joints)
        iq, iv = [], []
        for k, j in enumerate(joints):
            if not isinstance(j, str) or not model.existJointName(j):
                close = difflib.get_close_matches(str(j), names, n=5, cutoff=0.5)
                hint = f"; close names: {', '.join(close)}" if close else ""
                raise ValueError(f"joints[{k}]: robot {robot.name!r} has no joint {j!r}{hint}")
            joint = model.joints[model.getJointId(j)]
            if joint.nq != 1 or joint.nv != 1:
                raise ValueError(
                    f"joints[{k}]: joint {j!r} ({joint.shortname()}) has nq = {joint.nq}, "
                    f"nv = {joint.nv}; a coupling needs one-DoF joints"
                )
            iq.append(joint.idx_q)
            iv.append(joint.idx_v)
        if len(set(iq)) != len(iq):
            raise ValueError(f"joints has a repeated joint: {self.joints}")
        self.ratios = _vector(ratios, len(iq), "ratios", "dimensionless")
        if not np.any(self.ratios):
            raise ValueError(f"ratios must not all be zero, got {self.ratios}")
        self._iq = np.array(iq)
        self.gain = _gain(gain)
        self.offset = offset  # checked by _checked_parameter, as an assignment
        w = _number(weight, "weight", "per (rad or m)²", positive=True)
        self._init_equality(robot, 1, np.ones(1, dtype=bool), w, name)
        self._init_lm(lm_damping)
        J = np.zeros((1, robot.nv))
        J[0, iv] = self.ratios
        self._J = J

    def _checked_parameter(self, name: str, value: Any) -> Any:
        if name == "offset":  # at construction and on assignment alike
            if isinstance(value, bool) or not isinstance(
                value, (int, float, np.integer, np.floating)
            ):
                raise ValueError(f"offset must be a number (rad or m), got {value!r}")
            if not np.isfinite(value):
                raise ValueError(f"offset must be finite (rad or m), got {value!r}")
            return float(value)
        return super()._checked_parameter(name, value)

    def set_offset_from_configuration(self, q: Any) -> None:
        """Set ``offset = Σ rᵢ qᵢ`` at configuration ``q`` (keep the current relation)."""
        q = self.robot.check_configuration(q)
        self.offset = float(self.ratios @ q[self._iq])

    def _evaluate(self, q):
        return np.array([self.ratios @ q[self._iq] - self.offset]), self._J, None


class DampingTask(_ErrorTask):
    """Velocity damping ``v = 0`` on all ``nv`` rows (floating base included).

    A regulariser: at a low level it picks, among the motions the levels above allow, the
    slowest one (weighted by ``weight``). As a configuration task it *holds the
    configuration of the last update*: ``compute_error(q) = difference(q_hold, q)`` (size
    ``nv``; rad, m, base twist) with ``compute_jacobian = ∂ difference / ∂q`` (the identity
    at ``q_hold``), so that the rows ``J v = −K e`` are ``v = 0`` at every update.

    Parameters
    ----------
    robot : Robot
    weight : float or array_like (nv,)
        Row weights inside the level ((s/rad)² or (s/m)²), default 1.
    name : str

    Raises
    ------
    ValueError
        A weight that is not positive and finite, or not 1 or ``nv`` numbers.
    """

    gain = 1.0

    def __init__(self, robot: Robot, weight: Any = 1.0, name: str = "damping") -> None:
        self.robot = _check_robot(robot)
        nv = robot.nv
        try:
            w = np.broadcast_to(np.asarray(weight, dtype=float), (nv,)).copy()
        except (TypeError, ValueError):
            raise ValueError(
                f"weight must be a number or nv = {nv} numbers (> 0), got {weight!r}"
            ) from None
        if not np.all(np.isfinite(w)) or np.any(w <= 0):
            raise ValueError(f"weight must be finite and > 0, got {weight!r}")
        self.weight = w
        self._init_equality(robot, nv, np.ones(nv, dtype=bool), w, name)
        self.task._assign(np.eye(nv), np.zeros(nv))
        self._hold = np.full(robot.nq, np.nan)  # NaN: no update yet

    @property
    def q_hold(self) -> np.ndarray | None:
        """The configuration of the last update (nq,; rad, m), ``None`` before the first: one
        array for the task's life, written in place at each update (by a native IK step
        too); assigning copies into it."""
        return None if np.isnan(self._hold[0]) else self._hold

    @q_hold.setter
    def q_hold(self, value: Any) -> None:
        if value is None:
            self._hold[...] = np.nan
        else:
            self._hold[...] = self.robot.check_configuration(value)

    def _evaluate(self, q):
        robot = self.robot
        if self.q_hold is None:
            return np.zeros(robot.nv), np.eye(robot.nv), None
        if robot.euclidean:
            return q - self.q_hold, np.eye(robot.nv), None
        e = pin.difference(robot.model, self.q_hold, q)
        J = pin.dDifference(robot.model, self.q_hold, q, pin.ArgumentPosition.ARG1)
        return np.asarray(e), np.asarray(J).reshape(robot.nv, robot.nv), None

    def _refresh(self, q, t, dt, reference) -> Equality:
        self._hold[...] = q
        return self.task  # A = I, b = 0: constant


class LowAccelerationTask(DampingTask):
    """Low-acceleration regularisation ``v = v_prev`` on all ``nv`` rows.

    ``v_prev`` is the last step's velocity: the one given to :meth:`set_previous` since the
    last update, otherwise the one measured from the two last updates,
    ``difference(q_last, q) / dt`` (zero at the first update). At a low level it smooths
    the motion (``‖v − v_prev‖² = dt² ‖a‖²``). As a configuration task it is
    :class:`DampingTask`'s hold of the last update's configuration with ``v_prev`` as a
    feed-forward velocity.

    Parameters
    ----------
    robot : Robot
    weight : float or array_like (nv,)
        Row weights inside the level, default 1.
    name : str
    """

    def __init__(self, robot: Robot, weight: Any = 1.0, name: str = "low acceleration") -> None:
        super().__init__(robot, weight, name)
        self._v_prev = np.zeros(robot.nv)
        self._given: np.ndarray | None = None

    @property
    def v_prev(self) -> np.ndarray:
        """The previous step's velocity of the last update (nv,; rad/s, m/s, base twist): one
        array for the task's life, written in place at each update (by a native IK step
        too); assigning copies into it."""
        return self._v_prev

    @v_prev.setter
    def v_prev(self, value: Any) -> None:
        self._v_prev[...] = self.robot._check_velocity(value, "v_prev")

    def set_previous(self, v: Any) -> None:
        """Set ``v_prev`` (size nv; rad/s, m/s, base twist) for the next update."""
        self._given = self.robot._check_velocity(v, "v").copy()
        if self._bound:  # a native IK step takes it for its next step
            self._parameters_written()

    def _refresh(self, q, t, dt, reference) -> Equality:
        if self._given is not None:
            self._v_prev[:] = self._given
            self._given = None
        elif self.q_hold is None:
            self._v_prev[:] = 0.0
        else:
            robot = self.robot
            if robot.euclidean:
                self._v_prev[:] = (q - self.q_hold) / dt
            else:
                self._v_prev[:] = pin.difference(robot.model, self.q_hold, q) / dt
        self._hold[...] = q
        return self.task._assign(b=self._v_prev)
