"""Model-predictive coordination of the DDL as a prioritised stack, one QP per control step.

The dual stage is predicted with its linearised model (:meth:`DualStage.linearise`, inputs
piezo voltage ``v`` and stepper field phase ``α``) plus an integrating disturbance force on
the carriage (offset-free MPC: it absorbs the flexure load, detent and friction the linear
model lacks). The horizon is *move-blocked*: block ``j`` holds its inputs for ``L_j`` control
periods (default ``1, 2, 4, …, 128``: 255 periods, 32 ms at 8 kHz, with 16 variables), the
decision variables are the input increments ``Δv_j, Δα_j`` and predictions are taken at the
block ends. Condensed, every task matrix is constant; only right-hand sides move.

The stack (``qc.Stack``):

* hard: the fine stroke at every block end tightened by ``margin`` (default 10 % of the
  stroke at each end), the amplifier range ``v_min ≤ v_j ≤ v_max``, and bounds
  ``|Δα_j| ≤ Δα_max L_j`` that keep the carriage below ``max_speed`` (synchronism);
* level 0: output tracking ``y_j = r`` (µm);
* level 1: fine stage centred ``y_f,j = mid-stroke`` (µm) -- the saturation margin;
* level 2: least effort ``Δα_j = 0`` (rad) and ``Δv_j = 0`` (in units of
  :data:`V_EFFORT` = 10 V: the coarse phase costs most).

``method="weighted"`` solves it as one QP on a persistent workspace (native where built, else daqp)
(:class:`qpcoord.core.persistent.PersistentQP`, hot-started); ``method="hierarchical"`` solves
the strict hierarchy with :meth:`qpcoord.Stack.solve` each step (exact priorities, slower).
If a step's QP fails (infeasible hard constraints, backend failure), the step uses the fine
PI of a shadow :class:`~.coordinator.SisoCoordinator` (no feed-forward) with the field phase
held, and counts it in :attr:`MPC.fallback_steps`.

State estimate: the fine stage from its model driven by the applied voltage (as the thesis's
coordinator), the carriage position, speed and disturbance from a steady-state Kalman filter
on ``ŷ_c = y − ŷ_f`` (process noise: the flexure-load change at ``max_speed`` and the Coulomb
friction force, per period; measurement noise: the 1.25 nm quantisation).
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy.linalg import expm, solve_discrete_are

from ..core.persistent import PersistentQP
from ..core.stack import Stack
from ..core.tasks import Bounds, Equality, Inequality
from ._check import positive
from .coordinator import SisoCoordinator
from .guard import MeasurementGuard, guard_arg

__all__ = ["MPC", "prediction_model", "condense", "lq_first_move", "DEFAULT_BLOCKS"]

#: Default move-blocking: block lengths in control periods (255 periods in all).
DEFAULT_BLOCKS = (1, 2, 4, 8, 16, 32, 64, 128)

_UM = 1e6  # rows in micrometres: keeps the QP's numbers near 1
#: Voltage increment that costs as much effort as 1 rad of field phase (level 2), V.
V_EFFORT = 10.0


def prediction_model(plant, fs: float, current: float = 1.5):
    """Discrete model ``x⁺ = A x + B u`` at ``1/fs`` of the dual stage with a disturbance.

    The continuous model of :func:`qpcoord.ddl.lqr.design_model` (shared with the LQR:
    detent stiffness averaged over a full step, so the static gain α → y_c is right over
    moves longer than 10 µm) about the plant's current carriage position, plus a constant
    carriage acceleration ``d`` (the disturbance of offset-free MPC), held over each period.

    States ``(y_f [m], ẏ_f [m/s], y_c − y_c0 [m], ẏ_c [m/s], d [m/s²])``, inputs
    ``(v [V], α − α0 [rad])``, with ``(y_c0, α0)`` the plant's rest position and field phase
    at call time. The fine part is absolute (its model is linear, ``y_f = K v`` at rest).

    Returns
    -------
    A : ndarray, shape (5, 5)
    B : ndarray, shape (5, 2)
    """
    from .lqr import design_model

    fs = positive("fs", fs)
    lin = design_model(plant, fs, plant.y_c, current).continuous
    Ac = np.zeros((5, 5))
    Bc = np.zeros((5, 2))
    Ac[:4, :4] = np.asarray(lin.A)
    Bc[:4, :] = np.asarray(lin.B)
    Ac[3, 4] = 1.0
    M = np.zeros((7, 7))
    M[:5, :5] = Ac
    M[:5, 5:] = Bc
    E = expm(M / fs)
    return E[:5, :5], E[:5, 5:]


def condense(A, B, blocks):
    """Condensed predictions over a move-blocked horizon of input *increments*.

    With inputs held over block ``j`` (``L_j`` periods) at ``u_j = u₋₁ + Σ_{i≤j} Δu_i``, the
    state at the end of block ``j`` is ``x_j = Φ_j x₀ + Ψ_j u₋₁ + Γ_j ΔU``.

    Parameters
    ----------
    A : ndarray, shape (nx, nx)
    B : ndarray, shape (nx, nu)
    blocks : sequence of int
        Block lengths, periods.

    Returns
    -------
    Phi : ndarray, shape (N, nx, nx)
    Psi : ndarray, shape (N, nx, nu)
    Gam : ndarray, shape (N, nx, N·nu)
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    nx, nu = B.shape
    N = len(blocks)
    Phi = np.eye(nx)
    Psi = np.zeros((nx, nu))
    Gam = np.zeros((nx, nu * N))
    rows_phi, rows_psi, rows_gam = [], [], []
    for j, L in enumerate(blocks):
        Aj = np.linalg.matrix_power(A, L)
        Bj = sum(np.linalg.matrix_power(A, i) for i in range(L)) @ B
        S = np.zeros((nu, nu * N))
        for i in range(j + 1):
            S[:, nu * i : nu * i + nu] = np.eye(nu)
        Phi, Psi, Gam = Aj @ Phi, Aj @ Psi + Bj, Aj @ Gam + Bj @ S
        rows_phi.append(Phi)
        rows_psi.append(Psi)
        rows_gam.append(Gam)
    return np.stack(rows_phi), np.stack(rows_psi), np.stack(rows_gam)


def _sqrt_psd(M, name: str) -> np.ndarray:
    """Symmetric square root of a positive semi-definite matrix (``ValueError`` otherwise)."""
    M = np.asarray(M, dtype=float)
    if M.ndim != 2 or M.shape[0] != M.shape[1] or not np.allclose(M, M.T):
        raise ValueError(f"{name} must be a symmetric square matrix, got shape {M.shape}")
    lam, V = np.linalg.eigh(M)
    if lam.min() < -1e-12 * max(1.0, abs(lam.max())):
        raise ValueError(f"{name} must be positive semi-definite (eigenvalue {lam.min():.3g})")
    return (V * np.sqrt(np.clip(lam, 0.0, None))) @ V.T


def lq_first_move(A, B, Q, R, P, horizon: int, x0, method: str = "hierarchical") -> np.ndarray:
    """First input of the finite-horizon LQ problem, posed and solved as a :class:`Stack`.

    ``min Σ_{j<N} (x_jᵀQx_j + u_jᵀRu_j) + x_NᵀPx_N`` over ``u_0 … u_{N−1}`` (one level of
    rows ``√Q x_j``, ``√R u_j``, ``√P x_N``, condensed with :func:`condense`; no constraint).
    With ``P`` the discrete Riccati solution this is the LQR's ``−K x₀`` for every horizon:
    ``tests/test_ddl_mpc.py`` checks it on the dual-stage model.
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    nx, nu = B.shape
    x0 = np.asarray(x0, dtype=float).reshape(nx)
    N = int(horizon)
    if N < 1:
        raise ValueError(f"horizon must be >= 1, got {horizon!r}")
    Phi, Psi, Gam = condense(A, B, (1,) * N)  # u₋₁ = 0: ΔU are cumulative inputs
    Lq, Lr, Lp = (_sqrt_psd(M, name) for M, name in ((Q, "Q"), (R, "R"), (P, "P")))
    rows, rhs = [], []  # (x_0ᵀQx_0 is a constant: no row)
    for j in range(N):
        S = np.zeros((nu, nu * N))
        for i in range(j + 1):
            S[:, nu * i : nu * i + nu] = np.eye(nu)
        rows.append(Lr @ S)
        rhs.append(np.zeros(nu))
        Lx = Lp if j == N - 1 else Lq
        rows.append(Lx @ Gam[j])
        rhs.append(-Lx @ (Phi[j] @ x0))
    stack = Stack([Equality(np.vstack(rows), np.concatenate(rhs), name="LQ cost")])
    dU = stack.solve(method=method).x
    return dU[:nu].copy()


class MPC:
    """Condensed, move-blocked MPC of the dual stage posed as a prioritised stack.

    Parameters
    ----------
    method : {"weighted", "hierarchical"}
        One weighted QP on a persistent workspace (default; native where built, else
        daqp), or the strict hierarchy.
    blocks : sequence of int
        Move-blocking lengths, control periods (default :data:`DEFAULT_BLOCKS`).
    margin : float
        Saturation margin, fraction of the fine stroke kept free at each end, in [0, 0.5).
    weight_ratio : float
        Level weighting of ``method="weighted"`` (default 1e-3 per level).
    current : float
        Field amplitude, A (the coordinator's 1.5 A).
    max_speed : float
        Carriage speed limit, m/s (the coordinator's 3 mm/s).
    solver : str
        Backend of ``method="hierarchical"`` (default daqp).
    deadline : float, optional
        Time budget of a step, s (e.g. ``125e-6`` at 8 kHz). A step whose QP answer comes
        later uses the shadow fine PI's command with the phase held, as a failed step does,
        and is counted in :attr:`late_steps`. Default ``None``: no deadline, so that a
        simulation does not depend on the machine's speed.
    guard : MeasurementGuard, optional
        Measurement guard (default: a new :class:`.guard.MeasurementGuard` with the plant's
        physical bounds). A rejected measurement is replaced by the Kalman
        filter's predicted output (the measurement update is skipped); the shadow fine PI
        receives the same guarded value.

    Attributes
    ----------
    fallback_steps : int
        Steps whose QP failed (the shadow fine PI answered).
    late_steps : int
        Steps whose QP missed ``deadline`` (the shadow fine PI answered).
    solve_times : list of float
        Wall time of each step's ``step`` call, s (state update + QP).
    guard : MeasurementGuard
        The measurement guard (``guard.rejected``: measurements rejected).
    """

    def __init__(
        self,
        method: str = "weighted",
        blocks=DEFAULT_BLOCKS,
        margin: float = 0.1,
        weight_ratio: float = 1e-3,
        current: float = 1.5,
        max_speed: float = 3.0e-3,
        solver: str = "daqp",
        deadline: float | None = None,
        guard: MeasurementGuard | None = None,
    ) -> None:
        if method not in ("weighted", "hierarchical"):
            raise ValueError(f"method must be 'weighted' or 'hierarchical', got {method!r}")
        blocks = tuple(int(b) for b in blocks)
        if len(blocks) < 1 or any(b < 1 for b in blocks):
            raise ValueError(f"blocks must be a non-empty sequence of integers >= 1, got {blocks}")
        if isinstance(margin, bool) or not np.isfinite(margin) or not 0 <= margin < 0.5:
            raise ValueError(f"margin must be in [0, 0.5) of the stroke, got {margin!r}")
        self.method = method
        self.blocks = blocks
        self.margin = float(margin)
        self.weight_ratio = positive("weight_ratio", weight_ratio)
        self.current = positive("current", current)
        self.max_speed = positive("max_speed", max_speed)
        self.solver = solver
        if deadline is not None:
            deadline = positive("deadline", deadline)
        self.deadline = deadline
        self.guard = guard_arg(guard)
        self.late_steps = 0
        self.y_c_hat = 0.0
        self.fallback_steps = 0
        self.solve_times: list[float] = []

    # ------------------------------------------------------------------ design
    def _condense(self, A, B):
        return condense(A, B, self.blocks)

    def reset(self, plant, fs: float, y0: float, r0: float) -> None:
        """Design for ``plant`` (at rest, just reset) at ``fs`` Hz and initialise the state."""
        fs = positive("fs", fs)
        fp = plant.fine
        st = plant.stepper
        self._fs = fs
        A, B = prediction_model(plant, fs, self.current)
        self._A, self._B = A, B
        Phi, Psi, Gam = self._condense(A, B)
        N = len(self.blocks)
        cy = np.array([1.0, 0.0, 1.0, 0.0, 0.0])
        cf = np.array([1.0, 0.0, 0.0, 0.0, 0.0])
        # output rows at the block ends: c ᵀ Φ_j (N, 5), c ᵀ Ψ_j (N, 2)
        self._Py, self._Ppy = np.einsum("k,jkn->jn", cy, Phi), np.einsum("k,jkn->jn", cy, Psi)
        self._Pf, self._Ppf = np.einsum("k,jkn->jn", cf, Phi), np.einsum("k,jkn->jn", cf, Psi)
        Gy = np.einsum("k,jkn->jn", cy, Gam) * _UM
        Gf = np.einsum("k,jkn->jn", cf, Gam) * _UM
        # inputs: cumulative voltage rows (v_j = v_prev + Σ Δv_i)
        Sv = np.zeros((N, 2 * N))
        for j in range(N):
            Sv[j, 0 : 2 * j + 1 : 2] = 1.0
        # effort rows: every increment, Δα in rad and Δv in units of V_EFFORT volts (the
        # voltage rows keep the QP well conditioned: without them the later blocks' Δv are
        # set by the 1e-9 regularisation alone, cond(H) ≈ 1.5e9 measured)
        Sa = np.eye(2 * N)
        Sa[0::2] /= V_EFFORT
        stroke = fp.stroke_max - fp.stroke_min
        self._f_lo = fp.stroke_min + self.margin * stroke
        self._f_hi = fp.stroke_max - self.margin * stroke
        self._f_mid = 0.5 * (fp.stroke_min + fp.stroke_max)
        self._vmin, self._vmax = fp.v_min, fp.v_max
        self.track = Equality(Gy, np.zeros(N), name="output tracking (µm)")
        self.centre = Equality(Gf, np.zeros(N), name="fine centred (µm)")
        self.effort = Equality(Sa, np.zeros(2 * N), name="effort (rad, V/V_EFFORT)")
        self.stroke = Inequality(Gf, -1.0, 1.0, name="fine stroke with margin (µm)")
        self.volts = Inequality(Sv, -1.0, 1.0, name="amplifier range (V)")
        m_per_rad = st.screw_radius / st.pole_pairs
        dmax = self.max_speed / fs / m_per_rad  # rad per period
        ub = np.full(2 * N, np.inf)
        ub[1::2] = dmax * np.asarray(self.blocks, dtype=float)
        self.bounds = Bounds(-ub, ub, name="synchronism (phase rate)")
        self.stack = Stack(
            [self.track, self.centre, self.effort],
            bounds=self.bounds,
            constraints=[self.stroke, self.volts],
            weight_ratio=self.weight_ratio,
        )
        self._pq = PersistentQP(self.stack) if self.method == "weighted" else None
        # carriage Kalman filter on (y_c − y_c0, ẏ_c, d) with measurement ŷ_c
        Ac, Bc = A[2:, 2:], B[2:, 1]
        mass = plant.carriage_mass(plant.y_c)
        q_d = (plant.flexure.spring_rate * self.max_speed / mass / fs) ** 2
        q_v = (st.coulomb_torque / st.screw_radius / mass / fs) ** 2
        Qn = np.diag([1e-30, q_v, q_d])
        Rn = np.array([[max(plant.resolution, 1e-12) ** 2 / 12.0 + plant.noise_rms**2]])
        C = np.array([[1.0, 0.0, 0.0]])
        P = solve_discrete_are(Ac.T, C.T, Qn, Rn)
        self._K = (P @ C.T / (C @ P @ C.T + Rn)).ravel()
        self._Ac, self._Bc = Ac, Bc
        # initial state: at rest
        v0 = plant.v_applied
        self._v = v0
        self._alpha0 = plant.equilibrium_phase(self.current)
        self._alpha = self._alpha0
        self._yc0 = float(plant.y_c)
        self._xf = np.array([fp.gain * v0, 0.0])
        self._xc = np.zeros(3)  # (y_c − y_c0, ẏ_c, d), prior for the first measurement
        self._theta = np.zeros(8)  # (x0, u_prev, r)
        self._z = self._theta[:7]  # (x0, u_prev)
        # per step, one matvec gives the free response of (y, y_f, y_f, y_f) at the block
        # ends from (x0, u_prev); the four right-hand sides (tracking, centring, stroke
        # lower and upper, µm) are views of one buffer, refreshed by one multiply-add
        Pyz = np.hstack((self._Py, self._Ppy))
        Pfz = np.hstack((self._Pf, self._Ppf))
        self._Pfree = -_UM * np.vstack((Pyz, Pfz, Pfz, Pfz))
        self._rhs_off = _UM * np.concatenate(
            (
                np.full(N, -self._yc0),
                np.full(N, self._f_mid),
                np.full(N, self._f_lo),
                np.full(N, self._f_hi),
            )
        )
        self._rhs_r = np.concatenate((np.full(N, _UM), np.zeros(3 * N)))
        self._rhs = self._rhs_off.copy()
        self.track.b = self._rhs[:N]
        self.centre.b = self._rhs[N : 2 * N]
        self.stroke.lower = self._rhs[2 * N : 3 * N]
        self.stroke.upper = self._rhs[3 * N :]
        self._ABx = np.hstack((A, B))  # estimate update: x⁺ = A x + B u from (x, u)
        if self._pq is not None:
            # every right-hand side and limit is affine in θ = (x0, u_prev, r)
            def rows(k: int, r_coef: float):
                sl = slice(k * N, (k + 1) * N)
                M = np.hstack((self._Pfree[sl], np.full((N, 1), r_coef)))
                return self._rhs_off[sl], M

            dv = np.zeros((N, 8))
            dv[:, 5] = -1.0  # v_j − v_prev limits: (v_min − v_prev, v_max − v_prev)
            self._pq.parametrize(
                8,
                {
                    self.track: rows(0, _UM),
                    self.centre: rows(1, 0.0),
                    self.stroke: (rows(2, 0.0), rows(3, 0.0)),
                    self.volts: ((np.full(N, self._vmin), dv), (np.full(N, self._vmax), dv)),
                },
            )
        self._zu = np.zeros(7)
        self._Af, self._Bf = A[:2, :2], B[:2, 0]
        self._shadow = SisoCoordinator(current=self.current, feedforward=False)
        self._shadow.reset(plant, fs, y0, r0)
        self.y_c_hat = y0 - self._xf[0]
        self.guard.reset(plant, fs, y0, r0)
        self.fallback_steps = 0
        self.late_steps = 0
        self.solve_times = []

    def sync_tasks(self) -> None:
        """Write the last step's QP numbers into the stack's tasks.

        With ``method="weighted"`` the persistent QP reads its parameters
        ``θ = (x0, u_prev, r)`` directly and the tasks are not updated every step; call
        this to inspect them or to solve the same QP with another method or backend
        (``mpc.stack.solve(...)``).
        """
        if self._pq is not None:
            self._pq.write_tasks(self._theta)

    # ------------------------------------------------------------------ per step
    def step(self, y: float, r: float) -> tuple[float, float, float]:
        """One control period: measurement ``y`` (m), reference ``r`` (m) → (V, A, A)."""
        t0 = time.perf_counter()
        # estimate: fine model (prior for this sample) and carriage Kalman update
        xf = self._xf
        xc = self._xc
        y, r = self.guard.filter(y, r, self._yc0 + xc[0] + xf[0])
        z = y - xf[0] - self._yc0
        xc += self._K * (z - xc[0])
        self.y_c_hat = self._yc0 + xc[0]
        theta = self._theta  # (x0, u_prev, r): the QP's parameters
        z7 = self._z  # a view of its first 7 entries
        z7[:2] = xf
        z7[2:5] = xc
        z7[5] = self._v
        z7[6] = self._alpha - self._alpha0
        theta[7] = r
        shadow_v, _, _ = self._shadow.step(y, r)
        try:
            if self._pq is not None:
                # right-hand sides and limits are affine in θ (declared at reset)
                x = self._pq.solve_theta(theta)
            else:
                # right-hand sides (µm): offsets + r (tracking rows) − free response
                rhs = self._rhs
                np.dot(self._Pfree, z7, out=rhs)
                rhs += self._rhs_off
                rhs += r * self._rhs_r
                self.volts._assign(self._vmin - self._v, self._vmax - self._v)
                x = self.stack.solve(solver=self.solver, method="hierarchical").x
            if self.deadline is not None and time.perf_counter() - t0 > self.deadline:
                self.late_steps += 1
                v, alpha = shadow_v, self._alpha
            else:
                v, alpha = self._v + float(x[0]), self._alpha + float(x[1])
        except (ValueError, RuntimeError):
            self.fallback_steps += 1
            v, alpha = shadow_v, self._alpha
        v = min(max(v, self._vmin), self._vmax)
        # advance the estimates with the applied inputs (one matvec of the 5-state model;
        # θ is left as the QP saw it)
        zu = self._zu
        zu[:5] = z7[:5]
        zu[5] = v
        zu[6] = alpha - self._alpha0
        nxt = self._ABx @ zu
        self._xf = nxt[:2]
        self._xc = nxt[2:5]
        self._v, self._alpha = v, alpha
        cur = self.current
        self.solve_times.append(time.perf_counter() - t0)
        return v, cur * math.sin(alpha), cur * math.cos(alpha)
