"""The PQ method for the DDL dual stage (Schroeck & Messner 1999): `PQ`.

Dual-input single-output loop (thesis §6.1.4): coarse plant ``G1`` (field phase α → y_c, with
the ≈ 116 Hz electromechanical mode) and fine plant ``G2`` (piezo voltage → y_f); the controllers
``C1`` and ``C2`` act on the same output error ``e = r − y``::

    y = (G1 C1 + G2 C2) e = G2 C2 (1 + P Q) e,      P = G1/G2,   Q = C1/C2

The PQ method designs in two SISO steps (Schroeck & Messner, "On controller design for linear
time-invariant dual-input single-output systems", ACC 1999):

1. **Q** shapes the *relative* loop ``P Q``: its crossover ``f_pq`` is the frequency at which
   both stages contribute equally (coarse below, fine above) and its phase margin there keeps
   the two contributions from cancelling (destructive interference: equal magnitudes in
   opposition, ``1 + PQ ≈ 0``, thesis Fig 6.11). Here ``Q = (ω_pq / P(0)) · (1/s) · LP(s)``:
   ``PQ ≈ ω_pq/s`` at low frequency (the coarse stage takes the DC, so the fine stage returns
   to mid-stroke), ``LP`` a second-order low-pass (ζ = 0.7) that keeps ``|PQ|`` small at the
   coarse resonance.
2. **C2** is designed for the combined plant ``G2 (1 + PQ)``; where ``|PQ| ≪ 1`` (above a few
   ``f_pq``) this is the fine plant, so the coordinator's fine PI (same design rule: minimum
   |S| at 50 Hz under PM ≥ 60°, GM ≥ 10 dB, peak |S| ≤ 1.6) is reused; :meth:`PQ.report` gives
   the margins of the complete loop ``L = G2 C2 (1 + PQ)`` to check it.

Then ``C1 = Q C2``: the coarse command is the (low-passed, integrated) fine-controller output —
the coarse stage moves so as to bring the fine command back to mid-stroke.

Default design choices (rules, not fits):

* ``f_pq = 2 Hz``: the same split frequency as the coordinator's coarse loop bandwidth, so the
  two SISO-style designs divide the work at the same frequency;
* low-pass corner ``f_lp = 20 Hz``: a decade above ``f_pq`` (costs ≈ 8° of PQ phase margin) and
  ≈ 0.17× the coarse mode (``|LP| ≈ −31 dB`` there);
* fine PI: ``kp = 0.8/K_f``, ``ki = 2π·180/K_f`` (the coordinator's).

Discrete implementation at ``fs`` (what :meth:`PQ.step` executes and :meth:`PQ.report` analyses):
``C2(z) = kp + ki h z/(z − 1)`` (conditional integration while the voltage clips),
``Q(z) = LP(z) · (h ω_pq / P(0)) · z/(z − 1)`` with ``LP`` the Tustin (pre-warped) biquad; the
integrator of ``Q`` is the field phase itself, ``α(k) = α(k−1) + sat(g w(k), ±Δα_max)``, so
the hardware rate limit (3 mm/s, as the coordinator) is also its anti-windup. Coils
``i_a = I sin α``, ``i_b = I cos α``.
"""

from __future__ import annotations

import math

import numpy as np

from ._check import finite, nonnegative, positive
from .guard import MeasurementGuard, guard_arg
from .lqr import delay_margin, design_model, loop_margins
from .pi import clamp_with_antiwindup

__all__ = ["PQ"]


class PQ:
    """PQ-method dual-stage controller (Schroeck & Messner) on the combined output error.

    Parameters
    ----------
    pq_crossover : float
        Crossover of the relative loop ``PQ`` (stages contribute equally), Hz.
    lowpass : float
        Corner of the second-order low-pass in ``Q``, Hz.
    lowpass_damping : float
        Its damping ratio.
    fine_kp : float
        Proportional gain of ``C2`` × K_f (dimensionless).
    fine_ki : float
        Integral gain of ``C2`` × K_f, 1/s.
    current : float
        Field amplitude I, A.
    max_speed : float
        Rate limit of the field phase as a carriage speed, m/s.
    design_plant : DualStage, optional
        Plant whose parameters define ``G1``, ``G2`` (default: the plant given to
        :meth:`reset`).
    guard : MeasurementGuard, optional
        Measurement guard (default: a new :class:`.guard.MeasurementGuard` with the plant's
        physical bounds). A rejected measurement is replaced by the a-priori prediction
        ``ŷ_c(k−1) + Δα lead/(2π p) + ŷ_f(k)`` (carriage estimate moved with the field
        phase, fine model advanced).

    Attributes
    ----------
    y_c_hat : float
        Carriage estimate ``y − ŷ_f`` (fine-stage model driven by the applied voltage), m —
        logged only; the PQ law itself uses the output error alone.
    guard : MeasurementGuard
        The measurement guard (``guard.rejected``: measurements rejected).
    """

    def __init__(
        self,
        pq_crossover: float = 2.0,
        lowpass: float = 20.0,
        lowpass_damping: float = 0.7,
        fine_kp: float = 0.8,
        fine_ki: float = 2.0 * math.pi * 180.0,
        current: float = 1.5,
        max_speed: float = 3.0e-3,
        design_plant=None,
        guard: MeasurementGuard | None = None,
    ):
        self.pq_crossover = positive("pq_crossover", pq_crossover)
        self.lowpass = positive("lowpass", lowpass)
        self.lowpass_damping = positive("lowpass_damping", lowpass_damping)
        if self.lowpass <= self.pq_crossover:
            raise ValueError(
                f"lowpass = {lowpass!r} Hz must lie above pq_crossover = {pq_crossover!r} Hz"
            )
        self.fine_kp = nonnegative("fine_kp", fine_kp)
        self.fine_ki = positive("fine_ki", fine_ki)
        self.current = positive("current", current)
        self.max_speed = positive("max_speed", max_speed)
        self.design_plant = design_plant
        self.guard = guard_arg(guard)
        self.y_c_hat = 0.0
        self.model = None

    # ------------------------------------------------------------------ design
    def design(self, plant, fs: float, y_c_op: float = 0.0) -> PQ:
        """Discrete ``C2``, ``Q`` and the design model for ``plant`` at ``fs`` Hz."""
        fs = positive("fs", fs)
        if self.lowpass >= 0.45 * fs:
            raise ValueError(f"lowpass = {self.lowpass!r} Hz must be below 0.45 fs")
        dp = plant if self.design_plant is None else self.design_plant
        self.model = mo = design_model(dp, fs, y_c_op, self.current)
        h = mo.h
        kf = dp.fine.gain
        self._kp = self.fine_kp / kf
        self._kih = self.fine_ki / kf * h
        # P(0) = G1(0)/G2(0), V per rad
        a, b = mo.A, mo.B
        g1_0 = float((np.linalg.solve(np.eye(2) - a[2:, 2:], b[2:, 1]))[0])
        g2_0 = float((np.linalg.solve(np.eye(2) - a[:2, :2], b[:2, 0]))[0])
        self.P0 = g1_0 / g2_0
        self._g = h * 2.0 * math.pi * self.pq_crossover / self.P0  # rad per V per step
        # Tustin low-pass with pre-warping: ω_l²/(s² + 2ζω_l s + ω_l²)
        wl = 2.0 * math.pi * self.lowpass
        kk = wl / math.tan(wl * h / 2.0)
        z = self.lowpass_damping
        a0 = kk * kk + 2.0 * z * wl * kk + wl * wl
        self._lp = (
            wl * wl / a0,
            2.0 * wl * wl / a0,
            wl * wl / a0,
            (2.0 * wl * wl - 2.0 * kk * kk) / a0,
            (kk * kk - 2.0 * z * wl * kk + wl * wl) / a0,
        )
        return self

    def _transfer_functions(self):
        """Discrete ``G1, G2, C2, Q`` (python-control, dt = 1/fs)."""
        import control

        mo = self.model
        h = mo.h
        a, b = mo.A, mo.B
        g2 = control.ss(a[:2, :2], b[:2, :1], [[1.0, 0.0]], [[0.0]], dt=h)
        g1 = control.ss(a[2:, 2:], b[2:, 1:], [[1.0, 0.0]], [[0.0]], dt=h)
        c2 = control.tf([self._kp + self._kih, -self._kp], [1.0, -1.0], dt=h)
        b0, b1, b2, a1, a2 = self._lp
        lp = control.tf([b0, b1, b2], [1.0, a1, a2], dt=h)
        integ = control.tf([self._g, 0.0], [1.0, -1.0], dt=h)
        return g1, g2, c2, lp * integ

    def controller_ss(self):
        """The discrete controller ``e → (v − v_mid, α − α(0))`` exactly as :meth:`step` runs it.

        States ``(I, z1, z2, α_prev)``: PI integrator, low-pass biquad (DF2T), phase. Minimal
        realisation (python-control ``StateSpace``, 1 input, 2 outputs), no clipping.
        """
        import control

        b0, b1, b2, a1, a2 = self._lp
        d = self._kp + self._kih
        g = self._g
        ac = np.array(
            [
                [1.0, 0.0, 0.0, 0.0],
                [b1 - a1 * b0, -a1, 1.0, 0.0],
                [b2 - a2 * b0, -a2, 0.0, 0.0],
                [g * b0, g, 0.0, 1.0],
            ]
        )
        bc = np.array([[self._kih], [(b1 - a1 * b0) * d], [(b2 - a2 * b0) * d], [g * b0 * d]])
        cc = np.array([[1.0, 0.0, 0.0, 0.0], [g * b0, g, 0.0, 1.0]])
        dc = np.array([[d], [g * b0 * d]])
        return control.ss(ac, bc, cc, dc, dt=self.model.h)

    def loop_transfer(self):
        """Discrete open loop ``L = G1 C1 + G2 C2`` (python-control, minimal: 8 states)."""
        import control

        mo = self.model
        plant = control.ss(mo.A, mo.B, mo.C, np.zeros((1, 2)), dt=mo.h)
        return plant * self.controller_ss()

    def closed_loop_poles(self) -> np.ndarray:
        """Poles of the linear closed loop ``L/(1 + L)`` (no clipping)."""
        import control

        return np.asarray(control.poles(control.feedback(self.loop_transfer(), 1)))

    def report(self, n: int = 4000) -> dict:
        """Crossovers, margins and the stages' relative contribution (requires :meth:`design`).

        Returns
        -------
        dict
            ``pq_crossover_hz`` (|PQ| = 1: equal contributions), ``pq_phase_deg`` (∠PQ there:
            phase of the coarse contribution relative to the fine one), ``pq_phase_margin_deg``
            (180° + ∠PQ: distance from destructive interference), ``pq_at_resonance_db``
            (|PQ| at the coarse mode ``coarse_resonance_hz``), ``coarse_share`` ({Hz:
            |PQ/(1+PQ)|}, the coarse stage's fraction of the output motion),
            ``max_pole_modulus`` (closed loop, < 1 = stable), ``P0_v_per_rad``, and the
            complete loop's :func:`.lqr.loop_margins` (``crossover_hz``,
            ``phase_margin_deg``, ``gain_margin_db``, ``gain_reduction_margin_db``,
            ``peak_sensitivity``, ``peak_sensitivity_hz``) and ``delay_margin_samples``
            (:func:`.lqr.delay_margin`).
        """
        if self.model is None:
            raise RuntimeError("call design(plant, fs) or reset(...) before report()")
        g1, g2, c2, q = self._transfer_functions()
        fs = self.model.fs
        f = np.logspace(-2, math.log10(0.499 * fs), int(n))
        w = 2.0 * math.pi * f

        def resp(sys):
            return np.asarray(sys.frequency_response(w).complex).reshape(-1)

        def at(fh):
            zz = np.exp(2j * math.pi * fh / fs)
            return complex((g1 * q)(zz)) / complex(g2(zz))

        mag = np.abs(resp(g1 * q) / resp(g2))
        k = int(np.flatnonzero((mag[:-1] >= 1.0) & (mag[1:] < 1.0))[0])
        t = math.log(mag[k]) / (math.log(mag[k]) - math.log(mag[k + 1]))
        f_pq = float(f[k] * (f[k + 1] / f[k]) ** t)
        pq_x = at(f_pq)
        ph = math.degrees(math.atan2(pq_x.imag, pq_x.real))
        f_res = math.sqrt(-self.model.continuous.A[3, 2]) / (2.0 * math.pi)
        share = {}
        for fh in (0.1, 1.0, 2.0, 10.0, 100.0):
            x = at(fh)
            share[fh] = abs(x / (1.0 + x))
        out = {
            "pq_crossover_hz": f_pq,
            "pq_phase_deg": ph,
            "pq_phase_margin_deg": 180.0 + ph,
            "pq_at_resonance_db": 20.0 * math.log10(abs(at(f_res))),
            "coarse_resonance_hz": f_res,
            "coarse_share": share,
            "max_pole_modulus": float(np.max(np.abs(self.closed_loop_poles()))),
            "P0_v_per_rad": self.P0,
        }
        loop = self.loop_transfer()
        out.update(loop_margins(loop, fs))
        out["delay_margin_samples"] = delay_margin(loop)
        return out

    # ------------------------------------------------------------------ interface
    def reset(self, plant, fs: float, y0: float, r0: float) -> None:
        """Design for ``plant`` at ``fs`` Hz (linearised at the carriage position) and start."""
        fs = positive("fs", fs)
        y0 = finite("y0", y0)
        finite("r0", r0)
        self.design(plant, fs, plant.y_c)
        fp = plant.fine
        self._vmin = fp.v_min
        self._vmax = fp.v_max
        self._vmid = fp.v_centre
        # bumpless start: the PI integrator holds the voltage already applied
        self._integ = plant.v_applied - fp.v_centre
        self._z1 = 0.0
        self._z2 = 0.0
        st = plant.stepper
        self._dmax = self.max_speed / fs * st.pole_pairs / st.screw_radius
        self._alpha = plant.equilibrium_phase(self.current)
        # fine-stage model (estimate only, logged as y_c_hat)
        mo = self.model
        self._fa = tuple(float(v) for v in mo.A[:2, :2].ravel())
        self._fb = (float(mo.B[0, 0]), float(mo.B[1, 0]))
        self._mf = fp.gain * plant.v_applied - mo.y_f_op
        self._mfd = 0.0
        self._yf_op = mo.y_f_op
        self.y_c_hat = y0 - fp.gain * plant.v_applied
        self.clipped_steps = 0
        self._m_per_rad = st.screw_radius / st.pole_pairs
        self._dyc = 0.0  # carriage motion predicted for the coming period (m)
        self.guard.reset(plant, fs, y0, r0)

    def step(self, y: float, r: float) -> tuple[float, float, float]:
        """One period: measured output ``y`` (m), reference ``r`` (m) → (V, A, A)."""
        y, r = self.guard.filter(y, r, self.y_c_hat + self._dyc + self._yf_op + self._mf)
        e = r - y
        self.y_c_hat = y - self._yf_op - self._mf
        # C2: PI with conditional integration
        ii = self._kih * e
        u2 = self._kp * e + self._integ + ii
        raw = self._vmid + u2
        v, self._integ = clamp_with_antiwindup(raw, self._integ, ii, self._vmin, self._vmax)
        clipped = v != raw
        # C1 = Q C2: low-pass (DF2T biquad) then the phase integrator (rate-limited)
        b0, b1, b2, a1, a2 = self._lp
        w = b0 * u2 + self._z1
        self._z1 = b1 * u2 - a1 * w + self._z2
        self._z2 = b2 * u2 - a2 * w
        d = self._g * w
        dmax = self._dmax
        if d > dmax:
            d = dmax
            clipped = True
        elif d < -dmax:
            d = -dmax
            clipped = True
        if clipped:
            self.clipped_steps += 1
        alpha = self._alpha + d
        self._alpha = alpha
        self._dyc = d * self._m_per_rad
        # fine model for the logged carriage estimate
        fa = self._fa
        dv = v - self._vmid
        mf = self._mf
        mfd = self._mfd
        self._mf = fa[0] * mf + fa[1] * mfd + self._fb[0] * dv
        self._mfd = fa[2] * mf + fa[3] * mfd + self._fb[1] * dv
        cur = self.current
        return v, cur * math.sin(alpha), cur * math.cos(alpha)
