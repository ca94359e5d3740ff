"""Chapter 6, beyond the thesis: robustness of the designed coordinator, the LQR and the MPC.

A robustness study. Three controllers, all designed on (and initialised from) the
*nominal* PRIMA plant (``qpcoord.ddl.compare.DesignedOn``):

* the coordinator **designed** for the sky by ``qpcoord.ddl.design_coordinator`` from one 2-s
  record (seed 0) of the ``paranal_250hz_lf10`` preset (10× the low-frequency power of the
  default sky; ``docs/ch6.md``, "Designing the coordinator for a turbulence");
* the ``LQR`` and the ``MPC`` with their default arguments,

track fresh ``paranal_250hz_lf10`` references (seeds from ``qpcoord.studies.sweep.seeds``) on
the nominal plant and on plants with one parameter 20 % off — piezo gain, carriage mass (rotor
inertia through the screw and the flexure masses, scaled together), flexure stiffness, stepper
torque constant — each with one metrology fault at mid-run (or none):

* ``NaN``: one sample not a number;
* ``spike 1 mm``: one sample 1 mm off (outside what the stages can move in a period);
* ``frozen 50 ms``: the sensor repeats one reading for 400 samples (50 ms at 8 kHz);
* ``dropped``: one sample lost, the acquisition repeats the previous reading.

Per run: RMSE of the measured error, saturated fine-stage steps, rejected samples (the
controllers' ``MeasurementGuard``), loss of synchronism, and the **recovery time** after the
fault, with the protocol of ``docs/ch6.md`` ("Measurement faults"): the time from the fault's
start until every trailing 5 ms window of the error has an RMSE within 10 % + 1.25 nm of the
fault-free run's (same controller, plant and seed; 0 = never outside, ``None`` = not recovered
by the end of the run). The script fails if any command is not finite (a controller must never
propagate a NaN).

Run: ``python examples/ch6_robustness.py [--quick] [--seeds N] [--duration S] [--out DIR]
[--n-jobs N]`` (default 20 seeds × 2 s, the fault at 1 s; ``--quick``: 1 seed × 0.3 s).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from pathlib import Path

import numpy as np

import qpcoord.ddl as ddl
from qpcoord.ddl import faults as fl
from qpcoord.ddl.compare import DesignedOn
from qpcoord.studies.claims import claim
from qpcoord.studies.files import TextLog, write_json
from qpcoord.studies.sweep import grid, seeds, sweep

FS = 8000.0
PRESET = "paranal_250hz_lf10"
DESIGN_SEED = 0
CONTROLLERS = ("designed coordinator", "LQR", "MPC")
#: Plant cases: name -> (parameter scaled, factor).
CASES = {
    "nominal": ("none", 1.0),
    "piezo gain +20 %": ("piezo gain", 1.2),
    "piezo gain -20 %": ("piezo gain", 0.8),
    "carriage mass +20 %": ("carriage mass", 1.2),
    "carriage mass -20 %": ("carriage mass", 0.8),
    "flexure stiffness +20 %": ("flexure stiffness", 1.2),
    "flexure stiffness -20 %": ("flexure stiffness", 0.8),
    "stepper torque +20 %": ("stepper torque", 1.2),
    "stepper torque -20 %": ("stepper torque", 0.8),
}
FAULTS = ("none", "NaN", "spike 1 mm", "frozen 50 ms", "dropped")
FROZEN = 0.05  # s
SPIKE = 1e-3  # m
WINDOW = 0.005  # s: trailing window of the recovery criterion
Q = 1.25e-9  # m: metrology quantum
SPEC_RMSE = 70e-9  # m, §6.1.2


def make_plant(param: str, factor: float) -> ddl.DualStage:
    """The true (simulated) plant: one parameter of the default plant times ``factor``."""
    base = ddl.DualStage()
    fine, st, flex = base.fine, base.stepper, base.flexure
    if param == "piezo gain":
        fine = dataclasses.replace(fine, gain=fine.gain * factor)
    elif param == "carriage mass":
        st = dataclasses.replace(st, inertia=st.inertia * factor)
        flex = dataclasses.replace(
            flex, main_mass=flex.main_mass * factor, platform_mass=flex.platform_mass * factor
        )
    elif param == "flexure stiffness":
        flex = dataclasses.replace(flex, stiffness_sum=flex.stiffness_sum * factor)
    elif param == "stepper torque":
        st = dataclasses.replace(st, torque_constant=st.torque_constant * factor)
    elif param != "none":
        raise ValueError(f"unknown plant parameter {param!r}")
    return ddl.DualStage(fine, st, flex)


def make_controller(name: str, design: dict):
    if name == "designed coordinator":
        inner = ddl.SisoCoordinator(**design)
    elif name == "LQR":
        inner = ddl.LQR()
    elif name == "MPC":
        inner = ddl.MPC()
    else:
        raise ValueError(f"unknown controller {name!r}")
    return DesignedOn(inner, ddl.DualStage())


def make_fault(name: str, kf: int, fs: float):
    """The fault of ``name`` starting at sample ``kf`` (None for ``"none"``)."""
    if name == "none":
        return None
    if name == "NaN":
        return fl.sample(kf)
    if name == "spike 1 mm":
        return fl.spike(kf, SPIKE)
    if name == "frozen 50 ms":
        return fl.stuck(kf, round(FROZEN * fs))
    if name == "dropped":
        return fl.stuck(kf - 1, 2)  # sample kf lost: the previous reading is repeated
    raise ValueError(f"unknown fault {name!r}")


def trailing_rms(e: np.ndarray, n: int) -> np.ndarray:
    """RMS of ``e`` over the ``n`` samples ending at each index (shorter at the start)."""
    c = np.concatenate(([0.0], np.cumsum(e * e)))
    k = np.arange(1, e.size + 1)
    lo = np.maximum(k - n, 0)
    return np.sqrt((c[k] - c[lo]) / (k - lo))


def recovery_time(e: np.ndarray, e0: np.ndarray, kf: int, fs: float) -> float | None:
    """Seconds after ``kf`` until every trailing window RMS of ``e`` is within 10 % + 1 quantum
    of the fault-free ``e0``'s; 0 if never outside, None if still outside at the end."""
    n = max(1, round(WINDOW * fs))
    bad = np.flatnonzero(trailing_rms(e, n)[kf:] > 1.1 * trailing_rms(e0, n)[kf:] + Q)
    if bad.size == 0:
        return 0.0
    if bad[-1] == e.size - kf - 1:
        return None
    return float((bad[-1] + 1) / fs)


def run_point(controller: str, case: str, seed: int, duration: float, design: dict) -> dict:
    """The five fault variants of one controller × plant × seed: metrics (SI units)."""
    r = ddl.kolmogorov_opd(duration, FS, seed=seed, preset=PRESET)
    kf = r.size // 2
    out = {}
    e0 = None
    for fault in FAULTS:
        ctl = make_controller(controller, design)
        run = ddl.simulate(
            make_plant(*CASES[case]), ctl, r, FS, seed=seed, faults=make_fault(fault, kf, FS)
        )
        m = run.metrics
        finite = bool(
            np.isfinite(run.v).all() and np.isfinite(run.i_a).all() and np.isfinite(run.i_b).all()
        )
        e = run.error
        if fault == "none":
            e0 = e
        row = {
            "rmse": m["rmse"],
            "saturated_steps": m["saturated_steps"],
            "fine_margin_min": m["fine_margin_min"],
            "rejected_samples": m["rejected_samples"],
            "lost_sync": bool(m["lost_sync"]),
            "power": m["power"],
            "finite_commands": finite,
        }
        if fault != "none":
            row["recovery"] = recovery_time(e, e0, kf, FS)
            row["max_dev"] = float(np.max(np.abs(e[kf:] - e0[kf:])))
        out[fault] = row
    return out


def _ms(v) -> str:
    return "never" if v is None else f"{v * 1e3:.1f}"


def summarise(points: list, results: list) -> dict:
    """Tables: per controller × case (fault-free) and per controller × fault (all cases)."""
    by_case, by_fault = {}, {}
    for ctl in CONTROLLERS:
        for case in CASES:
            rows = [
                res["none"]
                for p, res in zip(points, results, strict=True)
                if p["controller"] == ctl and p["case"] == case
            ]
            rm = np.array([x["rmse"] for x in rows]) * 1e9
            by_case[f"{ctl} | {case}"] = {
                "controller": ctl,
                "case": case,
                "runs": len(rows),
                "rmse_median_nm": float(np.median(rm)),
                "rmse_max_nm": float(rm.max()),
                "saturated_steps": int(sum(x["saturated_steps"] for x in rows)),
                "saturated_runs": int(sum(x["saturated_steps"] > 0 for x in rows)),
                "margin_min_um": float(min(x["fine_margin_min"] for x in rows) * 1e6),
                "lost_sync_runs": int(sum(x["lost_sync"] for x in rows)),
                "power_w": float(np.mean([x["power"] for x in rows])),
            }
        for fault in FAULTS[1:]:
            pairs = [
                (res["none"], res[fault])
                for p, res in zip(points, results, strict=True)
                if p["controller"] == ctl
            ]
            rec = [f["recovery"] for _, f in pairs]
            done = [x for x in rec if x is not None]
            # percentiles with "not recovered" as +inf (None when they fall there)
            v = np.array([math.inf if x is None else x for x in rec])
            q50, q95 = (float(np.quantile(v, q, method="lower")) for q in (0.5, 0.95))
            dev = np.array([f["max_dev"] for _, f in pairs]) * 1e9
            by_fault[f"{ctl} | {fault}"] = {
                "controller": ctl,
                "fault": fault,
                "runs": len(pairs),
                "rejected_samples": int(sum(f["rejected_samples"] for _, f in pairs)),
                "recovered_25ms_runs": int(np.sum(v <= 0.025)),
                "recovery_median_s": q50 if math.isfinite(q50) else None,
                "recovery_p95_s": q95 if math.isfinite(q95) else None,
                "recovery_max_s": None if len(done) < len(rec) else float(max(done)),
                "not_recovered_runs": len(rec) - len(done),
                "added_saturated_steps": int(
                    sum(max(0, f["saturated_steps"] - c["saturated_steps"]) for c, f in pairs)
                ),
                "runs_with_added_saturation": int(
                    sum(f["saturated_steps"] > c["saturated_steps"] for c, f in pairs)
                ),
                "max_dev_median_nm": float(np.median(dev)),
                "max_dev_nm": float(dev.max()),
                "lost_sync_runs": int(sum(f["lost_sync"] for _, f in pairs)),
            }
    return {"by_case": by_case, "by_fault": by_fault}


def make_claims(tables, results, nseeds, duration, design_report) -> list[dict]:
    nonfinite = sum(not f["finite_commands"] for res in results for f in res.values())
    bf = tables["by_fault"]
    runs_per_ctl = len(results) // len(CONTROLLERS)
    rej = {
        fault: [bf[f"{c} | {fault}"]["rejected_samples"] for c in CONTROLLERS]
        for fault in FAULTS[1:]
    }
    counted = all(v == runs_per_ctl for f in ("NaN", "spike 1 mm") for v in rej[f])
    rows = [
        claim(
            "robustness-no-nan-propagated",
            "No controller propagates a bad metrology sample: a NaN or a 1 mm spike is "
            "rejected and counted in the run's metrics, and every command stays finite.",
            "Not in the thesis: qpcoord's robustness study",
            f"{nonfinite} runs with a non-finite command of "
            f"{sum(len(res) for res in results)}; rejected samples per controller "
            f"(designed coordinator, LQR, MPC): NaN {rej['NaN']}, spike {rej['spike 1 mm']}, "
            f"frozen {rej['frozen 50 ms']}, dropped {rej['dropped']} over {runs_per_ctl} "
            "runs each",
            "not in thesis",
            "Our own check. Criterion: 0 non-finite commands and exactly one rejected sample "
            "per NaN or spike run — "
            + ("met" if nonfinite == 0 and counted else "NOT met")
            + ". A frozen or repeated reading is a possible value: not rejected by design.",
        )
    ]
    bc = tables["by_case"]
    d = [bc[f"designed coordinator | {c}"] for c in CASES]
    worst = max(d, key=lambda x: x["rmse_max_nm"])
    sat = sum(x["saturated_steps"] for x in d)
    lost = sum(x["lost_sync_runs"] for x in d)
    full = nseeds >= 20 and duration >= 2.0
    ok = worst["rmse_max_nm"] < SPEC_RMSE * 1e9 and sat == 0 and lost == 0
    rows.append(
        claim(
            "robustness-designed-coordinator-mismatch",
            "The coordinator designed for the sky on the nominal plant keeps RMSE < 70 nm, "
            "no saturated step and synchronism with any one of piezo gain, carriage mass, "
            "flexure stiffness or stepper torque 20 % off.",
            "Not in the thesis: qpcoord's robustness study (spec §6.1.2: < 70 nm)",
            f"worst RMSE {worst['rmse_max_nm']:.1f} nm ({worst['case']}); {sat} saturated "
            f"steps, {lost} runs with lost sync over {sum(x['runs'] for x in d)} fault-free "
            f"runs ({nseeds} seeds × {duration:g} s); designed tuning: coarse "
            f"{design_report.coarse_bandwidth:g} Hz, filter {design_report.coarse_cutoff:g} Hz, "
            f"PI {design_report.fine_kp:g} / 2π·{design_report.fine_ki / (2 * math.pi):.4g}",
            "not in thesis",
            "Our own check. Criterion: every run < 70 nm, 0 saturated steps, no lost sync — "
            + ("met" if ok else "NOT met")
            + (
                ""
                if full
                else f". This run ({nseeds} seed(s) × {duration:g} s) is shorter than the "
                "20 × 2 s study that decides it"
            )
            + ".",
        )
    )
    rec = []
    for c in CONTROLLERS:
        parts = []
        for fault in FAULTS[1:]:
            row = bf[f"{c} | {fault}"]
            parts.append(
                f"{fault} {row['recovered_25ms_runs']}/{row['runs']} within 25 ms "
                f"(median {_ms(row['recovery_median_s'])} ms)"
            )
        rec.append(f"{c}: " + ", ".join(parts))
    rows.append(
        claim(
            "robustness-fault-recovery",
            "After one metrology fault the error returns to its fault-free level.",
            "Not in the thesis: qpcoord's robustness study",
            "runs recovered within 25 ms of the fault, over plants × seeds — " + "; ".join(rec),
            "not in thesis",
            "Our own measurement (protocol of docs/ch6.md, 'Measurement faults': every "
            "trailing 5 ms window within 10 % + 1.25 nm of the fault-free run's RMSE). "
            "Reported, not a pass/fail criterion: a frozen sensor is invisible to the guard, and "
            "the criterion also flags late, nm-level differences between two runs of a "
            "nonlinear loop (see docs/ch6.md).",
        )
    )
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="1 seed × 0.3 s (CI)")
    p.add_argument("--out", type=Path, default=Path("out/ch6_robustness"))
    p.add_argument("--seeds", type=int, default=None, help="number of seeds (default 20)")
    p.add_argument("--duration", type=float, default=None, help="run length, s (default 2)")
    p.add_argument("--n-jobs", type=int, default=1, help="worker processes (default 1)")
    p.add_argument("--progress", action="store_true", help="tqdm bar on stderr")
    args = p.parse_args(argv)
    log = TextLog()
    say = log.say
    duration = args.duration or (0.3 if args.quick else 2.0)
    nseeds = args.seeds or (1 if args.quick else 20)
    t0 = time.perf_counter()

    record = ddl.kolmogorov_opd(2.0, FS, seed=DESIGN_SEED, preset=PRESET)
    ctl, rep = ddl.design_coordinator(record, FS)
    design = {
        "coarse_bandwidth": ctl.coarse_bandwidth,
        "coarse_cutoff": ctl.coarse_cutoff,
        "fine_kp": ctl.fine_kp,
        "fine_ki": ctl.fine_ki,
    }
    say(f"design_coordinator on one 2-s {PRESET} record (seed {DESIGN_SEED}):")
    for line in rep.summary().splitlines():
        say("  " + line)

    points = grid(
        controller=list(CONTROLLERS),
        case=list(CASES),
        seed=seeds(nseeds, root=17),
        duration=[duration],
        design=[design],
    )
    say(
        f"\n{len(CONTROLLERS)} controllers × {len(CASES)} plants × {nseeds} seeds × "
        f"{len(FAULTS)} fault variants = {len(points) * len(FAULTS)} runs of {duration:g} s "
        f"at {FS:.0f} Hz, fault at {duration / 2:g} s; controllers designed on the nominal plant"
    )
    backend = "serial" if args.n_jobs == 1 else "processes"
    results = sweep(run_point, points, backend=backend, n_jobs=args.n_jobs, progress=args.progress)
    bad = [
        (pt["controller"], pt["case"], f)
        for pt, res in zip(points, results, strict=True)
        for f, row in res.items()
        if not row["finite_commands"]
    ]
    tables = summarise(points, results)

    say("\nFault-free runs, per plant (RMSE median (max) over seeds; saturated steps total):")
    say(
        f"{'controller':21s} {'plant':24s} {'RMSE nm':>16s} {'sat.':>6s} {'margin µm':>9s} "
        f"{'lost sync':>9s}"
    )
    for row in tables["by_case"].values():
        say(
            f"{row['controller']:21s} {row['case']:24s} "
            f"{row['rmse_median_nm']:7.1f} ({row['rmse_max_nm']:6.1f}) "
            f"{row['saturated_steps']:6d} {row['margin_min_um']:9.2f} {row['lost_sync_runs']:9d}"
        )
    say(
        "\nFaults, over all plants × seeds: rejected samples; runs recovered within 25 ms; "
        "recovery median / 95th percentile / max, ms ('never' = still outside at the end); "
        "added saturated steps vs the fault-free run; max |e − e_fault-free| median / max:"
    )
    say(
        f"{'controller':21s} {'fault':13s} {'rejected':>8s} {'<=25ms':>7s} "
        f"{'recovery ms':>22s} {'not rec.':>8s} {'+sat.':>6s} {'max dev nm':>17s} {'lost':>4s}"
    )
    for row in tables["by_fault"].values():
        rec = (
            f"{_ms(row['recovery_median_s'])} / {_ms(row['recovery_p95_s'])} / "
            f"{_ms(row['recovery_max_s'])}"
        )
        dev = f"{row['max_dev_median_nm']:.1f} / {row['max_dev_nm']:.1f}"
        say(
            f"{row['controller']:21s} {row['fault']:13s} {row['rejected_samples']:8d} "
            f"{row['recovered_25ms_runs']:4d}/{row['runs']:<3d}{rec:>22s} "
            f"{row['not_recovered_runs']:8d} {row['added_saturated_steps']:6d} {dev:>17s} "
            f"{row['lost_sync_runs']:4d}"
        )
    wall = time.perf_counter() - t0
    say(f"\nwall time {wall:.1f} s")
    if bad:
        say(f"NON-FINITE COMMANDS in {len(bad)} runs, e.g. {bad[0]}")

    claims = make_claims(tables, results, nseeds, duration, rep)

    try:
        from qpcoord.studies.figures import _pyplot, save
    except ImportError:  # pragma: no cover
        say("matplotlib not installed: figure skipped")
    else:
        plt = _pyplot()
        fig, ax = plt.subplots(1, 2, figsize=(12, 4.2))
        for j, c in enumerate(CONTROLLERS):
            for k, case in enumerate(CASES):
                v = [
                    res["none"]["rmse"] * 1e9
                    for pt, res in zip(points, results, strict=True)
                    if pt["controller"] == c and pt["case"] == case
                ]
                x = k + 0.25 * (j - 1) + np.linspace(-0.05, 0.05, len(v))
                ax[0].plot(x, v, "o", ms=2.5, color=f"C{j}", label=c if k == 0 else None)
            for k, fault in enumerate(FAULTS[1:]):
                v = [
                    res[fault]["recovery"]
                    for pt, res in zip(points, results, strict=True)
                    if pt["controller"] == c
                ]
                v = [duration / 2 if x is None else x for x in v]
                x = k + 0.25 * (j - 1) + np.linspace(-0.05, 0.05, len(v))
                ax[1].plot(
                    x, np.array(v) * 1e3, "o", ms=2.5, color=f"C{j}", label=c if k == 0 else None
                )
        ax[0].axhline(SPEC_RMSE * 1e9, color="C3", ls=":", lw=1, label="spec 70 nm")
        ax[0].set_xticks(range(len(CASES)), list(CASES), rotation=30, ha="right", fontsize=7)
        ax[0].set_yscale("log")
        ax[0].set_ylabel("RMSE, fault-free (nm)")
        ax[0].legend(fontsize=7)
        ax[0].set_title(f"plant mismatch ({nseeds} seeds × {duration:g} s, {PRESET})", fontsize=9)
        ax[1].axhline(duration / 2 * 1e3, color="k", ls=":", lw=1, label="not recovered (end)")
        ax[1].set_xticks(range(len(FAULTS) - 1), list(FAULTS[1:]), fontsize=8)
        ax[1].set_ylabel("recovery time (ms)")
        ax[1].legend(fontsize=7)
        ax[1].set_title("recovery after one metrology fault (all plants)", fontsize=9)
        fig.tight_layout()
        save(fig, args.out / "robustness.png")

    log.write(args.out / "summary.txt")
    write_json(
        args.out / "summary.json",
        {
            "fs_hz": FS,
            "preset": PRESET,
            "duration_s": duration,
            "seeds": nseeds,
            "design": {**design, "summary": rep.summary(), "met": rep.met},
            "cases": {k: {"scaled": v[0], "factor": v[1]} for k, v in CASES.items()},
            "faults": list(FAULTS),
            "tables": tables,
            "nonfinite_runs": len(bad),
            "wall_time_s": wall,
            "runs": [
                {k: v for k, v in pt.items() if k != "design"} | {"results": res}
                for pt, res in zip(points, results, strict=True)
            ],
            "claims": claims,
        },
    )
    print(f"wrote {args.out}")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
