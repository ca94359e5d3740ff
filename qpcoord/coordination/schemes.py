"""Coordination schemes of the thesis, usable with :func:`qpcoord.simulate`.

Each scheme is an object with ``velocity(q, t, reference) -> q̇`` (rad/s), where
``reference`` is the end-effector path (:mod:`qpcoord.kinematics.paths`). Where the method is a QP
it
is posed as a :class:`~qpcoord.Stack` through :class:`~qpcoord.IK`.

Chapter 4:

- :class:`PseudoInverse` -- §4.3.1, Eq. 4.1: ``q̇ = J⁺ Ẏ`` (one equality level, minimum
  norm, thesis Thm 3.2);
- :class:`OutputManifoldBasis` -- §4.3.2, Prop. 4.1, Eqs. 4.2–4.3: ``Ẏ = α v₁ + β v₂`` in
  the sphere's involutive basis, ``q̇ = α J⁺v₁ + β J⁺v₂``;
- :class:`InvolutiveBasis` -- Thm 4.2 / Ex. 4.4: the main task with complementary
  integrable 1-forms held at zero (``ω₄ q̇ = 0``, ``ω₅ q̇ = 0`` as hard constraints).

Chapter 5 (defined in :mod:`qpcoord.coordination.extensions` and
:mod:`qpcoord.coordination.curvature`, re-exported):

- :class:`RigidExtension` -- Def. 5.2: ``[J; G] q̇ = [Ẏ; 0]``, algorithmic singularities
  reported;
- :class:`SoftExtension` -- Defs. 5.3/5.4: potentials in strict priority in the reduced
  null spaces (projection formula or lexicographic QP with hard limits);
- :class:`HessianDirection` -- §5.4: the maximal-curvature direction of the task manifold;
- :class:`ComplementaryForm` -- §5.5: a constant 1-form tangent to the fibre at ``q̄``.

``gain`` adds closed-loop correction ``K (Y_ref − Y)`` to ``Ẏ`` (1/s; the thesis integrates
the open-loop maps, ``gain = 0``, the default).
"""

from __future__ import annotations

import numpy as np

from ..kinematics.ik import IK
from ..kinematics.robot import Robot
from ..kinematics.tasks import PositionTask
from .curvature import ComplementaryForm, HessianDirection
from .extensions import RigidExtension, SoftExtension

__all__ = [
    "PseudoInverse",
    "OutputManifoldBasis",
    "InvolutiveBasis",
    "RigidExtension",
    "SoftExtension",
    "HessianDirection",
    "ComplementaryForm",
    "sphere_basis",
    "sphere_forms",
]


def _robot(robot) -> Robot:
    if not isinstance(robot, Robot):
        raise ValueError(f"robot must be a qpcoord.Robot, got {type(robot).__name__}")
    return robot


class PseudoInverse:
    """§4.3.1: ``q̇ = J⁺ (Ẏ_ref + K (Y_ref − Y))`` -- one equality level of a Stack.

    Parameters
    ----------
    robot : Robot
    gain : float
        ``K`` (1/s), default 0 (the thesis's open-loop map).
    solver : str, optional
        QP backend (not used while the level's closed form applies: always, here).
    """

    def __init__(self, robot, gain: float = 0.0, solver: str | None = None) -> None:
        self.robot = _robot(robot)
        self.task = PositionTask(robot, gain=gain)
        self.ik = IK(robot, [self.task], dt=1.0, limits=None, solver=solver)

    def velocity(self, q, t: float = 0.0, reference=None) -> np.ndarray:
        return self.ik.velocity(q, t, reference)


def sphere_basis(y, center) -> tuple[np.ndarray, np.ndarray]:
    """Prop. 4.1: ``v₁ = (−(z − c_z), 0, x − c_x)``, ``v₂ = (−(y − c_y), x − c_x, 0)``.

    Tangent to every sphere about ``center`` and involutive; independent except on the
    line ``x = c_x`` (the "equator" of the thesis).
    """
    d = np.asarray(y, dtype=float) - np.asarray(center, dtype=float)
    return np.array([-d[2], 0.0, d[0]]), np.array([-d[1], d[0], 0.0])


def sphere_forms(robot, center, complementary):
    """Thm 4.2's 1-forms ``q ↦ [ω₁(q); ω₄; ω₅; …]`` (rows, ``(1 + k) × nq``).

    ``ω₁ = ∇_q h`` for the sphere ``h(y) = ‖y − center‖² − R²`` (its radius does not
    matter), pulled back through the robot; ``complementary`` are the constant 1-forms
    (``k × nq``, Ex. 4.4: ``[[1,0,0,0,1], [0,1,0,1,0]]``). Their dual fields are
    :func:`qpcoord.coordination.geometry.dual_fields`.
    """
    from .geometry import pullback

    c = np.asarray(center, dtype=float).reshape(-1)
    W = np.atleast_2d(np.asarray(complementary, dtype=float))
    if c.shape != (robot.m,) or W.shape[1] != robot.nq:
        raise ValueError(
            f"center must have {robot.m} entries and complementary {robot.nq} columns, "
            f"got {c.shape} and {W.shape}"
        )
    omega1 = pullback(robot, lambda y: 2.0 * (y - c))

    def forms(q) -> np.ndarray:
        return np.vstack((omega1(q), W))

    return forms


class OutputManifoldBasis:
    """§4.3.2 (Ex. 4.2): decompose ``Ẏ = α v₁ + β v₂`` in the sphere basis of Prop. 4.1
    (least squares), then ``q̇ = α J⁺v₁ + β J⁺v₂`` (Eq. 4.3).

    By linearity of ``J⁺`` this is ``J⁺`` applied to the part of ``Ẏ`` tangent to the
    sphere through the current end-effector point: on the sphere it equals
    :class:`PseudoInverse` up to the tracking error (the thesis's Fig. 4.4 differs from
    its Fig. 4.3; see the chapter 4 example for what is measured here).

    Parameters
    ----------
    robot : Robot
        Spatial robot (3 task rows).
    center : array_like, shape (3,)
        Sphere centre (m).
    gain : float
        ``K`` (1/s), default 0.

    Raises
    ------
    ValueError
        On the line ``x = c_x`` the basis degenerates: reported with the configuration.
    """

    def __init__(self, robot, center, gain: float = 0.0) -> None:
        self.robot = _robot(robot)
        if robot.m != 3:
            raise ValueError(f"the sphere basis needs 3 task rows, robot has {robot.m}")
        self.center = np.asarray(center, dtype=float).reshape(3)
        self.task = PositionTask(robot, gain=gain)

    def velocity(self, q, t: float = 0.0, reference=None) -> np.ndarray:
        q = self.robot.check_configuration(q)
        y_ref, v_ref = self.task.reference_at(t, reference)
        y, J = self.robot.kinematics(q)
        ydot = v_ref + self.task.gain * (y_ref - y)
        v1, v2 = sphere_basis(y, self.center)
        V = np.column_stack((v1, v2))
        s = np.linalg.svd(V, compute_uv=False)
        if s[-1] <= 1e-9 * max(1.0, s[0]):
            raise ValueError(
                f"the sphere basis degenerates at y = {y.tolist()} (x = c_x), q = {q.tolist()}"
            )
        ab = np.linalg.lstsq(V, ydot, rcond=None)[0]
        Jp = np.linalg.pinv(J)
        return ab[0] * (Jp @ v1) + ab[1] * (Jp @ v2)


class InvolutiveBasis(RigidExtension):
    """Thm 4.2 / Ex. 4.4: track ``Y`` with complementary integrable 1-forms held at zero.

    A :class:`RigidExtension` whose ``G`` are integrable 1-forms: the Stack has the position
    task as its level and ``ω q̇ = 0`` for the given 1-forms as hard constraints. When
    ``[J; ω]`` is square and invertible (5R with ω₄, ω₅) the solution is unique and equals
    ``α f₁ + β f₂`` with ``f₁, f₂`` dual to ``(ω₁, ω₄, ω₅)`` and ``Ẏ = α J f₁ + β J f₂``
    -- the construction of the theorem (``tests/test_schemes.py``). Fewer forms than
    ``nq − rows`` are accepted (the rest of the freedom goes to the minimum-norm ``q̇``).

    Parameters
    ----------
    robot : Robot
    forms : array_like, shape (k, nq), or callable
        Complementary 1-forms (Ex. 4.4: ``[[1,0,0,0,1], [0,1,0,1,0]]``).
    gain : float
        ``K`` (1/s), default 0.
    solver : str, optional
    tol : float
        Relative smallest singular value of ``[J; ω]`` below which
        :class:`~qpcoord.core.errors.AlgorithmicSingularity` is raised (default 1e-6).
    """

    def __init__(
        self, robot, forms, gain: float = 0.0, solver: str | None = None, tol: float = 1e-6
    ) -> None:
        super().__init__(robot, forms, gain=gain, tol=tol, square=False, solver=solver)
        self.forms = self.extension
