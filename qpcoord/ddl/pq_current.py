"""The PQ method with the coarse stage as the main actuator, current-driven: :class:`PQCurrent`.

Thesis Table 6.2 lists a PQ controller beside the LQR (global structure, 0.012 W in Table 6.1,
i.e. an amplitude-controlled stepper) whose coarse stage is "quite at the limit of what is
allowed" and shows "a sort of stepping behavior" from static friction (§6.4.2, Fig 6.18b).
:class:`.pq.PQ` splits the work at 2 Hz like the coordinator, with the field phase at fixed
amplitude, and behaves like it; :class:`PQCurrent` is the hard-disk-drive design the thesis
cites (Schroeck & Messner, ACC 1999; the voice-coil motor as main actuator, the
micro-actuator correcting the high-frequency residual):

* coarse plant ``G1 = 1/(s(Ms + c))`` (force → y_c, the feedback-linearised stepper of
  :class:`.drive.LinearisingDrive`, friction not modelled), fine plant ``G2 = K_f H(s)``;
* ``Q`` cancels the coarse plant's known dynamics and makes the relative loop an integrator
  that hands over at ``f_pq``::

      Q(s) = K_f ω_pq (M s + c) / (1 + s/ω_l)²,      PQ = ω_pq / (s H(s) (1 + s/ω_l)²)

  so the coarse stage takes everything below ``f_pq`` (the DC and the low-frequency OPD),
  the fine stage the rest;
* ``C2`` is the fine PI of the coordinator (``kp = 0.8/K_f``, ``ki = 2π·180/K_f``), ``C1 = Q C2``
  — the coarse force is the filtered fine command, so the carriage moves to bring the fine
  stage back to mid-stroke.

Design rules (not fits): ``f_pq`` = 60 Hz, a quarter of the fine loop's 234 Hz crossover (in
HDD practice the hand-over sits a small fraction below the servo bandwidth so that the
coarse actuator is the main one); ``f_l = 4 f_pq`` (keeps the relative loop's phase margin
large, so the stages do not cancel). Measured at 8 kHz (:meth:`PQCurrent.report`): |PQ| = 1
at 56.8 Hz with 78.7° of PQ phase margin; coarse share |PQ/(1+PQ)| 0.99 at 10 Hz, 0.16 at
234 Hz; complete loop crossover 224 Hz, PM 56.1°, GM 16.6 dB, peak |S| 1.66 (the
coordinator's fine-loop rule asks ≤ 1.6: 4 % over, not re-tuned), delay margin 5 periods.

With friction in the plant and none in the design, the coarse force ``Q(0) u_2 = ω_pq c x``
builds up with the fine stage's share ``x`` of the motion until it breaks stiction
(x ≈ F_s/(ω_pq c) ≈ 7 µm): the coarse stage moves in steps, the behaviour the thesis reports.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from ._check import finite, nonnegative, positive
from .drive import LinearisingDrive
from .fine import fine_zoh
from .guard import MeasurementGuard, guard_arg
from .lqr import delay_margin, loop_margins
from .pi import clamp_with_antiwindup

__all__ = ["PQCurrent"]


class PQCurrent:
    """PQ-method controller, coarse stage as main actuator, feedback-linearised stepper.

    Parameters
    ----------
    pq_crossover : float
        Hand-over frequency ``f_pq`` (|PQ| = 1), Hz.
    lowpass_ratio : float
        ``f_l / f_pq`` (> 1): corner of the double low-pass in ``Q``.
    fine_kp, fine_ki : float
        ``C2`` gains × K_f (dimensionless, 1/s).
    current, d_current : float
        Quadrature-current limit and direct-axis current, A (:class:`.drive.LinearisingDrive`).
    design_plant : DualStage, optional
        Plant whose parameters define ``G1``, ``G2`` (default: the plant given to ``reset``).
    guard : MeasurementGuard, optional
        Measurement guard; a rejected measurement is replaced by ``ŷ_c(k−1) + ŷ_f(k)``.

    Attributes
    ----------
    y_c_hat : float
        Carriage estimate ``y − ŷ_f`` (fine model driven by the applied voltage), m.
    clipped_steps : int
        Steps with the voltage or the current at its limit.
    """

    def __init__(
        self,
        pq_crossover: float = 60.0,
        lowpass_ratio: float = 4.0,
        fine_kp: float = 0.8,
        fine_ki: float = 2.0 * math.pi * 180.0,
        current: float = 1.5,
        d_current: float = 0.01,
        design_plant=None,
        guard: MeasurementGuard | None = None,
    ):
        self.pq_crossover = positive("pq_crossover", pq_crossover)
        self.lowpass_ratio = positive("lowpass_ratio", lowpass_ratio)
        if self.lowpass_ratio <= 1.0:
            raise ValueError(f"lowpass_ratio must be > 1, got {lowpass_ratio!r}")
        self.fine_kp = nonnegative("fine_kp", fine_kp)
        self.fine_ki = positive("fine_ki", fine_ki)
        self.current = positive("current", current)
        self.drive = LinearisingDrive(current, d_current)
        self.design_plant = design_plant
        self.guard = guard_arg(guard)
        self.y_c_hat = 0.0
        self.fs = None

    # ------------------------------------------------------------------ design
    def design(self, plant, fs: float) -> PQCurrent:
        """Discrete ``C2`` and ``Q`` for ``plant`` at ``fs`` Hz (Tustin for ``Q``)."""
        fs = positive("fs", fs)
        fl = self.lowpass_ratio * self.pq_crossover
        if fl >= 0.45 * fs:
            raise ValueError(f"lowpass corner {fl!r} Hz must be below 0.45 fs = {0.45 * fs} Hz")
        dp = plant if self.design_plant is None else self.design_plant
        self._dp = dp
        self.fs = fs
        kf = dp.fine.gain
        self._kp = self.fine_kp / kf
        self._kih = self.fine_ki / kf / fs
        self._mass = dp.carriage_mass(0.0)
        self._damp = dp.stepper.viscous_damping
        wpq = 2.0 * math.pi * self.pq_crossover
        wl = 2.0 * math.pi * fl
        g = kf * wpq * wl * wl
        num = [g * self._mass, g * self._damp]
        den = [1.0, 2.0 * wl, wl * wl]
        bz, az = signal.bilinear(num, den, fs)
        bz = np.concatenate([np.zeros(3 - len(bz)), bz])
        self._q = (float(bz[0]), float(bz[1]), float(bz[2]), float(az[1]), float(az[2]))
        return self

    def _systems(self):
        """Discrete ``G1`` (N → m), ``G2`` (V → m), ``C2`` (m → V), ``Q`` (V → N)."""
        import control

        h = 1.0 / self.fs
        m, c = self._mass, self._damp
        g1 = control.c2d(control.tf([1.0], [m, c, 0.0]), h, method="zoh")
        fa, fb = self._dp.fine.continuous()
        g2 = control.c2d(control.ss(fa, fb.reshape(2, 1), [[1.0, 0.0]], [[0.0]]), h)
        c2 = control.tf([self._kp + self._kih, -self._kp], [1.0, -1.0], dt=h)
        b0, b1, b2, a1, a2 = self._q
        q = control.tf([b0, b1, b2], [1.0, a1, a2], dt=h)
        return g1, g2, c2, q

    def report(self, n: int = 4000) -> dict:
        """``pq_crossover_hz``, ``pq_phase_margin_deg`` (180° + ∠PQ there), the coarse share
        ``|PQ/(1+PQ)|`` at 1, 10, 60 and 234 Hz, and the complete loop
        ``L = (G1 Q + G2) C2``'s :func:`.lqr.loop_margins`, ``delay_margin_samples`` and
        ``max_pole_modulus`` (closed loop, < 1 = stable). Requires :meth:`design`."""
        import control

        if self.fs is None:
            raise RuntimeError("call design(plant, fs) or reset(...) before report()")
        g1, g2, c2, q = self._systems()
        fs = self.fs
        f = np.logspace(-1, math.log10(0.499 * fs), int(n))

        def pq(fh):
            z = np.exp(2j * math.pi * np.asarray(fh) / fs)
            return np.asarray(g1(z)) * np.asarray(q(z)) / np.asarray(g2(z))

        mag = np.abs(pq(f))
        k = int(np.flatnonzero((mag[:-1] >= 1.0) & (mag[1:] < 1.0))[0])
        t = math.log(mag[k]) / (math.log(mag[k]) - math.log(mag[k + 1]))
        f_pq = float(f[k] * (f[k + 1] / f[k]) ** t)
        x = complex(pq(f_pq))
        loop = control.minreal((g1 * q + g2) * c2, verbose=False)
        out = {
            "pq_crossover_hz": f_pq,
            "pq_phase_margin_deg": 180.0 + math.degrees(math.atan2(x.imag, x.real)),
            "coarse_share": {
                fh: float(abs(complex(pq(fh)) / (1.0 + complex(pq(fh)))))
                for fh in (1.0, 10.0, 60.0, 234.0)
            },
        }
        out.update(loop_margins(loop, fs))
        out["delay_margin_samples"] = delay_margin(loop)
        out["max_pole_modulus"] = float(np.max(np.abs(control.poles(control.feedback(loop, 1)))))
        return out

    # ------------------------------------------------------------------ interface
    def reset(self, plant, fs: float, y0: float, r0: float) -> None:
        """Design for ``plant`` at ``fs`` Hz and start at rest (bumpless fine integrator)."""
        fs = positive("fs", fs)
        y0 = finite("y0", y0)
        finite("r0", r0)
        self.design(plant, fs)
        dp = self._dp
        fp = dp.fine
        self._vmin, self._vmax, self._vmid = fp.v_min, fp.v_max, fp.v_centre
        self._integ = plant.v_applied - fp.v_centre
        self._z1 = 0.0
        self._z2 = 0.0
        self._fz = fine_zoh(fp, 1.0 / fs)
        self._mf = fp.gain * plant.v_applied
        self._mfd = 0.0
        self.drive.reset(dp)
        self.y_c_hat = y0 - self._mf
        self.clipped_steps = 0
        self.guard.reset(plant, fs, y0, r0)

    def step(self, y: float, r: float) -> tuple[float, float, float]:
        """One period: measured output ``y`` (m), reference ``r`` (m) → (V, A, A)."""
        y, r = self.guard.filter(y, r, self.y_c_hat + self._mf)
        e = r - y
        yc = y - self._mf
        self.y_c_hat = yc
        # C2: PI with conditional integration
        ii = self._kih * e
        u2 = self._kp * e + self._integ + ii
        raw = self._vmid + u2
        v, self._integ = clamp_with_antiwindup(raw, self._integ, ii, self._vmin, self._vmax)
        # C1 = Q C2 (DF2T biquad): the coarse force
        b0, b1, b2, a1, a2 = self._q
        f = b0 * u2 + self._z1
        self._z1 = b1 * u2 - a1 * f + self._z2
        self._z2 = b2 * u2 - a2 * f
        ia, ib, _ = self.drive.command(f, yc)
        if v != raw or self.drive.saturated:
            self.clipped_steps += 1
        # fine model for the carriage estimate
        a11, a12, a21, a22, bf1, bf2 = self._fz
        mf, mfd = self._mf, self._mfd
        self._mf = a11 * mf + a12 * mfd + bf1 * v
        self._mfd = a21 * mf + a22 * mfd + bf2 * v
        return v, ia, ib
