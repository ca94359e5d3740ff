"""Model-predictive control of any linear dual stage as a prioritised stack: :class:`LinearMPC`.

Prediction model: the plant's discrete model with its disturbance models
(:meth:`.linear_plant.LinearDualStage.discrete`), from the current estimate of an
:class:`.lqg.LQG` observer (its Kalman filter, fed the commands actually applied). The
horizon is move-blocked: block ``j`` holds ``(u_c, u_f)`` for ``L_j`` periods; predictions are
taken at the block ends. Condensed, every task matrix is constant and only the right-hand
sides move with the estimate.

The stack (``qc.Stack``, solved each period, strict priorities):

* hard: the input ranges (bounds) and rate limits (between consecutive blocks and from the
  last applied command);
* level 0: the **fine stroke** at every block end, tightened by ``margin`` (a fraction of the
  stroke at each end) — a priority, not a hard constraint, so that a disturbance beyond reach
  is met as closely as possible instead of making the QP infeasible;
* level 1: the **tracking cost**, the LQG's own cost at the block ends: ``e/σ_e``,
  ``y_f/σ_f``, ``u_c/σ_uc``, ``u_f/σ_uf`` (rows weighted by the block length).

* terminal cost: the LQG's cost-to-go ``x_Nᵀ P x_N`` after the last block.

With unit blocks (the default: 10 periods) the stage costs are exact and, with the terminal
cost, the first move where no constraint acts is the LQG's (checked to 1e-3 relative on the
PRIMA model). Longer blocks look further ahead but only approximate the stage costs between
block ends: measured on the PRIMA model, blocks 1, 2, …, 128 gave a first coarse move 10×
smaller than the LQG's and lost the stepper's synchronism on the nonlinear plant. If the QP
fails, the period uses the LQG's command and counts it in :attr:`LinearMPC.fallback_steps`.
"""

from __future__ import annotations

import numpy as np

from ..core.stack import Stack
from ..core.tasks import Bounds, Equality, Inequality
from .lqg import LQG

__all__ = ["LinearMPC"]

DEFAULT_BLOCKS = (1,) * 10


class LinearMPC:
    """Stacked MPC for a :class:`.linear_plant.LinearDualStage` (see module docstring).

    Parameters
    ----------
    plant : LinearDualStage
    blocks : sequence of int
        Block lengths in periods (each ≥ 1).
    margin : float
        Fraction of the fine stroke kept free at each end (0 ≤ margin < 0.5).
    lqg : LQG, optional
        Observer and cost (default ``LQG(plant)``).
    solver : str, optional
        QP backend for :meth:`qpcoord.Stack.solve`.

    Attributes
    ----------
    stack : qpcoord.Stack
    fallback_steps : int
        Periods in which the QP failed and the LQG's command was used.
    """

    def __init__(
        self,
        plant,
        *,
        blocks=DEFAULT_BLOCKS,
        margin: float = 0.1,
        lqg=None,
        solver: str | None = None,
    ):
        blocks = tuple(int(b) for b in blocks)
        if not blocks or min(blocks) < 1:
            raise ValueError(f"blocks must be positive integers, got {blocks!r}")
        margin = float(margin)
        if not 0.0 <= margin < 0.5:
            raise ValueError(f"margin must be in [0, 0.5), got {margin!r}")
        self.plant = plant
        self.blocks = blocks
        self.margin = margin
        self.solver = solver
        self.lqg = LQG(plant) if lqg is None else lqg
        if self.lqg.plant is not plant:
            raise ValueError("lqg must be designed on the same plant")
        m = plant.discrete()
        sc = self.lqg.scales
        nb, n = len(blocks), m.n
        nv = 2 * nb
        phi = np.eye(n)
        gam = np.zeros((n, nv))
        phis, gams = [], []
        for j, length in enumerate(blocks):
            for _ in range(length):
                phi = m.A @ phi
                gam = m.A @ gam
                gam[:, 2 * j : 2 * j + 2] += m.B
            phis.append(phi.copy())
            gams.append(gam.copy())
        phi_e = np.array([p for p in phis])  # (nb, n, n)
        ce, cf = m.c_error[0], m.c_fine[0]
        self._free_e = np.einsum("k,jkn->jn", ce, phi_e)  # e at block ends from x0
        self._free_f = np.einsum("k,jkn->jn", cf, phi_e)
        ge = np.einsum("k,jkn->jn", ce, np.array(gams))
        gf = np.einsum("k,jkn->jn", cf, np.array(gams))
        w = np.sqrt(np.asarray(blocks, dtype=float))
        half_f = 0.5 * (plant.fine_stroke[1] - plant.fine_stroke[0])
        self._sf = half_f  # stroke rows in units of the half stroke
        lo, hi = plant.fine_stroke
        self._f_lo = lo + margin * (hi - lo)
        self._f_hi = hi - margin * (hi - lo)
        self.stroke = Inequality(gf / half_f, -1.0, 1.0, name="fine stroke with margin")
        su = np.empty(nv)
        su[0::2] = sc["coarse_input"]
        su[1::2] = sc["fine_input"]
        # stage costs of the states x_1 … x_{N−1} (x_0's is a constant) and terminal cost
        # x_Nᵀ P x_N (the LQG's cost-to-go): with unit blocks the first move is the LQG's
        # where no constraint acts
        ev, evec = np.linalg.eigh(self.lqg.P)
        keep = ev > 1e-12 * ev.max()
        self._pt = np.sqrt(ev[keep])[:, None] * evec[:, keep].T
        self._free_t = self._pt @ phis[-1]
        rows = np.vstack(
            (
                w[:-1, None] * ge[:-1] / sc["error"],
                w[:-1, None] * gf[:-1] / sc["fine"],
                np.repeat(w, 2)[:, None] * np.eye(nv) / su[:, None],
                self._pt @ gams[-1],
            )
        )
        self._w = w
        self.track = Equality(rows, np.zeros(rows.shape[0]), name="tracking cost")
        lo_u = np.tile([plant.coarse_range[0], plant.fine_range[0]], nb)
        hi_u = np.tile([plant.coarse_range[1], plant.fine_range[1]], nb)
        self.bounds = Bounds(lo_u, hi_u, name="input ranges")
        # rate limits: u_0 − u_prev and u_j − u_{j−1}, per period (a block change is one)
        d = np.zeros((nv, nv))
        for j in range(nb):
            d[2 * j : 2 * j + 2, 2 * j : 2 * j + 2] = np.eye(2)
            if j:
                d[2 * j : 2 * j + 2, 2 * j - 2 : 2 * j] = -np.eye(2)
        self._dmax = np.tile([plant.coarse_rate * plant.Ts, plant.fine_rate * plant.Ts], nb)
        finite_rate = np.isfinite(self._dmax)
        self._rate_rows = np.flatnonzero(finite_rate)
        cons = []
        if self._rate_rows.size:
            self.rate = Inequality(
                d[self._rate_rows],
                -self._dmax[self._rate_rows],
                self._dmax[self._rate_rows],
                name="rate limits",
            )
            cons.append(self.rate)
        else:
            self.rate = None
        self.stack = Stack(
            [self.stroke, self.track],
            bounds=self.bounds if np.any(np.isfinite(lo_u) | np.isfinite(hi_u)) else None,
            constraints=cons or None,
        )
        self._ne = ge.shape[0]
        self.reset()

    def reset(self) -> None:
        """Start from rest."""
        self.lqg.reset()
        self._u_prev = np.zeros(2)
        self.fallback_steps = 0

    def step(self, e: float) -> tuple[float, float]:
        """One period: measured error ``e`` (m) → ``(u_c, u_f)`` (clipped as the plant)."""
        q = self.lqg
        xh = q._xbar + q.L * (e - q._ce @ q._xbar)
        ef = self._free_e @ xh
        ff = self._free_f @ xh
        nb = len(self.blocks)
        b = np.zeros(self.track.A.shape[0])
        k = nb - 1  # the state rows stop before the last block end: its cost is terminal
        b[:k] = -self._w[:k] * ef[:k] / q.scales["error"]
        b[k : 2 * k] = -self._w[:k] * ff[:k] / q.scales["fine"]
        b[2 * k + 2 * nb :] = -(self._free_t @ xh)
        self.track.update(b=b)
        self.stroke.update(lower=(self._f_lo - ff) / self._sf, upper=(self._f_hi - ff) / self._sf)
        if self.rate is not None:
            off = np.zeros(2 * nb)
            off[:2] = self._u_prev
            r = self._rate_rows
            self.rate.update(lower=off[r] - self._dmax[r], upper=off[r] + self._dmax[r])
        try:
            u = self.stack.solve(solver=self.solver, method="hierarchical").x[:2].copy()
        except (ValueError, RuntimeError, ArithmeticError):
            self.fallback_steps += 1
            u = -(q.K @ xh)
        p = self.plant
        du = np.array([p.coarse_rate, p.fine_rate]) * p.Ts
        lo = np.maximum([p.coarse_range[0], p.fine_range[0]], self._u_prev - du)
        hi = np.minimum([p.coarse_range[1], p.fine_range[1]], self._u_prev + du)
        u = np.minimum(np.maximum(u, lo), hi)
        self._u_prev = u
        q._u_prev = u
        q._xbar = q._A @ xh + q._B @ u
        return float(u[0]), float(u[1])
