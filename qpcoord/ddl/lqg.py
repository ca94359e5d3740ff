"""LQG for any :class:`.linear_plant.LinearDualStage`: :class:`LQG`, and the linear-controller
tools shared by the generic controllers (:class:`LinearLaw`, :func:`sensitivity`).

Design model: the plant's discrete model at ``Ts`` with its disturbance models
(:meth:`.linear_plant.LinearDualStage.discrete`), ``x⁺ = A x + B u + G w``, measured error
``e = c_e x``. The regulator minimises ::

    Σ  e²/σ_e²  +  y_f²/σ_f²  +  u_c²/σ_uc²  +  u_f²/σ_uf²

(the error, the fine stage off its centre, the efforts; the disturbance states are not
controllable but enter the cost through ``e``, so the law feeds their estimate forward). The
steady-state Kalman filter (current estimator) has the disturbances' noise ``G W Gᵀ`` plus an
input noise of ``input_noise`` × each input scale (robustness), and a measurement noise.

Per period (observer form, the observer sees the command actually applied)::

    x̂ = x̄ + L (e − c_e x̄);   u = −K x̂;   u_applied = u clipped (range, rate)
    x̄ ← A x̂ + B u_applied

Without clipping this is the discrete linear system :meth:`LinearLaw.state_space` exports
(``e`` → ``(u_c, u_f)``, ``D ≠ 0``: the current estimator acts within the period).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import solve_discrete_are

__all__ = ["LQG", "LinearLaw", "closed_loop_poles", "dare_gain", "sensitivity", "state_scale"]


def dare_gain(a, b, q, r) -> tuple[np.ndarray, np.ndarray]:
    """Stabilising DARE solution ``P`` and gain ``K = (R + BᵀPB)⁻¹BᵀPA``; raises ValueError
    when the equation has no stabilising solution or its residual is not small against
    ``‖Q‖ + ‖AᵀPA‖`` (the scale of its terms)."""
    try:
        p = solve_discrete_are(a, b, q, r)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ValueError(f"no stabilising LQ solution: {exc}") from exc
    p = 0.5 * (p + p.T)
    g = r + b.T @ p @ b
    k = np.linalg.solve(g, b.T @ p @ a)
    res = a.T @ p @ a - p - a.T @ p @ b @ k + q
    scale = np.linalg.norm(q) + np.linalg.norm(a.T @ p @ a)
    if not np.all(np.isfinite(p)) or np.linalg.norm(res) > 1e-6 * scale:
        raise ValueError("the Riccati equation is too ill-conditioned to solve reliably")
    return p, k


class LinearLaw:
    """A linear controller in observer form on a plant's discrete model (base class).

    Subclasses set ``plant``, ``_A``, ``_B``, ``_ce``, ``K`` (2 × n) and ``L`` (n) before
    calling :meth:`reset`.
    """

    def reset(self) -> None:
        """Start from rest (estimate zero, previous commands zero)."""
        self._xbar = np.zeros(self._A.shape[0])
        self._u_prev = np.zeros(2)
        p = self.plant
        self._lo = np.array([p.coarse_range[0], p.fine_range[0]])
        self._hi = np.array([p.coarse_range[1], p.fine_range[1]])
        self._du = np.array([p.coarse_rate, p.fine_rate]) * p.Ts

    def step(self, e: float) -> tuple[float, float]:
        """One period: measured error ``e`` (m) → ``(u_c, u_f)`` (input units), clipped."""
        xh = self._xbar + self.L * (e - self._ce @ self._xbar)
        u = -(self.K @ xh)
        up = self._u_prev
        u = np.minimum(
            np.maximum(u, np.maximum(self._lo, up - self._du)), np.minimum(self._hi, up + self._du)
        )
        self._u_prev = u
        self._xbar = self._A @ xh + self._B @ u
        return float(u[0]), float(u[1])

    def state_space(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
        """The unclipped law as one discrete system at ``Ts`` from ``e`` (m) to
        ``(u_c, u_f)``: ``(A, B, C, D, Ts)`` with shapes (n, n), (n, 1), (2, n), (2, 1)."""
        n = self._A.shape[0]
        i_lc = np.eye(n) - np.outer(self.L, self._ce)
        abk = self._A - self._B @ self.K
        return (
            abk @ i_lc,
            (abk @ self.L)[:, None],
            -self.K @ i_lc,
            -(self.K @ self.L)[:, None],
            self.plant.Ts,
        )


def sensitivity(plant, law, f) -> np.ndarray:
    """``S = 1/(1 + P C)`` at frequencies ``f`` (Hz): ``P = (P_c, P_f)`` the plant's
    actuator channels at ``Ts`` (from input to position), ``C`` the law's ``e → u``."""
    f = np.asarray(f, dtype=float)
    m = plant.discrete()
    npl = m.n_plant
    a, b = m.A[:npl, :npl], m.B[:npl]
    cc, cf = m.c_coarse[0, :npl], m.c_fine[0, :npl]
    ak, bk, ck, dk, ts = law.state_space()
    z = np.exp(2j * math.pi * f * ts)
    s = np.empty(f.size, dtype=complex)
    ip, ik = np.eye(npl), np.eye(ak.shape[0])
    for i, zi in enumerate(z):
        gp = np.linalg.solve(zi * ip - a, b)  # n × 2
        pc, pf = cc @ gp[:, 0], cf @ gp[:, 1]
        kk = ck @ np.linalg.solve(zi * ik - ak, bk) + dk  # 2 × 1
        s[i] = 1.0 / (1.0 + pc * kk[0, 0] + pf * kk[1, 0])
    return s


def state_scale(a, b, w, steps: int = 400) -> np.ndarray:
    """Typical size of each state (> 0): the square root of the diagonal of the finite-horizon
    Gramian ``Σ_{k<steps} A^k (B Bᵀ + W) A^kᵀ`` (inputs already in their typical units; a
    horizon, so that marginal modes such as a rigid body count too). Zero rows (states no
    input reaches) get the median size."""
    x = b @ b.T + w
    g = x.copy()
    ak = np.eye(a.shape[0])
    for _ in range(int(steps) - 1):
        ak = a @ ak
        g += ak @ x @ ak.T
        if not np.all(np.isfinite(g)):
            raise ValueError("the plant's states grow without bound: cannot scale them")
    d = np.sqrt(np.maximum(np.diag(g), 0.0))
    pos = d[d > 0.0]
    fill = float(np.median(pos)) if pos.size else 1.0
    return np.where(d > 1e-300, d, fill)


def closed_loop_poles(plant, law) -> np.ndarray:
    """Poles of ``plant``'s actuators (their discrete model at ``Ts``) in loop with the
    unclipped ``law`` (``e = −y_c − y_f``): all inside the unit circle iff stable."""
    m = plant.discrete()
    npl = m.n_plant
    a, b = m.A[:npl, :npl], m.B[:npl]
    cy = (m.c_coarse + m.c_fine)[:, :npl]
    ak, bk, ck, dk, _ = law.state_space()
    nk = ak.shape[0]
    acl = np.zeros((npl + nk, npl + nk))
    acl[:npl, :npl] = a - b @ dk @ cy
    acl[:npl, npl:] = b @ ck
    acl[npl:, :npl] = -bk @ cy
    acl[npl:, npl:] = ak
    return np.linalg.eigvals(acl)


def _scale(name: str, value, default: float) -> float:
    v = default if value is None else float(value)
    if not math.isfinite(v) or v <= 0.0:
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return v


def _half(rng) -> float:
    lo, hi = rng
    return 0.5 * (hi - lo) if math.isfinite(lo) and math.isfinite(hi) else 1.0


class LQG(LinearLaw):
    """LQG (steady-state LQR + current-estimator Kalman filter) for a linear dual stage.

    Parameters
    ----------
    plant : LinearDualStage
    error_scale : float, optional
        ``σ_e``, m (default: 1 % of the fine half stroke).
    fine_scale : float, optional
        ``σ_f``, m (default: the fine half stroke).
    coarse_input_scale, fine_input_scale : float, optional
        ``σ_uc``, ``σ_uf``, input units (default: half the input range, 1 if unbounded).
    measurement_noise : float, optional
        Kalman measurement noise, m rms. Default: the smallest (fastest observer) at or
        above the plant's ``noise_rms`` for which the peak sensitivity ``|1/(1 + P C)|``
        stays ≤ ``max_peak_sensitivity`` (bisection in log scale over ``1e-8`` to ``1`` ×
        the fine half stroke, to 5 %; :func:`sensitivity` on 300 frequencies).
    input_noise : float
        Kalman process noise on each input, as a fraction of its input scale.
    max_peak_sensitivity : float
        Robustness bound of the default measurement noise (absolute; 2 = 6 dB).
    robust_plants : sequence of LinearDualStage
        Other plants (the same actuators' structure: plant variations) on which the default
        rule also keeps the peak sensitivity; :attr:`peak_sensitivity` is the largest.

    Attributes
    ----------
    K : ndarray (2, n)
        Regulator gain on the estimate.
    P : ndarray (n, n)
        The regulator's cost-to-go (``xᵀ P x``, the DARE's solution).
    L : ndarray (n,)
        Current-estimator gain.
    peak_sensitivity : float
        Peak of ``|S|`` of the design (absolute).
    scales : dict
        The scales used (``error``, ``fine``, ``coarse_input``, ``fine_input``,
        ``measurement_noise``).
    """

    def __init__(
        self,
        plant,
        *,
        error_scale: float | None = None,
        fine_scale: float | None = None,
        coarse_input_scale: float | None = None,
        fine_input_scale: float | None = None,
        measurement_noise: float | None = None,
        input_noise: float = 0.01,
        max_peak_sensitivity: float = 2.0,
        robust_plants=(),
    ):
        self.plant = plant
        self.robust_plants = tuple(robust_plants)
        m = plant.discrete()
        for i, rp in enumerate(self.robust_plants):
            rm = rp.discrete()
            if rm.n_plant != m.n_plant or rm.n_coarse != m.n_coarse or rp.Ts != plant.Ts:
                raise ValueError(
                    f"robust_plants[{i}] must have the plant's actuator structure and Ts"
                )
        half_f = 0.5 * (plant.fine_stroke[1] - plant.fine_stroke[0])
        se = _scale("error_scale", error_scale, 0.01 * half_f)
        sf = _scale("fine_scale", fine_scale, half_f)
        suc = _scale("coarse_input_scale", coarse_input_scale, _half(plant.coarse_range))
        suf = _scale("fine_input_scale", fine_input_scale, _half(plant.fine_range))
        inn = _scale("input_noise", input_noise, 0.01)
        ms = _scale("max_peak_sensitivity", max_peak_sensitivity, 2.0)
        ce, cf = m.c_error, m.c_fine
        wn = m.G @ m.W @ m.G.T + m.B @ np.diag([(inn * suc) ** 2, (inn * suf) ** 2]) @ m.B.T
        # the Riccati equations are solved with each state in units of its typical size
        # (hard-disk plants mix nm positions, 40 kHz modes and 1e7 input gains)
        t = state_scale(m.A, m.B @ np.diag([suc, suf]), wn)
        ti = 1.0 / t
        su = np.array([suc, suf])
        a_s = ti[:, None] * m.A * t[None, :]
        b_s = ti[:, None] * m.B * su[None, :]  # inputs in units of their scales: R = I
        ce_s, cf_s = ce * t[None, :], cf * t[None, :]
        q = ce_s.T @ ce_s / se**2 + cf_s.T @ cf_s / sf**2
        p_s, k_s = dare_gain(a_s, b_s, q, np.eye(2))
        self.P = ti[:, None] * p_s * ti[None, :]
        self.K = su[:, None] * k_s * ti[None, :]
        self._t = t
        self._scaled = (a_s, ce_s)
        self._A, self._B, self._ce = m.A, m.B, ce[0]
        wn_s = ti[:, None] * wn * ti[None, :]
        self._wn = wn_s + 1e-12 * np.max(np.abs(np.diag(wn_s))) * np.eye(m.n)
        if measurement_noise is not None:
            sv = _scale("measurement_noise", measurement_noise, 1.0)
            self._observer(sv)
        else:
            sv = self._robust_noise(max(plant.noise_rms, 1e-8 * half_f), half_f, ms)
        self.peak_sensitivity = self.peak()
        self.scales = {
            "error": se,
            "fine": sf,
            "coarse_input": suc,
            "fine_input": suf,
            "measurement_noise": sv,
        }
        self.reset()

    def _observer(self, sv: float) -> None:
        a_s, ce = self._scaled
        pk, _ = dare_gain(a_s.T, ce.T, self._wn, np.array([[sv * sv]]))
        self.L = self._t * (pk @ ce.T / (ce @ pk @ ce.T + sv * sv))[:, 0]

    def peak(self, n: int = 300) -> float:
        """Peak of ``|S|`` (absolute) over ``n`` log-spaced frequencies up to Nyquist, the
        largest over the plant and ``robust_plants``; ``inf`` if the loop is unstable on
        one of them (a small ``|S|`` does not certify stability)."""
        ts = self.plant.Ts
        f = np.geomspace(1e-4 / ts, 0.499 / ts, n)
        worst = 0.0
        for p in (self.plant, *self.robust_plants):
            if np.max(np.abs(closed_loop_poles(p, self))) >= 1.0:
                return math.inf
            worst = max(worst, float(np.max(np.abs(sensitivity(p, self, f)))))
        return worst

    def _robust_noise(self, lo: float, hi: float, bound: float) -> float:
        self._observer(lo)
        if self.peak() <= bound:
            return lo
        self._observer(hi)
        if self.peak() > bound:
            raise ValueError(
                f"no measurement noise up to {hi:.3g} m keeps the peak sensitivity <= {bound:g}: "
                "raise error_scale or the input scales"
            )
        while hi / lo > 1.05:  # the noise to 5 %
            mid = math.sqrt(lo * hi)
            self._observer(mid)
            if self.peak() <= bound:
                hi = mid
            else:
                lo = mid
        self._observer(hi)
        return hi
