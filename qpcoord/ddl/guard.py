"""The measurement guard shared by every DDL controller: :class:`MeasurementGuard`.

A metrology sample that is not finite, or that no stage could have produced, must not reach a
controller's integrators, observers or QP: one NaN latches NaN commands for ever, and one
0.1 m sample winds an integrator up for seconds. Every controller of :mod:`qpcoord.ddl` owns
one :class:`MeasurementGuard` (attribute ``guard``) and passes each period's measurement and
reference through :meth:`MeasurementGuard.filter` before using them.

Rule (all in SI units; ``h = 1/fs``):

* a measurement ``y`` is **rejected** if it is not finite, if it lies outside the plant's
  output range ``[−L + y_f,min, L + y_f,max]`` widened by one ``max_jump``, or if it differs
  from the last *accepted* measurement by more than ``n · max_jump``, ``n`` the number of
  periods since that measurement (the allowance grows while samples are rejected, so a real
  motion is never locked out);
* ``max_jump = safety · (Δy_f,max + v_c,max h) + 2 q + 12 σ`` — what the two stages together
  can move in one period, plus quantisation ``q`` and noise ``σ``:

  - ``Δy_f,max = min(stroke, v_f,max h)``, ``v_f,max`` the largest speed the piezo model can
    reach with its voltage anywhere in the amplifier range: ``(v_max − v_min)`` times the
    total upward variation of its impulse response (for the 300 Hz, ζ = 0.7 S-325:
    ``v_f,max`` = 27.1 mm/s, 3.39 µm per period at 8 kHz);
  - ``v_c,max = F_max / c``: with ``M ẍ = F − c ẋ − friction`` and ``|F| ≤ F_max`` the carriage
    speed can never exceed ``F_max/c`` (it starts at rest). ``F_max`` = the stepper's largest
    torque (``√2 · Km · I_max``, both phases at their current limit) through the screw + the
    flexure's largest spring force + the detent: 4 666 + 150 + 31 = 4 847 N; with
    ``c`` = 14 790 N·s/m, ``v_c,max`` = 0.328 m/s, 41.0 µm per period at 8 kHz;
  - ``safety = 1.5`` covers ±20 % parameter errors (the comparison's mismatch cases) with
    margin; with the default plant at 8 kHz ``max_jump`` = 66.6 µm.

  A carriage without viscous damping (``c = 0``) has no speed bound: then only non-finite and
  out-of-range samples are rejected;
* a rejected measurement is replaced by the controller's own **a-priori prediction** of it
  (its model's estimate before the measurement update: the carriage estimate held plus the
  fine-stage model's output; for the LQR and the MPC the observer's predicted output, i.e. the
  update is skipped). A non-finite prediction is replaced by the last accepted measurement;
* the reference is guarded too (a controller may be stepped outside :func:`.simulate`, which
  validates its reference): a non-finite reference, or one outside the output range, is
  replaced by the last valid one. There is no rate bound on the reference: a step reference
  (5 mm in one sample, Fig 6.19) is legitimate;
* counts: :attr:`rejected` (measurements, reported by :func:`.simulate` as the metric
  ``rejected_samples``) and :attr:`rejected_references`.

What the guard cannot see: a wrong sample inside the physical bound (e.g. a 10 µm spike) or a
stuck sensor (a frozen value is a possible value). The loop handles those; ``docs/ch6.md``
gives the measured recoveries.

Cost: one method call a period, ≈ 0.2–0.4 µs (measured in ``docs/ch6.md``).
"""

from __future__ import annotations

import math

from ._check import positive

__all__ = [
    "MeasurementGuard",
    "fine_speed_bound",
    "carriage_speed_bound",
    "max_jump",
    "describe_bounds",
    "guard_arg",
]


def fine_speed_bound(fine) -> float:
    """Largest speed of the second-order fine-stage model for any voltage history in range, m/s.

    ``|ẏ_f| ≤ (v_max − v_min) · TV⁺(h)``, ``h`` the model's impulse response (m/(V·s)) and
    ``TV⁺`` its total upward variation (the positive area of ``ḣ``): the velocity is the
    convolution of ``ḣ`` with the voltage, whose integral is 0, so the bound is reached by the
    bang-bang voltage that follows the sign of ``ḣ``. Underdamped closed form:
    ``TV⁺ = H/(1 − ρ)`` with ``H`` the first peak of ``h`` and ``ρ = exp(−ζπ/√(1 − ζ²))``;
    (critically) overdamped: ``TV⁺ = H``.
    """
    k = fine.gain
    wn = 2.0 * math.pi * fine.natural_frequency
    z = fine.damping
    if z < 1.0:
        wd = wn * math.sqrt(1.0 - z * z)
        a = z * wn
        t = math.atan2(wd, a) / wd
        peak = k * wn * wn / wd * math.exp(-a * t) * math.sin(wd * t)
        rho = math.exp(-z * math.pi / math.sqrt(1.0 - z * z))
        tv = peak / (1.0 - rho)
    elif z == 1.0:
        tv = k * wn * math.exp(-1.0)  # h = K ωn² t e^{−ωn t}, peak at t = 1/ωn
    else:
        s = math.sqrt(z * z - 1.0)
        s1, s2 = -wn * (z - s), -wn * (z + s)
        t = math.log(s2 / s1) / (s1 - s2)
        tv = k * wn * wn * (math.exp(s1 * t) - math.exp(s2 * t)) / (s1 - s2)
    return (fine.v_max - fine.v_min) * tv


def carriage_speed_bound(plant) -> float:
    """Largest carriage speed the plant allows, m/s: ``F_max / c`` (``inf`` if ``c = 0``).

    ``F_max`` (N) = stepper torque with both phases at ``current_max`` (``√2 Km I_max``) through
    the screw + the flexure's spring force at the end of the stroke + the detent torque
    through the screw; ``c`` the viscous damping referred to the carriage (N·s/m). Friction
    only slows the carriage, so it is left out.
    """
    st = plant.stepper
    r = st.screw_radius
    f_max = (
        math.sqrt(2.0) * st.torque_constant * st.current_max / r
        + abs(float(plant.flexure.force(plant.flexure.half_stroke)))
        + st.detent_torque / r
    )
    c = st.viscous_damping
    return math.inf if c <= 0.0 else f_max / c


def max_jump(plant, fs: float, safety: float = 1.5) -> float:
    """Largest change of the measured output in one period at ``fs`` Hz, m (see module)."""
    fs = positive("fs", fs)
    fp = plant.fine
    dyf = min(fp.stroke_max - fp.stroke_min, fine_speed_bound(fp) / fs)
    dyc = carriage_speed_bound(plant) / fs
    return safety * (dyf + dyc) + 2.0 * plant.resolution + 12.0 * plant.noise_rms


class MeasurementGuard:
    """Reject non-finite or physically impossible measurements (and bad references).

    Parameters
    ----------
    max_jump : float, optional
        Largest accepted change of the measurement in one period, m. Default: derived from
        the plant at :meth:`reset` by :func:`max_jump` (66.6 µm for the default plant at
        8 kHz).
    safety : float
        Factor on the physical one-period bound when ``max_jump`` is derived (default 1.5).

    Attributes
    ----------
    rejected : int
        Measurements rejected since :meth:`reset`.
    rejected_references : int
        References rejected since :meth:`reset`.
    max_jump : float
        Bound in use, m (after :meth:`reset`).
    lower, upper : float
        Accepted measurement range, m (after :meth:`reset`).
    """

    def __init__(self, max_jump: float | None = None, safety: float = 1.5):
        self.max_jump_arg = None if max_jump is None else positive("max_jump", max_jump)
        self.safety = positive("safety", safety)
        self.max_jump = math.nan
        self.lower = -math.inf
        self.upper = math.inf
        self.rejected = 0
        self.rejected_references = 0
        self._last = 0.0
        self._allow = math.inf
        self._r = 0.0

    def reset(self, plant, fs: float, y0: float, r0: float) -> None:
        """Derive the bounds for ``plant`` at ``fs`` Hz; ``y0``, ``r0`` (m) are the first
        measurement and reference (validated by the controller), the first "last valid" values.
        """
        jump = self.max_jump_arg
        if jump is None:
            jump = max_jump(plant, fs, self.safety)
        self.max_jump = jump
        lo, hi = plant.output_range
        self._rlo, self._rhi = lo, hi
        self.lower = lo - jump
        self.upper = hi + jump
        self._last = float(y0)
        self._allow = jump
        self._r = float(r0)
        self.rejected = 0
        self.rejected_references = 0

    def filter(self, y: float, r: float, y_pred: float) -> tuple[float, float]:
        """This period's measurement and reference, checked (m).

        Returns ``(y, r)`` if both are valid. A rejected ``y`` is replaced by ``y_pred`` (the
        controller's a-priori prediction of it, m; the last accepted measurement if
        ``y_pred`` is not finite), a rejected ``r`` by the last valid reference; each
        rejection is counted. NaN fails every comparison, so one chained test rejects it.
        """
        d = y - self._last
        allow = self._allow
        if -allow <= d <= allow and self.lower <= y <= self.upper:
            self._last = y
            self._allow = self.max_jump
        else:
            self.rejected += 1
            self._allow = allow + self.max_jump
            y = y_pred if y_pred - y_pred == 0.0 else self._last
        if self._rlo <= r <= self._rhi:
            self._r = r
        else:
            self.rejected_references += 1
            r = self._r
        return y, r


def describe_bounds(plant, fs: float, safety: float = 1.5) -> dict:
    """The numbers of the rule for ``plant`` at ``fs`` Hz: ``fine_speed_bound``,
    ``carriage_speed_bound`` (m/s), ``fine_jump``, ``carriage_jump``, ``max_jump`` (m per
    period) and ``output_range`` (m)."""
    fp = plant.fine
    vf = fine_speed_bound(fp)
    vc = carriage_speed_bound(plant)
    return {
        "fine_speed_bound": vf,
        "fine_jump": min(fp.stroke_max - fp.stroke_min, vf / fs),
        "carriage_speed_bound": vc,
        "carriage_jump": vc / fs,
        "max_jump": max_jump(plant, fs, safety),
        "output_range": tuple(float(v) for v in plant.output_range),
    }


def guard_arg(guard) -> MeasurementGuard:
    """A controller's ``guard=`` argument: a :class:`MeasurementGuard`, or None for a new one."""
    if guard is None:
        return MeasurementGuard()
    if not isinstance(guard, MeasurementGuard):
        raise ValueError(f"guard must be a MeasurementGuard or None, got {guard!r}")
    return guard
