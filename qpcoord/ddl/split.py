"""The thesis's frequency split for any linear dual stage: :class:`FrequencySplit`.

Two loops, as the thesis's coordinator (Fig 6.10) with the reference replaced by the
measured error:

* **fine loop** on the measured error ``e``: ``u_f = C_f(z) e``;
* **coarse loop** on the coarse stage's own error, estimated as the thesis's coordinator does
  (output minus a fine-stage model): ``e_c = e + ŷ_f = d − y_c``, with ``ŷ_f`` the fine
  channel's model driven by the fine command actually applied: ``u_c = C_c(z) e_c``.

The coarse loop's crossover sets the split frequency: below it the coarse stage takes the
motion, above it the fine stage does (the fine stage sees the coarse loop's residual, so the
error's sensitivity is the product ``S_c S_f``). Each loop is an LQG on its own channel and
the plant's disturbance models (:class:`.lqg.LQG`'s cost and filter with one input), its error
weight set by bisection so that the loop ``P_c C_c`` (resp. ``P_f C_f``) crosses 0 dB at the
requested bandwidth, its Kalman measurement noise equal to its error scale.
"""

from __future__ import annotations

import math

import numpy as np

from .lqg import dare_gain, state_scale

__all__ = ["FrequencySplit"]


def _siso_lqg(a, b, c, se, su, wn):
    """One-input LQG (regulator on ``c x/se``, input ``u/su``; Kalman noise ``wn``, ``se²``),
    its Riccati equations solved with states in their typical units (:func:`.lqg.state_scale`).
    """
    t = state_scale(a, b * su, wn)
    ti = 1.0 / t
    a_s = ti[:, None] * a * t[None, :]
    b_s = ti[:, None] * b * su
    c_s = c * t[None, :]
    _, k_s = dare_gain(a_s, b_s, c_s.T @ c_s / se**2, np.eye(1))
    w_s = ti[:, None] * wn * ti[None, :]
    pk, _ = dare_gain(a_s.T, c_s.T, w_s, np.array([[se * se]]))
    ll = t * (pk @ c_s.T / (c_s @ pk @ c_s.T + se * se))[:, 0]
    return su * k_s[0] * ti, ll


def _loop(a, b, c, k, ll, ap, bp, cp, z):
    """``P(z) C(z)`` of a current-estimator LQG ``(k, ll)`` on the channel ``(ap, bp, cp)``
    (the plant from u to the position the loop's error subtracts), and the law."""
    n = a.shape[0]
    i_lc = np.eye(n) - np.outer(ll, c[0])
    abk = a - np.outer(b[:, 0], k)
    law = (abk @ i_lc, abk @ ll, -k @ i_lc, float(-(k @ ll)))
    return _frf(law, ap, bp, cp, z), law


def _frf(law, ap, bp, cp, z):
    """``P(z) C(z)`` of a SISO law ``(A, b, c, d)`` on the channel ``(ap, bp, cp)``."""
    ak, bk, ck, dk = law
    n = ak.shape[0]
    out = np.empty(z.size, dtype=complex)
    ip, ik = np.eye(ap.shape[0]), np.eye(n)
    for i, zi in enumerate(z):
        p = cp[0] @ np.linalg.solve(zi * ip - ap, bp[:, 0])
        cz = ck @ np.linalg.solve(zi * ik - ak, bk) + dk
        out[i] = p * cz
    return out


def _crossover(f, lz) -> float:
    """Highest frequency (Hz) where ``|L|`` falls through 1 (log interpolation)."""
    mag = np.abs(lz)
    above = np.flatnonzero(mag >= 1.0)
    if above.size == 0:
        return float(f[0])
    k = above[-1] + 1
    if k == mag.size:
        return math.inf
    t = math.log(mag[k - 1]) / (math.log(mag[k - 1]) - math.log(mag[k]))
    return float(f[k - 1] * (f[k] / f[k - 1]) ** t)


class FrequencySplit:
    """Coarse loop on ``e + ŷ_f``, fine loop on ``e`` (see module docstring).

    Parameters
    ----------
    plant : LinearDualStage
    coarse_bandwidth : float
        Crossover of the coarse loop, Hz (the split frequency).
    fine_bandwidth : float
        Crossover of the fine loop, Hz.
    coarse_input_scale, fine_input_scale : float, optional
        LQ input scales, input units (default: half the input range, 1 if unbounded).

    Attributes
    ----------
    coarse_crossover, fine_crossover : float
        The loops' crossovers achieved, Hz.

    Raises
    ------
    ValueError
        Bandwidths not ordered below Nyquist, or a closed loop that is unstable on the plant
        (e.g. an integral law above a stiff channel's first resonance).
    """

    def __init__(
        self,
        plant,
        coarse_bandwidth: float,
        fine_bandwidth: float,
        *,
        coarse_input_scale: float | None = None,
        fine_input_scale: float | None = None,
    ):
        from .lqg import _half, _scale

        self.plant = plant
        m = plant.discrete()
        ts = plant.Ts
        fbw = _scale("fine_bandwidth", fine_bandwidth, 1.0)
        cbw = _scale("coarse_bandwidth", coarse_bandwidth, 1.0)
        if not cbw < fbw < 0.5 / ts:
            raise ValueError(
                f"need coarse_bandwidth < fine_bandwidth < Nyquist ({0.5 / ts:g} Hz), got "
                f"{coarse_bandwidth!r} and {fine_bandwidth!r}"
            )
        suc = _scale("coarse_input_scale", coarse_input_scale, _half(plant.coarse_range))
        suf = _scale("fine_input_scale", fine_input_scale, _half(plant.fine_range))
        cc, cf, cd = m.c_coarse, m.c_fine, m.c_dist
        npl, n_c = m.n_plant, m.n_coarse
        idx_c = np.r_[0:n_c, npl : m.n]
        idx_f = np.r_[n_c:npl, npl : m.n]
        self._idx_c, self._idx_f = idx_c, idx_f
        self._n_c = n_c
        wfull = m.G @ m.W @ m.G.T
        self._fine_model = (m.A[n_c:npl, n_c:npl], m.B[n_c:npl, 1:2], cf[:, n_c:npl])
        self._coarse_model = (m.A[:n_c, :n_c], m.B[:n_c, 0:1], cc[:, :n_c])
        self._loops = {}
        for name, idx, col, c_loop, bw, su in (
            ("coarse", idx_c, 0, (cd - cc)[:, idx_c], cbw, suc),
            ("fine", idx_f, 1, (cd - cf)[:, idx_f], fbw, suf),
        ):
            a = m.A[np.ix_(idx, idx)]
            b = m.B[idx, col : col + 1]
            ap, bp, cp = self._coarse_model if name == "coarse" else self._fine_model
            wn = wfull[np.ix_(idx, idx)] + b @ b.T * (0.01 * su) ** 2
            wn = wn + 1e-12 * max(np.max(np.abs(np.diag(wn))), 1e-300) * np.eye(idx.size)
            f = np.geomspace(bw / 30.0, min(30.0 * bw, 0.499 / ts), 240)
            z = np.exp(2j * math.pi * f * ts)
            ipa = np.eye(ap.shape[0]) - ap
            if np.linalg.cond(ipa) < 1e12:
                # a stiff channel (finite static gain g): the thesis's integral law
                # u(k) = u(k−1) + (2π f_bw Ts / g) e(k), a loop of bandwidth ≈ f_bw
                g = float(cp[0] @ np.linalg.solve(ipa, bp[:, 0]))
                gi = 2.0 * math.pi * bw * ts / g
                law = (np.ones((1, 1)), np.array([gi]), np.ones(1), gi)
                lz = _frf(law, ap, bp, cp, z)
            else:  # an integrating channel: LQG, error weight by bisection on the crossover
                lz, law = self._lqg_loop(a, b, c_loop, su, wn, ap, bp, cp, f, z, bw, plant)
            self._loops[name] = law
            setattr(self, f"{name}_crossover", _crossover(f, lz))
        self.reset()
        from .lqg import closed_loop_poles

        rho = float(np.max(np.abs(closed_loop_poles(plant, self))))
        if rho >= 1.0:
            raise ValueError(
                f"coarse_bandwidth = {coarse_bandwidth!r} Hz and fine_bandwidth = "
                f"{fine_bandwidth!r} Hz give an unstable loop on this plant (largest "
                f"closed-loop pole modulus {rho:.4f}): lower them below the channels' first "
                "resonances"
            )

    @staticmethod
    def _lqg_loop(a, b, c_loop, su, wn, ap, bp, cp, f, z, bw, plant):
        half = 0.5 * (plant.fine_stroke[1] - plant.fine_stroke[0])
        lo, hi = 1e-9 * half, 10.0 * half  # error scale: small = fast loop
        for _ in range(60):
            se = math.sqrt(lo * hi)
            k, ll = _siso_lqg(a, b, c_loop, se, su, wn)
            lz, _ = _loop(a, b, c_loop, k, ll, ap, bp, cp, z)
            if _crossover(f, lz) > bw:
                lo = se
            else:
                hi = se
            if hi / lo < 1.0 + 1e-3:
                break
        k, ll = _siso_lqg(a, b, c_loop, hi, su, wn)
        return _loop(a, b, c_loop, k, ll, ap, bp, cp, z)

    def reset(self) -> None:
        """Start from rest."""
        self._xc = np.zeros(self._loops["coarse"][0].shape[0])
        self._xf = np.zeros(self._loops["fine"][0].shape[0])
        self._yf = np.zeros(self._fine_model[0].shape[0])
        p = self.plant
        self._u_prev = [0.0, 0.0]
        self._lim = (
            (p.coarse_range, p.coarse_rate * p.Ts),
            (p.fine_range, p.fine_rate * p.Ts),
        )

    def _clip(self, i: int, u: float) -> float:
        (lo, hi), d = self._lim[i]
        up = self._u_prev[i]
        return min(max(u, lo, up - d), hi, up + d)

    def step(self, e: float) -> tuple[float, float]:
        """One period: measured error ``e`` (m) → ``(u_c, u_f)``, clipped as the plant would."""
        af, bf, cf = self._fine_model
        ec = e + float(cf[0] @ self._yf)  # d − y_c: the output minus the fine model
        ak, bk, ck, dk = self._loops["coarse"]
        uc = self._clip(0, float(ck @ self._xc + dk * ec))
        self._xc = ak @ self._xc + bk * ec
        ak, bk, ck, dk = self._loops["fine"]
        uf = self._clip(1, float(ck @ self._xf + dk * e))
        self._xf = ak @ self._xf + bk * e
        self._yf = af @ self._yf + bf[:, 0] * uf
        self._u_prev = [uc, uf]
        return uc, uf

    def state_space(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
        """The unclipped law ``e → (u_c, u_f)`` as one discrete system ``(A, B, C, D, Ts)``;
        states (coarse law, fine law, fine model)."""
        akc, bkc, ckc, dkc = self._loops["coarse"]
        akf, bkf, ckf, dkf = self._loops["fine"]
        af, bf, cf = self._fine_model
        nc, nf, nm = akc.shape[0], akf.shape[0], af.shape[0]
        n = nc + nf + nm
        a = np.zeros((n, n))
        b = np.zeros((n, 1))
        c = np.zeros((2, n))
        d = np.zeros((2, 1))
        # fine law: u_f = ckf x_f + dkf e
        sf, sm = slice(nc, nc + nf), slice(nc + nf, n)
        a[sf, sf] = akf
        b[sf, 0] = bkf
        c[1, sf] = ckf
        d[1, 0] = dkf
        # fine model: y_f⁺ = af y_f + bf u_f
        a[sm, sm] = af
        a[sm, sf] = np.outer(bf[:, 0], ckf)
        b[sm, 0] = bf[:, 0] * dkf
        # coarse law on e_c = e + cf y_f
        a[:nc, :nc] = akc
        a[:nc, sm] = np.outer(bkc, cf[0])
        b[:nc, 0] = bkc
        c[0, :nc] = ckc
        c[0, sm] = dkc * cf[0]
        d[0, 0] = dkc
        return a, b, c, d, self.plant.Ts
