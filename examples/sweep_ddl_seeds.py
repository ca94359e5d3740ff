"""Sweep: the DDL coordinator over seeds × plant mismatch, serial vs worker processes.

A study of the kind run by the thousand, written with ``qpcoord.studies.sweep``: the thesis
coordinator (``SisoCoordinator``, designed on and initialised from the nominal PRIMA plant, as
``qpcoord.ddl.compare.DesignedOn``) tracks the ``paranal_250hz`` Kolmogorov OPD at 8 kHz on
plants that are off nominal — piezo gain alone ±20 %, or piezo gain, flexure stiffness and
friction all ±20 % (``qpcoord.ddl.compare.mismatched_plant``, the ``mismatch±`` cases of
``ch6_compare.py``) — for independent seeds from ``qpcoord.studies.sweep.seeds``. The grid
seed × case runs with ``sweep(..., backend="processes")``, then again serially: the results
must be equal bit for bit, and the wall times give the parallel speed-up on this machine
(reported, not asserted; ``--dask`` also times a 2-worker Dask ``LocalCluster``).

Table: RMSE per case, median / min / max over seeds. Thesis Table 6.1 (hardware, direct
coil): 25 nm RMSE on the nominal plant; spec §6.1.2: < 70 nm.

Run: ``python examples/sweep_ddl_seeds.py [--quick] [--out DIR] [--seeds N] [--n-jobs N]
[--dask] [--progress]`` (default 10 s × 6 seeds × 5 cases; ``--quick``: 0.5 s × 2 seeds).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from pathlib import Path

import numpy as np

import qpcoord.ddl as ddl
from qpcoord.ddl.compare import DesignedOn, mismatched_plant
from qpcoord.studies.claims import QUICK, claim
from qpcoord.studies.files import TextLog, write_json
from qpcoord.studies.sweep import grid, seeds, sweep

FS = 8000.0
#: Plant cases: name -> (what is scaled, factor).
CASES = {
    "nominal": ("none", 1.0),
    "piezo gain +20 %": ("piezo", 1.2),
    "piezo gain -20 %": ("piezo", 0.8),
    "all +20 %": ("all", 1.2),
    "all -20 %": ("all", 0.8),
}
THESIS_RMSE_NM = 25.0  # Table 6.1, direct coil (hardware)
SPEC_RMSE_NM = 70.0  # §6.1.2


def make_plant(case: str) -> ddl.DualStage:
    """The true (simulated) plant of a case; the controller always sees the nominal one."""
    what, factor = CASES[case]
    if what == "none":
        return ddl.DualStage()
    if what == "all":
        return mismatched_plant(factor)
    base = ddl.DualStage()
    fine = dataclasses.replace(base.fine, gain=base.fine.gain * factor)
    return ddl.DualStage(fine, base.stepper, base.flexure)


def run_point(seed: int, case: str, duration: float) -> dict:
    """One closed-loop run: the Table 6.1 metrics (SI units) of ``case`` with ``seed``."""
    r = ddl.kolmogorov_opd(duration, FS, seed=seed, preset="paranal_250hz")
    controller = DesignedOn(ddl.SisoCoordinator(), ddl.DualStage())
    m = ddl.simulate(make_plant(case), controller, r, FS, seed=seed).metrics
    keys = ("rmse", "max_abs", "mean_abs", "power", "fine_margin_min", "saturated_steps")
    out = {k: m[k] for k in keys}
    out["lost_sync"] = bool(m["lost_sync"])
    return out


def timed(label: str, fn, times: dict):
    t0 = time.perf_counter()
    out = fn()
    times[label] = time.perf_counter() - t0
    return out


def run_dask(points: list, n_jobs: int, times: dict):
    """The same sweep on a fresh 2-process Dask LocalCluster (start-up timed separately)."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        return None
    t0 = time.perf_counter()
    with (
        LocalCluster(
            n_workers=n_jobs, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as cluster,
        Client(cluster) as client,
    ):
        times["dask cluster start-up"] = time.perf_counter() - t0
        return timed("dask", lambda: sweep(run_point, points, backend=client), times)


def rmse_table(points: list, results: list, nseeds: int) -> dict:
    table = {}
    for case in CASES:
        v = np.array(
            [res["rmse"] for p, res in zip(points, results, strict=True) if p["case"] == case]
        )
        v = v * 1e9
        table[case] = {
            "median": float(np.median(v)),
            "min": float(v.min()),
            "max": float(v.max()),
            "n": int(v.size),
        }
    assert all(row["n"] == nseeds for row in table.values())
    return table


def make_claims(table, results, times, identical, duration, nseeds, n_jobs) -> list[dict]:
    full = duration >= 10.0 and nseeds >= 3
    short = (
        f" This run ({duration:g} s × {nseeds} seeds) is shorter than the thesis's 10 s "
        "Kolmogorov runs: the full run (10 s × 6 seeds) decides this row."
    )
    nominal = table["nominal"]
    ok = abs(nominal["median"] - THESIS_RMSE_NM) <= 0.3 * THESIS_RMSE_NM
    st = ("reproduced" if ok else "differs") if full else QUICK
    rows = [
        claim(
            "table6.1-rmse-nominal",
            "Direct-coil coordinator RMSE on Kolmogorov tracking is 25 nm.",
            "Table 6.1, Direct Coil: RMSE 25 nm (hardware)",
            f"{nominal['median']:.1f} nm median ({nominal['min']:.1f}–{nominal['max']:.1f} nm)"
            f" over {nseeds} seeds (nominal plant)",
            st,
            "Criterion: median within ±30 % of 25 nm (as ch6_tracking.py). Simulation on the "
            "paranal_250hz preset."
            + (" The median is outside ±30 % of 25 nm." if st == "differs" else "")
            + (short if st == QUICK else ""),
        )
    ]
    worst_case = max(table, key=lambda c: table[c]["max"])
    worst = table[worst_case]["max"]
    ratio = max(table[c]["median"] for c in CASES) / nominal["median"]
    sat = sum(r["saturated_steps"] for r in results)
    lost = sum(r["lost_sync"] for r in results)
    rows.append(
        claim(
            "sweep-mismatch-robustness",
            "Designed on the nominal plant, the coordinator keeps the RMSE below the 70 nm "
            "spec on plants with piezo gain (alone, or with flexure stiffness and friction) "
            "±20 % off.",
            "Not in the thesis: §6.1.2 sets the 70 nm spec for the nominal system only",
            f"worst RMSE {worst:.1f} nm ({worst_case}); worst median / nominal median "
            f"{ratio:.2f}; {sat} saturated steps, {lost} runs with lost sync, over "
            f"{len(results)} runs",
            "not in thesis",
            "Our study. Criterion we would use: every run < 70 nm, no fine saturation, no "
            f"lost sync — {'met' if worst < SPEC_RMSE_NM and not sat and not lost else 'not met'}"
            " here.",
        )
    )
    speed = times["serial"] / times["processes"]
    rows.append(
        claim(
            "sweep-processes-deterministic",
            "A sweep over worker processes returns the serial results, bit for bit, in input "
            "order.",
            "Not in the thesis: a property of qpcoord.studies.sweep",
            f"identical: {identical}; serial {times['serial']:.2f} s, processes "
            f"{times['processes']:.2f} s with {n_jobs} workers (×{speed:.2f}; "
            f"{times['processes (cold)']:.2f} s when starting the workers)",
            "not in thesis",
            f"Wall times are of this machine and its load (1-min load average "
            f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores at the end of the run); the "
            "speed-up is reported, not asserted.",
        )
    )
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="0.5 s runs, 2 seeds (CI)")
    p.add_argument("--out", type=Path, default=Path("out/sweep_ddl_seeds"))
    p.add_argument("--seeds", type=int, default=None, help="number of seeds (default 6)")
    p.add_argument("--duration", type=float, default=None, help="run length, s (default 10)")
    p.add_argument("--n-jobs", type=int, default=None, help="worker processes (default: cores)")
    p.add_argument("--dask", action="store_true", help="also time a Dask LocalCluster")
    p.add_argument("--progress", action="store_true", help="tqdm bars on stderr")
    args = p.parse_args(argv)
    log = TextLog()
    say = log.say
    duration = args.duration or (0.5 if args.quick else 10.0)
    nseeds = args.seeds or (2 if args.quick else 6)
    n_jobs = args.n_jobs or len(os.sched_getaffinity(0))

    points = grid(seed=seeds(nseeds, root=2026), case=list(CASES), duration=[duration])
    say(
        f"SisoCoordinator designed on the nominal plant, paranal_250hz, {duration:g} s at "
        f"{FS:.0f} Hz: {nseeds} seeds × {len(CASES)} cases = {len(points)} runs"
    )
    times: dict[str, float] = {}

    def parallel():
        return sweep(run_point, points, backend="processes", n_jobs=n_jobs, progress=args.progress)

    results = timed("processes (cold)", parallel, times)  # includes starting the workers
    serial = timed(
        "serial", lambda: sweep(run_point, points, backend="serial", progress=args.progress), times
    )
    warm = timed("processes", parallel, times)  # joblib's reusable pool: workers are up
    identical = serial == results == warm
    dask_results = run_dask(points, min(n_jobs, 2), times) if args.dask else None
    if dask_results is not None:
        identical = identical and dask_results == results

    table = rmse_table(points, results, nseeds)
    say(f"\n{'case':18s} {'median nm':>9s} {'min nm':>7s} {'max nm':>7s}")
    for case, row in table.items():
        say(f"{case:18s} {row['median']:9.1f} {row['min']:7.1f} {row['max']:7.1f}")
    say(f"thesis Table 6.1 (hardware, direct coil, nominal): {THESIS_RMSE_NM:g} nm; spec < 70 nm")
    load = os.getloadavg()[0]
    say(
        f"\nwall time on {os.cpu_count()} cores, {n_jobs} workers, load average {load:.1f} "
        "(cold: includes start-up):"
    )
    for label, t in times.items():
        say(f"  {label:22s} {t:7.2f} s")
    say(f"  serial / processes     ×{times['serial'] / times['processes']:.2f} (warm pool)")
    say(f"  serial / processes     ×{times['serial'] / times['processes (cold)']:.2f} (cold)")
    if "dask" in times:
        say(f"  serial / dask          ×{times['serial'] / times['dask']:.2f}")
    say(f"results identical across backends (bit for bit): {identical}")
    if not identical:
        raise SystemExit("sweep backends disagree: results are not deterministic")

    claims = make_claims(table, results, times, identical, duration, nseeds, n_jobs)

    try:
        from qpcoord.studies.figures import _pyplot, save
    except ImportError:  # pragma: no cover
        say("matplotlib not installed: figure skipped")
    else:
        plt = _pyplot()
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.8), gridspec_kw={"width_ratios": [2, 1.2]})
        for k, case in enumerate(CASES):
            v = [
                res["rmse"] * 1e9
                for pt, res in zip(points, results, strict=True)
                if pt["case"] == case
            ]
            jitter = np.linspace(-0.15, 0.15, len(v)) if len(v) > 1 else [0.0]
            ax[0].plot(k + np.asarray(jitter), v, "o", ms=3, alpha=0.6, color="C0")
            ax[0].plot([k - 0.25, k + 0.25], [np.median(v)] * 2, "k-", lw=2)
        ax[0].axhline(THESIS_RMSE_NM, color="C2", ls="--", lw=1, label="thesis Table 6.1: 25 nm")
        ax[0].axhline(SPEC_RMSE_NM, color="C3", ls=":", lw=1, label="spec: 70 nm")
        ax[0].set_xticks(range(len(CASES)), list(CASES), rotation=15, fontsize=8)
        ax[0].set_ylabel("RMSE (nm)")
        ax[0].set_ylim(bottom=0)
        ax[0].legend(fontsize=7)
        ax[0].set_title(f"coordinator on mismatched plants ({nseeds} seeds × {duration:g} s)")
        labels = [k for k in ("serial", "processes (cold)", "processes", "dask") if k in times]
        ticks = {"processes (cold)": "processes\n(cold)", "processes": "processes\n(warm)"}
        colors = ["C7", "C0", "C0", "C1"][: len(labels)]
        ax[1].bar(range(len(labels)), [times[k] for k in labels], color=colors)
        ax[1].set_xticks(range(len(labels)), [ticks.get(k, k) for k in labels], fontsize=8)
        ax[1].set_ylabel("wall time (s)")
        ax[1].set_title(f"{len(points)} runs, {n_jobs} workers, load {load:.1f}", fontsize=10)
        save(fig, args.out / "sweep_ddl_seeds.png")

    log.write(args.out / "summary.txt")
    write_json(
        args.out / "summary.json",
        {
            "fs_hz": FS,
            "duration_s": duration,
            "seeds": nseeds,
            "cases": {k: {"scaled": v[0], "factor": v[1]} for k, v in CASES.items()},
            "n_jobs": n_jobs,
            "rmse_nm": table,
            "wall_time_s": times,
            "load_average_1min": load,
            "speedup_serial_over_processes": times["serial"] / times["processes"],
            "speedup_serial_over_processes_cold": times["serial"] / times["processes (cold)"],
            "identical_across_backends": identical,
            "runs": [{**pt, **res} for pt, res in zip(points, results, strict=True)],
            "claims": claims,
        },
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
