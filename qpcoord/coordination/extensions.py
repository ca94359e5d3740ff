"""Extensions of the Jacobian (thesis §5.3): rigid (Def. 5.2) and soft (Defs. 5.3/5.4).

- :class:`RigidExtension` -- Baillieul's extended Jacobian: ``[J; G] q̇ = [Ẏ; 0]`` with
  ``m + k = nq``, unique solution, periodic responses, but an *algorithmic singularity*
  wherever ``[J; G]`` loses rank while ``J`` does not: reported as
  :class:`~qpcoord.core.errors.AlgorithmicSingularity` with the configuration.
- :class:`SoftExtension` -- the softly-augmented Jacobian: the main task by ``J⁺``, then
  the gradients of potentials ``g₁, g₂, …`` in strict priority in the reduced null spaces
  (``q̇ = J⁺Ẏ + N₁N₁ᵀΦ₁ + N₂N₂ᵀΦ₂ + …``, ``Φ_k = −∇g_kᵀ g_k``).

Both are schemes for :func:`qpcoord.simulate` (``velocity(q, t, reference)``).
"""

from __future__ import annotations

import numpy as np

from ..core.errors import AlgorithmicSingularity
from ..core.linalg import filtered_svd, null_space, svd
from ..core.tasks import Equality
from ..kinematics.ik import DEFAULT_IK_DAMPING, IK
from ..kinematics.robot import Robot
from ..kinematics.tasks import KinematicTask, OneFormTask, PositionTask, _gain
from .potentials import Potential

__all__ = ["RigidExtension", "SoftExtension", "SOFT_METHODS"]

SOFT_METHODS = ("hierarchical", "nullspace")


def _robot(robot) -> Robot:
    if not isinstance(robot, Robot):
        raise ValueError(f"robot must be a qpcoord.Robot, got {type(robot).__name__}")
    return robot


class RigidExtension:
    """Def. 5.2: the rigidly extended Jacobian ``[J; G(q)] q̇ = [Ẏ_ref + K (Y_ref − Y); 0]``.

    Posed as a :class:`~qpcoord.Stack` (:class:`~qpcoord.IK`): the position task is the
    level, ``G q̇ = 0`` a hard constraint. After each step the relative smallest singular
    value ``σ_min/σ_max`` of ``[J; G]`` is checked; below ``tol`` the scheme raises
    :class:`~qpcoord.core.errors.AlgorithmicSingularity` carrying ``q`` and ``t``.
    ``sigma_min`` keeps the smallest value met (reset it with :meth:`reset`).

    Parameters
    ----------
    robot : Robot
    G : array_like, shape (k, nq), or callable ``q -> (k, nq)``
        The appended differential relations (1-forms).
    gain : float
        ``K`` (1/s), default 0 (the thesis's open-loop map).
    tol : float
        Relative singular-value threshold of an algorithmic singularity (default 1e-6).
    square : bool
        Require ``rows + k = nq`` (Def. 5.2, default). ``False`` accepts fewer rows (the
        remaining freedom then goes to the minimum-norm ``q̇``).
    solver : str, optional
    """

    def __init__(
        self,
        robot,
        G,
        gain: float = 0.0,
        tol: float = 1e-6,
        square: bool = True,
        solver: str | None = None,
    ) -> None:
        self.robot = _robot(robot)
        self.task = PositionTask(robot, gain=gain)
        self.extension = OneFormTask(robot, G, name="extension G")
        k = self.extension.task.A.shape[0]
        if square and robot.m + k != robot.nq:
            raise ValueError(
                f"Def. 5.2 needs a square [J; G]: {robot.m} task rows + {k} rows of G "
                f"≠ {robot.nq} joints"
            )
        if isinstance(tol, bool) or not np.isfinite(tol) or not 0 <= tol < 1:
            raise ValueError(f"tol must be in [0, 1), got {tol!r}")
        self.tol = float(tol)
        self.ik = IK(
            robot, [self.task], dt=1.0, limits=None, constraints=[self.extension], solver=solver
        )
        self.sigma_min = np.inf

    def reset(self) -> None:
        """Forget the smallest singular value met."""
        self.sigma_min = np.inf

    def velocity(self, q, t: float = 0.0, reference=None) -> np.ndarray:
        qdot, _ = self.ik.step(q, t, reference)
        s = svd(np.vstack((self.task.task.A, self.extension.task.A)), full=False)[1]
        ratio = float(s[-1] / s[0]) if s[0] > 0 else 0.0
        self.sigma_min = min(self.sigma_min, ratio)
        if ratio < self.tol:
            qq = np.asarray(q, dtype=float)
            raise AlgorithmicSingularity(
                f"algorithmic singularity at t = {t:.6g} s: [J; G] has relative smallest "
                f"singular value {ratio:.3g} < tol {self.tol:g} at q = {qq.tolist()}",
                q=qq.copy(),
                t=float(t),
                sigma=ratio,
            )
        return qdot


class _RateTask(KinematicTask):
    """Level of potential ``k`` in the QP form: ``∇g_k q̇ = r_k`` (numbers set by the scheme)."""

    def __init__(self, scheme: SoftExtension, k: int, name: str) -> None:
        self.robot = scheme.robot
        self.scheme = scheme
        self.k = k
        self.task = Equality(np.zeros((1, self.robot.nv)), np.zeros(1), name=name)

    def _refresh(self, q, t, dt, reference) -> Equality:
        s = self.scheme
        return self.task._assign(s._grads[self.k][None, :], s._rates[self.k : self.k + 1])


class SoftExtension:
    """Defs. 5.3/5.4: potentials tracked in strict priority in the reduced null spaces.

    The thesis's law (Def. 5.4 with Def. 5.3's gradients)::

        q̇ = J⁺Ẏ + N₁N₁ᵀΦ₁ + N₂N₂ᵀΦ₂ + …,    Φ_k = −c_k ∇g_k(q)ᵀ g_k(q)

    where ``Ẏ = Ẏ_ref + K (Y_ref − Y)``, ``N₁`` is an orthonormal basis of the null space
    of ``J`` and ``N_{k+1}`` of the null space of ``[J; ∇g₁; …; ∇g_k]`` (the reduced null
    spaces: the term of ``g_k`` changes neither ``Y`` nor ``g₁ … g_{k−1}`` to first order).

    ``method="nullspace"`` returns that formula. ``method="hierarchical"`` solves the same
    priorities as a lexicographic QP (:class:`~qpcoord.IK`): level 0 ``J q̇ = Ẏ``, level
    ``k`` ``∇g_k q̇ = r_k`` where ``r_k = ∇g_k q̇_formula`` is the rate the formula gives
    to ``g_k``. With no active inequality the two are equal (min-norm lexicographic solution
    = the nested projections; ``tests/test_extension.py``: 1e-9) as long as every level keeps
    some authority; a level whose authority falls below the stack's damping threshold
    (``1e-4`` by default) is damped by the QP, and near zero authority the QP's target is
    ill-conditioned: measured differences of 1e-8 rad/s at authority 3.7e-9 and 4.7e-4 rad/s
    at 6.6e-5 (5R, ``examples/ch5_hierarchy.py``). With ``limits`` the QP keeps them
    as **hard** bounds and each potential gets as much of its rate as the limits and the
    levels above allow -- the formula has no way to do that.

    Parameters
    ----------
    robot : Robot
    potentials : Potential or sequence of Potential
        ``g₁, g₂, …`` in priority order (:mod:`qpcoord.coordination.potentials`).
    method : {"hierarchical", "nullspace"}
    gain : float
        Closed-loop gain ``K`` (1/s) of the main task, default 0 (the thesis's open loop).
    scale : float or sequence of float
        ``c_k > 0`` multiplying each ``Φ_k`` (default 1; the thesis's α sits in ``g``).
    limits : "robot", sequence of Limit, or None
        Hard joint boxes for ``method="hierarchical"`` (as in :class:`~qpcoord.IK`);
        default none.
    dt : float
        Control period (s), used by :class:`~qpcoord.JointLimits`.
    solver : str, optional
    damping : float
        Relative singular-value damping of ``J⁺`` and of the stack (default
        :data:`~qpcoord.kinematics.ik.DEFAULT_IK_DAMPING`).

    Attributes
    ----------
    info : dict
        After each call: ``values`` (``g_k``), ``rates`` (``ġ_k = ∇g_k q̇`` achieved),
        ``authority`` (``‖N_kᵀ∇g_kᵀ‖/‖∇g_k‖``, 0 when the level cannot act: no freedom
        left, or its gradient lies in the span of the levels above), ``achievable``
        (``authority > 1e-9`` or ``∇g_k = 0``), ``free_dofs`` (columns of ``N_k``).

    Raises
    ------
    ValueError
        No redundancy (``nq ≤ rows``: δ = 0 leaves nothing for the potentials), an unknown
        method, limits with ``method="nullspace"``, a potential that is not a
        :class:`~qpcoord.coordination.potentials.Potential`, or (per step) a potential whose value
        or
        gradient is not finite or has the wrong shape.
    """

    def __init__(
        self,
        robot,
        potentials,
        method: str = "hierarchical",
        gain: float = 0.0,
        scale=1.0,
        limits=None,
        dt: float = 1e-3,
        solver: str | None = None,
        damping: float = DEFAULT_IK_DAMPING,
    ) -> None:
        self.robot = _robot(robot)
        if robot.nq <= robot.m:
            raise ValueError(
                f"robot {robot.name!r} has no redundancy (nq = {robot.nq} ≤ {robot.m} task "
                f"rows, δ = 0): there is no null space for the potentials"
            )
        if method not in SOFT_METHODS:
            raise ValueError(f"method must be one of {SOFT_METHODS}, got {method!r}")
        pots = [potentials] if isinstance(potentials, Potential) else list(potentials)
        if not pots:
            raise ValueError("potentials must hold at least one Potential")
        for i, p in enumerate(pots):
            if not isinstance(p, Potential):
                raise ValueError(
                    f"potentials[{i}] must be a qpcoord.potentials.Potential (wrap functions "
                    f"with FunctionPotential), got {p!r}"
                )
        c = np.broadcast_to(np.asarray(scale, dtype=float), (len(pots),)).copy()
        if not np.all(np.isfinite(c)) or np.any(c <= 0):
            raise ValueError(f"scale must be > 0 and finite, got {scale!r}")
        if method == "nullspace" and limits:
            raise ValueError("method='nullspace' cannot keep limits: use 'hierarchical'")
        if isinstance(damping, bool) or not np.isfinite(damping) or damping < 0:
            raise ValueError(f"damping must be >= 0, got {damping!r}")
        self.potentials: list[Potential] = pots
        self.scale = c
        self.method = method
        self.damping = float(damping)
        self.task = PositionTask(robot, gain=_gain(gain))
        n = robot.nq
        self._grads = np.zeros((len(pots), n))
        self._rates = np.zeros(len(pots))
        self.info: dict = {}
        self.ik: IK | None = None
        if method == "hierarchical":
            levels = [self.task] + [
                _RateTask(self, k, f"potential {k + 1}: {p.name}") for k, p in enumerate(pots)
            ]
            self.ik = IK(robot, levels, dt, limits=limits, solver=solver, damping=self.damping)

    def formula(self, q, t: float = 0.0, reference=None) -> np.ndarray:
        """The thesis's projection formula at ``(q, t)`` (rad/s); fills :attr:`info`."""
        q = self.robot.check_configuration(q)
        y_ref, v_ref = self.task.reference_at(t, reference)
        y, J = self.robot._kinematics(q)
        ydot = v_ref + self.task.gain * (y_ref - y)
        U, s, Vt, rank, gains, _ = filtered_svd(J, self.damping)
        qdot = Vt[:rank].T @ (gains * (U[:, :rank].T @ ydot))
        N = Vt[rank:].T  # nq × (nq − rank)
        K = len(self.potentials)
        values = np.zeros(K)
        authority = np.zeros(K)
        free = np.zeros(K, dtype=int)
        for k, pot in enumerate(self.potentials):
            g, grad = pot.evaluate(q)
            values[k] = g
            self._grads[k] = grad
            free[k] = N.shape[1]
            if N.shape[1] == 0:
                continue
            p = grad @ N  # components of ∇g_k in the free directions
            norm = float(np.linalg.norm(grad))
            authority[k] = float(np.linalg.norm(p)) / norm if norm > 0 else 0.0
            qdot = qdot - self.scale[k] * g * (N @ p)  # N Nᵀ Φ_k, Φ_k = −c ∇gᵀ g
            N = N @ null_space(p[None, :], scale=norm)
        rates = self._grads @ qdot
        self._rates[:] = rates
        self.info = {
            "values": values,
            "rates": rates,
            "authority": authority,
            "achievable": (authority > 1e-9) | (np.linalg.norm(self._grads, axis=1) == 0),
            "free_dofs": free,
        }
        return qdot

    def velocity(self, q, t: float = 0.0, reference=None) -> np.ndarray:
        """Joint velocity (rad/s) at ``(q, t)`` -- the scheme interface of :func:`simulate`."""
        qdot = self.formula(q, t, reference)
        if self.ik is None:
            return qdot
        x, _ = self.ik.step(q, t, reference)
        self.info["rates"] = self._grads @ x
        return x

    @property
    def last(self):
        """The stack's last :class:`~qpcoord.Solution` (``method="hierarchical"``)."""
        return None if self.ik is None else self.ik.last
