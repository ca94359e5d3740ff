"""Chapter 6: Kolmogorov tracking by the thesis coordinator (Figs 6.7, 6.16, 6.17).

The DDL plant (``qpcoord.ddl.DualStage``, PRIMA defaults) is driven by the thesis coordinator
(``SisoCoordinator``: fine PI on the output, direct-coil integral phase control of the stepper on
a 10 Hz Butterworth reference, model-based carriage estimate and pre-compensation) at 8 kHz on
the ``paranal_250hz`` OPD preset (10 s, 20 seeds; ``--quick``: 10 s, 3 seeds). Reported per seed
and as a spread: RMSE / max / mean error (Eqs 6.3–6.5), power (Eq 6.6), closest approach of
the piezo to a stroke limit, saturated steps, lost synchronism. Also: the chirp
identification of the coarse-stage resonance at the stroke centre (Fig 6.7; thesis: 120 Hz) and
the piezo bandwidth (Fig 6.6; thesis ≈ 300 Hz), and the PSD slopes of the reference in the
three atmospheric regimes. Table 6.1's RMSE is judged over the preset's vibration lines absent,
as shipped and doubled (10 seeds; ``--quick`` 3): the lines are an assumption, not the thesis's.

Spec (§6.1.2): RMSE < 70 nm, power < 5 W, fine stage never saturates. The spec and Fig 6.16
are judged on references that need both stages: the first five ``paranal_250hz_lf10``
realisations whose peak-to-peak excursion exceeds the 30 µm fine stroke (the same in quick
and full runs), each also run with the coarse stage frozen as a control that must fail.
Thesis Table 6.1
(hardware, direct coil): 25 nm RMSE, 308 nm max, 19.6 nm mean, 2.25 W.

Run: ``python examples/ch6_tracking.py [--quick] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy import signal

import qpcoord.ddl as ddl
from qpcoord.ddl.identify import coarse_frf, fine_frf, peak_frequency
from qpcoord.studies.claims import QUICK, claim
from qpcoord.studies.criteria import (
    across_assumptions,
    coordination_spec,
    fine_never_saturates,
    needs_both_stages,
    within,
)
from qpcoord.studies.files import TextLog, write_json

FS = 8000.0


def psd_slopes(seed: int) -> dict:
    """Slopes of the synthesised OPD PSD (L0 = ∞) in the three regimes, log-binned fits."""

    def slope(x, fs, lo, hi):
        f, p = signal.welch(x, fs=fs, nperseg=len(x) // 8)
        edges = np.logspace(np.log10(lo), np.log10(hi), 5)
        fc = [np.sqrt(a * b) for a, b in zip(edges[:-1], edges[1:], strict=True)]
        pc = [p[(f >= a) & (f < b)].mean() for a, b in zip(edges[:-1], edges[1:], strict=True)]
        return float(np.polyfit(np.log(fc), np.log(pc), 1)[0])

    inf = float("inf")
    return {
        "low_3e-4_4e-3_Hz": slope(ddl.kolmogorov_opd(2e5, 0.2, seed, L0=inf), 0.2, 3e-4, 4e-3),
        "mid_0.15_0.9_Hz": slope(ddl.kolmogorov_opd(2000, 20.0, seed, L0=inf), 20.0, 0.15, 0.9),
        "high_10_60_Hz": slope(ddl.kolmogorov_opd(300, 250.0, seed, L0=inf), 250.0, 10, 60),
        "theory": {"low": -2 / 3, "mid": -8 / 3, "high": -17 / 3},
    }


def lines_sweep(duration: float, seeds: list[int], shipped: list[dict]) -> dict:
    """Direct-coil RMSE and mean |e| (nm) per seed with the ``paranal_250hz`` vibration lines
    scaled by 0 (none), 1 (as shipped: ``shipped``, the main run's metrics of these seeds) and
    2 (doubled): ``{"rmse": {case: [...]}, "mean_abs": {case: [...]}}``.

    The lines are an assumption of the preset (the thesis's test signal is not given), so
    Table 6.1's RMSE and mean error are judged over this plausible range of them.
    """
    from dataclasses import replace

    base = ddl.PRESETS["paranal_250hz"]["lines"]
    keys = ("rmse", "mean_abs")
    runs = {"as shipped": list(shipped)}
    for name, scale in (("none", 0.0), ("doubled", 2.0)):
        lines = tuple(replace(v, rms=scale * v.rms) for v in base) if scale else ()
        runs[name] = []
        for seed in seeds:
            r = ddl.kolmogorov_opd(duration, FS, seed=seed, preset="paranal_250hz", lines=lines)
            run = ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(), r, FS, seed=seed)
            runs[name].append(run.metrics)
    cases = ("none", "as shipped", "doubled")
    return {k: {c: [m[k] * 1e9 for m in runs[c]] for c in cases} for k in keys}


#: Seeds of the full run's Table 6.1 runs, and of its vibration-line sweep.
FULL_SEEDS = 20
SWEEP_SEEDS = 10
#: Preset of the references that need both stages: the shipped preset with 10x the turbulence
#: power below 2 Hz (its excursion over 10 s is 24-45 µm; the shipped preset's 10-14 µm fits
#: in the 30 µm fine stroke).
COORD_PRESET = "paranal_250hz_lf10"
#: References judged for the spec and Fig 6.16, the same in quick and full runs.
N_COORD = 5
#: The control: the coarse reference filtered at 0.01 Hz keeps the carriage within 1 % of the
#: reference's travel over 10 s -- the coarse stage frozen.
FROZEN_CUTOFF_HZ = 0.01


def fig617_condition_run(duration: float, seed: int) -> dict:
    """The coordinator on ``paranal_250hz`` band-limited at 200 Hz without vibration lines
    (Fig 6.17's only stated condition: 'a frequency content of up to 200 Hz')."""
    r = ddl.kolmogorov_opd(duration, FS, seed=seed, preset="paranal_250hz", lines=(), f_max=200.0)
    run = ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(), r, FS, seed=seed)
    return {"seed": seed, **run.metrics}


def reference_stats(seed: int, r: np.ndarray) -> dict:
    """Peak to peak and rms (µm), and the content above 50 Hz (nm: rms and max of a 4th-order
    zero-phase high-pass), of a reference ``r`` (m) sampled at :data:`FS`."""
    b, a = signal.butter(4, 50.0, "high", fs=FS)
    hf = signal.filtfilt(b, a, r)
    return {
        "seed": seed,
        "ptp_um": float(np.ptp(r) * 1e6),
        "rms_um": float(np.std(r) * 1e6),
        "above_50hz_rms_nm": float(np.std(hf) * 1e9),
        "above_50hz_max_nm": float(np.max(np.abs(hf)) * 1e9),
    }


def coordination_runs(duration: float, n: int = N_COORD) -> dict:
    """The coordinator and the frozen-coarse control on the first ``n`` seeds of
    :data:`COORD_PRESET` whose peak-to-peak excursion exceeds the fine stroke."""
    plant = ddl.DualStage()
    stroke = plant.fine.stroke_max - plant.fine.stroke_min
    refs, runs, frozen = [], [], []
    seed = 0
    while len(refs) < n:
        r = ddl.kolmogorov_opd(duration, FS, seed=seed, preset=COORD_PRESET)
        if needs_both_stages(float(np.ptp(r)), stroke):
            refs.append(reference_stats(seed, r))
            for out, ctl in (
                (runs, ddl.SisoCoordinator()),
                (frozen, ddl.SisoCoordinator(coarse_cutoff=FROZEN_CUTOFF_HZ)),
            ):
                run = ddl.simulate(ddl.DualStage(), ctl, r, FS, seed=seed)
                out.append({**run.metrics, "travel": float(np.ptp(run.y_c) / np.ptp(r))})
        seed += 1
        if seed > 50 * n:
            raise RuntimeError(f"fewer than {n} {COORD_PRESET} references exceed the stroke")
    return {
        "preset": COORD_PRESET,
        "fine_stroke_um": stroke * 1e6,
        "references": refs,
        "runs": runs,
        "frozen": frozen,
    }


def tracking_claims(
    rows, spread, f_res, bw_fine, slopes, duration, nseeds, coord, fig617, sweep=None
) -> list[dict]:
    """Claim rows (``qpcoord.studies.claims.claim``): each thesis number beside this run's value.

    Table 6.1's and Fig 6.17's rows on the ``paranal_250hz`` runs are decided only by the
    full run's 10 s × :data:`FULL_SEEDS` seeds; a smaller run gives
    :data:`~qpcoord.studies.claims.QUICK`. The spec and Fig 6.16 rows (``coord``,
    :func:`coordination_runs`) use the same references in every run. ``sweep`` (from
    :func:`lines_sweep`): the RMSE and mean-error rows are reproduced only if the median is
    within ±30 % of the thesis's number with the preset's vibration lines absent, as shipped
    and doubled; they differ if outside in all three; otherwise the result depends on the
    unknown test signal and the row is inconclusive.
    """
    full = duration >= 10.0 and nseeds >= FULL_SEEDS
    short = (
        f" This run ({duration:g} s × {nseeds} seeds) is smaller than the full run's "
        f"(10 s × {FULL_SEEDS} seeds, the vibration-line sweep on {SWEEP_SEEDS}): a median "
        "or a best seed over fewer seeds is another rule, so the full run decides this row."
    )

    rmse, mx, mean = spread["rmse_nm"], spread["max_abs_nm"], spread["mean_abs_nm"]
    power = spread["power_w"]
    best = min(rows, key=lambda row: row["rmse"])
    out = []
    ok = abs(f_res - 120.0) <= 0.05 * 120.0
    st = "calibrated" if ok else "differs"  # an input: shown, never counted as reproduced
    out.append(
        claim(
            "fig6.7-coarse-resonance",
            "The coarse stage (stepper + screw + flexure) has an electromechanical resonance "
            "at 120 Hz.",
            "Fig 6.7: resonant mode identified at 120 Hz",
            f"{f_res:.1f} Hz (chirp of the field phase, 0.05 rad, stroke centre)",
            st,
            "Criterion: within ±5 % of 120 Hz. The rotor inertia is calibrated so that the "
            "linearised mode is 120 Hz at the centre; the chirp checks the nonlinear plant "
            "against that calibration (the peak falls with the chirp amplitude, docs/ch6.md)."
            + ("" if st != "differs" else " The nonlinear peak has moved off the calibration."),
            cause="our model" if st == "differs" else "",
        )
    )
    ok = abs(bw_fine - 300.0) <= 0.10 * 300.0
    st = "calibrated" if ok else "differs"  # ωn = 300 Hz is an input
    out.append(
        claim(
            "fig6.6-piezo-bandwidth",
            "The piezo fine stage (S-325) has a bandwidth of about 300 Hz.",
            "Fig 6.6: estimated bandwidth ≈ 300 Hz, static gain ≈ 3 µm/V",
            f"{bw_fine:.1f} Hz (−3 dB, chirp of the piezo voltage)",
            st,
            "Criterion: within ±10 % of 300 Hz. ωn = 300 Hz is a model input taken from "
            "Fig 6.6 (ζ = 0.7 chosen so the −3 dB point is near ωn): this checks the "
            "discretised model and the identification, not hardware."
            + ("" if st != "differs" else " The identified bandwidth left the band."),
            cause="our model" if st == "differs" else "",
        )
    )
    refs = coord["references"]
    ptp = [x["ptp_um"] for x in refs]
    hf = [x["above_50hz_max_nm"] for x in refs]
    ref_stats = (
        f"{len(refs)} references of {duration:g} s ({coord['preset']}, seeds "
        f"{', '.join(str(x['seed']) for x in refs)}): peak to peak {min(ptp):.1f}–"
        f"{max(ptp):.1f} µm against the {coord['fine_stroke_um']:g} µm fine stroke, "
        f"above 50 Hz at most {max(hf):.0f} nm"
    )
    thesis_ref = (
        "; reference (§6.1.2, §6.4.2): Kolmogorov, content to 250 Hz, < 1 µm above 50 Hz, "
        "10 s runs; its excursion is not given"
    )
    crmse = [m["rmse"] * 1e9 for m in coord["runs"]]
    frmse = [m["rmse"] * 1e9 for m in coord["frozen"]]
    fsat = [m["saturated_steps"] for m in coord["frozen"]]
    st, why_st = coordination_spec(coord["runs"], coord["frozen"])
    out.append(
        claim(
            "spec-rmse-70nm",
            "The coordinator tracks the Kolmogorov OPD with less than 70 nm RMS residual.",
            "§6.1.2 and §6.4.2: residual < 70 nm RMS with content up to 250 Hz" + thesis_ref,
            f"worst RMSE {max(crmse):.1f} nm; coarse stage frozen: {min(frmse):.0f}–"
            f"{max(frmse):.0f} nm. {ref_stats}",
            st,
            "Criterion (criteria.coordination_spec): RMSE < 70 nm on every reference whose "
            "peak-to-peak excursion exceeds the fine stroke, and the control run with the "
            "coarse stage frozen (coarse cut-off 0.01 Hz) fails the spec on each -- otherwise "
            "the reference does not test coordination. The same references and run length "
            "in quick and full runs. The shipped paranal_250hz preset spans about 10–14 µm and "
            "is tracked within spec by the fine stage alone, so it does not decide this "
            f"row. {why_st[0].upper()}{why_st[1:]}.",
        )
    )
    contradiction = (
        " The thesis contradicts itself here (listed as a contradiction in the report): for "
        "the same direct-coil controller on Kolmogorov tracking it gives < 8 nm rms (§6.4.2, "
        "'as low as the measurement noise') and < 8 nm rms, 30 nm max (Fig 6.17's caption) "
        "beside Table 6.1's 25 nm rms, 308 nm max."
    )
    why = {
        "rmse": " Simulation on the paranal_250hz preset, whose vibration lines (an "
        "assumption, not tuned on results) set most of the error.",
        "max_abs": " Not shown to be the hardware's: no run of ours reproduces the hardware's "
        "conditions (its noise sources, unmodelled modes and test signal are not given), so "
        "the cause is our model -- a plant without those effects and an assumed test "
        "signal, whose error peaks come from the preset's vibration lines only.",
        "mean_abs": "",
    }
    for key, label, value, sp in (
        ("rmse", "RMSE", 25.0, rmse),
        ("max_abs", "maximum |e|", 308.0, mx),
        ("mean_abs", "mean |e|", 19.6, mean),
    ):
        ok = within(sp["median"], value, 0.3)
        st = ("reproduced" if ok else "differs") if full else QUICK
        measured = (
            f"{sp['median']:.1f} nm median ({sp['min']:.1f}–{sp['max']:.1f} nm) over {nseeds} seeds"
        )
        note = f"Criterion: median within ±30 % of {value:g} nm."
        if key in (sweep or {}):
            med = {k: float(np.median(v)) for k, v in sweep[key].items()}
            measured += "; vibration lines of the preset " + ", ".join(
                f"{k}: {m:.1f} nm" for k, m in med.items()
            )
            measured += f" (median over {len(next(iter(sweep[key].values())))} seeds)"
            note = (
                f"Criterion (criteria.across_assumptions): median within ±30 % of {value:g} nm "
                "with the preset's vibration lines absent, as shipped and doubled (the lines "
                "are our assumption, the thesis's test signal is not given): reproduced if "
                "inside for all three, differs if outside for all three, else inconclusive."
            )
            if full:
                st, why_st = across_assumptions(med, value, 0.3)
                if st == "inconclusive":
                    note += (
                        f" {why_st[0].upper()}{why_st[1:]} (the vibration content of the "
                        f"unknown test signal), so Table 6.1's {value:g} nm can be neither "
                        "confirmed nor refuted."
                    )
            if key == "mean_abs":
                note += (
                    " The same rule as the RMSE row: the mean error depends on the lines as "
                    "the RMSE does (the median as shipped alone was within ±30 %)."
                )
        out.append(
            claim(
                f"table6.1-{key.split('_')[0]}",
                f"Direct-coil coordinator {label} on Kolmogorov tracking is {value:g} nm.",
                f"Table 6.1, Direct Coil: {label} {value:g} nm (hardware)",
                measured,
                st,
                note
                + (f" Outside ±30 %.{why[key]}" if st == "differs" else "")
                + (short if st == QUICK else "")
                + (contradiction if key in ("rmse", "max_abs") else ""),
                cause="our model" if st == "differs" else "",
            )
        )
    ok = power["max"] < 5.0 and abs(power["median"] - 2.25) <= 0.01 * 2.25
    st = "calibrated" if ok else "differs"  # the current was chosen from the 2.25 W
    out.append(
        claim(
            "table6.1-power",
            "The direct-coil coordinator dissipates 2.25 W, under the 5 W vacuum spec.",
            "Table 6.1, Direct Coil: P = 2.25 W; §6.1.2: P < 5 W",
            f"{power['median']:.3f} W median (max {power['max']:.3f} W)",
            st,
            "Criterion: every seed < 5 W and median within ±1 % of 2.25 W (Eq 6.6). Not an "
            "independent reproduction: the field amplitude I = 1.5 A was chosen from the "
            "thesis's 2.25 W, and at fixed amplitude P does not depend on the run length."
            + (" Power off 2.25 W or above 5 W." if st == "differs" else ""),
            cause="our model" if st == "differs" else "",
        )
    )
    csat = sum(m["saturated_steps"] for m in coord["runs"])
    clost = sum(bool(m["lost_sync"]) for m in coord["runs"])
    cmargin = min(m["fine_margin_min"] for m in coord["runs"]) * 1e6
    ctravel = min(m["travel"] for m in coord["runs"])
    st, why_st = fine_never_saturates(coord["runs"], coord["frozen"])
    out.append(
        claim(
            "fig6.16-fine-never-saturates",
            "During Kolmogorov tracking the piezo never reaches its saturation limits.",
            "Fig 6.16 and §6.4.2: the piezo output never reaches its saturation limits"
            + thesis_ref,
            f"{csat} saturated steps, {clost} lost-sync runs; closest approach to a stop "
            f"{cmargin:.2f} µm; carriage travel / reference travel ≥ {ctravel:.2f}; coarse "
            f"stage frozen: {min(fsat)}–{max(fsat)} saturated steps. {ref_stats}",
            st,
            "Criterion (criteria.fine_never_saturates): no saturated step and no lost "
            "synchronism on every reference whose excursion exceeds the fine stroke, and the "
            "frozen-coarse control saturates on each (it replaces the carriage-travel guard, "
            "which showed the carriage moves, not that it is needed). The same references in "
            f"quick and full runs. {why_st[0].upper()}{why_st[1:]}.",
        )
    )
    ok = best["rmse"] <= 8e-9 and best["max_abs"] <= 30e-9
    st = ("reproduced" if ok else "differs") if full else QUICK
    out.append(
        claim(
            "fig6.17-best-run",
            "The best direct-coil run tracks with less than 8 nm RMS and 30 nm maximum error.",
            "Fig 6.17 caption: < 8 nm rms, 30 nm max (Kolmogorov up to 200 Hz)",
            f"best seed {best['seed']}: {best['rmse'] * 1e9:.1f} nm RMS, "
            f"{best['max_abs'] * 1e9:.1f} nm max; the figure's stated condition (content "
            f"to 200 Hz, no vibration lines) on that seed: {fig617['rmse'] * 1e9:.1f} nm RMS, "
            f"{fig617['max_abs'] * 1e9:.1f} nm max",
            st,
            "Criterion: the best seed ≤ 8 nm RMS and ≤ 30 nm max."
            + (
                " The simulation does worse than the hardware, even under the figure's only "
                "stated condition (content up to 200 Hz, here without the preset's vibration "
                "lines): the floor is our model's -- the 234 Hz fine loop on our plant and "
                "preset -- not shown to be a property of the hardware data."
                if st == "differs"
                else ""
            )
            + (short if st == QUICK else "")
            + contradiction,
            cause="our model" if st == "differs" else "",
        )
    )
    th = slopes["theory"]
    got = (slopes["low_3e-4_4e-3_Hz"], slopes["mid_0.15_0.9_Hz"], slopes["high_10_60_Hz"])
    theory = (th["low"], th["mid"], th["high"])
    ok = all(abs(g - t) <= 0.3 for g, t in zip(got, theory, strict=True))
    out.append(
        claim(
            "opd-psd-slopes",
            "The synthesised OPD follows the −2/3, −8/3, −17/3 regimes of differential piston.",
            "not in the thesis (§6.1.2 names a Kolmogorov signal; slopes from Conan et al.)",
            f"slopes {got[0]:.2f} / {got[1]:.2f} / {got[2]:.2f} "
            f"({'all' if ok else 'not all'} within ±0.3 of theory)",
            "not in thesis",
            "Welch PSD of the L0 = ∞ synthesis, log-binned fits in 3e-4–4e-3, 0.15–0.9 and "
            "10–60 Hz.",
        )
    )
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="3 seeds (10 s each, as the thesis), CI")
    p.add_argument("--out", type=Path, default=Path("out/ch6_tracking"))
    p.add_argument("--seeds", type=int, default=None, help="number of seeds (default 20)")
    args = p.parse_args(argv)
    log = TextLog()
    say = log.say
    duration = 10.0  # the thesis's run length; one 10 s run takes about 0.5 s
    nseeds = args.seeds or (3 if args.quick else FULL_SEEDS)

    plant = ddl.DualStage()
    f, h, _ = coarse_frf(plant, fs=FS, y_c=0.0)
    f_res = peak_frequency(f, h, 30.0, 300.0)
    ff, hf, _ = fine_frf(plant, fs=FS)
    bw_fine = ddl.bandwidth_3db(ff[5:], hf[5:], reference=1.0)
    say(f"coarse resonance (chirp, centre): {f_res:.1f} Hz (thesis Fig 6.7: 120 Hz)")
    say(f"piezo -3 dB bandwidth (chirp):    {bw_fine:.1f} Hz (thesis Fig 6.6: ≈ 300 Hz)")
    slopes = psd_slopes(0)
    say(
        "OPD PSD slopes (L0 = inf): low {:.2f} (−0.67), mid {:.2f} (−2.67), "
        "high {:.2f} (−5.67)".format(
            slopes["low_3e-4_4e-3_Hz"], slopes["mid_0.15_0.9_Hz"], slopes["high_10_60_Hz"]
        )
    )

    rows = []
    keep = None
    say(f"\nSisoCoordinator, paranal_250hz preset, {duration:g} s at {FS:.0f} Hz, {nseeds} seeds")
    say(
        f"{'seed':>4} {'RMSE nm':>8} {'max nm':>7} {'mean nm':>8} {'P W':>6} "
        f"{'margin µm':>9} {'sat':>4} {'sync':>5} {'run s':>6}"
    )
    for seed in range(nseeds):
        r = ddl.kolmogorov_opd(duration, FS, seed=seed, preset="paranal_250hz")
        t0 = time.perf_counter()
        run = ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(), r, FS, seed=seed)
        wall = time.perf_counter() - t0
        m = run.metrics
        travel = float(np.ptp(run.y_c) / np.ptp(r))  # carriage travel / reference travel
        rows.append({"seed": seed, **m, "run_wall_s": wall, "travel": travel})
        say(
            f"{seed:4d} {m['rmse'] * 1e9:8.1f} {m['max_abs'] * 1e9:7.1f} "
            f"{m['mean_abs'] * 1e9:8.1f} "
            f"{m['power']:6.2f} {m['fine_margin_min'] * 1e6:9.2f} {m['saturated_steps']:4d} "
            f"{'LOST' if m['lost_sync'] else 'ok':>5} {wall:6.2f}"
        )
        if keep is None:
            keep = run

    def spread(key, scale=1.0):
        v = np.array([row[key] for row in rows], dtype=float) * scale
        return {"min": float(v.min()), "median": float(np.median(v)), "max": float(v.max())}

    summary_spread = {
        "rmse_nm": spread("rmse", 1e9),
        "max_abs_nm": spread("max_abs", 1e9),
        "mean_abs_nm": spread("mean_abs", 1e9),
        "power_w": spread("power"),
        "fine_margin_min_um": spread("fine_margin_min", 1e6),
        "run_wall_s": spread("run_wall_s"),
    }
    ok = all(
        row["rmse"] < 70e-9 and row["saturated_steps"] == 0 and row["power"] < 5.0 for row in rows
    )
    say("\nspread over seeds (min / median / max):")
    for k, v in summary_spread.items():
        say(f"  {k:20s} {v['min']:9.3f} {v['median']:9.3f} {v['max']:9.3f}")
    say(
        f"spec (RMSE < 70 nm, no fine saturation, P < 5 W) on all {nseeds} seeds: "
        f"{'MET' if ok else 'NOT MET'}"
    )
    say("thesis Table 6.1 (hardware, direct coil): 25 nm, 308 nm, 19.6 nm, 2.25 W")

    sweep_seeds = list(range(min(nseeds, 3 if args.quick else SWEEP_SEEDS)))
    sweep = lines_sweep(duration, sweep_seeds, [rows[i] for i in sweep_seeds])
    say(
        "RMSE vs the preset's vibration lines (median nm over seeds "
        f"{sweep_seeds[0]}–{sweep_seeds[-1]}): "
        + ", ".join(f"{k} {np.median(v):.1f}" for k, v in sweep["rmse"].items())
    )
    coord = coordination_runs(duration)
    say(
        f"\nreferences that need both stages ({COORD_PRESET}, peak to peak > "
        f"{coord['fine_stroke_um']:g} µm): coordinator / coarse frozen"
    )
    for ref, m, fz in zip(coord["references"], coord["runs"], coord["frozen"], strict=True):
        say(
            f"  seed {ref['seed']:2d} ptp {ref['ptp_um']:5.1f} µm: RMSE {m['rmse'] * 1e9:6.1f} / "
            f"{fz['rmse'] * 1e9:7.1f} nm, saturated steps {m['saturated_steps']} / "
            f"{fz['saturated_steps']}, travel {m['travel']:.2f} / {fz['travel']:.3f}"
        )
    fig617 = fig617_condition_run(duration, min(rows, key=lambda row: row["rmse"])["seed"])
    say(
        f"Fig 6.17's condition (content to 200 Hz, no vibration lines), seed {fig617['seed']}: "
        f"{fig617['rmse'] * 1e9:.1f} nm RMS, {fig617['max_abs'] * 1e9:.1f} nm max"
    )
    claims = tracking_claims(
        rows, summary_spread, f_res, bw_fine, slopes, duration, nseeds, coord, fig617, sweep
    )
    say("\nclaims (id: measured → status):")
    for c in claims:
        say(f"  {c['id']}: {c['measured']} → {c['status']}")

    try:
        from qpcoord.studies.figures import _pyplot, save
    except ImportError:  # pragma: no cover
        say("matplotlib not installed: figures skipped")
    else:
        plt = _pyplot()
        fig, ax = plt.subplots(3, 1, figsize=(7, 7.5), sharex=True)
        t = keep.t
        ax[0].plot(t, keep.r * 1e6, lw=1.0, label="reference r")
        ax[0].plot(t, keep.y * 1e6, "--", lw=0.8, label="output y")
        ax[0].plot(t, (keep.y_c_hat + 15e-6) * 1e6, "-.", lw=0.8, label="ŷ_c + 15 µm")
        ax[0].set_ylabel("µm")
        ax[0].legend(fontsize=7)
        ax[0].set_title("Kolmogorov tracking (cf. Fig 6.17a)")
        ax[1].plot(t, keep.error * 1e9, lw=0.5)
        ax[1].set_ylabel("error (nm)")
        ax[2].plot(t, keep.y_f * 1e6, lw=0.8)
        for lim in (0.0, 30.0):
            ax[2].axhline(lim, color="r", ls=":")
        ax[2].set_ylabel("piezo y_f (µm)")
        ax[2].set_xlabel("t (s)")
        ax[2].set_title("fine stage stays inside its stroke (cf. Fig 6.16)")
        save(fig, args.out / "tracking.png")
        fig, ax = plt.subplots(figsize=(6, 3.5))
        sel = (f > 5) & (f < 400)
        ax.semilogy(f[sel], np.abs(h[sel]), label="coarse α → y (normalised)")
        sel = (ff > 5) & (ff < 1500)
        ax.semilogy(ff[sel], np.abs(hf[sel]), label="piezo v → y (normalised)")
        ax.axvline(120, color="k", ls=":", lw=0.8)
        ax.set_xlabel("f (Hz)")
        ax.set_ylabel("|H|")
        ax.legend(fontsize=7)
        ax.set_title("chirp identification (cf. Figs 6.6, 6.7)")
        save(fig, args.out / "identification.png")

    log.write(args.out / "summary.txt")
    write_json(
        args.out / "summary.json",
        {
            "fs_hz": FS,
            "duration_s": duration,
            "seeds": nseeds,
            "preset": "paranal_250hz",
            "coarse_resonance_hz": f_res,
            "piezo_bandwidth_hz": bw_fine,
            "opd_psd_slopes": slopes,
            "spread": summary_spread,
            "spec_met_all_seeds": ok,
            "nm_vs_vibration_lines": sweep,
            "coordination": coord,
            "fig6_17_condition_run": fig617,
            "runs": rows,
            "claims": claims,
            "thesis_table_6_1_direct_coil": {
                "rmse_nm": 25,
                "max_nm": 308,
                "mean_nm": 19.6,
                "power_w": 2.25,
            },
        },
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
