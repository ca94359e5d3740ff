"""Kinematics of a serial robot from Pinocchio: :class:`Robot`.

A :class:`Robot` wraps a :class:`pinocchio.Model` and one end-effector frame, and gives the
three maps every IK scheme of the thesis needs (§3.4–3.5):

- ``position(q)`` -- the forward map ``Y = ζ(q)`` (m), world frame, only the task rows;
- ``jacobian(q)`` -- ``J = ∂ζ/∂q`` (m/rad), world-aligned, task rows × nq;
- ``hessian(q)`` -- ``H[k, i, j] = ∂²ζ_k/∂q_i∂q_j`` (m/rad²), from Pinocchio's kinematic
  Hessians (not finite differences).

Coordinates
-----------
The robot's coordinates ``q`` may differ from Pinocchio's by a constant invertible matrix:
``q_pin = coordinate_map @ q``. The thesis 3R arm uses **absolute** joint angles
(``q_abs = T q_rel`` with ``T`` lower-triangular ones), so its map is ``T⁻¹``; Jacobian and
Hessian are mapped consistently (``J = J_pin M``, ``H_k = Mᵀ H_pin,k M``).

Only models whose joints all have one configuration variable per velocity (revolute,
prismatic, fixed) are accepted: ``nq == nv``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin

__all__ = ["Robot"]


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


class Robot:
    """A Pinocchio model with one end-effector point, as the IK layer sees it.

    Parameters
    ----------
    model : pinocchio.Model
        Kinematic model; every joint must have ``nq == nv`` (revolute or prismatic).
    frame : str
        Name of the end-effector frame (its origin is the controlled point).
    rows : sequence of int
        Which of the world position coordinates ``(x, y, z)`` form the task (default all
        three; ``(0, 1)`` for a planar arm).
    coordinate_map : array_like, shape (nq, nq), optional
        Constant invertible ``M`` with ``q_pin = M q`` (default identity).
    lower, upper : array_like, shape (nq,), optional
        Joint position limits in the robot's coordinates (rad or m). Default: the model's
        limits when ``coordinate_map`` is the identity, else unlimited.
    velocity_limit : array_like, shape (nq,), optional
        Joint speed limits (rad/s or m/s). Default: the model's when ``coordinate_map`` is
        the identity, else unlimited.
    name : str
        Label used in messages.

    Raises
    ------
    ValueError
        Unknown frame (the message lists the frames), unsupported joints, bad rows, a
        singular coordinate map or bad limits.
    """

    def __init__(
        self,
        model: pin.Model,
        frame: str,
        rows=(0, 1, 2),
        coordinate_map=None,
        lower=None,
        upper=None,
        velocity_limit=None,
        name: str = "",
    ) -> None:
        if not isinstance(model, pin.Model):
            raise ValueError(f"model must be a pinocchio.Model, got {type(model).__name__}")
        self.name = name or model.name or "robot"
        if model.nq != model.nv:
            raise ValueError(
                f"robot {self.name!r}: only joints with one coordinate per velocity are "
                f"supported (nq = {model.nq} ≠ nv = {model.nv}; continuous or free joints?)"
            )
        if model.nq == 0:
            raise ValueError(f"robot {self.name!r}: the model has no joints")
        if not isinstance(frame, str) or not model.existFrame(frame):
            known = ", ".join(f.name for f in model.frames)
            raise ValueError(f"robot {self.name!r}: no frame {frame!r}; frames are: {known}")
        rows = tuple(int(r) for r in rows)
        if not rows or len(set(rows)) != len(rows) or any(r not in (0, 1, 2) for r in rows):
            raise ValueError(f"rows must be distinct entries of (0, 1, 2), got {rows!r}")
        self.model = model
        self.data = model.createData()
        self.frame = frame
        self.frame_id = model.getFrameId(frame)
        self.joint_id = model.frames[self.frame_id].parentJoint
        self.rows = np.array(rows, dtype=int)
        # a leading run of rows is read as a slice (a view, no fancy-index copy)
        self._rows = slice(0, len(rows)) if rows == tuple(range(len(rows))) else self.rows
        self.nq = int(model.nq)
        self.m = len(rows)
        identity = coordinate_map is None
        if identity:
            self.coordinate_map = None
        else:
            M = np.array(coordinate_map, dtype=float)
            if M.shape != (self.nq, self.nq) or not np.all(np.isfinite(M)):
                raise ValueError(
                    f"coordinate_map must be a finite {self.nq}×{self.nq} matrix, "
                    f"got shape {M.shape}"
                )
            if np.linalg.cond(M) > 1e12:
                raise ValueError("coordinate_map is singular")
            self.coordinate_map = M
        inf = np.full(self.nq, np.inf)
        self.lower = self._limit(
            lower, model.lowerPositionLimit if identity else -inf, "lower", allow=-1
        )
        self.upper = self._limit(
            upper, model.upperPositionLimit if identity else inf, "upper", allow=1
        )
        bad = self.lower > self.upper
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(f"lower > upper at joint {i} ({self.lower[i]} > {self.upper[i]})")
        self.velocity_limit = self._limit(
            velocity_limit, model.velocityLimit if identity else inf, "velocity_limit", allow=1
        )
        if np.any(self.velocity_limit <= 0):
            raise ValueError(f"velocity_limit must be > 0, got {self.velocity_limit}")
        self._q = np.full(self.nq, np.nan)  # configuration of the cached kinematics
        self._qkey = b""  # its bytes (cheap equality test)
        self._state = 0  # 0 nothing, 1 placements+jacobian, 2 + hessian
        self._layout = None  # tensor layout of Pinocchio's kinematic Hessian binding

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_urdf(
        cls,
        path,
        frame: str,
        rows=(0, 1, 2),
        locked_joints=(),
        name: str = "",
        **kwargs,
    ) -> Robot:
        """Build a robot from a URDF file (kinematics only; meshes are not read).

        Parameters
        ----------
        path : str or Path
            URDF file.
        frame : str
            End-effector frame name.
        rows : sequence of int
            Task rows of the world position (default ``(0, 1, 2)``).
        locked_joints : sequence of str
            Joints to lock at zero (e.g. gripper fingers), removed from ``q``.
        name : str
            Label (default: the file stem).
        **kwargs
            Passed to :class:`Robot` (``coordinate_map``, limits).

        Raises
        ------
        ValueError
            The file does not exist or does not parse, a locked joint is unknown.
        """
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"URDF file {str(path)!r} does not exist")
        try:
            model = pin.buildModelFromUrdf(str(path))
        except Exception as exc:  # pinocchio raises ValueError/RuntimeError by version
            raise ValueError(f"URDF file {str(path)!r} failed to parse: {exc}") from None
        if locked_joints:
            ids = []
            for j in locked_joints:
                if not model.existJointName(j):
                    known = ", ".join(model.names[1:])
                    raise ValueError(f"locked joint {j!r} not in {str(path)!r}; joints: {known}")
                ids.append(model.getJointId(j))
            model = pin.buildReducedModel(model, ids, pin.neutral(model))
        return cls(model, frame, rows=rows, name=name or path.stem, **kwargs)

    def with_frame(self, frame: str, name: str = "") -> Robot:
        """The same arm (model, coordinates, rows, limits) with another controlled point.

        Used for points on the links, e.g. an elbow kept away from an obstacle
        (:class:`qpcoord.coordination.potentials.ObstacleDistance`). The new robot has its own
        Pinocchio
        data, so the two never share cached kinematics.

        Raises
        ------
        ValueError
            Unknown frame (the message lists the frames).
        """
        return Robot(
            self.model,
            frame,
            rows=tuple(int(r) for r in self.rows),
            coordinate_map=self.coordinate_map,
            lower=self.lower,
            upper=self.upper,
            velocity_limit=self.velocity_limit,
            name=name or f"{self.name}@{frame}",
        )

    def _limit(self, value, default, what: str, allow: int) -> np.ndarray:
        arr = np.array(default if value is None else value, dtype=float).reshape(-1)
        if arr.size == 1:
            arr = np.full(self.nq, float(arr[0]))
        if arr.shape != (self.nq,):
            raise ValueError(f"{what} must have {self.nq} entries, got shape {arr.shape}")
        if np.any(np.isnan(arr)) or np.any(arr == -allow * np.inf):
            raise ValueError(f"{what} contains NaN or a wrong-signed infinity: {arr}")
        return arr

    # ------------------------------------------------------------------ checks
    def check_configuration(self, q, what: str = "q") -> np.ndarray:
        """Return ``q`` as a float array of shape (nq,), or raise ``ValueError``."""
        try:
            arr = np.asarray(q, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"{what} must be numeric, got {q!r}") from None
        if arr.shape[0] != self.nq:
            raise ValueError(
                f"{what} must have {self.nq} entries for robot {self.name!r}, "
                f"got shape {np.shape(q)}"
            )
        if not np.isfinite(arr.sum()):
            i = int(np.flatnonzero(~np.isfinite(arr))[0])
            raise ValueError(f"{what}[{i}] is {float(arr[i])}: configurations must be finite")
        return arr

    # ------------------------------------------------------------------ kinematics
    def _to_pin(self, q: np.ndarray) -> np.ndarray:
        return q if self.coordinate_map is None else self.coordinate_map @ q

    def _update(self, q: np.ndarray, level: int) -> None:
        key = q.tobytes()
        if self._state >= level and key == self._qkey:
            return
        m, d = self.model, self.data
        qp = self._to_pin(q)
        pin.computeJointJacobians(m, d, qp)  # also the forward kinematics
        pin.updateFramePlacement(m, d, self.frame_id)
        if level >= 2:
            pin.computeJointKinematicHessians(m, d, qp)
        self._q[:] = q
        self._qkey = key
        self._state = level

    def position(self, q) -> np.ndarray:
        """End-effector position ``ζ(q)`` (m), world frame, the task rows only."""
        q = self.check_configuration(q)
        self._update(q, 1)
        return self.data.oMf[self.frame_id].translation[self._rows].copy()

    def jacobian(self, q) -> np.ndarray:
        """Position Jacobian ``∂ζ/∂q`` (m/rad), world-aligned, shape (task rows, nq)."""
        q = self.check_configuration(q)
        self._update(q, 1)
        J = self._jacobian_pin()[self._rows]
        return J.copy() if self.coordinate_map is None else J @ self.coordinate_map

    def kinematics(self, q) -> tuple[np.ndarray, np.ndarray]:
        """``(position(q), jacobian(q))`` from one kinematics pass (the per-step call)."""
        y, J = self._kinematics(self.check_configuration(q))
        return y.copy(), J

    def _kinematics(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`kinematics` for a validated ``q`` (float array of shape (nq,)); ``y`` is a
        view into the Pinocchio data, valid until the next kinematics call."""
        self._update(q, 1)
        y = self.data.oMf[self.frame_id].translation[self._rows]
        J = self._jacobian_pin()[self._rows]
        if self.coordinate_map is not None:
            J = J @ self.coordinate_map
        return y, J  # y is a view into the Pinocchio data: copy it to keep it

    def _jacobian_pin(self) -> np.ndarray:
        J = pin.getFrameJacobian(self.model, self.data, self.frame_id, pin.LOCAL_WORLD_ALIGNED)
        if J.ndim == 1:  # nq = 1: the binding returns the 6×1 matrix as a vector
            J = J.reshape(6, 1)
        return J[:3]

    def hessian(self, q) -> np.ndarray:
        """Position Hessian ``H[k, i, j] = ∂²ζ_k/∂q_i∂q_j`` (m/rad²), shape (rows, nq, nq).

        Built from Pinocchio's kinematic Hessian of the parent joint (world frame) and the
        point offset: with ``J_p = J_v − [p]× J_ω`` (``p`` the frame origin),
        ``∂J_p/∂q_i = ∂J_v/∂q_i − [∂p/∂q_i]× J_ω − [p]× ∂J_ω/∂q_i``.
        """
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
        return f"Robot({self.name!r}, nq={self.nq}, frame={self.frame!r}, rows={rows})"
