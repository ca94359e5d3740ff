"""The DDL dual-stage plant: piezo fine stage on a stepper-driven, flexure-guided carriage.

One control period of ``1/fs`` seconds is simulated per :meth:`DualStage.step` call with the
controller's commands held constant (zero-order hold):

* fine stage: exact ZOH discretisation of the second-order piezo model (:mod:`.fine`), input
  voltage clipped to the amplifier range, hard stroke limits (a stage that reaches a limit
  stops there); an optional hysteresis element in front of the linear dynamics;
* coarse stage: the nonlinear stepper (:mod:`.stepper`) + lead screw + blade flexure
  (:mod:`.flexure`) integrated with ``n_sub`` semi-implicit Euler sub-steps per period
  (sub-step rate ≥ ``substep_rate``, 32 kHz by default: ≥ 260 sub-steps per period of the
  120 Hz mode), with Coulomb + viscous friction and stiction (a Karnopp stick band: a carriage at
  rest stays at rest while the driving force is below the static friction force), end stops at
  ±half stroke, and loss-of-synchronism detection (the rotor's electrical angle more than π
  away from the commanded field phase: it has slipped to another pole);
* metrology: ``y = y_c + y_f`` plus optional Gaussian noise, quantised to 1.25 nm.

Coordinates: ``y_c`` is the carriage displacement from the flexure's rest position (stroke
centre), ``y_f`` the piezo extension from its 0 V length (0–30 µm). All SI units.
"""

from __future__ import annotations

import math
import random

import numpy as np

from ._check import finite, nonnegative, positive
from .fine import FineParams, fine_zoh
from .flexure import BladeFlexure
from .stepper import StepperParams

__all__ = ["DualStage"]

_TWO_PI = 2.0 * math.pi


class DualStage:
    """ESO/PRIMA Differential Delay Line dual-stage plant (PRIMA defaults).

    Parameters
    ----------
    fine : FineParams, optional
        Piezo fine stage (default: S-325, 3 µm/V, 300 Hz, 0–30 µm).
    stepper : StepperParams, optional
        PM stepper, lead screw and friction (defaults documented in :mod:`.stepper`).
    flexure : BladeFlexure, optional
        Blade-flexure guide (appendix B; defaults documented in :mod:`.flexure`).
    resolution : float
        Metrology quantisation step, m (Agilent 10897B: 1.25 nm). 0 disables quantisation.
    noise_rms : float
        Metrology white noise, m rms (default 0).
    hysteresis : object, optional
        Any object with ``reset()`` and ``step(volts) -> float`` (e.g. a Preisach model). It is
        placed in series in front of the linear piezo dynamics; ``hysteresis_output`` says what
        its ``step`` returns: ``"V"`` (an equivalent voltage) or ``"m"`` (a static extension,
        divided by the fine gain to drive the dynamics).
    hysteresis_output : {"V", "m"}
        Unit of the hysteresis element's output.
    substep_rate : float
        Minimum internal integration rate of the coarse stage, Hz.

    Notes
    -----
    Call :meth:`reset` (with the sampling rate) before :meth:`step`. After each step the
    attributes ``y_c``, ``yd_c`` (carriage, m and m/s), ``y_f``, ``yd_f`` (piezo), ``v_applied``
    (V after clipping), ``field_phase`` (unwrapped commanded phase, rad electrical),
    ``fine_saturated`` (bool, this step), ``coarse_at_stop`` (bool), ``lost_sync`` (latched
    bool) and ``sync_slip_steps`` (number of steps with the rotor > π from the field) describe
    the true state.
    """

    def __init__(
        self,
        fine: FineParams | None = None,
        stepper: StepperParams | None = None,
        flexure: BladeFlexure | None = None,
        *,
        resolution: float = 1.25e-9,
        noise_rms: float = 0.0,
        hysteresis=None,
        hysteresis_output: str = "V",
        substep_rate: float = 32000.0,
    ):
        self.fine = FineParams() if fine is None else fine
        self.stepper = StepperParams() if stepper is None else stepper
        self.flexure = BladeFlexure() if flexure is None else flexure
        for name, obj, cls in (
            ("fine", self.fine, FineParams),
            ("stepper", self.stepper, StepperParams),
            ("flexure", self.flexure, BladeFlexure),
        ):
            if not isinstance(obj, cls):
                raise ValueError(f"{name} must be a {cls.__name__}, got {obj!r}")
        self.resolution = nonnegative("resolution", resolution)
        self.noise_rms = nonnegative("noise_rms", noise_rms)
        if hysteresis is not None and not (
            callable(getattr(hysteresis, "reset", None))
            and callable(getattr(hysteresis, "step", None))
        ):
            raise ValueError(
                f"hysteresis must have reset() and step(volts) methods, got {hysteresis!r}"
            )
        if hysteresis_output not in ("V", "m"):
            raise ValueError(f"hysteresis_output must be 'V' or 'm', got {hysteresis_output!r}")
        self.hysteresis = hysteresis
        self.hysteresis_output = hysteresis_output
        self.substep_rate = positive("substep_rate", substep_rate)
        self.fs = None

    # ------------------------------------------------------------------ properties
    @property
    def coarse_half_stroke(self) -> float:
        """Half of the coarse stroke, m (the carriage moves in ±this)."""
        return self.flexure.half_stroke

    @property
    def output_range(self) -> tuple[float, float]:
        """Smallest and largest reachable output ``y = y_c + y_f``, m."""
        h = self.coarse_half_stroke
        return (-h + self.fine.stroke_min, h + self.fine.stroke_max)

    def carriage_mass(self, y_c: float = 0.0) -> float:
        """Total carriage-equivalent mass (rotor inertia through the screw + flexure), kg."""
        r = self.stepper.screw_radius
        return self.stepper.inertia / (r * r) + float(self.flexure.effective_mass(y_c))

    def coarse_stiffness(self, y_c: float = 0.0, current: float = 1.5) -> float:
        """Small-signal stiffness of the carriage held by a field of amplitude ``current``.

        Magnetic + detent + flexure spring at carriage position ``y_c`` (m), N/m.
        """
        s = self.stepper
        r = s.screw_radius
        n = s.pole_pairs
        th = y_c * n / r
        load = -float(self.flexure.force(y_c)) * r + s.detent_torque * math.sin(4.0 * th)
        km_i = s.torque_constant * current
        if abs(load) >= km_i:
            raise ValueError(
                f"current {current!r} A cannot hold the carriage at y_c = {y_c!r} m "
                f"(load torque {load:.3g} N·m)"
            )
        cos_d = math.sqrt(1.0 - (load / km_i) ** 2)
        k_mag = km_i * cos_d * n / (r * r)
        k_det = 4.0 * s.detent_torque * n * math.cos(4.0 * th) / (r * r)
        return k_mag + k_det + self.flexure.spring_rate

    def coarse_resonance(self, y_c: float = 0.0, current: float = 1.5) -> float:
        """Undamped electromechanical resonance of the linearised coarse stage, Hz."""
        k = self.coarse_stiffness(y_c, current)
        return math.sqrt(k / self.carriage_mass(y_c)) / _TWO_PI

    @property
    def min_sample_rate(self) -> float:
        """Lowest accepted controller rate, Hz: 4 × the fastest plant mode (fine or coarse).

        Below it the controller could not observe or act on the piezo's or the stepper's
        modes (Nyquist with a factor-2 margin).
        """
        return 4.0 * max(self.fine.natural_frequency, self.coarse_resonance(0.0, 1.5))

    # ------------------------------------------------------------------ reset / equilibrium
    def equilibrium_phase(self, current: float) -> float:
        """Field phase α (rad electrical, unwrapped) that holds the carriage at rest where it is.

        Solves ``Km I sin(α − θe) = load torque`` (flexure spring + detent) with
        ``|α − θe| < π/2``. Raises ValueError if ``current`` cannot hold the load.
        """
        current = positive("current", current)
        if self.fs is None:
            raise RuntimeError("call DualStage.reset(fs, ...) before equilibrium_phase()")
        s = self.stepper
        r = s.screw_radius
        th = self.y_c * s.pole_pairs / r
        load = -float(self.flexure.force(self.y_c)) * r + s.detent_torque * math.sin(4.0 * th)
        km_i = s.torque_constant * current
        if abs(load) >= km_i:
            raise ValueError(f"current {current!r} A cannot hold the load torque {load:.3g} N·m")
        return th + math.asin(load / km_i)

    def reset(
        self,
        fs: float,
        y0: float = 0.0,
        *,
        coarse0: float | None = None,
        v0: float | None = None,
        seed: int = 0,
    ) -> float:
        """Put the plant at rest and return the first (quantised) measurement, m.

        Parameters
        ----------
        fs : float
            Controller sampling rate, Hz (≥ :attr:`min_sample_rate`).
        y0 : float
            Initial output, m. The carriage is placed at ``y0 − y_f`` (fine stage at rest at
            ``v0``) unless ``coarse0`` is given.
        coarse0 : float, optional
            Initial carriage position, m (overrides ``y0``).
        v0 : float, optional
            Initial piezo voltage, V (default: mid-stroke voltage).
        seed : int
            Seed of the metrology noise.
        """
        fs = positive("fs", fs)
        if fs < self.min_sample_rate:
            raise ValueError(
                f"fs = {fs!r} Hz is too low for the plant's fast modes: need at least "
                f"{self.min_sample_rate:.0f} Hz (4 × the fastest mode)"
            )
        y0 = finite("y0", y0)
        fp = self.fine
        v0 = fp.v_centre if v0 is None else finite("v0", v0)
        if not fp.v_min <= v0 <= fp.v_max:
            raise ValueError(f"v0 must lie in [{fp.v_min}, {fp.v_max}] V, got {v0!r}")
        self.fs = fs
        self.dt = 1.0 / fs
        self._fz = fine_zoh(fp, self.dt)
        if self.hysteresis is not None:
            self.hysteresis.reset()
            ve = float(self.hysteresis.step(v0))
            if self.hysteresis_output == "m":
                ve /= fp.gain
        else:
            ve = v0
        self.v_applied = v0
        self.y_f = min(max(fp.gain * ve, fp.stroke_min), fp.stroke_max)
        self.yd_f = 0.0
        yc = (y0 - self.y_f) if coarse0 is None else finite("coarse0", coarse0)
        h = self.coarse_half_stroke
        if not -h <= yc <= h:
            raise ValueError(
                f"initial carriage position {yc!r} m is outside the coarse stroke ±{h} m "
                f"(y0 = {y0!r} m)"
            )
        self.y_c = yc
        self.yd_c = 0.0
        s = self.stepper
        self._n_sub = max(1, math.ceil(self.substep_rate / fs))
        self._h = self.dt / self._n_sub
        r = s.screw_radius
        self._ne = s.pole_pairs / r  # electrical rad per metre
        self._kc = s.torque_constant / r  # N per A
        self._kd = s.detent_torque / r  # N
        self._fc = s.coulomb_torque / r  # N
        self._fst = s.static_torque / r  # N
        self._cv = s.viscous_damping
        self._kf = self.flexure.spring_rate
        self._m0 = s.inertia / (r * r) + self.flexure.main_mass + 0.25 * self.flexure.platform_mass
        self._mq = self.flexure.mass_curvature
        self._imax = s.current_max
        self.field_phase = self.y_c * self._ne
        self._phase_wrapped = math.atan2(math.sin(self.field_phase), math.cos(self.field_phase))
        self.fine_saturated = False
        self.coarse_at_stop = False
        self.lost_sync = False
        self.sync_slip_steps = 0
        self._rng = random.Random(int(seed))
        return self.measure()

    def measure(self) -> float:
        """Metrology reading of the current state: ``y_c + y_f`` + noise, quantised, m."""
        y = self.y_c + self.y_f
        if self.noise_rms > 0.0:
            y += self._rng.gauss(0.0, self.noise_rms)
        q = self.resolution
        if q > 0.0:
            y = math.floor(y / q + 0.5) * q
        return y

    # ------------------------------------------------------------------ one period
    def step(self, v: float, ia: float, ib: float) -> float:
        """Advance one control period with piezo voltage ``v`` (V) and coil currents (A).

        Commands are clipped to the amplifier ranges (0–10 V, ±``current_max``). Returns the
        metrology measurement at the end of the period, m. Non-finite commands raise
        ValueError.
        """
        if not (v - v == 0.0 and ia - ia == 0.0 and ib - ib == 0.0):
            raise ValueError(f"non-finite command: v={v!r}, ia={ia!r}, ib={ib!r}")
        fp = self.fine
        # ---- fine stage (exact ZOH, hard stops)
        if v < fp.v_min:
            v = fp.v_min
        elif v > fp.v_max:
            v = fp.v_max
        self.v_applied = v
        hyst = self.hysteresis
        if hyst is not None:
            ve = float(hyst.step(v))
            if self.hysteresis_output == "m":
                ve /= fp.gain
        else:
            ve = v
        a11, a12, a21, a22, b1, b2 = self._fz
        yf = self.y_f
        vf = self.yd_f
        yf_n = a11 * yf + a12 * vf + b1 * ve
        vf = a21 * yf + a22 * vf + b2 * ve
        sat = False
        if yf_n >= fp.stroke_max:
            yf_n = fp.stroke_max
            vf = 0.0
            sat = True
        elif yf_n <= fp.stroke_min:
            yf_n = fp.stroke_min
            vf = 0.0
            sat = True
        self.y_f = yf_n
        self.yd_f = vf
        self.fine_saturated = sat
        # ---- coarse stage
        imax = self._imax
        if ia > imax:
            ia = imax
        elif ia < -imax:
            ia = -imax
        if ib > imax:
            ib = imax
        elif ib < -imax:
            ib = -imax
        x = self.y_c
        xd = self.yd_c
        ne = self._ne
        kia = self._kc * ia
        kib = self._kc * ib
        kd = self._kd
        kf = self._kf
        fc = self._fc
        fst = self._fst
        cv = self._cv
        mq = self._mq
        minv = 1.0 / (self._m0 + mq * x * x)
        h = self._h
        hm = h * minv
        cos = math.cos
        sin = math.sin
        for _ in range(self._n_sub):
            th = ne * x
            c = cos(th)
            s = sin(th)
            f = kia * c - kib * s - kd * 4.0 * s * c * (c * c - s * s) - kf * x
            if xd == 0.0:
                if -fst <= f <= fst:
                    continue  # stuck (stiction)
                xd = hm * (f - fc) if f > 0.0 else hm * (f + fc)
            else:
                if xd > 0.0:
                    f -= fc + cv * xd + mq * x * xd * xd
                    xd_n = xd + hm * f
                    xd = 0.0 if xd_n < 0.0 else xd_n
                else:
                    f += fc - cv * xd - mq * x * xd * xd
                    xd_n = xd + hm * f
                    xd = 0.0 if xd_n > 0.0 else xd_n
            x += h * xd
        hs = self.flexure.half_stroke
        stop = False
        if x >= hs:
            x = hs
            xd = 0.0
            stop = True
        elif x <= -hs:
            x = -hs
            xd = 0.0
            stop = True
        self.coarse_at_stop = stop
        self.y_c = x
        self.yd_c = xd
        # ---- synchronism: unwrapped field phase vs rotor electrical angle
        if ia != 0.0 or ib != 0.0:
            a = math.atan2(ia, ib)
            d = a - self._phase_wrapped
            if d > math.pi:
                d -= _TWO_PI
            elif d < -math.pi:
                d += _TWO_PI
            self.field_phase += d
            self._phase_wrapped = a
        lag = self.field_phase - ne * x
        if lag > math.pi or lag < -math.pi:
            self.lost_sync = True
            self.sync_slip_steps += 1
        # ---- metrology
        y = x + yf_n
        if self.noise_rms > 0.0:
            y += self._rng.gauss(0.0, self.noise_rms)
        q = self.resolution
        if q > 0.0:
            y = math.floor(y / q + 0.5) * q
        return y

    # ------------------------------------------------------------------ linear model
    def linearise(self, y_c: float = 0.0, current: float = 1.5, inputs: str = "phase"):
        """Small-signal state-space model about rest at carriage position ``y_c``.

        Parameters
        ----------
        y_c : float
            Operating carriage position, m.
        current : float
            Field amplitude I (A) of the direct-coil commands ``i_a = I sin α``,
            ``i_b = I cos α`` at the operating point.
        inputs : {"phase", "currents"}
            ``"phase"``: inputs (v [V], α [rad electrical]); ``"currents"``: inputs
            (v [V], i_a [A], i_b [A]).

        Returns
        -------
        control.StateSpace
            Continuous-time model, states (y_f m, ẏ_f m/s, y_c m, ẏ_c m/s) as deviations
            from the operating point, outputs (y, y_f, y_c) in m. Coulomb friction, stiction,
            quantisation and hysteresis are not in the linear model; viscous friction is.
        """
        import control

        y_c = finite("y_c", y_c)
        current = positive("current", current)
        if inputs not in ("phase", "currents"):
            raise ValueError(f"inputs must be 'phase' or 'currents', got {inputs!r}")
        h = self.coarse_half_stroke
        if not -h <= y_c <= h:
            raise ValueError(f"y_c = {y_c!r} m is outside the coarse stroke ±{h} m")
        s = self.stepper
        r = s.screw_radius
        ne = s.pole_pairs / r
        th = y_c * ne
        load = -float(self.flexure.force(y_c)) * r + s.detent_torque * math.sin(4.0 * th)
        km_i = s.torque_constant * current
        if abs(load) >= km_i:
            raise ValueError(f"current {current!r} A cannot hold the carriage at y_c = {y_c!r} m")
        alpha = th + math.asin(load / km_i)
        k = self.coarse_stiffness(y_c, current)
        m = self.carriage_mass(y_c)
        fa, fb = self.fine.continuous()
        a = np.zeros((4, 4))
        a[:2, :2] = fa
        a[2, 3] = 1.0
        a[3, 2] = -k / m
        a[3, 3] = -s.viscous_damping / m
        if inputs == "phase":
            b = np.zeros((4, 2))
            b[1, 0] = fb[1]
            b[3, 1] = km_i * math.cos(alpha - th) / r / m
        else:
            b = np.zeros((4, 3))
            b[1, 0] = fb[1]
            b[3, 1] = s.torque_constant * math.cos(th) / r / m
            b[3, 2] = -s.torque_constant * math.sin(th) / r / m
        c = np.array([[1.0, 0.0, 1.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
        d = np.zeros((3, b.shape[1]))
        return control.ss(
            a,
            b,
            c,
            d,
            states=["y_f", "yd_f", "y_c", "yd_c"],
            inputs=["v", "alpha"] if inputs == "phase" else ["v", "i_a", "i_b"],
            outputs=["y", "y_f", "y_c"],
        )

    def linear(
        self,
        fs: float = 8000.0,
        *,
        y_c: float = 0.0,
        current: float = 1.5,
        max_speed: float = 3.0e-3,
        disturbances=(),
    ):
        """This plant as a :class:`.linear_plant.LinearDualStage` at ``fs`` Hz.

        The LQR/MPC design model (:func:`.lqr.design_model`: linearised about rest at ``y_c``
        with the field amplitude ``current``, the detent averaged over a full step) split into
        its two actuators: coarse input the field phase α (rad electrical, deviation from
        the holding phase), fine input the piezo voltage (V, deviation from mid-stroke), both
        positions in m from the operating point (the fine stage's centre is 0). Fine input
        range and stroke from :attr:`fine`; coarse stroke what is left of the flexure's
        travel from ``y_c``; the field phase's rate limit keeps the carriage below
        ``max_speed`` (m/s, the synchronism limit of the coordinator); measurement noise the
        metrology quantisation ``q/√12`` and ``noise_rms``. Friction, stiction and the
        stepper's nonlinear torque are not in it.
        """
        from .linear_plant import LinearDualStage
        from .lqr import design_model

        sysc = design_model(self, fs, y_c, current).continuous
        a = np.asarray(sysc.A, dtype=float)
        b = np.asarray(sysc.B, dtype=float)
        fp = self.fine
        h = self.coarse_half_stroke
        zero = np.zeros((1, 1))
        return LinearDualStage(
            (a[2:, 2:], b[2:, 1:2], np.array([[1.0, 0.0]]), zero),
            (a[:2, :2], b[:2, 0:1], np.array([[1.0, 0.0]]), zero),
            1.0 / positive("fs", fs),
            fine_range=(fp.v_min - fp.v_centre, fp.v_max - fp.v_centre),
            coarse_rate=positive("max_speed", max_speed) * self.stepper.electrical_per_metre,
            coarse_stroke=(-h - y_c, h - y_c),
            fine_stroke=(fp.stroke_min - fp.centre, fp.stroke_max - fp.centre),
            disturbances=disturbances,
            noise_rms=math.sqrt(self.resolution**2 / 12.0 + self.noise_rms**2),
            name="PRIMA DDL",
        )
