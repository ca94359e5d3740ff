"""Muscle-force sharing (thesis appendix A, Eqs A.20–A.31) as one prioritised stack.

Given the moment-arm matrix ``W(q)`` (3 × 11, m) and the generalised forces ``Q`` (N·m) a
motion needs, find muscle forces ``F`` (N) with

1. ``W F = Q`` (top level; best effort, ``‖W F − Q‖`` minimised, when no admissible F
   produces Q),
2. ``0 ≤ F ≤ F_max`` (hard bounds, Eq. A.24 with ``F_min`` at activation 0),
3. minimal stress cost ``Σ (F_i / PCSA_i)²`` (Eq. A.21 with ``e_i = 1/PCSA_i²``, A.23).

:func:`distribute` (and :class:`MuscleSharing`, which keeps one :class:`~qpcoord.Stack`
for a whole motion) solves it as ``Stack([Equality(W, Q), Equality(diag(1/PCSA), 0)],
bounds=Bounds(F_min, F_max))``. :func:`two_step` is the thesis's own method: the
stress-weighted pseudo-inverse (A.22), then, when that violates a bound, a QP over the
null-space multipliers μ (A.25–A.30). Both give the same forces (tested against each other
and against cvxpy). Activations are ``a = F / F_max`` (A.13, A.31: ``J = diag(F_max)``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
from scipy.optimize import linprog

from ..core.backends import check_solver, solve_dense_qp
from ..core.errors import InfeasibleError, SolverError
from ..core.stack import Solution, Stack
from ..core.tasks import Bounds, Equality

__all__ = [
    "Distribution",
    "MuscleSharing",
    "distribute",
    "two_step",
    "activations",
    "FEASIBLE_TOL",
]

#: Relative top-level residual ``‖W F − Q‖ / max(‖Q‖, Q_ref)`` under which Q counts as
#: produced; ``Q_ref`` = 1 N·m keeps Q = 0 on an absolute scale.
FEASIBLE_TOL = 1e-9
#: Scale of the generalised forces below which a residual is judged absolutely (N·m).
Q_REF = 1.0
#: The stack's point is polished on its active set (see :class:`MuscleSharing`) when its
#: top-level relative residual is at most this (interior-point backends leave ~1e-10…1e-8,
#: once 8e-7, measured). Safe to be generous: a polished point must meet W F = Q within
#: the bounds and the KKT conditions, which no point does when Q is out of reach.
POLISH_TOL = 1e-3
#: A force within this fraction of F_max of a bound counts as at that bound.
BOUND_TOL = 1e-9


@dataclass
class Distribution:
    """Muscle forces for one posture and load.

    Attributes
    ----------
    forces : numpy.ndarray, shape (m,)
        Muscle forces F (N), ``F_min ≤ F ≤ F_max`` (checked).
    activations : numpy.ndarray, shape (m,)
        ``F / F_max`` (dimensionless, Eq. A.31).
    stresses : numpy.ndarray, shape (m,)
        ``F / PCSA`` (Pa).
    Q : numpy.ndarray, shape (3,)
        Requested generalised forces (N·m).
    Q_achieved : numpy.ndarray, shape (3,)
        ``W F`` (N·m).
    residual : float
        ``‖W F − Q‖`` (N·m).
    relative_residual : float
        ``residual / max(‖Q‖, 1 N·m)``.
    feasible : bool
        ``relative_residual ≤ FEASIBLE_TOL``: Q is produced exactly. ``False`` means Q is
        beyond what the muscles can produce at this posture and F is the best effort
        (closest ``W F`` to Q, then least stress).
    bound_violation : float
        ``max(F_min − F, F − F_max, 0)`` (N) of the returned forces (never clipped beyond
        the polish's 1e-12·F_max rounding).
    saturated : numpy.ndarray of bool, shape (m,)
        Muscles at ``F_max`` (within ``BOUND_TOL · F_max``).
    inactive : numpy.ndarray of bool, shape (m,)
        Muscles at ``F_min`` = 0.
    method : str
        ``"stack"`` or ``"two-step"``.
    solve_time : float
        Wall-clock time of the distribution (s).
    solution : Solution or None
        The stack's :class:`~qpcoord.Solution` (``"stack"``).
    info : dict
        ``"two-step"``: ``F_eff`` (pseudo-inverse forces, N), ``mu`` (null-space
        multipliers), ``qp`` (whether the null-space QP ran), ``refined``.
    """

    forces: np.ndarray
    activations: np.ndarray
    stresses: np.ndarray
    Q: np.ndarray
    Q_achieved: np.ndarray
    residual: float
    relative_residual: float
    feasible: bool
    bound_violation: float
    saturated: np.ndarray
    inactive: np.ndarray
    method: str
    solve_time: float
    solution: Solution | None = None
    info: dict = field(default_factory=dict)


def activations(model, forces) -> np.ndarray:
    """Eq. A.31 with the linear force law A.13: ``a = F / F_max`` (dimensionless).

    Raises
    ------
    ValueError
        Wrong shape or a non-finite force (named).
    """
    F = _vector(forces, model.n_muscles, "forces")
    return F / model.f_max


def _vector(value, n: int, what: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a numeric array of length {n}, got {value!r}") from None
    if arr.shape != (n,):
        raise ValueError(f"{what} must have shape ({n},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        k = int(np.argwhere(~np.isfinite(arr))[0, 0])
        raise ValueError(f"{what}[{k}] is {float(arr[k])!r}: {what} must be finite")
    return arr


def _check_model(model) -> None:
    f_max = np.asarray(model.f_max, dtype=float)
    if not np.all(np.isfinite(f_max)) or np.any(f_max <= 0.0):
        k = int(np.argmax(~np.isfinite(f_max) | (f_max <= 0.0)))
        raise ValueError(f"f_max[{k}] ({model.names[k]!r}) = {float(f_max[k])!r} N: must be > 0")


def _result(model, W, Q, F, method, t0, solution=None, info=None) -> Distribution:
    lo, hi = model.f_min, model.f_max
    viol = max(float(np.max(lo - F)), float(np.max(F - hi)), 0.0)
    if not np.all(np.isfinite(F)) or viol > 1e-6 * float(np.max(hi)):
        raise SolverError(f"muscle forces violate their bounds by {viol:.3g} N")
    QA = W @ F
    res = float(np.linalg.norm(QA - Q))
    rel = res / max(float(np.linalg.norm(Q)), Q_REF)
    return Distribution(
        forces=F,
        activations=F / hi,
        stresses=F / model.pcsa,
        Q=Q.copy(),
        Q_achieved=QA,
        residual=res,
        relative_residual=rel,
        feasible=rel <= FEASIBLE_TOL,
        bound_violation=viol,
        saturated=F >= hi * (1.0 - BOUND_TOL),
        inactive=F <= lo + BOUND_TOL * hi,
        method=method,
        solve_time=time.perf_counter() - t0,
        solution=solution,
        info=info or {},
    )


class MuscleSharing:
    """One stack for a whole motion: ``W F = Q`` ≻ minimal stress, ``0 ≤ F ≤ F_max`` hard.

    Parameters
    ----------
    model : ShoulderModel
        From ``qpcoord.robots.load("shoulder")`` (any object with ``n_muscles``,
        ``f_min``, ``f_max``, ``pcsa``, ``names`` and ``moment_arms(q)``).
    solver : str, optional
        QP backend (default: qpcoord's default).

    Notes
    -----
    The stress level is ``Equality(diag(s / PCSA), 0)`` with ``s = mean(PCSA)``: its cost
    is ``s² Σ (F_i/PCSA_i)²``, the thesis's cost up to a constant (``s`` only keeps the
    numbers of order 1/N; a strict hierarchy's answer does not depend on it).

    With piqp, clarabel, osqp (and on some problems proxqp) the stack's top level is met
    to only ~1e-10…1e-8 relative, 8e-7 once for clarabel (the stack's refinement of that
    level is rejected; measured, see ``docs/appA.md``). When the stack needed a QP and its
    top-level relative residual is ≤ ``POLISH_TOL``, the
    point is then solved exactly on its active set: the muscles at a bound stay there, the
    others get the stress-weighted pseudo-inverse of the rest of Q. The polished point is
    kept only if it is within the bounds and passes the KKT conditions of the problem
    (a certificate that it is the optimum, see ``_refine``);
    ``Distribution.info["polished"]`` says whether it was used.
    """

    def __init__(self, model, solver: str | None = None) -> None:
        _check_model(model)
        self.model = model
        self.solver = solver
        m = model.n_muscles
        pcsa = np.asarray(model.pcsa, dtype=float)
        self._top = Equality(np.zeros((3, m)), np.zeros(3), name="generalised forces W F = Q")
        self._stress = Equality(
            np.diag(np.mean(pcsa) / pcsa), np.zeros(m), name="muscle stress F/PCSA"
        )
        self.stack = Stack([self._top, self._stress], bounds=Bounds(model.f_min, model.f_max))
        self._e = (np.mean(pcsa) / pcsa) ** 2

    def solve(self, q, Q) -> Distribution:
        """Muscle forces for posture ``q`` (rad) and generalised forces ``Q`` (N·m).

        Raises
        ------
        ValueError
            ``q`` outside the model range or ``Q`` of the wrong shape or not finite.
        SolverError
            The backend failed (never an unchecked point).
        """
        t0 = time.perf_counter()
        Q = _vector(Q, 3, "Q")
        W = self.model.moment_arms(q)
        self._top.update(A=W, b=Q)
        # no warm start: measured on the appendix A motion it slowed proxqp (63 → 132 ms
        # median) and osqp (21 → 55 ms) and did not help daqp or quadprog
        sol = self.stack.solve(solver=self.solver)
        F = sol.x
        info = {"polished": False}
        rel = sol.level_residuals[0] / max(float(np.linalg.norm(Q)), Q_REF)
        if sol.info.get("qp_calls") and rel <= POLISH_TOL:
            Fp = _refine(W, Q, self._e, self.model.f_min, self.model.f_max, F)
            if Fp is not None:
                F = Fp
                info["polished"] = True
        return _result(self.model, W, Q, F, "stack", t0, solution=sol, info=info)


def distribute(model, q, Q, solver: str | None = None, method: str = "stack") -> Distribution:
    """Muscle forces producing ``Q`` at posture ``q`` with least stress (Eqs A.20–A.31).

    Parameters
    ----------
    model : ShoulderModel
        The muscle model (``qpcoord.robots.load("shoulder")``).
    q : array_like, shape (3,)
        Posture ``(θ, ϕ, ψ)`` (rad), inside the model range.
    Q : array_like, shape (3,)
        Generalised forces to produce (N·m), e.g. ``model.generalised_forces(q, qd, qdd)``.
    solver : str, optional
        QP backend name (:func:`qpcoord.available_solvers`).
    method : {"stack", "two-step"}
        One prioritised stack (best effort when Q is out of reach), or the thesis's
        pseudo-inverse + null-space QP (:func:`two_step`; raises when Q is out of reach).

    Returns
    -------
    Distribution

    Raises
    ------
    ValueError
        Bad ``q``, ``Q`` (NaN, shape), model (``f_max ≤ 0``) or ``method``.
    InfeasibleError
        ``method="two-step"`` and no admissible F produces Q.
    SolverError
        A backend failed.
    """
    if method == "stack":
        return MuscleSharing(model, solver).solve(q, Q)
    if method == "two-step":
        return two_step(model, q, Q, solver=solver)
    raise ValueError(f"method must be 'stack' or 'two-step', got {method!r}")


def two_step(model, q, Q, solver: str | None = None) -> Distribution:
    """The thesis's two coordinations: pseudo-inverse (A.22), then null-space QP (A.28).

    1. ``F_eff = E⁻¹Wᵀ(W E⁻¹ Wᵀ)⁻¹ Q`` with ``E = diag(1/PCSA²)`` (A.22–A.23).
    2. If ``F_eff`` leaves ``[F_min, F_max]``: ``F = F_eff + N μ`` with ``N`` a basis of
       null(W) (11 × 8) and μ minimising ``½ μᵀ (Nᵀ E N) μ`` subject to
       ``F_min ≤ F_eff + N μ ≤ F_max`` (A.26–A.29; the thesis's split of μ into 16
       variables tied by A.30 is the same problem). The QP needs no linear term:
       ``Nᵀ E F_eff = Nᵀ Wᵀ λ = 0``. The QP's active set is then solved exactly
       (weighted pseudo-inverse on the free muscles, kept if it passes the KKT conditions)
       to remove the backend's tolerance.

    Parameters
    ----------
    model, q, Q, solver
        As :func:`distribute`. The QP goes to the backend directly
        (:func:`qpcoord.core.backends.solve_dense_qp`, the Stack's tuned settings), not through
        a :class:`~qpcoord.Stack`: an independent formulation of the same problem.

    Raises
    ------
    ValueError
        Bad input, or ``W`` not of rank 3 at ``q``.
    InfeasibleError
        No ``F`` in the bounds gives ``W F = Q`` (decided by an LP, HiGHS): the two-step
        method has no best-effort answer.
    SolverError
        The QP backend failed.
    """
    t0 = time.perf_counter()
    _check_model(model)
    Q = _vector(Q, 3, "Q")
    W = model.moment_arms(q)
    lo, hi = model.f_min, model.f_max
    pcsa = np.asarray(model.pcsa, dtype=float)
    e = (np.mean(pcsa) / pcsa) ** 2  # E up to a constant factor (cancels in A.22)
    s = np.linalg.svd(W, compute_uv=False)
    if s[-1] <= 1e-10 * s[0]:
        raise ValueError(f"W has rank < 3 at q = {np.asarray(q).tolist()} (singular values {s})")
    Ei = 1.0 / e
    F_eff = Ei * (W.T @ np.linalg.solve((W * Ei) @ W.T, Q))
    info = {"F_eff": F_eff, "mu": np.zeros(W.shape[1] - 3), "qp": False, "refined": False}
    tol = BOUND_TOL * hi
    if np.all(F_eff >= lo - tol) and np.all(F_eff <= hi + tol):
        return _result(model, W, Q, F_eff, "two-step", t0, info=info)
    # is Q reachable at all?  (LP; the thesis's QP would just fail)
    lp = linprog(
        np.zeros(W.shape[1]), A_eq=W, b_eq=Q, bounds=list(zip(lo, hi, strict=True)), method="highs"
    )
    if lp.status == 2:
        raise InfeasibleError(
            f"Q = {Q.tolist()} N·m is beyond what the muscles can produce at "
            f"q = {np.asarray(q, dtype=float).tolist()} rad (no 0 ≤ F ≤ F_max with W F = Q)"
        )
    N = scipy.linalg.null_space(W)  # 11 × 8, orthonormal
    H = N.T @ (e[:, None] * N)
    name = check_solver(solver)
    res = solve_dense_qp(name, H, np.zeros(N.shape[1]), N, lo - F_eff, hi - F_eff)
    if res.code != 0:
        raise SolverError(f"null-space QP (A.28) at q = {q}, Q = {Q.tolist()}: {res.message}")
    mu = res.y
    F = F_eff + N @ mu
    info.update(mu=mu, qp=True)
    F_ref = _refine(W, Q, e, lo, hi, F)
    if F_ref is not None:
        F = F_ref
        info["refined"] = True
    return _result(model, W, Q, F, "two-step", t0, info=info)


def _refine(W, Q, e, lo, hi, F, active_tol: float = 1e-6, kkt_tol: float = 1e-8):
    """Exact optimum on the active set of an approximate answer ``F``, with a certificate.

    Muscles within ``active_tol · F_max`` of a bound are pinned there, the others get the
    weighted pseudo-inverse of the rest of Q: ``F_f = E_f⁻¹ W_fᵀ λ``. The point is returned
    only if it is admissible and meets the KKT conditions of
    ``min ½ Σ e_i F_i²  s.t.  W F = Q,  lo ≤ F ≤ hi`` — ``(Wᵀλ)_i ≤ e_i lo_i`` for muscles
    at ``lo`` and ``≥ e_i hi_i`` at ``hi`` (to ``kkt_tol`` relative) — so that it is *the*
    optimum (the problem is strictly convex). Otherwise ``None``.
    """
    span = hi - lo
    at_lo = F <= lo + active_tol * span
    at_hi = F >= hi - active_tol * span
    free = ~(at_lo | at_hi)
    Fx = np.where(at_hi, hi, lo).astype(float)
    rhs = Q - W[:, ~free] @ Fx[~free]
    Wf = W[:, free]
    if Wf.shape[1] < W.shape[0] or np.linalg.matrix_rank(Wf) < W.shape[0]:
        return None
    Ei = 1.0 / e[free]
    lam = np.linalg.solve((Wf * Ei) @ Wf.T, rhs)
    Fx[free] = Ei * (Wf.T @ lam)
    if np.any(Fx < lo - 1e-12 * span) or np.any(Fx > hi + 1e-12 * span):
        return None
    g = W.T @ lam  # stationarity: e F = Wᵀλ + ν_lo − ν_hi, ν ≥ 0
    scale = kkt_tol * max(float(np.max(np.abs(g))), float(np.max(e * hi)))
    if np.any(g[at_lo] > e[at_lo] * lo[at_lo] + scale):
        return None
    if np.any(g[at_hi] < e[at_hi] * hi[at_hi] - scale):
        return None
    return np.clip(Fx, lo, hi)
