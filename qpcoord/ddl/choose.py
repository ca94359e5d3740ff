"""Choose a controller for a linear dual stage: :func:`choose_controller`.

The candidates — :class:`.lqg.LQG` (its robust rule), :class:`.linear_mpc.LinearMPC` and
:class:`.split.FrequencySplit` over a grid of split frequencies — are each designed on the
plant, rejected when their loop is unstable, then simulated
(:func:`.linear_sim.simulate_linear`) on fresh disturbances: the plant's disturbance models
driven by new seeds and, when a recording is given, surrogate recordings with its power
spectrum (random phases: the recording itself is never replayed). Every spec item is checked
on every realisation; the candidate meeting all of them with the smallest worst-case error
is returned, and when none does the report says which items fail, by how much, for each.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Spec", "Choice", "choose_controller", "surrogate"]


@dataclass(frozen=True)
class Spec:
    """What the closed loop must achieve (SI units; ``None``: not required).

    Attributes
    ----------
    rms : float, optional
        Largest rms of the measured error over a realisation, m.
    sigma3 : float, optional
        Largest 3 × std of the error, m.
    fine_margin : float
        Smallest distance the fine stage keeps to its stroke ends, m (0: never outside).
    peak_sensitivity : float
        Largest peak of ``|S|`` (absolute; 2 = 6 dB) of the linear law.
    """

    rms: float | None = None
    sigma3: float | None = None
    fine_margin: float = 0.0
    peak_sensitivity: float = 2.0


@dataclass
class Choice:
    """The outcome of :func:`choose_controller`.

    Attributes
    ----------
    controller : object
        The chosen controller (the best candidate even when none meets the spec).
    name : str
        Its label.
    met : bool
        Whether it meets every spec item on every realisation.
    candidates : list of dict
        Per candidate: ``name``, ``rms`` / ``sigma3`` (worst over realisations, m),
        ``fine_margin`` (smallest, m), ``peak_sensitivity``, ``failures`` (list of strings:
        item, value, limit) or ``error`` (why it could not be designed).
    """

    controller: object
    name: str
    met: bool
    candidates: list = field(default_factory=list)

    def __str__(self) -> str:
        lines = [f"chosen: {self.name} ({'meets the spec' if self.met else 'spec NOT met'})"]
        for c in self.candidates:
            if "error" in c:
                lines.append(f"  {c['name']}: not designed ({c['error']})")
                continue
            fails = "; ".join(c["failures"]) or "meets the spec"
            lines.append(
                f"  {c['name']}: rms {c['rms'] * 1e9:.3g} nm, 3σ {c['sigma3'] * 1e9:.3g} nm, "
                f"fine margin {c['fine_margin'] * 1e9:.4g} nm, peak |S| "
                f"{20 * math.log10(c['peak_sensitivity']):.2f} dB: {fails}"
            )
        return "\n".join(lines)


def surrogate(recording, seed: int) -> np.ndarray:
    """A new signal with the power spectrum of ``recording`` (1-D, finite): its FFT with
    random phases (the mean kept), same length."""
    x = np.asarray(recording, dtype=float)
    if x.ndim != 1 or x.size < 4 or not np.all(np.isfinite(x)):
        raise ValueError("recording must be a finite 1-D array of at least 4 samples")
    spec = np.fft.rfft(x - x.mean())
    rng = np.random.default_rng(seed)
    ph = np.exp(2j * math.pi * rng.random(spec.size))
    ph[0] = 1.0
    if x.size % 2 == 0:
        ph[-1] = 1.0
    return np.fft.irfft(np.abs(spec) * ph, n=x.size) + x.mean()


def _candidates(plant, split_bandwidths):
    from .linear_mpc import LinearMPC
    from .lqg import LQG
    from .split import FrequencySplit

    out = [("LQG", lambda: LQG(plant))]
    out.append(("LinearMPC", lambda: LinearMPC(plant)))
    for cb, fb in split_bandwidths:
        out.append(
            (
                f"FrequencySplit({cb:g} Hz, {fb:g} Hz)",
                lambda cb=cb, fb=fb: FrequencySplit(plant, cb, fb),
            )
        )
    return out


def choose_controller(
    plant,
    spec: Spec,
    *,
    recording=None,
    realisations: int = 3,
    steps: int | None = None,
    seed: int = 1000,
    split_bandwidths=None,
) -> Choice:
    """Design the candidates on ``plant`` and return the best that meets ``spec``.

    Parameters
    ----------
    plant : LinearDualStage
        With the disturbance models the design assumes (they are also what the fresh
        realisations are drawn from).
    spec : Spec
    recording : array_like, optional
        A recorded output disturbance or reference (m, one sample per ``Ts``): each
        realisation adds a surrogate of it (:func:`surrogate`) at the output.
    realisations : int
        Fresh realisations per candidate (seeds ``seed``, ``seed + 1``, …).
    steps : int, optional
        Periods per realisation (default: the recording's length, else 2000).
    split_bandwidths : sequence of (float, float), optional
        ``(coarse, fine)`` bandwidths (Hz) of the FrequencySplit candidates (default: coarse
        1, 3, 10 Hz × fine 0.05 / (2 Ts), capped by Nyquist).
    """
    from .lqg import closed_loop_poles, sensitivity

    if not isinstance(spec, Spec):
        raise ValueError(f"spec must be a Spec, got {spec!r}")
    realisations = int(realisations)
    if realisations < 1:
        raise ValueError(f"realisations must be >= 1, got {realisations!r}")
    if steps is None:
        steps = 2000 if recording is None else int(np.asarray(recording).size)
    if split_bandwidths is None:
        fb = 0.05 / (2.0 * plant.Ts)
        split_bandwidths = [(cb, fb) for cb in (1.0, 3.0, 10.0) if cb < fb]
    ts = plant.Ts
    f = np.geomspace(1e-4 / ts, 0.499 / ts, 300)
    rows = []
    best = None
    for name, make in _candidates(plant, split_bandwidths):
        try:
            ctl = make()
            law = getattr(ctl, "lqg", ctl)  # the MPC's linear law where no constraint acts
            if np.max(np.abs(closed_loop_poles(plant, law))) >= 1.0:
                raise ValueError("unstable loop")
        except ValueError as exc:
            rows.append({"name": name, "error": str(exc)})
            continue
        pk = float(np.max(np.abs(sensitivity(plant, law, f))))
        worst = {"rms": 0.0, "sigma3": 0.0, "fine_margin": math.inf}
        try:
            for k in range(realisations):
                sig = None
                if recording is not None:
                    sig = {"output": surrogate(recording, seed + k)[:steps]}
                from .linear_sim import simulate_linear

                m = simulate_linear(plant, ctl, steps, seed=seed + k, signals=sig).metrics
                worst["rms"] = max(worst["rms"], m["rms"])
                worst["sigma3"] = max(worst["sigma3"], m["sigma3"])
                worst["fine_margin"] = min(worst["fine_margin"], m["fine_margin_min"])
        except FloatingPointError as exc:
            rows.append({"name": name, "error": str(exc)})
            continue
        fails = []
        if spec.rms is not None and worst["rms"] > spec.rms:
            fails.append(f"rms {worst['rms']:.3g} m > {spec.rms:.3g} m")
        if spec.sigma3 is not None and worst["sigma3"] > spec.sigma3:
            fails.append(f"3σ {worst['sigma3']:.3g} m > {spec.sigma3:.3g} m")
        if worst["fine_margin"] < spec.fine_margin:
            fails.append(f"fine margin {worst['fine_margin']:.3g} m < {spec.fine_margin:.3g} m")
        if pk > spec.peak_sensitivity:
            fails.append(f"peak |S| {pk:.3g} > {spec.peak_sensitivity:.3g}")
        row = dict(worst, name=name, peak_sensitivity=pk, failures=fails)
        rows.append(row)
        key = (bool(fails), len(fails), worst["rms"])
        if best is None or key < best[0]:
            best = (key, name, ctl)
    if best is None:
        raise ValueError(
            "no candidate could be designed on this plant: "
            + "; ".join(f"{r['name']}: {r['error']}" for r in rows)
        )
    return Choice(controller=best[2], name=best[1], met=not best[0][0], candidates=rows)
