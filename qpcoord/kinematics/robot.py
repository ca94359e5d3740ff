"""Kinematics of a robot from Pinocchio: :class:`Robot`, a whole Pinocchio model.

A :class:`Robot` wraps a :class:`pinocchio.Model` -- fixed or floating base, any joint type
Pinocchio knows (revolute, prismatic, continuous, spherical, planar, free-flyer) -- and gives

- the configuration manifold: ``nq``, ``nv``, :meth:`~Robot.neutral`,
  :meth:`~Robot.integrate` (quaternions stay unit), :meth:`~Robot.difference`,
  :meth:`~Robot.check_configuration`, the SRDF's :meth:`~Robot.reference_configuration`;
- any frame: :meth:`~Robot.frame_pose` (4×4, m) and :meth:`~Robot.frame_jacobian`
  (6 × nv, world-aligned at the frame, linear rows then angular);
- the centre of mass: :meth:`~Robot.com` (m) and :meth:`~Robot.com_jacobian` (3 × nv);
- the thesis **one-point API** of an optional default frame (§3.4–3.5):

  - ``position(q)`` -- the forward map ``Y = ζ(q)`` (m), world frame, only the task rows;
  - ``jacobian(q)`` -- ``J = ∂ζ/∂q`` (m/rad), world-aligned, task rows × nv;
  - ``hessian(q)`` -- ``H[k, i, j] = ∂²ζ_k/∂q_i∂q_j`` (m/rad²), from Pinocchio's kinematic
    Hessians (not finite differences); models with ``nq == nv`` only.

Velocities
----------
``v`` (size ``nv``) is Pinocchio's tangent vector: for a free-flyer root its first six
entries are the base's linear and angular velocity **in the base frame** (m/s, rad/s), so
``q_next = integrate(q, v, dt)`` and ``difference(q0, q1)`` agree with every Jacobian here
(``frame_pose(integrate(q, v, ε)) ≈ frame_pose(q)`` moved by ``frame_jacobian(q) @ v · ε``).

One forward-kinematics pass per configuration
---------------------------------------------
Every query at the same ``q`` shares one pass of Pinocchio's ``computeJointJacobians``
(placements of all joints and their world Jacobians), cached on the bytes of ``q``: a
control step that asks for five frames and the CoM at one ``q`` pays for one pass, plus
a frame placement (≈ 0.1 µs) or the CoM sweep per query. Evaluating another ``q`` replaces
the cache. The cache lives in the robot's own ``pinocchio.Data``: a robot is not meant to be
shared between threads (``with_frame`` gives another robot with its own data).

Coordinates
-----------
The robot's coordinates ``q`` may differ from Pinocchio's by a constant invertible matrix:
``q_pin = coordinate_map @ q``. The thesis 3R arm uses **absolute** joint angles
(``q_abs = T q_rel`` with ``T`` lower-triangular ones), so its map is ``T⁻¹``; Jacobians and
Hessian are mapped consistently (``J = J_pin M``, ``H_k = Mᵀ H_pin,k M``). A coordinate map
needs a model whose configuration space is a vector space (``nq == nv``).
"""

from __future__ import annotations

import difflib
from collections.abc import Sequence
from math import isfinite
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

__all__ = ["Robot", "UNIT_NORM_TOLERANCE"]

#: Largest ``|‖u‖ − 1|`` accepted for the unit quaternion of a free-flyer or spherical joint
#: and for the ``(cos θ, sin θ)`` pair of a continuous or planar joint (dimensionless).
UNIT_NORM_TOLERANCE = 1e-6

#: Joint types whose configuration holds a unit-norm block: (offset in the joint's q, size,
#: what it is).
_F64 = np.dtype(np.float64)

_UNIT_BLOCKS = {
    "JointModelFreeFlyer": (3, 4, "quaternion"),
    "JointModelSpherical": (0, 4, "quaternion"),
    "JointModelPlanar": (2, 2, "(cos, sin) pair"),
    "JointModelRUBX": (0, 2, "(cos, sin) pair"),
    "JointModelRUBY": (0, 2, "(cos, sin) pair"),
    "JointModelRUBZ": (0, 2, "(cos, sin) pair"),
    "JointModelRevoluteUnboundedUnaligned": (0, 2, "(cos, sin) pair"),
}

#: Root joints accepted by ``floating_base``.
_ROOT_JOINTS = {
    "free_flyer": pin.JointModelFreeFlyer,
    "planar": pin.JointModelPlanar,
}

#: Position limits at least this large (in magnitude) are read as "unlimited" when
#: sampling configurations (Pinocchio stores ±DBL_MAX for unbounded joints).
_HUGE = 1e300


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _root_joint(floating_base: Any) -> pin.JointModel | None:
    """The root joint asked for by ``floating_base`` (None: fixed base)."""
    if floating_base is False or floating_base is None:
        return None
    if floating_base is True:
        return pin.JointModelFreeFlyer()
    if isinstance(floating_base, str) and floating_base in _ROOT_JOINTS:
        return _ROOT_JOINTS[floating_base]()
    if isinstance(floating_base, pin.JointModel) or type(floating_base).__name__.startswith(
        "JointModel"
    ):
        return floating_base
    raise ValueError(
        "floating_base must be False (fixed base), True or 'free_flyer' (6-DoF root), "
        f"'planar' (x, y, yaw root) or a pinocchio joint model, got {floating_base!r}"
    )


def _existing_file(path: Any, what: str, kind: str) -> Path:
    try:
        p = Path(path)
    except TypeError:
        raise ValueError(f"{what} must be a path to a {kind} file, got {path!r}") from None
    if not p.is_file():
        raise ValueError(f"{what}: {kind} file {str(p)!r} does not exist")
    return p


def _package_dirs(package_dirs: Any) -> list[str]:
    if package_dirs is None:
        return []
    if isinstance(package_dirs, (str, PathLike)):
        package_dirs = [package_dirs]
    out = []
    for d in package_dirs:
        if not Path(d).is_dir():
            raise ValueError(f"package_dirs: {str(d)!r} is not a directory")
        out.append(str(d))
    return out


class Robot:
    """A whole Pinocchio model (fixed or floating base) with an optional default frame.

    Parameters
    ----------
    model : pinocchio.Model
        Kinematic model (any joints; ``nq`` may differ from ``nv``). The robot keeps a
        reference to it (not a copy) and creates its own ``pinocchio.Data``. Its
        ``referenceConfigurations`` (filled from an SRDF) become
        :meth:`reference_configuration`.
    frame : str, optional
        Default end-effector frame: the point of the one-point API (:meth:`position`,
        :meth:`jacobian`, :meth:`hessian`, :meth:`kinematics`). ``None`` (the default of the
        constructors) means no default frame: the one-point API then raises a
        ``ValueError``, and every frame query names its frame.
    rows : sequence of int
        Which of the world position coordinates ``(x, y, z)`` form the one-point task
        (default all three; ``(0, 1)`` for a planar arm).
    coordinate_map : array_like, shape (nq, nq), optional
        Constant invertible ``M`` with ``q_pin = M q`` (default identity). Only for models
        with ``nq == nv``.
    lower, upper : array_like, shape (nq,), optional
        Joint position limits in the robot's coordinates (rad or m). Default: the model's
        limits when ``coordinate_map`` is the identity, else unlimited.
    velocity_limit : array_like, shape (nv,), optional
        Joint speed limits (rad/s or m/s). Default: the model's when ``coordinate_map`` is
        the identity (a zero there -- a URDF joint without a velocity limit -- reads as
        unlimited), else unlimited.
    name : str
        Label used in messages.

    Raises
    ------
    ValueError
        Unknown frame (the message lists close names), bad rows, a singular coordinate
        map or one on a model with ``nq ≠ nv``, bad limits, a model without joints.
    """

    #: URDF / SRDF the robot was read from and the folders meshes are searched in (set by
    #: :meth:`from_urdf`; ``None`` / empty otherwise).
    urdf_path: Path | None = None
    srdf_path: Path | None = None
    package_dirs: tuple[str, ...] = ()

    def __init__(
        self,
        model: pin.Model,
        frame: str | None = None,
        rows: Sequence[int] = (0, 1, 2),
        coordinate_map: Any = None,
        lower: Any = None,
        upper: Any = None,
        velocity_limit: Any = None,
        name: str = "",
    ) -> None:
        if not isinstance(model, pin.Model):
            raise ValueError(f"model must be a pinocchio.Model, got {type(model).__name__}")
        self.name = name or model.name or "robot"
        if model.nq == 0:
            raise ValueError(f"robot {self.name!r}: the model has no joints")
        rows = tuple(int(r) for r in rows)
        if not rows or len(set(rows)) != len(rows) or any(r not in (0, 1, 2) for r in rows):
            raise ValueError(f"rows must be distinct entries of (0, 1, 2), got {rows!r}")
        self.model = model
        self.data = model.createData()
        self.nq = int(model.nq)
        self.nv = int(model.nv)
        self.rows = np.array(rows, dtype=int)
        # a leading run of rows is read as a slice (a view, no fancy-index copy)
        self._rows = slice(0, len(rows)) if rows == tuple(range(len(rows))) else self.rows
        self.m = len(rows)
        self._frame_names = [f.name for f in model.frames]
        # name -> index; when a joint and a link share a name (URDF allows it) the link wins
        order = (pin.FrameType.BODY, pin.FrameType.OP_FRAME, pin.FrameType.FIXED_JOINT)
        rank = {t: k for k, t in enumerate(order)}
        self._frame_ids: dict[str, int] = {}
        for i, f in enumerate(model.frames):
            j = self._frame_ids.get(f.name)
            if j is None or rank.get(f.type, 9) < rank.get(model.frames[j].type, 9):
                self._frame_ids[f.name] = i
        if frame is None:
            self.frame: str | None = None
            self.frame_id: int | None = None
            self.joint_id: int | None = None
        else:
            if not isinstance(frame, str):
                raise ValueError(f"frame must be a frame name (str), got {frame!r}")
            self.frame = frame
            self.frame_id = self.frame_index(frame, "frame")
            self.joint_id = int(model.frames[self.frame_id].parentJoint)
        # joints whose configuration is not a vector space (quaternions, (cos, sin) pairs)
        self._unit_blocks: list[tuple[int, int, str, str]] = []
        for j in range(1, model.njoints):
            spec = _UNIT_BLOCKS.get(model.joints[j].shortname())
            if spec is not None:
                start = model.joints[j].idx_q + spec[0]
                self._unit_blocks.append((start, start + spec[1], model.names[j], spec[2]))
        self.euclidean = self.nq == self.nv and not self._unit_blocks
        identity = coordinate_map is None
        if identity:
            self.coordinate_map = None
        else:
            if not self.euclidean:
                raise ValueError(
                    f"robot {self.name!r}: coordinate_map needs a model whose configuration "
                    f"space is a vector space (nq == nv); this one has nq = {self.nq}, "
                    f"nv = {self.nv}"
                )
            M = np.array(coordinate_map, dtype=float)
            if M.shape != (self.nq, self.nq) or not np.all(np.isfinite(M)):
                raise ValueError(
                    f"coordinate_map must be a finite {self.nq}×{self.nq} matrix, "
                    f"got shape {M.shape}"
                )
            if np.linalg.cond(M) > 1e12:
                raise ValueError("coordinate_map is singular")
            self.coordinate_map = M
        inf_q, inf_v = np.full(self.nq, np.inf), np.full(self.nv, np.inf)
        self.lower = self._limit(
            lower, model.lowerPositionLimit if identity else -inf_q, "lower", allow=-1
        )
        self.upper = self._limit(
            upper, model.upperPositionLimit if identity else inf_q, "upper", allow=1
        )
        bad = self.lower > self.upper
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(f"lower > upper at joint {i} ({self.lower[i]} > {self.upper[i]})")
        # a URDF joint without a velocity limit reads as 0 in Pinocchio: no limit
        model_speed = np.where(model.velocityLimit > 0, model.velocityLimit, np.inf)
        self.velocity_limit = self._limit(
            velocity_limit,
            model_speed if identity else inf_v,
            "velocity_limit",
            allow=1,
            size=self.nv,
        )
        if np.any(self.velocity_limit <= 0):
            raise ValueError(f"velocity_limit must be > 0, got {self.velocity_limit}")
        self.mass = float(sum(inertia.mass for inertia in model.inertias))
        self._references = {
            str(entry.key()): self._from_pin(np.array(entry.data(), dtype=float))
            for entry in model.referenceConfigurations
            if np.asarray(entry.data()).shape == (self.nq,)
        }
        self._q = np.full(self.nq, np.nan)  # configuration of the cached kinematics
        self._qkey = b""  # its bytes (cheap equality test)
        self._state = 0  # 0 nothing, 1 placements+jacobians, 2 + hessian
        self._com_ready = False  # CoM and its Jacobian computed at the cached q
        self._layout: str | None = None  # tensor layout of Pinocchio's kinematic Hessian binding

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_model(
        cls, model: pin.Model, frame: str | None = None, name: str = "", **kwargs: Any
    ) -> Robot:
        """A robot of an existing Pinocchio model (kept by reference, not copied).

        Parameters
        ----------
        model : pinocchio.Model
            Any kinematic model; its ``referenceConfigurations`` are kept.
        frame : str, optional
            Default end-effector frame (``None``: none).
        name : str
            Label (default: the model's name).
        **kwargs
            Passed to :class:`Robot` (``rows``, ``coordinate_map``, limits).
        """
        return cls(model, frame, name=name, **kwargs)

    @classmethod
    def from_urdf(
        cls,
        path: str | PathLike,
        frame: str | None = None,
        rows: Sequence[int] = (0, 1, 2),
        locked_joints: Sequence[str] = (),
        name: str = "",
        *,
        package_dirs: str | PathLike | Sequence[str | PathLike] | None = None,
        floating_base: bool | str | pin.JointModel = False,
        srdf: str | PathLike | None = None,
        lock_configuration: str | Any | None = None,
        **kwargs: Any,
    ) -> Robot:
        """Build a robot from a URDF file (kinematics and inertias; meshes are not read).

        A URDF cannot say whether its root link is bolted down or free (a humanoid's and
        an arm's files look the same), so the base is **fixed unless** ``floating_base``
        asks otherwise: nothing is welded or freed silently. :func:`qpcoord.robots.load`
        passes ``floating_base=True`` for legged robots, humanoids and drones.

        Parameters
        ----------
        path : str or Path
            URDF file.
        frame : str, optional
            Default end-effector frame (``None``: none; see :class:`Robot`). It is the second
            positional argument, as before; the other options are keywords.
        rows : sequence of int
            Task rows of the world position (default ``(0, 1, 2)``).
        locked_joints : sequence of str
            Joints to lock (e.g. gripper fingers), removed from ``q``.
        name : str
            Label (default: the file stem).
        package_dirs : str, Path or sequence of them, optional
            Folders where ``package://`` mesh URIs are resolved (kept in
            :attr:`package_dirs` for geometry; the kinematics does not need them).
        floating_base : bool, str or pinocchio.JointModel
            Root joint between the world and the root link: ``False`` (fixed base), ``True``
            or ``"free_flyer"`` (6 DoF, nq 7 / nv 6, a unit quaternion ``(x, y, z, w)``),
            ``"planar"`` (x, y, yaw: nq 4 / nv 3), or any Pinocchio joint model. Pinocchio
            names it ``"root_joint"`` and puts it first in ``q``.
        srdf : str or Path, optional
            SRDF whose ``group_state`` entries become :meth:`reference_configuration`.
        lock_configuration : str or array_like, optional
            Configuration (Pinocchio coordinates of the full model) at which
            ``locked_joints`` are frozen, or the name of an SRDF reference configuration;
            default the neutral configuration.
        **kwargs
            Passed to :class:`Robot` (``coordinate_map``, limits).

        Raises
        ------
        ValueError
            A file does not exist or does not parse, a locked joint is unknown, a bad
            ``floating_base``, ``package_dirs`` or ``lock_configuration``.
        """
        path = _existing_file(path, "path", "URDF")
        if frame is not None and not isinstance(frame, str):
            raise ValueError(
                f"frame (the second argument of from_urdf) must be a frame name, got "
                f"{frame!r}; pass package_dirs=..., floating_base=..., srdf=... by keyword"
            )
        root = _root_joint(floating_base)
        dirs = _package_dirs(package_dirs)
        srdf_path = None if srdf is None else _existing_file(srdf, "srdf", "SRDF")
        try:
            if root is None:
                model = pin.buildModelFromUrdf(str(path))
            else:
                model = pin.buildModelFromUrdf(str(path), root)
        except Exception as exc:  # pinocchio raises ValueError/RuntimeError by version
            raise ValueError(f"URDF file {str(path)!r} failed to parse: {exc}") from None
        if srdf_path is not None:
            cls._load_srdf(model, srdf_path)
        if locked_joints:
            ids = []
            for j in locked_joints:
                if not model.existJointName(j):
                    known = ", ".join(model.names[1:])
                    raise ValueError(f"locked joint {j!r} not in {str(path)!r}; joints: {known}")
                ids.append(model.getJointId(j))
            q_lock = cls._lock_configuration(model, lock_configuration)
            model = pin.buildReducedModel(model, ids, q_lock)
            if srdf_path is not None:  # reference configurations of the reduced model
                cls._load_srdf(model, srdf_path)
        robot = cls(model, frame, rows=rows, name=name or path.stem, **kwargs)
        robot.urdf_path = path
        robot.srdf_path = srdf_path
        robot.package_dirs = tuple(dirs)
        return robot

    @classmethod
    def from_mjcf(
        cls,
        path: str | PathLike,
        frame: str | None = None,
        rows: Sequence[int] = (0, 1, 2),
        name: str = "",
        *,
        floating_base: bool | str | pin.JointModel = False,
        **kwargs: Any,
    ) -> Robot:
        """Build a robot from a MuJoCo MJCF file (``pinocchio.buildModelFromMJCF``).

        A ``<freejoint/>`` in the file becomes a free-flyer joint; ``floating_base`` adds a
        root joint above the file's root body (same values as in :meth:`from_urdf`).
        MJCF ``keyframe`` entries are not read.

        Parameters
        ----------
        path : str or Path
            MJCF (XML) file.
        frame : str, optional
            Default end-effector frame (``None``: none).
        rows : sequence of int
            Task rows of the world position.
        name : str
            Label (default: the file stem).
        floating_base : bool, str or pinocchio.JointModel
            Extra root joint (default none).
        **kwargs
            Passed to :class:`Robot`.

        Raises
        ------
        ValueError
            The file does not exist or does not parse.
        """
        path = _existing_file(path, "path", "MJCF")
        root = _root_joint(floating_base)
        try:
            if root is None:
                model = pin.buildModelFromMJCF(str(path))
            else:
                model = pin.buildModelFromMJCF(str(path), root)
        except Exception as exc:
            raise ValueError(f"MJCF file {str(path)!r} failed to parse: {exc}") from None
        if isinstance(model, tuple):  # some overloads also return constraint models
            model = model[0]
        return cls(model, frame, rows=rows, name=name or path.stem, **kwargs)

    @staticmethod
    def _load_srdf(model: pin.Model, srdf: Path) -> None:
        try:
            pin.loadReferenceConfigurations(model, str(srdf), False)
        except Exception as exc:
            raise ValueError(f"srdf: SRDF file {str(srdf)!r} failed to parse: {exc}") from None

    @staticmethod
    def _lock_configuration(model: pin.Model, value: Any) -> np.ndarray:
        if value is None:
            return pin.neutral(model)
        if isinstance(value, str):
            known = [str(e.key()) for e in model.referenceConfigurations]
            if value not in known:
                raise ValueError(
                    f"lock_configuration: no reference configuration {value!r}; known: "
                    f"{', '.join(known) or 'none (pass srdf=...)'}"
                )
            return np.array(model.referenceConfigurations[value], dtype=float)
        q = np.asarray(value, dtype=float).reshape(-1)
        if q.shape != (model.nq,) or not np.all(np.isfinite(q)):
            raise ValueError(
                f"lock_configuration must be {model.nq} finite numbers (the full model's q), "
                f"got shape {q.shape}"
            )
        return q

    def with_frame(self, frame: str, name: str = "") -> Robot:
        """The same robot (model, coordinates, rows, limits) with another default frame.

        Used for points on the links, e.g. an elbow kept away from an obstacle
        (:class:`qpcoord.coordination.potentials.ObstacleDistance`). The new robot shares the model
        and
        has its own Pinocchio data, so the two never share cached kinematics.

        Raises
        ------
        ValueError
            Unknown frame (the message lists close names).
        """
        robot = Robot(
            self.model,
            frame,
            rows=tuple(int(r) for r in self.rows),
            coordinate_map=self.coordinate_map,
            lower=self.lower,
            upper=self.upper,
            velocity_limit=self.velocity_limit,
            name=name or f"{self.name}@{frame}",
        )
        robot.urdf_path, robot.srdf_path = self.urdf_path, self.srdf_path
        robot.package_dirs = self.package_dirs
        return robot

    def _limit(
        self, value: Any, default: Any, what: str, allow: int, size: int | None = None
    ) -> np.ndarray:
        size = self.nq if size is None else size
        arr = np.array(default if value is None else value, dtype=float).reshape(-1)
        if arr.size == 1:
            arr = np.full(size, float(arr[0]))
        if arr.shape != (size,):
            raise ValueError(f"{what} must have {size} entries, got shape {arr.shape}")
        if np.any(np.isnan(arr)) or np.any(arr == -allow * np.inf):
            raise ValueError(f"{what} contains NaN or a wrong-signed infinity: {arr}")
        return arr

    # ------------------------------------------------------------------ frames
    def frame_names(self) -> list[str]:
        """Names of every frame of the model (bodies, joints, fixed joints, sensors)."""
        return list(self._frame_names)

    def frame_index(self, frame: str | int | np.integer, what: str = "frame") -> int:
        """Pinocchio index of ``frame`` (a name, or an index that is returned checked).

        When a joint and a link share the name (URDF allows it), the link's frame is meant.

        Raises
        ------
        ValueError
            Unknown frame: the message names the argument ``what`` and lists close names.
        """
        if type(frame) is str:  # the common case first
            index = self._frame_ids.get(frame)
            if index is not None:
                return index
        if isinstance(frame, (int, np.integer)) and not isinstance(frame, bool):
            if 0 <= int(frame) < len(self._frame_names):
                return int(frame)
            raise ValueError(
                f"{what}: frame index {int(frame)} out of range (robot {self.name!r} has "
                f"{len(self._frame_names)} frames)"
            )
        if not isinstance(frame, str):
            raise ValueError(f"{what} must be a frame name (str), got {frame!r}")
        index = self._frame_ids.get(frame)
        if index is not None:
            return index
        raise ValueError(f"{what}: {self._unknown_frame(frame)}")

    def _unknown_frame(self, frame: str) -> str:
        names = self._frame_names
        close = difflib.get_close_matches(frame, names, n=5, cutoff=0.5)
        low = frame.lower()
        close += [n for n in names if low and low in n.lower() and n not in close][:5]
        text = f"robot {self.name!r} has no frame {frame!r}"
        if close:
            text += f"; close names: {', '.join(close)}"
        if len(names) <= 30:
            text += f"; frames are: {', '.join(names)}"
        else:
            text += f" (it has {len(names)} frames: see robot.frame_names())"
        return text

    def _require_frame(self) -> int:
        if self.frame_id is None:
            raise ValueError(
                f"robot {self.name!r} has no default frame: pass frame=... when building it "
                "(Robot(model, frame=...), Robot.from_urdf(path, frame=...)), use "
                "robot.with_frame(name), or ask frame_pose / frame_jacobian for a frame"
            )
        return self.frame_id

    @property
    def unit_blocks(self) -> tuple[tuple[int, int, str, str], ...]:
        """The configuration's blocks that are not a vector space: ``(start, stop, joint,
        kind)`` per joint, ``q[start:stop]`` a unit quaternion (``kind="quaternion"``) or a
        unit ``(cos, sin)`` pair (``kind="(cos, sin) pair"``) of joint ``joint``."""
        return tuple(self._unit_blocks)

    def data_changed(self) -> None:
        """Declare that code outside the robot (a native IK step) computed the kinematics of
        another configuration in :attr:`data`: the next query recomputes its own."""
        self._state = 0

    # ------------------------------------------------------------------ configurations
    def check_configuration(self, q: Any, what: str = "q") -> np.ndarray:
        """Return ``q`` as a float array of shape (nq,), or raise ``ValueError``.

        Checked: numeric, ``nq`` entries, finite, and every quaternion (free-flyer,
        spherical joints) and ``(cos θ, sin θ)`` pair (continuous, planar joints) of unit
        norm within :data:`UNIT_NORM_TOLERANCE` (1e-6). The message names ``what``.
        """
        try:
            arr = np.asarray(q, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"{what} must be numeric, got {q!r}") from None
        if arr.shape[0] != self.nq:
            raise ValueError(
                f"{what} must have {self.nq} entries for robot {self.name!r} (nq = {self.nq}, "
                f"nv = {self.nv}), got shape {np.shape(q)}"
            )
        if not np.isfinite(arr.sum()) and not np.isfinite(arr).all():  # (a sum may overflow)
            i = int(np.flatnonzero(~np.isfinite(arr))[0])
            raise ValueError(f"{what}[{i}] is {float(arr[i])}: configurations must be finite")
        if self._unit_blocks:
            for start, stop, joint, kind in self._unit_blocks:
                block = arr[start:stop]
                norm = float(np.sqrt(block @ block))
                if abs(norm - 1.0) > UNIT_NORM_TOLERANCE:
                    raise ValueError(
                        f"{what}[{start}:{stop}] is the {kind} of joint {joint!r} and has "
                        f"norm {norm:.9g}: it must be of unit norm (within "
                        f"{UNIT_NORM_TOLERANCE:g}); see robot.normalize(q)"
                    )
        return arr

    def _check_velocity(self, v: Any, what: str = "v") -> np.ndarray:
        try:
            arr = np.asarray(v, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"{what} must be numeric, got {v!r}") from None
        if arr.shape[0] != self.nv:
            raise ValueError(
                f"{what} must have nv = {self.nv} entries for robot {self.name!r}, "
                f"got shape {np.shape(v)}"
            )
        if not np.isfinite(arr.sum()) and not np.isfinite(arr).all():  # (a sum may overflow)
            i = int(np.flatnonzero(~np.isfinite(arr))[0])
            raise ValueError(f"{what}[{i}] is {float(arr[i])}: velocities must be finite")
        return arr

    def _to_pin(self, q: np.ndarray) -> np.ndarray:
        return q if self.coordinate_map is None else self.coordinate_map @ q

    def _from_pin(self, q_pin: np.ndarray) -> np.ndarray:
        if self.coordinate_map is None:
            return q_pin
        return np.linalg.solve(self.coordinate_map, q_pin)

    def neutral(self) -> np.ndarray:
        """Pinocchio's neutral configuration (zero angles, identity quaternions), (nq,)."""
        return self._from_pin(np.array(pin.neutral(self.model), dtype=float))

    def normalize(self, q: Any) -> np.ndarray:
        """``q`` with its quaternions and ``(cos, sin)`` pairs scaled to unit norm, (nq,)."""
        try:
            arr = np.array(q, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"q must be numeric, got {q!r}") from None
        if arr.shape[0] != self.nq or not np.all(np.isfinite(arr)):
            raise ValueError(f"q must be {self.nq} finite numbers, got shape {np.shape(q)}")
        for start, stop, joint, kind in self._unit_blocks:
            norm = float(np.linalg.norm(arr[start:stop]))
            if norm == 0.0:
                raise ValueError(f"q[{start}:{stop}] ({kind} of joint {joint!r}) is zero")
            arr[start:stop] /= norm
        return arr

    def integrate(self, q: Any, v: Any, dt: float = 1.0) -> np.ndarray:
        """Configuration reached from ``q`` at velocity ``v`` (nv,) after ``dt`` (s).

        On the configuration manifold (``pinocchio.integrate(model, q, v * dt)``):
        quaternions stay unit, continuous joints stay on their circle. For a vector-space
        configuration (``nq == nv``, the thesis arms) it is exactly ``q + v * dt`` in the
        robot's coordinates.

        Raises
        ------
        ValueError
            Bad ``q`` (see :meth:`check_configuration`), ``v`` of the wrong size or not
            finite, ``dt`` not a finite number.
        """
        if (
            self.euclidean
            and type(q) is np.ndarray
            and type(v) is np.ndarray
            and q.dtype == _F64
            and v.dtype == _F64
            and q.shape == (self.nq,)
            and v.shape == (self.nv,)
            and type(dt) is float
            # all finite (an overflowing sum or a non-finite entry: the full checks below)
            and isfinite(sum(q.tolist()) + sum(v.tolist()) + dt)
        ):
            return q + v * dt
        q = self.check_configuration(q)
        v = self._check_velocity(v)
        try:
            dt = float(dt)
        except (TypeError, ValueError):
            raise ValueError(f"dt must be a number of seconds, got {dt!r}") from None
        if not np.isfinite(dt):
            raise ValueError(f"dt must be finite, got {dt!r}")
        if self.euclidean:
            return q + v * dt
        return np.array(pin.integrate(self.model, q, v * dt), dtype=float)

    def difference(self, q0: Any, q1: Any) -> np.ndarray:
        """Tangent vector ``v`` (nv,) with ``integrate(q0, v, 1) = q1``
        (``pinocchio.difference``; ``q1 − q0`` for a vector-space configuration)."""
        q0 = self.check_configuration(q0, "q0")
        q1 = self.check_configuration(q1, "q1")
        if self.euclidean:
            return q1 - q0
        return np.array(pin.difference(self.model, q0, q1), dtype=float)

    def reference_names(self) -> tuple[str, ...]:
        """Names of the reference configurations (the SRDF's ``group_state`` entries)."""
        return tuple(sorted(self._references))

    def reference_configuration(self, name: str) -> np.ndarray:
        """A reference configuration of the SRDF (e.g. Talos's ``"half_sitting"``), (nq,).

        Raises
        ------
        ValueError
            Unknown name: the message lists the known ones.
        """
        if name not in self._references:
            known = ", ".join(self.reference_names()) or "none (load the robot with an SRDF)"
            raise ValueError(
                f"name: robot {self.name!r} has no reference configuration {name!r}; known: {known}"
            )
        return self._references[name].copy()

    def random_configuration(self, seed: int | np.random.Generator | None = 0) -> np.ndarray:
        """A random configuration strictly inside the limits (5 % margin), (nq,).

        Unlimited coordinates are drawn in ``[-π, π]`` (rad) or ``[-1, 1]`` m for a
        floating base's translation; quaternions uniformly on the unit sphere.
        """
        rng = np.random.default_rng(seed)
        lo, hi = self.lower.copy(), self.upper.copy()
        unlimited = ~(np.isfinite(lo) & np.isfinite(hi) & (np.abs(lo) < _HUGE))
        unlimited |= np.abs(hi) >= _HUGE
        lo[unlimited], hi[unlimited] = -np.pi, np.pi
        margin = 0.05 * (hi - lo)
        q = rng.uniform(lo + margin, hi - margin)
        for j in range(1, self.model.njoints):  # a floating base's translation (m)
            joint = self.model.joints[j]
            size = {"JointModelFreeFlyer": 3, "JointModelPlanar": 2}.get(joint.shortname(), 0)
            span = slice(joint.idx_q, joint.idx_q + size)
            q[span] = np.where(unlimited[span], rng.uniform(-1.0, 1.0, size), q[span])
        for start, stop, _, kind in self._unit_blocks:
            if kind == "quaternion":
                u = rng.normal(size=4)
                q[start:stop] = u / np.linalg.norm(u)
            else:
                angle = rng.uniform(-np.pi, np.pi)
                q[start:stop] = (np.cos(angle), np.sin(angle))
        return q

    # ------------------------------------------------------------------ kinematics
    def _update(self, q: np.ndarray, level: int) -> None:
        key = q.tobytes()
        if self._state >= level and key == self._qkey:
            return
        m, d = self.model, self.data
        qp = self._to_pin(q)
        pin.computeJointJacobians(m, d, qp)  # also the forward kinematics
        if self.frame_id is not None:
            pin.updateFramePlacement(m, d, self.frame_id)
        if level >= 2:
            pin.computeJointKinematicHessians(m, d, qp)
        self._q[:] = q
        self._qkey = key
        self._state = level
        self._com_ready = False

    def _mapped(self, J: np.ndarray) -> np.ndarray:
        return J if self.coordinate_map is None else J @ self.coordinate_map

    def frame_pose(self, q: Any, frame: str | int) -> np.ndarray:
        """Pose of ``frame`` in the world, a 4×4 homogeneous matrix (rotation, metres)."""
        q = self.check_configuration(q)
        fid = self.frame_index(frame)
        self._update(q, 1)
        return pin.updateFramePlacement(self.model, self.data, fid).homogeneous

    def frame_jacobian(self, q: Any, frame: str | int) -> np.ndarray:
        """Jacobian of ``frame``, shape (6, nv): rows 0–2 the velocity of its origin (m/s
        per unit of ``v``), rows 3–5 its angular velocity (rad/s), both in world-aligned
        axes at the frame's origin (Pinocchio's ``LOCAL_WORLD_ALIGNED``)."""
        q = self.check_configuration(q)
        fid = self.frame_index(frame)
        self._update(q, 1)
        J = pin.getFrameJacobian(self.model, self.data, fid, pin.LOCAL_WORLD_ALIGNED)
        return self._mapped(np.asarray(J).reshape(6, self.nv))

    def _com_update(self, q: np.ndarray) -> None:
        if self.mass <= 0.0:
            raise ValueError(f"robot {self.name!r} has no mass: its centre of mass is undefined")
        self._update(q, 1)
        if not self._com_ready:
            pin.jacobianCenterOfMass(self.model, self.data, False)
            self._com_ready = True

    def com(self, q: Any) -> np.ndarray:
        """Centre of mass of the whole robot (m), world frame, shape (3,)."""
        q = self.check_configuration(q)
        self._com_update(q)
        return self.data.com[0].copy()

    def com_jacobian(self, q: Any) -> np.ndarray:
        """Jacobian of :meth:`com`, shape (3, nv) (m per unit of ``v``), world frame."""
        q = self.check_configuration(q)
        self._com_update(q)
        return self._mapped(np.asarray(self.data.Jcom).reshape(3, self.nv).copy())

    # ------------------------------------------------------------------ one-point API
    def position(self, q: Any) -> np.ndarray:
        """Default frame's position ``ζ(q)`` (m), world frame, the task rows only."""
        fid = self._require_frame()
        q = self.check_configuration(q)
        self._update(q, 1)
        return self.data.oMf[fid].translation[self._rows].copy()

    def jacobian(self, q: Any) -> np.ndarray:
        """Position Jacobian ``∂ζ/∂q`` (m/rad), world-aligned, shape (task rows, nv)."""
        self._require_frame()
        q = self.check_configuration(q)
        self._update(q, 1)
        J = self._jacobian_pin()[self._rows]
        return J.copy() if self.coordinate_map is None else J @ self.coordinate_map

    def kinematics(self, q: Any) -> tuple[np.ndarray, np.ndarray]:
        """``(position(q), jacobian(q))`` from one kinematics pass (the per-step call)."""
        y, J = self._kinematics(self.check_configuration(q))
        return y.copy(), J

    def _kinematics(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`kinematics` for a validated ``q`` (float array of shape (nq,)); ``y`` is a
        view into the Pinocchio data, valid until the next kinematics call."""
        fid = self._require_frame()
        self._update(q, 1)
        y = self.data.oMf[fid].translation[self._rows]
        J = self._jacobian_pin()[self._rows]
        if self.coordinate_map is not None:
            J = J @ self.coordinate_map
        return y, J  # y is a view into the Pinocchio data: copy it to keep it

    def _jacobian_pin(self) -> np.ndarray:
        J = pin.getFrameJacobian(self.model, self.data, self.frame_id, pin.LOCAL_WORLD_ALIGNED)
        if J.ndim == 1:  # nv = 1: the binding returns the 6×1 matrix as a vector
            J = J.reshape(6, 1)
        return J[:3]

    def hessian(self, q: Any) -> np.ndarray:
        """Position Hessian ``H[k, i, j] = ∂²ζ_k/∂q_i∂q_j`` (m/rad²), shape (rows, nq, nq).

        Built from Pinocchio's kinematic Hessian of the parent joint (world frame) and the
        point offset: with ``J_p = J_v − [p]× J_ω`` (``p`` the frame origin),
        ``∂J_p/∂q_i = ∂J_v/∂q_i − [∂p/∂q_i]× J_ω − [p]× ∂J_ω/∂q_i``.

        Raises
        ------
        ValueError
            No default frame, or a model whose configuration is not a vector space
            (``nq ≠ nv``: floating base, continuous joints), where the second derivative
            along the manifold is not a symmetric tensor of ``q``.
        """
        self._require_frame()
        if not self.euclidean:
            raise ValueError(
                f"robot {self.name!r}: hessian() needs a vector-space configuration "
                f"(nq == nv and no continuous joint); this one has nq = {self.nq}, "
                f"nv = {self.nv}"
            )
        q = self.check_configuration(q)
        self._update(q, 2)
        HW = self._world_hessian()
        JW = self._jacobian_world()
        p = self.data.oMf[self.frame_id].translation
        Jp = self._jacobian_pin()
        n = self.nq
        H = np.empty((3, n, n))  # H[k, j, i] = ∂(J_p)[k, j]/∂q_i
        Sp = _skew(p)
        for i in range(n):
            H[:, :, i] = HW[:3, :, i] - _skew(Jp[:, i]) @ JW[3:] - Sp @ HW[3:, :, i]
        H = 0.5 * (H + H.transpose(0, 2, 1))  # exact symmetry (rounding only)
        H = H[self.rows]
        if self.coordinate_map is not None:
            M = self.coordinate_map
            H = np.einsum("ia,kij,jb->kab", M, H, M)
        return H

    def _world_hessian(self) -> np.ndarray:
        """Joint kinematic Hessian ``HW[:, j, i] = ∂J_j/∂q_i`` (world frame, 6×nq×nq).

        pin 4.1's Python binding returns the tensor with its memory read in the wrong order
        (the data are column-major); which layout is right is decided once per robot
        against a finite difference of the Jacobian, so a fixed binding is also handled.
        """
        if self._layout is None:
            self._layout = self._detect_layout()
        raw = self._raw_hessian()
        if self._layout == "fortran":
            return raw.reshape(-1, order="C").reshape(raw.shape, order="F")
        return raw

    def _raw_hessian(self) -> np.ndarray:
        raw = pin.getJointKinematicHessian(self.model, self.data, self.joint_id, pin.WORLD)
        return np.asarray(raw).reshape(6, self.nq, self.nq)

    def _jacobian_world(self) -> np.ndarray:
        J = pin.getJointJacobian(self.model, self.data, self.joint_id, pin.WORLD)
        return np.asarray(J).reshape(6, self.nq)

    def _detect_layout(self) -> str:
        m, d = self.model, self.data
        q_saved = self._q.copy()
        qp = np.linspace(0.3, 1.1, self.nq)
        qp = np.clip(qp, m.lowerPositionLimit, m.upperPositionLimit)
        h = 1e-6
        dJ = np.empty((6, self.nq, self.nq))
        for i in range(self.nq):
            e = np.zeros(self.nq)
            e[i] = h
            pin.computeJointJacobians(m, d, qp + e)
            Jplus = self._jacobian_world().copy()
            pin.computeJointJacobians(m, d, qp - e)
            Jminus = self._jacobian_world()
            dJ[:, :, i] = (Jplus - Jminus) / (2 * h)
        pin.computeJointKinematicHessians(m, d, qp)
        raw = self._raw_hessian()
        fortran = raw.reshape(-1, order="C").reshape(raw.shape, order="F")
        scale = 1e-5 * max(1.0, float(np.abs(dJ).max()))
        err_c = float(np.abs(raw - dJ).max())
        err_f = float(np.abs(fortran - dJ).max())
        # restore the kinematics of the configuration being evaluated
        self._state = 0
        if np.all(np.isfinite(q_saved)):
            self._update(q_saved, 2)
        if err_f <= scale and err_f <= err_c:
            return "fortran"
        if err_c <= scale:
            return "c"
        raise RuntimeError(  # pragma: no cover - would mean a broken Pinocchio build
            f"Pinocchio's kinematic Hessian matches no known layout (errors {err_c:.3g}, "
            f"{err_f:.3g}); cannot compute robot Hessians"
        )

    def __repr__(self) -> str:
        rows = tuple(int(r) for r in self.rows)
        nv = "" if self.nv == self.nq else f", nv={self.nv}"
        return f"Robot({self.name!r}, nq={self.nq}{nv}, frame={self.frame!r}, rows={rows})"
