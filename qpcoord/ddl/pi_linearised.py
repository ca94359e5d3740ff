"""Thesis Table 6.1 rows "PI-linearised" and (with :mod:`.flatness`) "Flatness based".

Both keep the coordinator's decoupled SISO structure (fine PI on the combined output, 10 Hz
third-order Butterworth coarse reference, carriage estimate ``ŷ_c = y − ŷ_f``, pre-compensation
of the predicted coarse motion) and replace the direct-coil phase control of the stepper by
**exact feedback linearisation** — thesis Table 6.2 "Amplitude = controlled, Phase = fixed":
the field is placed in quadrature with the estimated rotor angle ``θ̂e = p ŷ_c / r_screw`` and
its amplitude commands the torque::

    i_q = (F_v r + k_f ŷ_c r + T_d sin 4θ̂e) / K_m       (cancels flexure spring and detent)
    α = θ̂e + atan2(i_q, i_d),   I = √(i_q² + i_d²),     i_a = I sin α, i_b = I cos α

so that the carriage obeys ``M ÿ_c + c ẏ_c = F_v − F_friction``, with ``M`` the
carriage-equivalent mass (491 kg: rotor inertia through the screw + flexure) and ``c`` the
viscous coefficient. ``F_v`` is a PI on ``e_c = r_c − ŷ_c`` (this module) or the same PI plus
the flat-output feed-forward ``M r̈_c + c ṙ_c`` (:class:`.flatness.FlatnessBased`).

**Friction** (``friction="dither"``, the default). The lead-screw friction (31 N Coulomb,
41 N stiction on the carriage) is large against the forces a µm-scale coarse reference
needs (``M ω² x`` ≈ 0.2 N for 10 µm at 1 Hz), and a PI designed on the friction-free model
at 2 Hz has a stiffness of 7.7e4 N/m: it would need a 0.5 mm error to break stiction, and
its carriage never moves on a Kolmogorov OPD (measured: travel ratio 0.00 — the
fine stage tracked alone and saturated on a 3× reference). So the linearising law also
handles friction, the two classical ways (Armstrong-Hélouvry et al. 1994):

* a square-wave **dither** force ``±A`` at ``fs/dither_period`` (2 kHz), ``A =
  dither_ratio · F̂_s`` (2 × the model's stiction force, so that +20 % friction still breaks
  away), keeps the carriage sliding (ripple ≈ 1 nm); friction then averages to the smooth
  ``F̄(u) = F̂_c clip(u/v_d, ±1)`` of :mod:`.dither` (a viscous ``c_d = F̂_c/v_d`` ≈ 1.8e6 N·s/m
  about rest);
* a friction **feed-forward** ``F̄(ṙ_c)`` at the rate-limited reference's speed;
* the **coarse PI is designed with that friction in the loop**: same rule (crossover 2 Hz,
  zero 4× below) on ``1/(s(Ms + c + c_d))`` — phase margin 75.8°, stiffness 2.2e7 N/m
  (22 N at 1 µm error); the coarse error is averaged over one dither period (a moving
  average, which has a zero at the dither frequency) so that the carriage's ripple does not
  feed back into the PI, and the pre-compensation's coarse model includes ``F̄``.

``friction="none"`` is the friction-free design the audit measured (kept for comparison).

Design rules (not fits):

* coarse PI: crossover 2 Hz (the coordinator's coarse bandwidth) on ``1/(s(Ms + c'))``, PI
  zero a factor 4 below (0.5 Hz), ``c' = c + c_d`` with the dither (``c' = c`` without:
  phase margin 53.3° on the nominal model);
* the coarse reference is rate-limited to ``max_speed`` (3 mm/s as the coordinator; the
  thesis: "strict rate limitations for speed have been introduced, for the controllers
  based on the decoupled SISO structure"); ``|i_q| ≤ current`` (1.5 A, the direct coil's
  amplitude) with conditional integration;
* ``i_d = 0.01 A``: a small direct-axis current keeps the commanded field angle continuous
  when the torque changes sign (a pure quadrature field would jump by π, which the plant's
  synchronism check cannot tell from a slip); it costs 1e-4 W under Eq 6.6;
* pre-compensation: ``u_d = (r_c − ŷ_c,pred)/K_f`` with ``ŷ_c,pred`` the output of the nominal
  linearised coarse closed loop driven by the rate-limited ``r_c`` (the analogue of the
  coordinator's prediction from the commanded phase).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

from ._check import finite, nonnegative, positive
from .biquad import butterworth_sections, filter_sample
from .dither import dither_model
from .fine import fine_zoh
from .guard import MeasurementGuard, guard_arg
from .pi import clamp_with_antiwindup

__all__ = ["PILinearised"]


class PILinearised:
    """Feedback-linearised stepper with a PI position loop inside the thesis coordinator.

    Parameters
    ----------
    fine_kp, fine_ki : float
        Fine PI gains × K_f (as :class:`.SisoCoordinator`: 0.8 and 2π·180 s⁻¹).
    coarse_cutoff : float
        Butterworth cut-off of the coarse reference, Hz (thesis: 10 Hz, order 3).
    coarse_bandwidth : float
        Crossover of the coarse PI loop on the linearised carriage, Hz.
    pi_ratio : float
        Crossover / PI-zero frequency ratio.
    current : float
        Limit of the quadrature current |i_q|, A.
    d_current : float
        Direct-axis current i_d, A (≥ 0).
    max_speed : float
        Rate limit of the coarse reference, m/s.
    feedforward : bool
        Pre-compensate the predicted coarse motion into the fine voltage.
    friction : {"dither", "none"}
        ``"dither"``: dither + averaged-friction feed-forward + PI designed with the averaged
        friction (module docstring); ``"none"``: friction-free design (the carriage sticks).
    dither_ratio : float
        Dither amplitude / the model's stiction force (> 1).
    dither_period : int
        Dither period, control periods (even ≥ 2).
    guard : MeasurementGuard, optional
        Measurement guard (default: a new :class:`.guard.MeasurementGuard` with the plant's
        physical bounds). A rejected measurement is replaced by the a-priori prediction
        ``2 ŷ_c(k−1) − ŷ_c(k−2) + ŷ_f(k)`` (carriage estimate extrapolated at its last
        speed, fine model advanced; the nominal coarse closed loop is a worse predictor:
        in stiction the carriage does not follow it). With the dither the carriage does
        not stick, and the estimate advances by the nominal model's motion instead (the
        last speed carries the dither's ripple).

    Attributes
    ----------
    y_c_hat : float
        Carriage estimate, m.
    guard : MeasurementGuard
        The measurement guard (``guard.rejected``: measurements rejected).
    """

    flat_feedforward = False

    def __init__(
        self,
        fine_kp: float = 0.8,
        fine_ki: float = 2.0 * math.pi * 180.0,
        coarse_cutoff: float = 10.0,
        coarse_bandwidth: float = 2.0,
        pi_ratio: float = 4.0,
        current: float = 1.5,
        d_current: float = 0.01,
        max_speed: float = 3.0e-3,
        feedforward: bool = True,
        friction: str = "dither",
        dither_ratio: float = 2.0,
        dither_period: int = 4,
        guard: MeasurementGuard | None = None,
    ):
        self.fine_kp = nonnegative("fine_kp", fine_kp)
        self.fine_ki = nonnegative("fine_ki", fine_ki)
        self.coarse_cutoff = positive("coarse_cutoff", coarse_cutoff)
        self.coarse_bandwidth = positive("coarse_bandwidth", coarse_bandwidth)
        self.pi_ratio = positive("pi_ratio", pi_ratio)
        self.current = positive("current", current)
        self.d_current = nonnegative("d_current", d_current)
        self.max_speed = positive("max_speed", max_speed)
        self.feedforward = bool(feedforward)
        if friction not in ("dither", "none"):
            raise ValueError(f"friction must be 'dither' or 'none', got {friction!r}")
        self.friction = friction
        self.dither_ratio = positive("dither_ratio", dither_ratio)
        if self.dither_ratio <= 1.0:
            raise ValueError(f"dither_ratio must be > 1, got {dither_ratio!r}")
        if int(dither_period) != dither_period or dither_period < 2 or int(dither_period) % 2:
            raise ValueError(f"dither_period must be an even integer >= 2, got {dither_period!r}")
        self.dither_period = int(dither_period)
        self.dither = None
        self.guard = guard_arg(guard)
        self.y_c_hat = 0.0

    def coarse_gains(self, mass: float, damping: float) -> tuple[float, float]:
        """``(Kp [N/m], Ki [N/(m·s)])`` of the coarse PI for ``1/(s(M s + c))``."""
        w = 2.0 * math.pi * self.coarse_bandwidth
        wi = w / self.pi_ratio
        kp = w * math.hypot(mass * w, damping) / math.hypot(1.0, wi / w)
        return kp, kp * wi

    def reset(self, plant, fs: float, y0: float, r0: float) -> None:
        """Initialise for ``plant`` at rest at ``fs`` Hz (first measurement/reference in m)."""
        fs = positive("fs", fs)
        y0 = finite("y0", y0)
        r0 = finite("r0", r0)
        if self.coarse_cutoff >= 0.5 * fs:
            raise ValueError(
                f"coarse_cutoff = {self.coarse_cutoff!r} Hz must be below fs/2 = {fs / 2} Hz"
            )
        fp = plant.fine
        st = plant.stepper
        h = 1.0 / fs
        self._h = h
        self._fs = fs
        self._kf = fp.gain
        self._kp = self.fine_kp / fp.gain
        self._kih = self.fine_ki / fp.gain * h
        self._vmin, self._vmax = fp.v_min, fp.v_max
        self._vmid = fp.v_centre
        self._yf_mid = fp.centre
        # coarse-reference Butterworth, started in steady state at r0
        self._bq = butterworth_sections(3, self.coarse_cutoff, fs, r0)
        self._fz = fine_zoh(fp, h)
        v0 = plant.v_applied
        self._mf = fp.gain * v0
        self._mfd = 0.0
        # bumpless start: the fine integrator holds the applied voltage
        self._integ = v0 - self._vmid
        # linearised coarse stage and its PI
        r = st.screw_radius
        self._r = r
        self._ne = st.pole_pairs / r
        self._km = st.torque_constant
        self._td = st.detent_torque
        self._kflex = plant.flexure.spring_rate
        mass = plant.carriage_mass(0.0)
        damp = st.viscous_damping
        self._mass = mass
        self._damp = damp
        if self.friction == "dither":
            r_s = st.screw_radius
            fst = st.static_torque / r_s
            self.dither = dither_model(
                self.dither_ratio * fst, st.coulomb_torque / r_s, fst, mass, fs, self.dither_period
            )
            self._ckp, self._cki = self.coarse_gains(mass, damp + self.dither.damping)
            self._ebuf = [0.0] * self.dither_period
            self._kd = 0
        else:
            self.dither = None
            self._ckp, self._cki = self.coarse_gains(mass, damp)
        self._cint = 0.0
        self._fmax = self.current * st.torque_constant / r  # N
        self._dr = self.max_speed * h
        yc0 = y0 - self._mf
        self._yc0 = yc0
        self._rcl = yc0  # rate-limited coarse reference starts at the carriage
        self._rcl1 = yc0
        self._rcl2 = yc0
        self.y_c_hat = yc0
        # nominal closed-loop coarse model for the pre-compensation (ZOH of M s² + c s)
        a = np.array([[0.0, 1.0], [0.0, -damp / mass]])
        big = np.zeros((3, 3))
        big[:2, :2] = a * h
        big[1, 2] = h / mass
        e = expm(big)
        self._pm = (float(e[0, 1]), float(e[1, 1]), float(e[0, 2]), float(e[1, 2]))
        self._pp = yc0
        self._pv = 0.0
        self._pint = 0.0
        self._dyc = 0.0  # carriage motion predicted for the coming period (m)
        self.guard.reset(plant, fs, y0, r0)

    def step(self, y: float, r: float) -> tuple[float, float, float]:
        """One period: measured output ``y`` (m), reference ``r`` (m) → (V, A, A)."""
        y, r = self.guard.filter(y, r, self.y_c_hat + self._dyc + self._mf)
        x = filter_sample(self._bq, r)
        rc = x - self._yf_mid
        # rate-limited coarse reference and its differences (flat outputs' derivatives)
        d = rc - self._rcl
        dr = self._dr
        if d > dr:
            d = dr
        elif d < -dr:
            d = -dr
        rcl = self._rcl + d
        self._rcl2 = self._rcl1
        self._rcl1 = self._rcl
        self._rcl = rcl
        if self.flat_feedforward:
            fs = self._fs
            vel = (rcl - self._rcl1) * fs
            acc = (rcl - 2.0 * self._rcl1 + self._rcl2) * fs * fs
            f_ff = self._mass * acc + self._damp * vel
        else:
            f_ff = 0.0
        # carriage estimate and the linearising torque command
        yc = y - self._mf
        self._dyc = yc - self.y_c_hat
        self.y_c_hat = yc
        ec = rcl - yc
        dm = self.dither
        fmax = self._fmax
        if dm is not None:
            # average the error over one dither period (removes the carriage's ripple)
            buf = self._ebuf
            kd = self._kd
            buf[kd % dm.period] = ec
            ec = sum(buf) / dm.period
            f_fr = dm.friction((rcl - self._rcl1) * self._fs)
            f_ff += f_fr
            dith = dm.amplitude if kd % dm.period < dm.period // 2 else -dm.amplitude
            self._kd = kd + 1
            flim = fmax - dm.amplitude
        else:
            dith = 0.0
            flim = fmax
        fv = self._ckp * ec + self._cki * self._cint + f_ff
        if -flim < fv < flim:
            self._cint += self._h * ec
        fv += dith
        th = self._ne * yc
        iq = (fv * self._r + self._kflex * yc * self._r + self._td * math.sin(4.0 * th)) / self._km
        cur = self.current
        if iq > cur:
            iq = cur
        elif iq < -cur:
            iq = -cur
        idc = self.d_current
        alpha = th + math.atan2(iq, idc)
        amp = math.hypot(iq, idc)
        # predicted coarse motion: nominal linear closed loop driven by the same reference
        pp, pv = self._pp, self._pv
        epc = rcl - pp
        fp_ = self._ckp * epc + self._cki * self._pint + f_ff
        if fp_ > flim:
            fp_ = flim
        elif fp_ < -flim:
            fp_ = -flim
        else:
            self._pint += self._h * epc
        m01, m11, b0, b1 = self._pm
        # fine PI on the combined output + pre-compensation of the predicted coarse motion
        e = r - y
        u = self._vmid + self._kp * e + self._integ
        if self.feedforward:
            u += (rc - pp) / self._kf
        ii = self._kih * e
        v, self._integ = clamp_with_antiwindup(u + ii, self._integ, ii, self._vmin, self._vmax)
        if dm is None:
            self._pp = pp + m01 * pv + b0 * fp_
            self._pv = m11 * pv + b1 * fp_
        else:  # the model with the averaged friction (semi-implicit Euler, stable: h c_d/M < 1)
            h = self._h
            pv = pv + h * (fp_ - self._damp * pv - dm.friction(pv)) / self._mass
            self._pv = pv
            self._pp = pp + h * pv
            self._dyc = h * pv  # the guard's prediction: the model's motion
        a11, a12, a21, a22, b1f, b2f = self._fz
        mf, mfd = self._mf, self._mfd
        self._mf = a11 * mf + a12 * mfd + b1f * v
        self._mfd = a21 * mf + a22 * mfd + b2f * v
        return v, amp * math.sin(alpha), amp * math.cos(alpha)
