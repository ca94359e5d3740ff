"""Tune the thesis coordinator (:func:`design_coordinator`) and the LQR (:func:`design_lqr`)
for a given sky.

The LQR has no closed-form excursion bound here: :func:`design_lqr` simulates a grid of its
weights under its robustness rule (its docstring). The MPC takes the margin as a hard
constraint (``MPC(margin=...)``): there is nothing to design for it beyond passing the number.

Method for the coordinator (``docs/ch6.md``, "Designing the coordinator for a turbulence"):

1. **Spectrum.** The reference's one-sided PSD ``S(f)`` is given (:class:`.psd.OpdPsd` or a pair
   ``(f, S)``) or estimated from one record (:meth:`.psd.OpdPsd.from_signal`).
2. **Frequency-domain bound.** For each candidate tuning (coarse bandwidth, coarse reference
   filter cut-off, fine PI) the linear loop (:mod:`.loops`) gives the fine-stage share
   ``H_f = y_f/r`` and the error ``H_e = e/r``. The fine excursion is Gaussian with
   ``σ_f² = ∫ |H_f|² S df`` and its rate ``σ_ḟ² = ∫ (2πf)² |H_f|² S df``; by Rice's formula
   the mean rate at which ``|y_f − centre|`` crosses ``u`` is
   ``2 ν₀ exp(−u²/2σ_f²)``, ``ν₀ = σ_ḟ/(2π σ_f)``, so the probability of never reaching
   ``u = half stroke − margin`` in ``horizon`` seconds is (Poisson crossings)
   ``P = exp(−2 ν₀ T exp(−u²/2σ_f²))``. The **predicted margin** at the stated
   ``probability`` p is ``half stroke − u_p`` with ``u_p = σ_f √(2 ln(2 ν₀ T / (−ln p)))``.
   The predicted RMSE is ``√(∫ |H_e|² S df)``.
3. **Constraints.** The coarse loop keeps a gain margin ≥ ``min_gain_margin`` (6 dB) at the
   carriage mode (111–120 Hz over a full step); the fine PI keeps the robustness rule it was
   designed with (phase margin ≥ 60°, gain margin ≥ 10 dB, peak |S| ≤ 1.6);
   ``P ≥ probability``.
4. **Choice, checked by simulation.** The candidates meeting the constraints are ranked by
   predicted RMSE; the best ``n_check`` are simulated on ``check_seeds`` fresh references
   synthesised from ``S`` (:meth:`.psd.OpdPsd.synthesize`, ``check_duration`` s each) and the
   one with the smallest simulated RMSE among those that kept the margin in every run (no
   saturated step) is chosen. If none did, the candidate with the largest simulated margin is
   returned and the report says the target was **not** met.

The returned coordinator is a plain :class:`.coordinator.SisoCoordinator` with the chosen
gains; its field amplitude, rate limit and feed-forward are the thesis's (the power is then
the thesis's 2.25 W).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ._check import positive
from .coordinator import SisoCoordinator
from .loops import coarse_gain_margin, coordinator_responses
from .psd import OpdPsd, psd_arg

__all__ = [
    "DesignReport",
    "LqrDesignReport",
    "design_coordinator",
    "design_lqr",
    "excursion_probability",
    "fine_loop_margins",
    "predict",
    "BANDWIDTHS",
    "CUTOFFS",
    "FINE_PI",
    "CENTRE_MAX",
    "INTEGRAL_CORNERS",
]

#: Candidate coarse-loop bandwidths, Hz (filtered by the carriage-mode gain margin).
BANDWIDTHS = (0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0, 2.25, 2.5, 3.0, 3.5, 4.0)
#: Candidate cut-offs of the 3rd-order Butterworth coarse reference filter, Hz.
CUTOFFS = (5.0, 10.0, 20.0, 40.0, 80.0)
#: Candidate fine PI pairs (k_p, k_i [1/s]), filtered by the robustness rule.
FINE_PI = tuple(
    (kp, 2.0 * math.pi * fi) for kp in (0.5, 0.65, 0.8, 1.0) for fi in (120.0, 180.0, 240.0)
)


@dataclass
class DesignReport:
    """What :func:`design_coordinator` chose and why (SI units; probabilities in [0, 1]).

    Attributes
    ----------
    coarse_bandwidth, coarse_cutoff : float
        Chosen coarse-loop bandwidth and reference-filter cut-off, Hz.
    coarse_order : int
        Order of the Butterworth reference filter.
    fine_kp, fine_ki : float
        Chosen fine PI (dimensionless, 1/s).
    margin : float
        Required distance of the fine stage from its stops, m.
    probability, horizon : float
        The margin is to hold with this probability over ``horizon`` seconds.
    predicted_sigma : float
        Predicted rms fine-stage excursion, m.
    predicted_margin : float
        Predicted margin at ``probability`` over ``horizon``, m.
    predicted_probability : float
        Predicted probability of keeping ``margin`` over ``horizon``.
    predicted_rmse : float
        Predicted tracking RMSE, m.
    coarse_gain_margin : float
        Gain margin of the coarse loop at the carriage mode (absolute) and
    coarse_gain_margin_db : float
        the same in dB; ``coarse_mode_frequency`` where it is taken, Hz.
    coarse_mode_frequency : float
    fine_phase_margin, fine_gain_margin_db, fine_peak_sensitivity : float
        Fine loop robustness of the chosen PI (degrees, dB, absolute).
    simulated : dict
        On fresh references: ``seeds``, ``duration`` (s), ``rmse`` (list, m),
        ``rmse_mean``, ``rmse_max`` (m), ``margin_min`` (m), ``saturated_steps`` (total),
        ``power`` (W, mean).
    met : bool
        The chosen design kept ``margin`` in the prediction and in every simulated run.
    reason : str
        One line.
    candidates : list of dict
        Every candidate evaluated in the frequency domain (and simulated, if it was).
    psd : OpdPsd
        The spectrum designed for.
    """

    coarse_bandwidth: float
    coarse_cutoff: float
    coarse_order: int
    fine_kp: float
    fine_ki: float
    margin: float
    probability: float
    horizon: float
    predicted_sigma: float
    predicted_margin: float
    predicted_probability: float
    predicted_rmse: float
    coarse_gain_margin: float
    coarse_gain_margin_db: float
    coarse_mode_frequency: float
    fine_phase_margin: float
    fine_gain_margin_db: float
    fine_peak_sensitivity: float
    simulated: dict
    met: bool
    reason: str
    candidates: list = field(default_factory=list, repr=False)
    psd: OpdPsd | None = field(default=None, repr=False)

    def summary(self) -> str:
        """A few lines for a terminal (nm, µm, Hz)."""
        s = self.simulated
        return "\n".join(
            [
                f"coarse bandwidth {self.coarse_bandwidth:g} Hz, reference filter "
                f"{self.coarse_order}rd-order Butterworth at {self.coarse_cutoff:g} Hz, "
                f"fine PI kp = {self.fine_kp:g}, ki = 2π·{self.fine_ki / (2 * math.pi):.4g} 1/s",
                f"coarse-mode gain margin {self.coarse_gain_margin_db:.1f} dB at "
                f"{self.coarse_mode_frequency:.1f} Hz; fine loop PM "
                f"{self.fine_phase_margin:.1f}°, GM {self.fine_gain_margin_db:.1f} dB, "
                f"peak |S| {self.fine_peak_sensitivity:.2f}",
                f"predicted: fine excursion {self.predicted_sigma * 1e6:.2f} µm rms, margin "
                f"{self.predicted_margin * 1e6:.2f} µm at p = {self.probability:g} over "
                f"{self.horizon:g} s (P(keep {self.margin * 1e6:.2f} µm) = "
                f"{self.predicted_probability:.4f}), RMSE {self.predicted_rmse * 1e9:.1f} nm",
                f"simulated on {len(s['seeds'])} fresh {s['duration']:g}-s references: RMSE "
                f"{s['rmse_mean'] * 1e9:.1f} nm mean, {s['rmse_max'] * 1e9:.1f} nm max; "
                f"min margin {s['margin_min'] * 1e6:.2f} µm; saturated steps "
                f"{s['saturated_steps']}; power {s['power']:.2f} W",
                f"{'met' if self.met else 'NOT met'}: {self.reason}",
            ]
        )


def excursion_probability(sigma: float, sigma_rate: float, level: float, horizon: float):
    """``P(|x| < level` for ``horizon`` s)`` for a stationary Gaussian ``x`` (Rice, Poisson
    crossings): ``exp(−2 ν₀ T exp(−level²/2σ²))``, ``ν₀ = σ_rate/(2π σ)``; and the level
    ``u_p`` that is kept with that same probability. Returns ``(P, nu0)``."""
    if sigma <= 0.0:
        return 1.0, 0.0
    nu0 = sigma_rate / (2.0 * math.pi * sigma)
    return math.exp(-2.0 * nu0 * horizon * math.exp(-0.5 * (level / sigma) ** 2)), nu0


def _level(sigma: float, nu0: float, horizon: float, probability: float) -> float:
    """Level kept with ``probability`` over ``horizon`` (inverse of excursion_probability)."""
    x = 2.0 * nu0 * horizon / (-math.log(probability))
    return sigma * math.sqrt(2.0 * math.log(max(x, math.e)))


def fine_loop_margins(kp: float, ki: float, plant, fs: float, n: int = 3000) -> dict:
    """Phase margin (°), gain margin (dB) and peak |S| of the fine loop ``P_f C`` alone."""
    from .fine import fine_zoh

    h = 1.0 / fs
    f = np.geomspace(1.0, 0.499 * fs, n)
    z = np.exp(2j * math.pi * f * h)
    a11, a12, a21, a22, b1, b2 = fine_zoh(plant.fine, h)
    det = (z - a11) * (z - a22) - a12 * a21
    pf = ((z - a22) * b1 + a12 * b2) / det
    lf = pf * (kp + ki * h * z / (z - 1.0)) / plant.fine.gain
    mag = np.abs(lf)
    ph = np.unwrap(np.angle(lf))
    k = np.flatnonzero((mag[:-1] >= 1.0) & (mag[1:] < 1.0))
    pm = float(180.0 + np.degrees(ph[k[0]])) if k.size else 180.0
    j = np.flatnonzero((ph[:-1] > -math.pi) & (ph[1:] <= -math.pi))
    gm = float(-20.0 * math.log10(mag[j[0]])) if j.size else math.inf
    return {"pm": pm, "gm_db": gm, "peak_s": float(np.max(np.abs(1.0 / (1.0 + lf))))}


def predict(ctl: SisoCoordinator, psd: OpdPsd, plant, fs: float) -> dict:
    """Frequency-domain prediction for ``ctl`` on ``psd``: ``sigma_f`` (m), ``sigma_rate``
    (m/s), ``rmse`` (m) of the linear loop (:mod:`.loops`)."""
    f = psd.grid(fs)
    s = psd(f)
    resp = coordinator_responses(ctl, plant, fs, f)
    hf2 = np.abs(resp.fine) ** 2
    sf = math.sqrt(max(0.0, float(np.trapezoid(hf2 * s, f))))
    sv = math.sqrt(max(0.0, float(np.trapezoid(hf2 * s * (2.0 * math.pi * f) ** 2, f))))
    se = math.sqrt(max(0.0, float(np.trapezoid(np.abs(resp.error) ** 2 * s, f))))
    q = plant.resolution
    return {"sigma_f": sf, "sigma_rate": sv, "rmse": math.sqrt(se * se + q * q / 12.0)}


def _simulate_check(make, psd: OpdPsd, plant, fs: float, seeds, duration: float) -> dict:
    """Run ``make()`` (a fresh controller) on references synthesised from ``psd``, one per
    seed; the summary dict of :attr:`DesignReport.simulated`."""
    from .simulate import simulate

    rmse, margin, sat, power = [], [], [], []
    for seed in seeds:
        r = psd.synthesize(duration, fs, seed=seed)
        m = simulate(plant, make(), r, fs, seed=seed).metrics
        rmse.append(m["rmse"])
        margin.append(m["fine_margin_min"])
        sat.append(m["saturated_steps"])
        power.append(m["power"])
    return {
        "seeds": list(seeds),
        "duration": duration,
        "rmse": rmse,
        "rmse_mean": float(np.mean(rmse)),
        "rmse_max": float(np.max(rmse)),
        "margin_min": float(np.min(margin)),
        "saturated_steps": int(np.sum(sat)),
        "power": float(np.mean(power)),
    }


def _margin_arg(margin, plant) -> tuple[float, float]:
    """``(margin, half stroke)`` in m: default 10 % of the half stroke, else in (0, half)."""
    half = 0.5 * (plant.fine.stroke_max - plant.fine.stroke_min)
    margin = 0.1 * half if margin is None else margin
    if isinstance(margin, bool) or not (math.isfinite(float(margin)) and 0 < margin < half):
        raise ValueError(
            f"margin must be in (0, {half!r}) m (half the fine stroke), got {margin!r}"
        )
    return float(margin), half


def _check_args(check_seeds, check_duration) -> tuple[tuple[int, ...], float]:
    check_seeds = tuple(int(s) for s in check_seeds)
    if not check_seeds:
        raise ValueError("check_seeds must not be empty")
    return check_seeds, positive("check_duration", check_duration)


def design_coordinator(
    reference,
    fs: float,
    plant=None,
    margin: float | None = None,
    *,
    probability: float = 0.99,
    horizon: float = 10.0,
    min_gain_margin: float = 2.0,
    check_seeds=(1001, 1002, 1003),
    check_duration: float = 2.0,
    n_check: int = 4,
    bandwidths=BANDWIDTHS,
    cutoffs=CUTOFFS,
    fine_pi=FINE_PI,
) -> tuple[SisoCoordinator, DesignReport]:
    """Tune a :class:`SisoCoordinator` for the statistics of ``reference`` (see module).

    Parameters
    ----------
    reference : array_like or OpdPsd or (f, S)
        One recorded reference (1-D, metres at ``fs``, at least one second, finite), or its
        one-sided PSD (m²/Hz at Hz).
    fs : float
        Control rate, Hz.
    plant : DualStage, optional
        Default ``DualStage()``.
    margin : float, optional
        Distance to keep between the fine stage and each stop, m, in (0, half stroke);
        default 10 % of the half stroke (1.5 µm).
    probability : float
        Probability, in (0, 1), with which the margin must hold over ``horizon`` s.
    horizon : float
        Duration the probability refers to, s.
    min_gain_margin : float
        Gain margin to keep on the coarse loop at the carriage mode (absolute, > 1).
    check_seeds : sequence of int
        Seeds of the fresh references of the simulation check (non-empty).
    check_duration : float
        Length of each check reference, s.
    n_check : int
        How many of the best predicted candidates are simulated.
    bandwidths, cutoffs, fine_pi : sequences
        Candidate grids (Hz, Hz, pairs ``(k_p, k_i)``).

    Returns
    -------
    (SisoCoordinator, DesignReport)
    """
    from .plant import DualStage

    fs = positive("fs", fs)
    plant = DualStage() if plant is None else plant
    psd, _ = psd_arg(reference, fs)
    margin, half = _margin_arg(margin, plant)
    probability = float(probability)
    if not 0.0 < probability < 1.0:
        raise ValueError(f"probability must be in (0, 1), got {probability!r}")
    horizon = positive("horizon", horizon)
    min_gain_margin = positive("min_gain_margin", min_gain_margin)
    if min_gain_margin <= 1.0:
        raise ValueError(f"min_gain_margin must be > 1 (absolute), got {min_gain_margin!r}")
    check_seeds, check_duration = _check_args(check_seeds, check_duration)
    n_check = int(n_check)
    if n_check < 1:
        raise ValueError(f"n_check must be >= 1, got {n_check!r}")
    usable = half - margin

    pis = []
    for kp, ki in fine_pi:
        fm = fine_loop_margins(kp, ki, plant, fs)
        if fm["pm"] >= 60.0 and fm["gm_db"] >= 10.0 and fm["peak_s"] <= 1.6:
            pis.append((float(kp), float(ki), fm))
    if not pis:
        raise ValueError("no fine PI candidate meets PM ≥ 60°, GM ≥ 10 dB, peak |S| ≤ 1.6")
    bws = []
    for bw in bandwidths:
        gm, fgm = coarse_gain_margin(SisoCoordinator(coarse_bandwidth=bw), plant, fs, n=4000)
        if gm >= min_gain_margin:
            bws.append((float(bw), gm, fgm))
    if not bws:
        raise ValueError(
            f"no coarse bandwidth in {tuple(bandwidths)} keeps the gain margin ≥ {min_gain_margin}"
        )
    cands = []
    for bw, gm, fgm in bws:
        for fc in cutoffs:
            if fc >= 0.45 * fs:
                continue
            for kp, ki, fm in pis:
                kw = {
                    "coarse_bandwidth": bw,
                    "coarse_cutoff": float(fc),
                    "fine_kp": kp,
                    "fine_ki": ki,
                }
                pr = predict(SisoCoordinator(**kw), psd, plant, fs)
                p_keep, nu0 = excursion_probability(
                    pr["sigma_f"], pr["sigma_rate"], usable, horizon
                )
                cands.append(
                    {
                        **kw,
                        "gm": gm,
                        "gm_f": fgm,
                        "fine": fm,
                        "sigma_f": pr["sigma_f"],
                        "rmse": pr["rmse"],
                        "p_keep": p_keep,
                        "margin_p": half - _level(pr["sigma_f"], nu0, horizon, probability),
                    }
                )
    ok = [c for c in cands if c["p_keep"] >= probability]
    pool = sorted(ok, key=lambda c: c["rmse"]) if ok else sorted(cands, key=lambda c: -c["p_keep"])
    checked = pool[:n_check]
    for c in checked:
        kw = {k: c[k] for k in ("coarse_bandwidth", "coarse_cutoff", "fine_kp", "fine_ki")}
        c["simulated"] = sim = _simulate_check(
            lambda kw=kw: SisoCoordinator(**kw), psd, plant, fs, check_seeds, check_duration
        )
        c["sim_ok"] = sim["saturated_steps"] == 0 and sim["margin_min"] >= margin
    good = [c for c in checked if c["sim_ok"]]
    if good:
        best = min(good, key=lambda c: c["simulated"]["rmse_mean"])
    else:
        best = max(checked, key=lambda c: c["simulated"]["margin_min"])
    met = bool(ok) and best["sim_ok"]
    if met:
        reason = (
            f"smallest simulated RMSE of the {min(n_check, len(pool))} best predicted "
            f"candidates meeting P ≥ {probability:g} ({len(ok)} of {len(cands)} did)"
        )
    elif not ok:
        reason = (
            f"no candidate reaches P ≥ {probability:g} of keeping {margin * 1e6:.2f} µm "
            f"(best P = {pool[0]['p_keep']:.3g}); the one with the largest margin is returned"
        )
    else:
        reason = "the predicted candidates saturated or lost the margin in simulation"
    kw = {k: best[k] for k in ("coarse_bandwidth", "coarse_cutoff", "fine_kp", "fine_ki")}
    fm = best["fine"]
    report = DesignReport(
        coarse_bandwidth=kw["coarse_bandwidth"],
        coarse_cutoff=kw["coarse_cutoff"],
        coarse_order=3,
        fine_kp=kw["fine_kp"],
        fine_ki=kw["fine_ki"],
        margin=margin,
        probability=probability,
        horizon=horizon,
        predicted_sigma=best["sigma_f"],
        predicted_margin=best["margin_p"],
        predicted_probability=best["p_keep"],
        predicted_rmse=best["rmse"],
        coarse_gain_margin=best["gm"],
        coarse_gain_margin_db=20.0 * math.log10(best["gm"]),
        coarse_mode_frequency=best["gm_f"],
        fine_phase_margin=fm["pm"],
        fine_gain_margin_db=fm["gm_db"],
        fine_peak_sensitivity=fm["peak_s"],
        simulated=best["simulated"],
        met=met,
        reason=reason,
        candidates=cands,
        psd=psd,
    )
    return SisoCoordinator(**kw), report


# ---------------------------------------------------------------------------- LQR
#: Candidate fine-stage centring scales ``centre_max`` of the LQR weights, m.
CENTRE_MAX = (3e-6, 5e-6, 10e-6, 20e-6)
#: Candidate integral corner frequencies of the LQR weights, Hz.
INTEGRAL_CORNERS = (10.0, 20.0, 30.0, 40.0, 50.0, 60.0)


@dataclass
class LqrDesignReport:
    """What :func:`design_lqr` chose and why (SI units).

    Attributes
    ----------
    centre_max : float
        Chosen fine-stage centring scale of :func:`.lqr.default_weights`, m.
    integral_corner : float
        Chosen integral corner, Hz.
    error_max : float
        Output-error scale (fixed by the robustness rule, not searched), m.
    margin : float
        Required distance of the fine stage from its stops, m.
    peak_sensitivity : float
        Peak |S| of the chosen design's loop broken at the measurement (absolute).
    gain_margin_db, phase_margin_deg : float
        Its margins (dB, degrees).
    delay_margin_samples : int
        Extra periods of latency it tolerates.
    simulated : dict
        As :attr:`DesignReport.simulated` (fresh references synthesised from the PSD).
    met : bool
        Some admissible candidate kept ``margin`` with no saturated step in every run.
    reason : str
        One line.
    candidates : list of dict
        Every candidate: its weights, its loop margins, whether it was admissible and its
        simulation.
    psd : OpdPsd
        The spectrum designed for.
    """

    centre_max: float
    integral_corner: float
    error_max: float
    margin: float
    peak_sensitivity: float
    gain_margin_db: float
    phase_margin_deg: float
    delay_margin_samples: int
    simulated: dict
    met: bool
    reason: str
    candidates: list = field(default_factory=list, repr=False)
    psd: OpdPsd | None = field(default=None, repr=False)

    def summary(self) -> str:
        """A few lines for a terminal (nm, µm, Hz)."""
        s = self.simulated
        return "\n".join(
            [
                f"LQR weights: centre_max {self.centre_max * 1e6:g} µm, integral corner "
                f"{self.integral_corner:g} Hz, error_max {self.error_max * 1e6:g} µm",
                f"loop: peak |S| {self.peak_sensitivity:.3f}, GM {self.gain_margin_db:.1f} dB, "
                f"PM {self.phase_margin_deg:.1f}°, delay margin {self.delay_margin_samples} "
                "period(s)",
                f"simulated on {len(s['seeds'])} fresh {s['duration']:g}-s references: RMSE "
                f"{s['rmse_mean'] * 1e9:.1f} nm mean, {s['rmse_max'] * 1e9:.1f} nm max; "
                f"min margin {s['margin_min'] * 1e6:.2f} µm (required "
                f"{self.margin * 1e6:.2f}); saturated steps {s['saturated_steps']}; power "
                f"{s['power']:.3f} W",
                f"{'met' if self.met else 'NOT met'}: {self.reason}",
            ]
        )


def design_lqr(
    reference,
    fs: float,
    plant=None,
    margin: float | None = None,
    *,
    check_seeds=(1001, 1002, 1003),
    check_duration: float = 2.0,
    centre_max=CENTRE_MAX,
    integral_corners=INTEGRAL_CORNERS,
    error_max: float = 1.3e-6,
    max_peak_sensitivity: float = 1.6,
    min_delay_margin: int = 1,
):
    """Tune the :class:`.lqr.LQR` weights for the statistics of ``reference``.

    The LQR's output-error scale ``error_max`` is fixed by its robustness rule (the most
    aggressive value keeping peak |S| ≤ 1.6, :func:`.lqr.tune_error_max`); its remaining
    knobs are the fine-stage centring scale ``centre_max`` (how much the fine stage is pulled
    to mid-stroke, i.e. how much of the reference the carriage takes) and the integral
    corner. No closed-form excursion bound is used: every candidate of the grid
    ``centre_max × integral_corners`` whose loop keeps peak |S| ≤ ``max_peak_sensitivity``,
    tolerates ``min_delay_margin`` extra periods of latency and is stable is **simulated**
    on fresh references synthesised from the reference's PSD (``check_seeds``,
    ``check_duration`` s each); the smallest mean RMSE among those with no saturated step
    and the fine stage at least ``margin`` from its stops in every run is chosen. If none
    kept the margin, the admissible one with the largest simulated margin is returned and
    the report says **NOT met**.

    Parameters
    ----------
    reference : array_like or OpdPsd or (f, S)
        As :func:`design_coordinator`.
    fs : float
        Control rate, Hz.
    plant : DualStage, optional
        Default ``DualStage()``.
    margin : float, optional
        Distance to keep between the fine stage and each stop, m, in (0, half stroke);
        default 10 % of the half stroke (1.5 µm).
    check_seeds : sequence of int
        Seeds of the fresh references (non-empty).
    check_duration : float
        Length of each, s.
    centre_max : sequence of float
        Candidate centring scales, m (> 0).
    integral_corners : sequence of float
        Candidate integral corners, Hz (> 0).
    error_max : float
        Output-error scale of the weights, m (default: :class:`.lqr.LQR`'s 1.3 µm).
    max_peak_sensitivity : float
        Robustness rule: largest peak |S| (> 1).
    min_delay_margin : int
        Extra periods of latency a candidate must tolerate (≥ 0).

    Returns
    -------
    (LQR, LqrDesignReport)
    """
    from .lqr import LQR, default_weights, design_model
    from .plant import DualStage

    fs = positive("fs", fs)
    plant = DualStage() if plant is None else plant
    psd, _ = psd_arg(reference, fs)
    margin, _ = _margin_arg(margin, plant)
    check_seeds, check_duration = _check_args(check_seeds, check_duration)
    cms = tuple(positive("centre_max", c) for c in centre_max)
    ics = tuple(positive("integral_corners", c) for c in integral_corners)
    if not cms:
        raise ValueError("centre_max must not be empty")
    if not ics:
        raise ValueError("integral_corners must not be empty")
    error_max = positive("error_max", error_max)
    max_peak_sensitivity = positive("max_peak_sensitivity", max_peak_sensitivity)
    if max_peak_sensitivity <= 1.0:
        raise ValueError(f"max_peak_sensitivity must be > 1, got {max_peak_sensitivity!r}")
    if int(min_delay_margin) != min_delay_margin or min_delay_margin < 0:
        raise ValueError(f"min_delay_margin must be an integer >= 0, got {min_delay_margin!r}")

    model = design_model(plant, fs)
    cands = []
    for cm in cms:
        for ic in ics:
            q, r = default_weights(model, error_max=error_max, centre_max=cm, integral_corner=ic)
            rep = LQR(q, r).design(plant, fs).report()
            ok = (
                rep["peak_sensitivity"] <= max_peak_sensitivity
                and rep["delay_margin_samples"] >= min_delay_margin
                and rep["max_pole_modulus"] < 1.0
            )
            c = {"centre_max": cm, "integral_corner": ic, "loop": rep, "admissible": ok}
            if ok:
                c["simulated"] = sim = _simulate_check(
                    lambda q=q, r=r: LQR(q, r), psd, plant, fs, check_seeds, check_duration
                )
                c["sim_ok"] = sim["saturated_steps"] == 0 and sim["margin_min"] >= margin
            cands.append(c)
    admissible = [c for c in cands if c["admissible"]]
    if not admissible:
        raise ValueError(
            f"no LQR candidate keeps peak |S| ≤ {max_peak_sensitivity} and a delay margin of "
            f"{min_delay_margin} period(s)"
        )
    good = [c for c in admissible if c["sim_ok"]]
    if good:
        best = min(good, key=lambda c: c["simulated"]["rmse_mean"])
        reason = (
            f"smallest simulated RMSE of the {len(good)} admissible candidates that kept "
            f"{margin * 1e6:.2f} µm ({len(admissible)} of {len(cands)} admissible)"
        )
    else:
        best = max(admissible, key=lambda c: c["simulated"]["margin_min"])
        reason = (
            f"no admissible candidate kept {margin * 1e6:.2f} µm in simulation; the one with "
            "the largest margin is returned"
        )
    q, r = default_weights(
        model,
        error_max=error_max,
        centre_max=best["centre_max"],
        integral_corner=best["integral_corner"],
    )
    loop = best["loop"]
    report = LqrDesignReport(
        centre_max=best["centre_max"],
        integral_corner=best["integral_corner"],
        error_max=error_max,
        margin=margin,
        peak_sensitivity=loop["peak_sensitivity"],
        gain_margin_db=loop["gain_margin_db"],
        phase_margin_deg=loop["phase_margin_deg"],
        delay_margin_samples=int(loop["delay_margin_samples"]),
        simulated=best["simulated"],
        met=bool(good),
        reason=reason,
        candidates=cands,
        psd=psd,
    )
    return LQR(q, r), report
