"""Chapter 6, Tables 6.1–6.2 and Fig 6.18: the coordinator against LQR, PQ (and the MPC).

Runs :func:`qpcoord.ddl.compare.compare` on the thesis coordinator (``SisoCoordinator``), the
thesis's current-driven LQR without rate limit (``LQRCurrent``) and PQ design with the coarse
stage as main actuator (``PQCurrent``), qpcoord's field-phase variants of both (``LQR``,
``PQ``: fixed amplitude, 3 mm/s rate limit), the prioritised-stack ``MPC`` and the
PI-linearised and flatness-based coarse controls (dither + friction feed-forward)
(:func:`qpcoord.ddl.compare.default_controllers`), all with default arguments, on the
same cases: the ``paranal_250hz`` Kolmogorov OPD (one realisation per seed), the two 5 mm
steps of Fig 6.19, the Kolmogorov reference on a plant ±20 % off in piezo gain, flexure
stiffness and friction (controllers designed on the nominal plant) and, beyond the thesis,
with two periods of command latency (``latency2``) and the OPD scaled by 3
(``kolmogorov3x``: a fine stage left alone would saturate there). Every coarse-controller
claim is conditional on the carriage carrying the low-frequency reference (carriage travel /
reference travel ≥ 0.5 on the Kolmogorov runs). Writes the Table 6.1-style
table and the Table 6.2-style grid (``summary.txt``), the design reports of LQR and PQ,
``summary.json`` and two figures: a 25 ms detail of the output tracking (Fig 6.18a) and the
carriage position over 4 s with the fine-stroke limits marked (Fig 6.18b).

Run: ``python examples/ch6_compare.py [--quick] [--seeds N] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

import qpcoord.ddl as ddl
from qpcoord.ddl.compare import (
    Case,
    compare,
    default_cases,
    default_controllers,
    format_grid,
    format_table,
    qualitative_grid,
)
from qpcoord.ddl.lqr_current import LQRCurrent
from qpcoord.ddl.plant import DualStage
from qpcoord.ddl.pq_current import PQCurrent
from qpcoord.studies.claims import QUICK, claim
from qpcoord.studies.files import TextLog, write_json

FS = 8000.0


def _clean(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {str(k): _clean(x) for k, x in v.items()}
    if isinstance(v, (np.floating, np.integer)):
        return _clean(v.item())
    return v


#: Thesis Table 6.1 (hardware): RMSE, |e|max, mean |e| (nm), P (W), under our names.
TABLE_6_1 = {
    "coordinator": ("Direct Coil", 25.0, 308.0, 19.6, 2.25),
    "FlatnessBased": ("Flatness based", 26.6, 147.5, 20.7, 0.016),
    "PILinearised": ("PI-linearized", 22.8, 133.0, 17.7, 0.017),
    "PQCurrent": ("PQ", 40.0, 270.0, 31.0, 0.012),
    "LQRCurrent": ("LQR", 44.8, 640.0, 30.7, 0.015),
}
#: A carriage carries the low-frequency reference when it travels at least this fraction of
#: the reference's travel on the Kolmogorov runs (otherwise the fine stage tracks
#: alone and a coarse-controller row measures nothing of the coarse controller).
MIN_TRAVEL = 0.5
#: Thesis Table 6.2 marks, same controller order as TABLE_6_1.
TABLE_6_2 = {
    "RMS error": ("++++", "++++", "++++", "++", "++"),
    "e_max": ("+++", "++++", "++++", "++++", "+"),
    "Power dissipation": ("-", "++++", "++++", "++++", "++++"),
    "Step response": ("++++", "-", "+", "--", "---"),
    "Robustness": ("++++", "--", "--", "---", "---"),
}
MARK_VALUE = {"++++": 4, "+++": 3, "++": 2, "+": 1, "-": 0, "--": -1, "---": -2}
#: Why our Table 6.2 orderings differ from the thesis's, per criterion (docs/ch6.md).
GRID_WHY = {
    "RMS error": "Without latency the LQR ranks first: our plant is its own design model up "
    "to friction, detent and quantisation (no unmodelled piezo modes, amplifier dynamics or "
    "computation delay), and under the same peak-|S| ≤ 1.6 rule its observer-based loop "
    "crosses over at ≈ 1 kHz against the PI's 234 Hz (current-driven and field-phase LQR "
    "alike). With two periods of latency it oscillates (row latency2-lqr), the thesis's "
    "ranking.",
    "e_max": "Same cause as the RMS row: the LQR has the smallest peaks without latency.",
    "Power dissipation": "A current-driven controller drew more than the direct coil's "
    "fixed 2.25 W (see the power column).",
    "Step response": "The current-driven LQR and PQ have no rate limit and the force for the "
    "step (1650 N at 1.5 A): they reach the 5 mm steps in 0.14–0.27 s without losing "
    "synchronism (row fig6.19a-lqr-desync), while the rate-limited SISO controllers take "
    "1.7–1.8 s; on the hardware the LQR lost synchronism and the linearised controllers "
    "stalled at the extremity (row fig6.19b-linearised-stall), neither of which our plant "
    "does.",
    "Robustness": "The dithered PI-linearised and flatness controllers degrade most on the "
    "±20 % plants (2.6× their nominal RMSE: the piezo-gain error enters their carriage "
    "estimate and the friction model is sized on the nominal plant), as in the thesis; but "
    "our LQR and PQ degrade less than they do (1.1× and 1.4×), unlike the thesis's.",
}


def _travel(rows: list[dict], ctl: str, case: str = "kolmogorov") -> float:
    """Median over seeds of carriage travel / reference travel (peak to peak) on ``case``."""
    vals = [
        np.ptp(r["run"].y_c) / np.ptp(r["run"].r)
        for r in rows
        if r["controller"] == ctl and r["case"] == case and "run" in r
    ]
    return float(np.median(vals)) if vals else math.nan


def _sync_margin(run, plant) -> tuple[float, float]:
    """Peak carriage speed (m/s) and largest |field angle − rotor electrical angle| (rad)."""
    ne = plant.stepper.electrical_per_metre
    field = np.unwrap(np.arctan2(run.i_a, run.i_b))
    lag = field - ne * run.y_c
    lag = lag - 2.0 * math.pi * np.round(np.median(lag) / (2.0 * math.pi))
    return float(np.max(np.abs(np.diff(run.y_c))) * FS), float(np.max(np.abs(lag)))


def compare_claims(rows: list[dict], full: bool, size: str) -> list[dict]:
    """Claim rows (``qpcoord.studies.claims.claim``) for Tables 6.1–6.2, Figs 6.18–6.19.

    ``full``: the run is as long as the thesis's (10 s Kolmogorov, ≥ 3 seeds, 6 s steps);
    otherwise every thesis row is :data:`~qpcoord.studies.claims.QUICK`. ``size`` describes
    the run. A claim on coarse controllers is ``"reproduced"`` only if their carriages carry
    the low-frequency reference (travel ratio ≥ :data:`MIN_TRAVEL`); otherwise it is
    ``"differs"`` with the stuck controllers named.
    """
    names = list(TABLE_6_1)
    short = (
        f" This run ({size}) is shorter than the thesis's 10 s runs: the full run (10 s × 3 "
        "seeds, 6 s steps at the centre and the extremity) decides."
    )

    def med(ctl, case, key, scale=1.0):
        v = [r[key] for r in rows if r["controller"] == ctl and r["case"] == case]
        v = [x for x in v if x is not None and not (isinstance(x, float) and math.isnan(x))]
        return float(np.median(v)) * scale if v else math.nan

    travel = {c: _travel(rows, c) for c in names}

    def stuck(ctls):
        return [c for c in ctls if not travel[c] >= MIN_TRAVEL]

    def verdict(ok, ctls):
        """Status and a note: pass only with every carriage of ``ctls`` carrying."""
        if not full:
            return QUICK, short
        st = stuck(ctls)
        if ok and st:
            return "differs", (
                " The criterion holds, but the carriage of "
                + ", ".join(TABLE_6_1[c][0] for c in st)
                + f" travels less than {MIN_TRAVEL:g} × the reference (travel "
                + ", ".join(f"{travel[c]:.2f}" for c in st)
                + "): the fine stage tracked alone, so the row does not test that coarse "
                "controller."
            )
        return ("reproduced" if ok else "differs"), ""

    def travels(ctls):
        return "carriage travel / reference travel " + ", ".join(
            f"{TABLE_6_1[c][0]} {travel[c]:.2f}" for c in ctls
        )

    out = []
    for ctl, (label, t_rmse, t_max, t_mean, t_p) in TABLE_6_1.items():
        rmse = med(ctl, "kolmogorov", "rmse", 1e9)
        ok = abs(rmse - t_rmse) <= 0.3 * t_rmse
        st, extra = verdict(ok, [ctl])
        why = {
            "LQRCurrent": " " + GRID_WHY["RMS error"],
            "PQCurrent": " Our PQ's fine PI is the coordinator's and, without latency or "
            "unmodelled modes, tracks like it; its coarse stage sticks on this small OPD.",
        }.get(ctl, " Simulation, not hardware.")
        out.append(
            claim(
                f"table6.1-{ctl}",
                f"{label}: Kolmogorov tracking RMSE {t_rmse:g} nm.",
                f"Table 6.1, {label}: {t_rmse:g} / {t_max:g} / {t_mean:g} nm, {t_p:g} W "
                "(RMSE / max / mean / P, hardware)",
                f"{rmse:.1f} / {med(ctl, 'kolmogorov', 'max_abs', 1e9):.1f} / "
                f"{med(ctl, 'kolmogorov', 'mean_abs', 1e9):.1f} nm, "
                f"{med(ctl, 'kolmogorov', 'power'):.3g} W (median over seeds); " + travels([ctl]),
                st,
                "Criterion: RMSE within ±30 % of the thesis and the carriage carrying the "
                f"low-frequency reference (travel ≥ {MIN_TRAVEL:g}; max, mean and power shown, "
                "not judged here)." + (why if st == "differs" and not extra else "") + extra,
                cause="our model" if st == "differs" else "",
            )
        )
    siso = ("coordinator", "PILinearised", "FlatnessBased")
    r = [med(c, "kolmogorov", "rmse", 1e9) for c in siso]
    m = [med(c, "kolmogorov", "mean_abs", 1e9) for c in siso]
    ok = max(r) <= 1.25 * min(r) and max(m) <= 1.25 * min(m)
    st, extra = verdict(ok, siso)
    out.append(
        claim(
            "table6.1-siso-similar",
            "The three decoupled-SISO controllers (direct coil, PI-linearised, flatness) have "
            "similar RMS and mean errors: they share the fine-stage controller.",
            "§6.4.2 on Table 6.1 (RMSE 25 / 22.8 / 26.6 nm, mean 19.6 / 17.7 / 20.7 nm)",
            "RMSE "
            + " / ".join(f"{v:.1f}" for v in r)
            + " nm, mean "
            + " / ".join(f"{v:.1f}" for v in m)
            + " nm; "
            + travels(siso),
            st,
            "Criterion: largest ≤ 1.25 × smallest, for RMSE and for mean, with every carriage "
            "carrying the low-frequency reference."
            + (" They are not similar here." if st == "differs" and not extra else "")
            + extra,
        )
    )
    p = {c: med(c, "kolmogorov", "power") for c in siso}
    ok = max(p["PILinearised"], p["FlatnessBased"]) <= 0.1 * p["coordinator"]
    st, extra = verdict(ok, siso)
    out.append(
        claim(
            "table6.1-linearised-power",
            "The feedback-linearised controllers dissipate much less power than direct coil.",
            "Table 6.1 column 4: 0.017 / 0.016 W against 2.25 W",
            f"PI-linearised {p['PILinearised']:.2g} W, flatness {p['FlatnessBased']:.2g} W, "
            f"direct coil {p['coordinator']:.3g} W; " + travels(siso),
            st,
            "Criterion: both ≤ 10 % of the direct coil's, with the carriages carrying the "
            "low-frequency reference (a carriage left in stiction draws no current). Most "
            "of the linearised controllers' power is their stiction-breaking dither "
            "(a ±0.074 A square wave: 0.0055 W)."
            + (" Not 10× lower here." if st == "differs" and not extra else "")
            + extra,
        )
    )
    grid = qualitative_grid([r for r in rows if r["controller"] in names])
    for crit, marks in TABLE_6_2.items():
        ours = grid.get(crit, {})
        pairs = [(a, b) for i, a in enumerate(names) for b in names[i + 1 :]]
        strict, kept = 0, 0
        for a, b in pairs:
            ta, tb = MARK_VALUE[marks[names.index(a)]], MARK_VALUE[marks[names.index(b)]]
            if ta == tb:
                continue
            strict += 1
            oa, ob = MARK_VALUE.get(ours.get(a)), MARK_VALUE.get(ours.get(b))
            kept += oa is not None and ob is not None and (oa - ob) * (ta - tb) > 0
        ok = strict > 0 and kept == strict
        st, extra = verdict(ok, names)
        key = crit.split()[0].lower().replace("_", "")
        out.append(
            claim(
                f"table6.2-{key}",
                f"Table 6.2 ranks the controllers on {crit.lower()} as: "
                + ", ".join(f"{TABLE_6_1[c][0]} {mk}" for c, mk in zip(names, marks, strict=True))
                + ".",
                f"Table 6.2, row {crit!r}",
                "ours: "
                + ", ".join(f"{TABLE_6_1[c][0]} {ours.get(c, 'n/a')}" for c in names)
                + f"; {kept}/{strict} of the thesis's strict pairwise orders kept",
                st,
                "Criterion: every pair the thesis rates differently is ordered the same way by "
                "our marks (qualitative_grid over these five controllers; a tie breaks it), "
                "with every carriage carrying the low-frequency reference."
                + (" " + GRID_WHY[crit] if st == "differs" and not extra else "")
                + extra,
            )
        )
    kol = [r for r in rows if r["case"] == "kolmogorov" and r["controller"] in names]
    sat = sum(int(r["saturated_steps"] or 0) for r in kol)
    ok = sat == 0 and not any(r["lost_sync"] or r["error"] for r in kol)
    st, extra = verdict(ok, names)
    out.append(
        claim(
            "fig6.18b-fine-within-limits",
            "On Kolmogorov tracking every controller's coarse stage keeps the fine stage "
            "within its saturation limits.",
            "Fig 6.18b and §6.4.2",
            f"{sat} saturated steps over {len(kol)} runs of the five thesis controllers; "
            "closest approach "
            f"{min(med(c, 'kolmogorov', 'fine_margin_min', 1e6) for c in names):.2f} µm; "
            + travels(names),
            st,
            "Criterion: zero saturated steps, no lost synchronism, no failed run, and each "
            f"carriage travels at least {MIN_TRAVEL:g} × as far as the reference (the coarse "
            "stage does the keeping, not the reference's small excursion)."
            + (
                " Some controller saturated the fine stage."
                if st == "differs" and not extra
                else ""
            )
            + extra,
        )
    )
    steps = [r for r in rows if r["controller"] == "LQRCurrent" and r["case"].startswith("step")]
    lost = sum(bool(r["lost_sync"]) for r in steps)
    margins = [_sync_margin(r["run"], DualStage()) for r in steps if "run" in r]
    margins = margins or [(math.nan, math.nan)]
    speed = [m[0] for m in margins]
    lag = [m[1] for m in margins]
    ok = lost > 0
    st = ("reproduced" if ok else "differs") if full else QUICK
    out.append(
        claim(
            "fig6.19a-lqr-desync",
            "On 5000 µm steps the LQR de-synchronises rotor and field (random behaviour).",
            'Fig 6.19a and §6.4.2: LQR, "de-synchronization between rotor and the generated '
            'magnetic field"',
            f"LQR (current-driven, no rate limit) lost synchronism in {lost}/{len(steps)} step "
            f"runs; peak carriage speed {max(speed) * 1e3:.0f} mm/s, largest field-to-rotor "
            f"angle {math.degrees(max(lag)):.0f}° (synchronism is lost beyond 180°); settled in "
            f"{med('LQRCurrent', 'step_extremity', 'settle_time'):.2f} s at the extremity",
            st,
            "Criterion: the LQR loses synchronism on a step."
            + (
                " Our feedback linearisation places the field from the observer's carriage "
                "estimate, which stays within a few µm (one step is 10 µm) of the carriage, "
                "so the field stays within ±90°–100° of the rotor even at the step's peak "
                "speed. Seen after this verdict and not a criterion: with one extra period "
                "of command latency (not in the thesis's description) the centre step slips."
                if st == "differs"
                else ""
            )
            + (short if st == QUICK else ""),
        )
    )
    ext = {c: med(c, "step_extremity", "settle_time") for c in ("PILinearised", "FlatnessBased")}
    ok = any(math.isnan(v) for v in ext.values())
    st = ("reproduced" if ok else "differs") if full else QUICK
    out.append(
        claim(
            "fig6.19b-linearised-stall",
            "Towards the stroke end the feedback-linearised controllers stall (current "
            "saturated, not enough torque) and the DDL stops moving.",
            "Fig 6.19b, Fig 6.20 and §6.4.2",
            "settling within 100 nm at the extremity: "
            + ", ".join(f"{c} {v:.2f} s" for c, v in ext.items())
            + " (nan = never)",
            st,
            "Criterion: one of them never settles on the extremity step."
            + (
                " 1.5 A gives ≈ 1650 N against ≈ 215 N needed (flexure 139 N + viscous + "
                "Coulomb at 3 mm/s): the simulated motor has the torque, what loaded the "
                "hardware's is not modelled."
                if st == "differs"
                else ""
            )
            + (short if st == QUICK else ""),
        )
    )
    lat = {c: med(c, "latency2", "rmse", 1e9) for c in ("coordinator", "LQR")}
    out.append(
        claim(
            "latency2-lqr",
            "With two periods (250 µs) of command latency the LQR loses its advantage.",
            "not in the thesis (our explanation of Table 6.1's LQR row)",
            f"latency2 RMSE: LQR {lat['LQR']:.1f} nm, coordinator {lat['coordinator']:.1f} nm "
            f"(nominal {med('LQR', 'kolmogorov', 'rmse', 1e9):.1f} / "
            f"{med('coordinator', 'kolmogorov', 'rmse', 1e9):.1f} nm); current-driven LQR "
            f"{med('LQRCurrent', 'latency2', 'rmse', 1e9):.1f} nm "
            f"(nominal {med('LQRCurrent', 'kolmogorov', 'rmse', 1e9):.1f} nm)",
            "not in thesis",
            "The LQR tolerates one extra period of delay, the coordinator's fine PI six.",
        )
    )
    x3 = [r for r in rows if r["case"] == "kolmogorov3x" and r["controller"] in names]
    sat3 = {c: med(c, "kolmogorov3x", "saturated_steps") for c in names}
    tr3 = {c: _travel(rows, c, "kolmogorov3x") for c in names}
    out.append(
        claim(
            "kolmogorov3x-coarse-carries",
            "With the OPD scaled by 3 (excursion beyond what the fine stage could take "
            "alone) every thesis controller's carriage carries the low-frequency reference "
            "and no fine stage saturates.",
            "not in the thesis (a check that the coarse controllers do their job)",
            (
                "; ".join(
                    f"{TABLE_6_1[c][0]}: travel {tr3[c]:.2f}, saturated steps {sat3[c]:.0f}, "
                    f"RMSE {med(c, 'kolmogorov3x', 'rmse', 1e9):.1f} nm"
                    for c in names
                )
                if x3
                else "not run"
            ),
            "not in thesis",
            "Own check; it can fail: the friction-free PI-linearised design gives travel "
            "0.00 and 2 651 saturated steps on this case.",
        )
    )
    out.append(
        claim(
            "mpc-stack",
            "The prioritised-stack MPC tracks and keeps the fine stage off its stops on steps.",
            "not in the thesis (qpcoord's MPC)",
            f"Kolmogorov RMSE {med('MPC', 'kolmogorov', 'rmse', 1e9):.1f} nm; fine margin "
            f"on the extremity step {med('MPC', 'step_extremity', 'fine_margin_min', 1e6):.2f} "
            f"µm, saturated steps {med('MPC', 'step_extremity', 'saturated_steps'):.0f}",
            "not in thesis",
            "Stroke margin of the MPC's hard constraint: 10 % of the stroke (3 µm).",
        )
    )
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="1 s Kolmogorov, one 2.5 s step (CI)")
    p.add_argument("--seeds", type=int, default=None, help="number of Kolmogorov seeds")
    p.add_argument("--out", type=Path, default=Path("out/ch6_compare"))
    args = p.parse_args(argv)
    log = TextLog()
    say = log.say
    duration, step_duration = (1.0, 2.5) if args.quick else (10.0, 6.0)
    nseeds = args.seeds if args.seeds is not None else (1 if args.quick else 3)
    seeds = tuple(range(nseeds))
    ctls = default_controllers()
    cases = default_cases(duration, step_duration, FS)
    if args.quick:  # CI: one step case (the centre behaves as the extremity in every run)
        cases = [c for c in cases if c.name != "step_centre"]
    cases.append(
        Case(
            "kolmogorov3x",
            lambda seed: 3.0 * ddl.kolmogorov_opd(duration, FS, seed=seed, preset="paranal_250hz"),
        )
    )
    say(
        f"DDL comparison at {FS:.0f} Hz: {', '.join(ctls)}; Kolmogorov {duration:g} s × "
        f"{nseeds} seed(s), steps {step_duration:g} s ({', '.join(c.name for c in cases)}), "
        "mismatch ±20 %, latency 2 periods"
    )
    rows = compare(ctls, cases, seeds=seeds, fs=FS, keep_runs=True)
    say("")
    say("Table 6.1 form (medians over seeds):")
    say(format_table(rows))
    say("Table 6.2 form (ratings from the measured rows, rules in qualitative_grid):")
    say(format_grid(rows))
    for r in rows:
        if r["error"]:
            say(f"FAILED {r['controller']} / {r['case']}: {r['error']}")
    # design reports (linear analysis at the stroke centre)
    plant = ddl.DualStage()
    lq = ddl.LQR().design(plant, FS)
    pq = ddl.PQ().design(plant, FS)
    rep = {
        "LQR": lq.report(),
        "PQ": pq.report(),
        "LQRCurrent": LQRCurrent().design(plant, FS).report(),
        "PQCurrent": PQCurrent().design(plant, FS).report(),
    }
    say("LQR design: " + ", ".join(f"{k} {v:.4g}" for k, v in rep["LQR"].items()))
    say(
        "PQ design: "
        + ", ".join(f"{k} {v:.4g}" for k, v in rep["PQ"].items() if not isinstance(v, dict))
    )
    say(
        "PQ coarse share |PQ/(1+PQ)|: "
        + ", ".join(f"{f:g} Hz {s:.3f}" for f, s in rep["PQ"]["coarse_share"].items())
    )
    say("LQRCurrent design: " + ", ".join(f"{k} {v:.4g}" for k, v in rep["LQRCurrent"].items()))
    say(
        "PQCurrent design: "
        + ", ".join(f"{k} {v:.4g}" for k, v in rep["PQCurrent"].items() if not isinstance(v, dict))
        + "; coarse share "
        + ", ".join(f"{f:g} Hz {s:.3f}" for f, s in rep["PQCurrent"]["coarse_share"].items())
    )
    full = duration >= 10.0 and nseeds >= 3 and step_duration >= 6.0
    claims = compare_claims(
        rows, full, f"{duration:g} s × {nseeds} seed(s), steps {step_duration:g} s"
    )
    say("claims (id: measured → status):")
    for c in claims:
        say(f"  {c['id']}: {c['measured']} → {c['status']}")
    # figures
    try:
        from qpcoord.studies.figures import _pyplot, save
    except ImportError:  # pragma: no cover
        say("matplotlib not installed: figures skipped")
    else:
        plt = _pyplot()
        kol = [r for r in rows if r["case"] == "kolmogorov" and r["seed"] == 0 and "run" in r]
        if kol:
            fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
            t0 = min(0.5, 0.5 * duration)
            run0 = kol[0]["run"]
            k0 = int(t0 * FS)
            k1 = k0 + int(0.025 * FS)
            t = run0.t[k0:k1] * 1e3
            ax[0].plot(t, run0.r[k0:k1] * 1e6, "k", lw=1.5, label="reference")
            for r in kol:
                run = r["run"]
                ax[0].plot(t, run.y[k0:k1] * 1e6, lw=0.9, label=r["controller"])
                ax[1].plot(t, run.error[k0:k1] * 1e9, lw=0.9, label=r["controller"])
            ax[0].set_ylabel("output (µm)")
            ax[0].set_title("Kolmogorov tracking, 25 ms detail (cf. Fig 6.18a)")
            ax[0].legend(fontsize=7)
            ax[1].set_ylabel("error (nm)")
            ax[1].set_xlabel("t (ms)")
            save(fig, args.out / "tracking_detail.png")
            fig, ax = plt.subplots(figsize=(8, 4))
            run0 = kol[0]["run"]
            n = min(run0.t.size, int(4.0 * FS))
            tt = run0.t[:n]
            ax.plot(tt, run0.r[:n] * 1e6, "k", lw=1.2, label="reference")
            fine = plant.fine
            for r in kol:
                run = r["run"]
                yc = run.y_c_hat[:n] if run.y_c_hat.size else run.y_c[:n]
                ax.plot(tt, yc * 1e6, lw=0.9, label=f"{r['controller']} carriage")
            # fine-stroke limits around the reference: the carriage must stay within
            # [r − y_f,max, r − y_f,min] for the piezo to reach the output
            ax.plot(
                tt,
                (run0.r[:n] - fine.stroke_max) * 1e6,
                "v",
                color="0.3",
                ms=3,
                markevery=max(1, n // 40),
            )
            ax.plot(
                tt,
                (run0.r[:n] - fine.stroke_min) * 1e6,
                "^",
                color="0.3",
                ms=3,
                markevery=max(1, n // 40),
                label="fine-stroke limits",
            )
            ax.set_xlabel("t (s)")
            ax.set_ylabel("µm")
            ax.set_title("Estimated carriage position (cf. Fig 6.18b)")
            ax.legend(fontsize=7)
            save(fig, args.out / "coarse_position.png")
    log.write(args.out / "summary.txt")
    keep = [k for k in dict.fromkeys(k for r in rows for k in r) if k not in ("run", "traceback")]
    summary = {
        "fs_hz": FS,
        "duration_s": duration,
        "step_duration_s": step_duration,
        "seeds": list(seeds),
        "controllers": list(ctls),
        "rows": [_clean({k: r.get(k) for k in keep}) for r in rows],
        "grid": qualitative_grid(rows),
        "design": _clean(rep),
        "claims": claims,
    }
    write_json(args.out / "summary.json", summary)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
