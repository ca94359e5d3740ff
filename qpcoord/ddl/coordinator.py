"""The thesis's closed-loop coordinator for the DDL (Fig 6.10, Eq 6.1): `SisoCoordinator`.

Controller interface (shared by every DDL controller, see :func:`.simulate.simulate`)::

    ctl.reset(plant, fs, y0, r0)          # plant: DualStage at rest; y0 first measurement (m);
                                          # r0 first reference sample (m); fs in Hz
    v, i_a, i_b = ctl.step(y, r)          # once per period: measured output y (m), reference
                                          # r (m) -> piezo voltage (V), coil currents (A)
    ctl.y_c_hat                           # optional: the controller's carriage estimate (m)

Structure (thesis §6.2.3, Fig 6.10):

* fine stage: PI on the combined output error ``e = r − y`` (no model in this loop);
* coarse reference ``r_c`` = 3rd-order Butterworth low-pass at 10 Hz of ``r``, minus the fine
  mid-stroke offset (so that tracking ``r_c`` keeps the piezo centred — goal 2 of §6.2.2);
* coordinator: carriage estimate ``ŷ_c = y − ŷ_f`` with ``ŷ_f`` the output of a second-order
  fine-stage model driven by the voltage actually applied;
* coarse "direct coil" phase controller (Eq 6.1): ``i_a = I sin α``, ``i_b = I cos α`` and the
  field phase α integrates the coarse error with a rate limit,
  ``α(k) = α(k−1) + sat(g e_c(k), ±Δα_max)``, ``e_c = r_c − ŷ_c``;
* pre-compensation of the coarse motion into the fine stage: the coarse displacement predicted
  from the commanded phase, ``ŷ_c,pred = ŷ_c(0) + (α − α(0)) lead/(2π p)`` (the rotor follows
  the field well below the 120 Hz mode), is subtracted in volts:
  ``u_d = (r_c − ŷ_c,pred) / K_f``. The thesis feeds ``−ŷ_c,pred/K_f``; the extra ``r_c/K_f``
  is a slow reference feed-forward the PI integrator would otherwise have to hold — with it the
  integrator stays near zero.

Interpretation of Eq 6.1. The thesis prints ``e_i(k) = e_i(k−1) + K_i (h/T_i) e_c(k)``, then
``α(k) = α(k−1) + e_i(k)``: read literally α is the double integral of the error and, with
the rotor following the field (a static gain from α to y_c), the discrete loop
``(z − 1)² + g = 0`` is unstable for every g > 0. The text describes "a simple integral
controller summing continuously the position error" whose increments of α are rate-limited
(Min/Max), which is what is implemented.

Gains (choices, not in the thesis):

* fine PI ``C(s) = (kp + ki/s)/K_f`` with ``kp = 0.8``, ``ki = 2π·180 s⁻¹``: the pair that
  minimises |S| at 50 Hz subject to phase margin ≥ 60°, gain margin ≥ 10 dB and peak |S| ≤ 1.6
  on the 300 Hz / ζ = 0.7 piezo model discretised at 8 kHz (grid search, ``docs/ch6.md``):
  crossover ≈ 234 Hz, PM 63°, GM 17.9 dB;
* coarse loop bandwidth 2 Hz: the integral loop ``g lead/(2π p)`` gives a first-order loop
  of that bandwidth; at the carriage mode (ζ = 0.02, peak ×25) its gain is about
  ``f_bw/f_mode · 25 · k`` with ``k`` the static gain from commanded to actual carriage
  position: 0.42 at the stroke centre (120 Hz, k = 0.93), 0.45 half a full step away where the
  detent softens the carriage (111 Hz, k = 1.08), i.e. 6.9 dB gain margin at the worst point
  (the thesis: "slow T_i ... to avoid exciting the resonant mode");
* field amplitude I = 1.5 A: 2.25 W under Eq 6.6, the thesis's direct-coil power;
* rate limit 3 mm/s: a sudden carriage speed change Δv excites the 120 Hz mode to a load
  angle ``p Δv / (ωn lead/2π)``; 3 mm/s keeps it below ≈ 0.6 rad electrical (π/4 at
  3.8 mm/s), far from the π/2 pull-out angle.
"""

from __future__ import annotations

import functools
import math

from ._check import finite, nonnegative, positive
from .biquad import butterworth_sections, filter_sample
from .fine import FineParams, fine_zoh
from .guard import MeasurementGuard, guard_arg
from .pi import clamp_with_antiwindup

__all__ = ["SisoCoordinator", "coarse_loop_margin"]


@functools.lru_cache(maxsize=256)
def _coarse_margin(stepper, flexure, fs: float, bandwidth: float, current: float):
    from .loops import coarse_gain_margin
    from .plant import DualStage

    plant = DualStage(stepper=stepper, flexure=flexure)
    ctl = SisoCoordinator(coarse_bandwidth=bandwidth, current=current)
    return coarse_gain_margin(ctl, plant, fs, n=4000)


def coarse_loop_margin(plant, fs: float, coarse_bandwidth: float, current: float = 1.5):
    """Gain margin (absolute) of the coordinator's linear coarse loop at the carriage mode and
    its frequency (Hz), for ``plant``'s stepper and flexure at ``fs`` Hz: the smallest over
    the carriage's operating points (:func:`.loops.coarse_gain_margin`; cached per parameter
    set, ≈ 30 ms when not). < 1 means the loop is unstable: the carriage mode oscillates,
    bounded only by friction (with an amplitude ≈ carriage speed / (2π f_mode) while the
    carriage slides) and the rate limit.
    """
    return _coarse_margin(
        plant.stepper, plant.flexure, float(fs), float(coarse_bandwidth), float(current)
    )


class SisoCoordinator:
    """Thesis coordinator: fine PI on the output, direct-coil integral phase control of the
    stepper on a 10 Hz Butterworth reference, model-based carriage estimate and
    pre-compensation (Fig 6.10, Eq 6.1).

    Parameters
    ----------
    fine_kp : float
        Proportional gain of the fine PI, dimensionless (V/m × K_f); ≥ 0.
    fine_ki : float
        Integral gain of the fine PI, 1/s (V/(m·s) × K_f); ≥ 0.
    coarse_cutoff : float
        Cut-off of the Butterworth low-pass on the coarse reference, Hz (thesis: 10 Hz).
    coarse_order : int
        Order of that Butterworth filter (thesis: 3).
    coarse_bandwidth : float
        Bandwidth of the coarse integral loop, Hz (``K_i/T_i`` of Eq 6.1 expressed as a
        closed-loop bandwidth). :meth:`reset` raises ``ValueError`` if, on the plant and at
        the rate it is given, the linear coarse loop has a negative gain margin at the
        carriage mode (:func:`coarse_loop_margin`; above 4.43 Hz for the default plant at
        8 kHz; the thesis's 2 Hz keeps 6.9 dB).
    current : float
        Field amplitude ``I_peak``, A.
    max_speed : float
        Rate limit of the field phase (Min/Max of Eq 6.1) as a carriage speed, m/s.
    feedforward : bool
        Pre-compensate the predicted coarse motion into the fine voltage.
    fine_model : FineParams, optional
        Fine-stage model used by the coordinator (default: the plant's own parameters —
        pass different ones to study model mismatch).
    guard : MeasurementGuard, optional
        Measurement guard (default: a new :class:`.guard.MeasurementGuard` with the plant's
        physical bounds). A rejected measurement is replaced by the a-priori prediction
        ``ŷ_c(k−1) + Δα lead/(2π p) + ŷ_f(k)`` (carriage estimate moved with the field
        phase, fine model advanced).
    saturation_guard : float, optional
        Saturation guard threshold, m (default ``None``: off, the thesis coordinator). When
        the fine-stage model's distance to a stop falls under it, the coarse loop takes more
        of the reference: with ``w = 1 − distance/threshold`` (0 → 1), its error becomes
        ``(1 − w) e_c + w (ŷ_f − centre)`` (the fine stage's offset, which the coarse stage
        must absorb for the piezo to return to mid-stroke) and its gain is multiplied by
        ``1 + (guard_gain − 1) w``; the phase increment stays rate-limited (``max_speed``).
        Steps in which it acted are counted in :attr:`saturation_guard_steps` (reported by
        :func:`.simulate.simulate` as the metric ``saturation_guard_steps``).
    guard_gain : float
        Largest multiplier of the coarse gain under the saturation guard (≥ 1). The boosted
        loop has less gain margin at the carriage mode (÷ ``guard_gain``), but only while
        the fine stage is near a stop.
    literal_eq61 : bool
        Use Eq 6.1 exactly as printed (``e_i`` accumulates the error, is clamped to the rate
        limit, and α integrates ``e_i``: a double integrator). Unstable — kept only to show
        why the default reads Eq 6.1 as a single, rate-limited integrator.

    Attributes
    ----------
    y_c_hat : float
        Latest carriage estimate, m.
    guard : MeasurementGuard
        The measurement guard (``guard.rejected``: measurements rejected).
    saturation_guard_steps : int
        Steps in which the saturation guard acted since :meth:`reset`.
    """

    def __init__(
        self,
        fine_kp: float = 0.8,
        fine_ki: float = 2.0 * math.pi * 180.0,
        coarse_cutoff: float = 10.0,
        coarse_order: int = 3,
        coarse_bandwidth: float = 2.0,
        current: float = 1.5,
        max_speed: float = 3.0e-3,
        feedforward: bool = True,
        fine_model: FineParams | None = None,
        literal_eq61: bool = False,
        guard: MeasurementGuard | None = None,
        saturation_guard: float | None = None,
        guard_gain: float = 3.0,
    ):
        self.fine_kp = nonnegative("fine_kp", fine_kp)
        self.fine_ki = nonnegative("fine_ki", fine_ki)
        self.coarse_cutoff = positive("coarse_cutoff", coarse_cutoff)
        if int(coarse_order) != coarse_order or not 1 <= coarse_order <= 8:
            raise ValueError(f"coarse_order must be an integer in 1..8, got {coarse_order!r}")
        self.coarse_order = int(coarse_order)
        self.coarse_bandwidth = positive("coarse_bandwidth", coarse_bandwidth)
        self.current = positive("current", current)
        self.max_speed = positive("max_speed", max_speed)
        self.feedforward = bool(feedforward)
        if fine_model is not None and not isinstance(fine_model, FineParams):
            raise ValueError(f"fine_model must be a FineParams, got {fine_model!r}")
        self.fine_model = fine_model
        self.literal_eq61 = bool(literal_eq61)
        self.guard = guard_arg(guard)
        self.saturation_guard = (
            None if saturation_guard is None else positive("saturation_guard", saturation_guard)
        )
        self.guard_gain = positive("guard_gain", guard_gain)
        if self.guard_gain < 1.0:
            raise ValueError(f"guard_gain must be >= 1, got {guard_gain!r}")
        self.saturation_guard_steps = 0
        self.y_c_hat = 0.0

    def reset(self, plant, fs: float, y0: float, r0: float, *, check_margin: bool = True) -> None:
        """Initialise for ``plant`` (at rest, just reset) at sampling rate ``fs`` (Hz).

        ``y0`` is the first measurement (m), ``r0`` the first reference sample (m). The field
        phase starts at the plant's equilibrium phase for ``current`` so that the carriage
        does not jump. ``check_margin=False`` skips the coarse-loop stability check: only for
        analysis that studies unstable settings on purpose
        (:func:`.stability.simulated_coarse_margin`).
        """
        fs = positive("fs", fs)
        y0 = finite("y0", y0)
        r0 = finite("r0", r0)
        if self.coarse_cutoff >= 0.5 * fs:
            raise ValueError(
                f"coarse_cutoff = {self.coarse_cutoff!r} Hz must be below fs/2 = {fs / 2} Hz"
            )
        if check_margin and not self.literal_eq61:
            gm, fgm = coarse_loop_margin(plant, fs, self.coarse_bandwidth, self.current)
            if gm < 1.0:
                raise ValueError(
                    f"coarse_bandwidth = {self.coarse_bandwidth!r} Hz makes the coarse loop "
                    f"unstable at the {fgm:.1f} Hz carriage mode of this plant at fs = {fs:g} Hz "
                    f"(gain margin {20.0 * math.log10(gm):.1f} dB < 0 dB); "
                    "qpcoord.ddl.check_reference(...).allowed_bandwidth or design_coordinator "
                    "gives a stable setting"
                )
        fp = plant.fine
        fm = fp if self.fine_model is None else self.fine_model
        self._h = 1.0 / fs
        self._kf = fm.gain
        self._kp = self.fine_kp / fm.gain
        self._kih = self.fine_ki / fm.gain / fs
        self._vmin = fp.v_min
        self._vmax = fp.v_max
        self._vmid = fm.v_centre
        self._yf_mid = fm.centre
        self._integ = 0.0
        # coarse-reference Butterworth, started in steady state at r0
        self._bq = butterworth_sections(self.coarse_order, self.coarse_cutoff, fs, r0)
        # fine-stage model for the carriage estimate, at rest at the applied voltage
        self._fz = fine_zoh(fm, self._h)
        v0 = plant.v_applied
        self._v = v0
        self._mf = fm.gain * v0
        self._mfd = 0.0
        # coarse phase controller
        st = plant.stepper
        gain_m = st.screw_radius / st.pole_pairs  # m per electrical rad
        self._m_per_rad = gain_m
        self._g = 2.0 * math.pi * self.coarse_bandwidth / fs / gain_m  # rad per m per step
        self._dmax = self.max_speed / fs / gain_m  # rad per step
        self._ei = 0.0
        self._alpha = plant.equilibrium_phase(self.current)
        self._alpha0 = self._alpha
        self._yc0 = y0 - self._mf
        self.y_c_hat = self._yc0
        self._dyc = 0.0  # carriage motion predicted for the coming period (m)
        self.guard.reset(plant, fs, y0, r0)
        self._fmin = fm.stroke_min
        self._fmax = fm.stroke_max
        self.saturation_guard_steps = 0

    def step(self, y: float, r: float) -> tuple[float, float, float]:
        """One control period: measurement ``y`` (m), reference ``r`` (m) → (V, A, A)."""
        y, r = self.guard.filter(y, r, self.y_c_hat + self._dyc + self._mf)
        # coarse reference: Butterworth low-pass, minus the fine mid-stroke offset
        x = filter_sample(self._bq, r)
        rc = x - self._yf_mid
        # coordinator: carriage estimate from the output and the fine-stage model
        yc_hat = y - self._mf
        self.y_c_hat = yc_hat
        # direct-coil integral phase control with rate limit (Eq 6.1)
        sg = self.saturation_guard
        if sg is None:
            d = self._g * (rc - yc_hat)
        else:
            mf = self._mf
            dist = min(mf - self._fmin, self._fmax - mf)
            if dist < sg:
                w = 1.0 if dist <= 0.0 else 1.0 - dist / sg
                ec = (1.0 - w) * (rc - yc_hat) + w * (mf - self._yf_mid)
                d = self._g * (1.0 + (self.guard_gain - 1.0) * w) * ec
                self.saturation_guard_steps += 1
            else:
                d = self._g * (rc - yc_hat)
        if self.literal_eq61:
            d += self._ei
        dmax = self._dmax
        if d > dmax:
            d = dmax
        elif d < -dmax:
            d = -dmax
        self._ei = d
        self._dyc = d * self._m_per_rad
        alpha = self._alpha + d
        self._alpha = alpha
        cur = self.current
        ia = cur * math.sin(alpha)
        ib = cur * math.cos(alpha)
        # fine PI on the combined output + pre-compensation of the coarse motion
        e = r - y
        u = self._vmid + self._kp * e + self._integ
        if self.feedforward:
            u += (rc - self._yc0 - (alpha - self._alpha0) * self._m_per_rad) / self._kf
        integ_step = self._kih * e
        v, self._integ = clamp_with_antiwindup(
            u + integ_step, self._integ, integ_step, self._vmin, self._vmax
        )
        # advance the fine model with the applied voltage (estimate for the next period)
        a11, a12, a21, a22, b1, b2 = self._fz
        mf = self._mf
        mfd = self._mfd
        self._mf = a11 * mf + a12 * mfd + b1 * v
        self._mfd = a21 * mf + a22 * mfd + b2 * v
        return v, ia, ib
