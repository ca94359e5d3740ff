"""Synthetic piezo stacks whose hysteresis is *not* the identified Preisach model.

Used to test the Preisach compensator of appendix C on plants it was not built from.

:class:`BoucWenPiezo` — Bouc–Wen: no wipe-out memory, no congruency, and its minor loops do
not close (they ratchet towards the loop centre), unlike a real stack's.

:class:`RelayPiezo` — a "perturbed Preisach" stack: a few thousand explicit relay
hysterons (Eq. C.1 computed by brute force, seeded random switching values, smooth
density, *not* on any identification mesh) plus a smooth anhysteretic curvature plus a
small Bouc–Wen part that breaks wipe-out and congruency.

Bouc–Wen model (rate-independent, voltage ``u`` in V, displacement ``x`` in m)::

    x = x₀ + d u + e (u − u_min)² − h
    dh = A du − β |du| h − γ du |h|        (Bouc–Wen, exponent 1)

``h`` (m) is integrated *exactly* over each voltage increment (on each piece where ``h``
keeps its sign the equation is linear in ``u``), so the response does not depend on the
sampling. ``x₀`` puts ``x = 0`` at ``u_min`` on the major loop.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

__all__ = ["BoucWenPiezo", "RelayPiezo"]


class _Stack(ABC):
    """Per-sample plumbing shared by the synthetic stacks: range checks, output units."""

    u_min: float
    u_max: float
    clip: bool
    output: str
    _x: float

    def _setup(self, u_min, u_max, clip, output) -> None:
        if not (math.isfinite(u_min) and math.isfinite(u_max) and u_max > u_min):
            raise ValueError(
                f"need finite u_min < u_max, got u_min = {u_min!r} V, u_max = {u_max!r} V"
            )
        if output not in ("metres", "volts"):
            raise ValueError(f"output must be 'metres' or 'volts', got {output!r}")
        self.u_min, self.u_max = float(u_min), float(u_max)
        self.clip = bool(clip)
        self.output = output

    def _finish(self) -> None:
        """Measure the stroke (m) from negative saturation to ``u_max``; then reset."""
        self.reset()
        self.stroke = self._advance_to(self.u_max)
        self.reset()

    @abstractmethod
    def _advance_to(self, u: float) -> float:
        """Move the input to ``u`` (V) along the stack's own path; return ``x`` (m)."""

    @abstractmethod
    def reset(self) -> None:
        """Put the stack on its major loop at ``u_min`` (negative saturation)."""

    @property
    def x(self) -> float:
        """Current displacement (m)."""
        return self._x

    def step(self, volts: float) -> float:
        """Apply ``volts`` (V) for one sample; return the displacement (m), or with
        ``output="volts"`` the effective voltage ``u_min + x (u_max − u_min)/stroke`` (V)."""
        u = float(volts)
        if not (self.u_min <= u <= self.u_max):
            if self.clip and u == u:
                u = min(max(u, self.u_min), self.u_max)
            else:
                what = "NaN" if u != u else "outside the amplifier range"
                raise ValueError(f"volts = {u!r} V is {what} [{self.u_min!r}, {self.u_max!r}] V")
        x = self._advance_to(u)
        if self.output == "volts":
            return self.u_min + x * (self.u_max - self.u_min) / self.stroke
        return x

    def run(self, u) -> np.ndarray:
        """Outputs (m, or V if ``output="volts"``) for a voltage signal ``u`` (V), continuing
        from the current state (a Python loop over :meth:`step`)."""
        u = np.array(u, dtype=float, ndmin=1)
        if u.ndim != 1:
            raise ValueError(f"u must be 1-D, got shape {u.shape}")
        step = self.step
        return np.fromiter((step(v) for v in u.tolist()), dtype=float, count=u.size)


class BoucWenPiezo(_Stack):
    """Bouc–Wen hysteretic piezo stack, stateful, per-sample and vectorised.

    Parameters
    ----------
    gain : float
        Linear gain ``d`` (m/V).
    quadratic : float
        Curvature ``e`` of the anhysteretic part (m/V²).
    a : float
        ``A = a·d``: hysteretic gain relative to ``d`` (dimensionless, 0 < a).
    beta, gamma : float
        Bouc–Wen shape parameters (1/V), ``beta > |gamma|``.
    u_min, u_max : float
        Amplifier range (V).
    clip : bool
        Saturate inputs outside ``[u_min, u_max]`` instead of raising.
    output : {"metres", "volts"}
        What :meth:`step` returns: the displacement (m), or the effective voltage
        ``u_min + x (u_max − u_min)/stroke`` (V) that a hysteresis-free stack with the same
        stroke would need (to put the hysteresis in front of a linear stage model).

    Notes
    -----
    The defaults give a stack of 27.3 µm for 0–10 V with a major-loop width of 2.0 µm
    (7.4 % of the stroke), as measured by ``examples/appC_preisach.py``. Attribute
    ``stroke`` (m): output at ``u_max`` after a rise from negative saturation.
    :meth:`reset` puts the stack on its major loop at ``u_min`` (negative saturation,
    reached by cycling the full range three times).
    """

    def __init__(
        self,
        gain: float = 2.6e-6,
        quadratic: float = 4.0e-8,
        a: float = 0.22,
        beta: float = 0.3,
        gamma: float = 0.1,
        u_min: float = 0.0,
        u_max: float = 10.0,
        clip: bool = False,
        output: str = "metres",
    ) -> None:
        self._setup(u_min, u_max, clip, output)
        for name, v in (
            ("gain", gain),
            ("quadratic", quadratic),
            ("a", a),
            ("beta", beta),
            ("gamma", gamma),
        ):
            if not math.isfinite(v):
                raise ValueError(f"{name} = {v!r} is not finite")
        if gain <= 0 or a <= 0:
            raise ValueError(f"gain = {gain!r} m/V and a = {a!r} must be positive")
        if not beta > abs(gamma):
            raise ValueError(f"beta = {beta!r} 1/V must exceed |gamma| = {abs(gamma)!r} 1/V")
        self.gain, self.quadratic = float(gain), float(quadratic)
        self.A = float(a) * self.gain
        self.beta, self.gamma = float(beta), float(gamma)
        # negative saturation on the major loop: cycle the range from h = 0
        h = 0.0
        for _ in range(3):
            h = self._advance(h, self.u_max - self.u_min)
            h = self._advance(h, self.u_min - self.u_max)
        self._h0 = h
        self._x0 = 0.0
        self._x0 = -self._output(self.u_min, h)
        self._finish()

    def _output(self, u: float, h: float) -> float:
        du = u - self.u_min
        return self._x0 + self.gain * u + self.quadratic * du * du - h

    def _advance(self, h: float, delta: float) -> float:
        """Exact Bouc–Wen increment of ``h`` (m) over a voltage change ``delta`` (V)."""
        if delta == 0.0:
            return h
        A, b, g = self.A, self.beta, self.gamma
        s = 1.0 if delta > 0 else -1.0
        rem = delta
        for _ in range(2):  # at most one sign change of h per monotone increment
            sigma = s if h == 0.0 else (1.0 if h > 0 else -1.0)
            k = b * s + g * sigma
            hinf = A / k
            if sigma != s:  # h moves towards 0: does it get there within rem?
                d0 = -h / A if k == 0.0 else -math.log(hinf / (hinf - h)) / k
                if abs(d0) < abs(rem):
                    h, rem = 0.0, rem - d0
                    continue
            return hinf + (h - hinf) * math.exp(-k * rem) if k != 0.0 else h + A * rem
        return h

    def reset(self) -> None:
        """Negative saturation: ``u = u_min`` on the major loop, ``x = 0``."""
        self._u = self.u_min
        self._h = self._h0
        self._x = self._output(self.u_min, self._h0)

    def _advance_to(self, u: float) -> float:
        self._h = self._advance(self._h, u - self._u)
        self._u = u
        self._x = self._output(u, self._h)
        return self._x


class RelayPiezo(_Stack):
    """Perturbed-Preisach piezo stack: explicit relay hysterons + curvature + Bouc–Wen.

    ``x = x₀ + d u + e (u − u_min)² + Σₖ wₖ γₖ[u] + x_bw(u)``, with relays ``γₖ`` of Eq.
    C.1 (1 above ``αₖ``, 0 below ``βₖ``, unchanged between) and ``x_bw`` the hysteretic
    part ``−h`` of a :class:`BoucWenPiezo` (its linear part removed).

    Parameters
    ----------
    n_relays : int
        Number of hysterons.
    hysteresis : float
        Total relay weight ``Σ wₖ`` (m).
    width : float
        Decay length (V) of the relay density away from the diagonal: ``μ ∝ exp(−(α −
        β)/width)``, uniform along it (so large loops are wider than small ones).
    gain, quadratic : float
        ``d`` (m/V) and ``e`` (m/V²) of the anhysteretic part.
    bouc_wen : float
        ``a`` of the added Bouc–Wen part (0 disables it); its ``beta``/``gamma`` are the
        :class:`BoucWenPiezo` defaults.
    u_min, u_max : float
        Amplifier range (V).
    seed : int
        Seed of the relays' switching values.
    clip : bool
        Saturate inputs outside ``[u_min, u_max]`` instead of raising.
    output : {"metres", "volts"}
        What :meth:`step` returns: the displacement (m), or the effective voltage
        ``u_min + x (u_max − u_min)/stroke`` (V) that a hysteresis-free stack with the same
        stroke would need (to put the hysteresis in front of a linear stage model).

    Notes
    -----
    A step costs a few numpy operations on ``n_relays`` values (12–28 µs median at 3000
    relays, measured by ``examples/appC_preisach.py``). The defaults give a 30.6 µm stroke
    with a 3.0 µm (9.8 %) major-loop width, as measured there. :meth:`reset` switches every
    relay off at ``u_min`` (negative saturation) and sets ``x = 0``. Attribute ``stroke``
    (m): output at ``u_max`` after a rise from negative saturation.
    """

    def __init__(
        self,
        n_relays: int = 3000,
        hysteresis: float = 8.0e-6,
        width: float = 2.5,
        gain: float = 2.1e-6,
        quadratic: float = 2.0e-8,
        bouc_wen: float = 0.04,
        u_min: float = 0.0,
        u_max: float = 10.0,
        seed: int = 0,
        clip: bool = False,
        output: str = "metres",
    ) -> None:
        self._setup(u_min, u_max, clip, output)
        n_relays = int(n_relays)
        if n_relays < 1:
            raise ValueError(f"n_relays = {n_relays!r} must be ≥ 1")
        for name, v in (("hysteresis", hysteresis), ("width", width), ("gain", gain)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} = {v!r} must be positive and finite")
        if not (math.isfinite(bouc_wen) and bouc_wen >= 0):
            raise ValueError(f"bouc_wen = {bouc_wen!r} must be ≥ 0 and finite")
        rng = np.random.default_rng(seed)
        span = self.u_max - self.u_min
        # (α − β) ~ exponential(width) truncated to the triangle, position uniform
        gap = -width * np.log1p(-rng.random(n_relays) * (1 - math.exp(-span / width)))
        lo = self.u_min + rng.random(n_relays) * (span - gap)
        self.beta_k = lo
        self.alpha_k = lo + gap
        self.weights = np.full(n_relays, hysteresis / n_relays)
        self.gain, self.quadratic = float(gain), float(quadratic)
        self._bw = (
            BoucWenPiezo(gain=gain, a=bouc_wen, quadratic=0.0, u_min=u_min, u_max=u_max)
            if bouc_wen > 0
            else None
        )
        self._on = np.zeros(n_relays, dtype=bool)
        self._finish()

    def reset(self) -> None:
        """Negative saturation: every relay off, ``u = u_min``, ``x = 0``."""
        self._on[:] = False
        self._u = self.u_min
        if self._bw is not None:
            self._bw.reset()
        self._x = 0.0

    def _advance_to(self, u: float) -> float:
        on = self._on
        if u > self._u:
            on |= self.alpha_k <= u
        elif u < self._u:
            on &= self.beta_k < u
        self._u = u
        du = u - self.u_min
        x = self.gain * du + self.quadratic * du * du + float(self.weights @ on)
        if self._bw is not None:
            bw = self._bw
            bw.step(u)
            x += bw.x - bw.gain * (u - self.u_min)  # the Bouc–Wen hysteretic part, h₀ − h
        self._x = x
        return x
