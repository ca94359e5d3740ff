"""Potential functions ``g(q)`` on the configuration space (thesis chapter 5).

A potential is a scalar function of the joint configuration ``q`` (rad) whose gradient
drives the self-motion of a redundant arm (Def. 5.3: ``Φ = −∇g(q)ᵀ g(q)`` projected into
the null space of the main task). Every potential here has

- ``value(q)`` -- ``g(q)`` (dimensionless unless stated);
- ``gradient(q)`` -- ``∇g(q)``, shape ``(nq,)`` (per rad);
- ``hessian(q)`` -- ``∇²g(q)``, shape ``(nq, nq)``: analytic where cheap, otherwise a
  central difference of the analytic gradient (:meth:`Potential.hessian`);
- ``evaluate(q)`` -- ``(value, gradient)`` checked for shape and finiteness: the call the
  schemes use, so a user potential that returns NaN or a wrong shape is reported by name.

Potentials add and scale: ``2.0 * JointCentring(...) + JointLimitAvoidance(...)``.

=========================== ===============================================================
:class:`JointCentring`      ``α Σ_i (q_i − c_i)²`` -- Thm 5.1 uses ``α (q₁ − π/2)²``
:class:`JointLimitAvoidance` barrier ``α/n Σ_i ((u−l)²/(4 (u−q)(q−l)) − 1)``, 0 at mid-range
:class:`PointDistance`      ``‖y(q) − c‖² − R²`` for a robot point -- the circle task ``h``
                            of Eq. 5.1 and the squared distance to an obstacle point
:class:`ObstacleDistance`   Khatib's ``α/2 (1/d − 1/d₀)²`` inside the influence distance
:class:`Manipulability`     ``α / det(J Jᵀ)`` -- grows toward a singular configuration
:class:`FunctionPotential`  wrap user callables ``value`` and ``gradient``
=========================== ===============================================================
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence

import numpy as np

__all__ = [
    "Potential",
    "JointCentring",
    "JointLimitAvoidance",
    "PointDistance",
    "ObstacleDistance",
    "Manipulability",
    "FunctionPotential",
    "Sum",
    "Scaled",
]


def _positive(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{what} must be a positive number, got {value!r}")
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"{what} must be > 0 and finite, got {value!r}")
    return float(value)


def _config(q) -> np.ndarray:
    try:
        arr = np.asarray(q, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"q must be numeric, got {q!r}") from None
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"q must be finite (rad), got {arr.tolist()}")
    return arr


class Potential(ABC):
    """Base class: a scalar function ``g(q)`` with its gradient.

    Subclasses implement :meth:`value` and :meth:`gradient`; :meth:`hessian` defaults to a
    central difference of the gradient (step ``1e-6`` rad, error ``O(1e-12)`` times the
    third derivative).
    """

    name: str = "potential"

    @abstractmethod
    def value(self, q) -> float:
        """``g(q)``."""

    @abstractmethod
    def gradient(self, q) -> np.ndarray:
        """``∇g(q)``, shape ``(nq,)`` (per rad)."""

    def hessian(self, q) -> np.ndarray:
        """``∇²g(q)``, shape ``(nq, nq)`` (per rad²); symmetrised central differences."""
        q = _config(q)
        n = q.size
        h = 1e-6
        H = np.empty((n, n))
        for i in range(n):
            e = np.zeros(n)
            e[i] = h
            H[:, i] = (self._grad_checked(q + e) - self._grad_checked(q - e)) / (2 * h)
        return 0.5 * (H + H.T)

    def __call__(self, q) -> float:
        return self.value(q)

    def evaluate(self, q) -> tuple[float, np.ndarray]:
        """``(g(q), ∇g(q))``, checked.

        Raises
        ------
        ValueError
            The value is not a finite scalar, or the gradient does not have ``len(q)``
            finite entries -- the message names the potential and ``q``.
        """
        q = _config(q)
        g = np.asarray(self.value(q), dtype=float)
        if g.size != 1 or not np.isfinite(g).all():
            raise ValueError(f"potential {self.name!r}: value at q = {q.tolist()} is {g!r}")
        return float(g.reshape(())), self._grad_checked(q)

    def _grad_checked(self, q: np.ndarray) -> np.ndarray:
        d = np.asarray(self.gradient(q), dtype=float).reshape(-1)
        if d.shape != q.shape:
            raise ValueError(
                f"potential {self.name!r}: gradient must have {q.size} entries, "
                f"got shape {np.shape(self.gradient(q))}"
            )
        if not np.all(np.isfinite(d)):
            raise ValueError(
                f"potential {self.name!r}: gradient at q = {q.tolist()} is not finite: {d.tolist()}"
            )
        return d

    def __add__(self, other: Potential) -> Sum:
        if not isinstance(other, Potential):
            return NotImplemented
        return Sum([self, other])

    def __mul__(self, factor: float) -> Scaled:
        return Scaled(self, factor)

    __rmul__ = __mul__

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


class Sum(Potential):
    """``Σ_k g_k(q)``."""

    def __init__(self, terms: Sequence[Potential], name: str = "") -> None:
        flat: list[Potential] = []
        for t in terms:
            if not isinstance(t, Potential):
                raise ValueError(f"Sum terms must be Potential objects, got {t!r}")
            flat.extend(t.terms if isinstance(t, Sum) else [t])
        if not flat:
            raise ValueError("Sum needs at least one potential")
        self.terms = flat
        self.name = name or " + ".join(t.name for t in flat)

    def value(self, q) -> float:
        return float(sum(t.value(q) for t in self.terms))

    def gradient(self, q) -> np.ndarray:
        return np.sum([t._grad_checked(_config(q)) for t in self.terms], axis=0)

    def hessian(self, q) -> np.ndarray:
        return np.sum([t.hessian(q) for t in self.terms], axis=0)


class Scaled(Potential):
    """``s · g(q)`` with a positive factor ``s``."""

    def __init__(self, potential: Potential, factor: float, name: str = "") -> None:
        if not isinstance(potential, Potential):
            raise ValueError(f"Scaled needs a Potential, got {potential!r}")
        self.potential = potential
        self.factor = _positive(factor, "factor")
        self.name = name or f"{self.factor:g}·{potential.name}"

    def value(self, q) -> float:
        return self.factor * self.potential.value(q)

    def gradient(self, q) -> np.ndarray:
        return self.factor * np.asarray(self.potential.gradient(q), dtype=float)

    def hessian(self, q) -> np.ndarray:
        return self.factor * self.potential.hessian(q)


class JointCentring(Potential):
    """Joint-centring quadratic ``g(q) = α Σ_{i ∈ joints} (q_i − c_i)²``.

    Thm 5.1 of the thesis uses ``g = α (q₁ − π/2)²`` on the 3R arm:
    ``JointCentring(np.pi / 2, alpha, joints=[0])``.

    Parameters
    ----------
    center : float or array_like
        ``c`` (rad): one value for every listed joint, or one per listed joint.
    alpha : float
        ``α > 0`` (per rad²).
    joints : sequence of int, optional
        Which joints (0-based); default all.
    name : str
    """

    def __init__(self, center, alpha: float = 1.0, joints=None, name: str = "") -> None:
        self.alpha = _positive(alpha, "alpha")
        c = np.asarray(center, dtype=float).reshape(-1)
        if c.size == 0 or not np.all(np.isfinite(c)):
            raise ValueError(f"center must be finite (rad), got {center!r}")
        if joints is None:
            self.joints = None
        else:
            idx = [int(j) for j in np.atleast_1d(joints)]
            if not idx or min(idx) < 0 or len(set(idx)) != len(idx):
                raise ValueError(f"joints must be distinct indices >= 0, got {joints!r}")
            if c.size not in (1, len(idx)):
                raise ValueError(
                    f"center has {c.size} entries for {len(idx)} joints {idx}: give one "
                    f"or one per joint"
                )
            self.joints = np.array(idx, dtype=int)
        self.center = c
        self.name = name or "joint centring"

    def _offset(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        idx = np.arange(q.size) if self.joints is None else self.joints
        if idx.size and idx.max() >= q.size:
            raise ValueError(
                f"{self.name}: joint index {int(idx.max())} out of range for {q.size} joints"
            )
        if self.center.size not in (1, idx.size):
            raise ValueError(
                f"{self.name}: center has {self.center.size} entries for {idx.size} joints"
            )
        return idx, q[idx] - self.center

    def value(self, q) -> float:
        _, d = self._offset(_config(q))
        return self.alpha * float(d @ d)

    def gradient(self, q) -> np.ndarray:
        q = _config(q)
        idx, d = self._offset(q)
        out = np.zeros(q.size)
        out[idx] = 2.0 * self.alpha * d
        return out

    def hessian(self, q) -> np.ndarray:
        q = _config(q)
        idx, _ = self._offset(q)
        H = np.zeros((q.size, q.size))
        H[idx, idx] = 2.0 * self.alpha
        return H


class JointLimitAvoidance(Potential):
    """Joint-range barrier ``g = α/n Σ_i ((u_i − l_i)² / (4 (u_i − q_i)(q_i − l_i)) − 1)``.

    Zero at mid-range, infinite at a limit (the "joint range availability" criterion of
    Zghal et al., 1990, shifted to vanish at its minimum). Only joints with finite limits
    count (``n`` of them).

    Parameters
    ----------
    lower, upper : array_like
        Limits (rad); or give ``robot=`` to take a :class:`~qpcoord.Robot`'s.
    alpha : float
        ``α > 0``.
    robot : Robot, optional

    Raises
    ------
    ValueError
        No joint has finite limits; ``lower ≥ upper``; at evaluation, ``q`` on or outside
        a limit (the message names the joint).
    """

    def __init__(self, lower=None, upper=None, alpha: float = 1.0, robot=None, name: str = ""):
        if robot is not None:
            lower = robot.lower if lower is None else lower
            upper = robot.upper if upper is None else upper
        if lower is None or upper is None:
            raise ValueError("JointLimitAvoidance needs lower and upper limits (or robot=)")
        lo = np.asarray(lower, dtype=float).reshape(-1)
        hi = np.asarray(upper, dtype=float).reshape(-1)
        if lo.shape != hi.shape or np.any(np.isnan(lo)) or np.any(np.isnan(hi)):
            raise ValueError(f"lower and upper must be matching arrays, got {lower!r}, {upper!r}")
        finite = np.isfinite(lo) & np.isfinite(hi)
        if not finite.any():
            raise ValueError("JointLimitAvoidance: no joint has finite lower and upper limits")
        if np.any(lo[finite] >= hi[finite]):
            i = int(np.flatnonzero(finite & (lo >= hi))[0])
            raise ValueError(f"lower[{i}] = {lo[i]} is not below upper[{i}] = {hi[i]}")
        self.alpha = _positive(alpha, "alpha")
        self.idx = np.flatnonzero(finite)
        self.lower, self.upper = lo, hi
        self.name = name or "joint limit avoidance"

    def _parts(self, q):
        q = _config(q)
        if q.size != self.lower.size:
            raise ValueError(f"{self.name}: q has {q.size} entries, limits {self.lower.size}")
        i = self.idx
        a, b = self.upper[i] - q[i], q[i] - self.lower[i]
        if np.any(a <= 0) or np.any(b <= 0):
            j = int(i[np.flatnonzero((a <= 0) | (b <= 0))[0]])
            raise ValueError(
                f"{self.name}: q[{j}] = {q[j]} is on or outside its limits "
                f"[{self.lower[j]}, {self.upper[j]}]"
            )
        r2 = (self.upper[i] - self.lower[i]) ** 2 / 4.0
        return q, i, a, b, r2, self.alpha / i.size

    def value(self, q) -> float:
        _, _, a, b, r2, k = self._parts(q)
        return k * float(np.sum(r2 / (a * b) - 1.0))

    def gradient(self, q) -> np.ndarray:
        q, i, a, b, r2, k = self._parts(q)
        out = np.zeros(q.size)
        # d/dq [r2 / ((u − q)(q − l))] = r2 ((q − l) − (u − q)) / (a b)²
        out[i] = k * r2 * (b - a) / (a * b) ** 2
        return out

    def hessian(self, q) -> np.ndarray:
        q, i, a, b, r2, k = self._parts(q)
        H = np.zeros((q.size, q.size))
        ab = a * b
        # d/dq [(b − a)/(ab)²] with da/dq = −1, db/dq = 1, d(ab)/dq = a − b
        H[i, i] = k * r2 * (2.0 / ab**2 - 2.0 * (b - a) * (a - b) / ab**3)
        return H


class PointDistance(Potential):
    """``h(q) = ‖y(q) − c‖² − R²`` for the controlled point ``y`` of a robot (m²).

    With ``R > 0`` this is the thesis's circle task (Eq. 5.1) pulled back to the joints:
    ``ω_h = ∇h = 2 (y − c)ᵀ J`` (the 1-form of §5.4) and
    ``∇²h = 2 (Jᵀ J + Σ_k (y − c)_k H_k)`` with ``H_k`` the robot's position Hessian (Eq.
    5.16). With ``R = 0`` it is the squared distance to the point ``c``.

    Parameters
    ----------
    robot : Robot
        Its controlled point is ``y``; use :meth:`~qpcoord.Robot.with_frame` for a link.
    center : array_like, shape (rows,)
        ``c`` (m).
    radius : float
        ``R ≥ 0`` (m).
    """

    def __init__(self, robot, center, radius: float = 0.0, name: str = "") -> None:
        self.robot = robot
        c = np.asarray(center, dtype=float).reshape(-1)
        if c.shape != (robot.m,) or not np.all(np.isfinite(c)):
            raise ValueError(f"center must be {robot.m} finite coordinates (m), got {center!r}")
        if isinstance(radius, bool) or not np.isfinite(radius) or radius < 0:
            raise ValueError(f"radius must be >= 0 and finite (m), got {radius!r}")
        self.center = c
        self.radius = float(radius)
        self.name = name or ("circle task" if radius > 0 else "squared distance")

    def value(self, q) -> float:
        d = self.robot.position(q) - self.center
        return float(d @ d) - self.radius**2

    def gradient(self, q) -> np.ndarray:
        y, J = self.robot.kinematics(q)
        return 2.0 * (y - self.center) @ J

    def hessian(self, q) -> np.ndarray:
        y, J = self.robot.kinematics(q)
        H = self.robot.hessian(q)
        return 2.0 * (J.T @ J + np.einsum("k,kij->ij", y - self.center, H))


class ObstacleDistance(Potential):
    """Khatib's repulsive potential ``g = α/2 (1/d − 1/d₀)²`` for ``d < d₀``, else 0.

    ``d = ‖y(q) − o‖`` is the distance (m) from a point of the robot to an obstacle
    point ``o``; ``d₀`` the influence distance.

    Parameters
    ----------
    robot : Robot
        Its controlled point is the one kept away (e.g. ``arm.with_frame("link2")``).
    obstacle : array_like, shape (rows,)
        ``o`` (m).
    influence : float
        ``d₀ > 0`` (m).
    alpha : float
        ``α > 0`` (m²).

    Raises
    ------
    ValueError
        At evaluation, the point on the obstacle (``d = 0``).
    """

    def __init__(self, robot, obstacle, influence: float, alpha: float = 1.0, name: str = ""):
        self.distance = PointDistance(robot, obstacle)
        self.influence = _positive(influence, "influence")
        self.alpha = _positive(alpha, "alpha")
        self.name = name or "obstacle distance"

    def _d(self, q) -> float:
        d = float(np.sqrt(max(self.distance.value(q), 0.0)))
        if d == 0.0:
            raise ValueError(f"{self.name}: the robot point is on the obstacle at q = {q!r}")
        return d

    def value(self, q) -> float:
        d = self._d(q)
        if d >= self.influence:
            return 0.0
        return 0.5 * self.alpha * (1.0 / d - 1.0 / self.influence) ** 2

    def gradient(self, q) -> np.ndarray:
        q = _config(q)
        d = self._d(q)
        if d >= self.influence:
            return np.zeros(q.size)
        # ∇d = ∇(d²) / (2d)
        grad_d = self.distance.gradient(q) / (2.0 * d)
        return -self.alpha * (1.0 / d - 1.0 / self.influence) / d**2 * grad_d


class Manipulability(Potential):
    """``g(q) = α / det(J Jᵀ)``: the inverse squared manipulability of Yoshikawa.

    Descending it moves away from singular configurations. The gradient is analytic:
    ``∂g/∂q_i = −2 g tr((J Jᵀ)⁻¹ (∂J/∂q_i) Jᵀ)``, with ``∂J/∂q_i`` from the robot's
    position Hessian.

    Parameters
    ----------
    robot : Robot
    alpha : float
        ``α > 0`` (m^(2·rows)).

    Raises
    ------
    ValueError
        At a (numerically) singular configuration, ``σ_min(J) ≤ 1e-8 σ_max(J)``: the
        potential is infinite there.
    """

    def __init__(self, robot, alpha: float = 1.0, name: str = "") -> None:
        self.robot = robot
        self.alpha = _positive(alpha, "alpha")
        self.name = name or "manipulability"

    def _det(self, q):
        J = self.robot.jacobian(q)
        sv = np.linalg.svd(J, compute_uv=False)
        if sv.size < J.shape[0] or not sv[-1] > 1e-8 * sv[0]:
            raise ValueError(
                f"{self.name}: singular configuration (σ_min/σ_max of J = "
                f"{sv[-1] / sv[0] if sv[0] else 0.0:.3g} ≤ 1e-8)"
            )
        return J, J @ J.T, float(np.prod(sv**2))

    def value(self, q) -> float:
        return self.alpha / self._det(q)[2]

    def gradient(self, q) -> np.ndarray:
        J, M, det = self._det(q)
        H = self.robot.hessian(q)  # H[k, j, i] = ∂J[k, j]/∂q_i
        X = np.linalg.solve(M, J)  # M⁻¹ J
        # tr(M⁻¹ ∂J_i Jᵀ) = Σ_kj (M⁻¹ J)[k, j] ∂J_i[k, j]
        return -2.0 * (self.alpha / det) * np.einsum("kj,kji->i", X, H)


class FunctionPotential(Potential):
    """A potential from user functions ``value(q) -> float`` and ``gradient(q) -> (nq,)``.

    ``hessian`` is optional (default: central differences of ``gradient``).
    """

    def __init__(
        self,
        value: Callable,
        gradient: Callable,
        hessian: Callable | None = None,
        name: str = "user potential",
    ) -> None:
        for what, fn in (("value", value), ("gradient", gradient)):
            if not callable(fn):
                raise ValueError(f"{what} must be callable, got {fn!r}")
        if hessian is not None and not callable(hessian):
            raise ValueError(f"hessian must be callable or None, got {hessian!r}")
        self._value, self._gradient, self._hessian = value, gradient, hessian
        self.name = name

    def value(self, q) -> float:
        return self._value(_config(q))  # checked by evaluate()

    def gradient(self, q) -> np.ndarray:
        return np.asarray(self._gradient(_config(q)), dtype=float)

    def hessian(self, q) -> np.ndarray:
        if self._hessian is None:
            return super().hessian(q)
        return np.asarray(self._hessian(_config(q)), dtype=float)
