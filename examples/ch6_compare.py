"""Chapter 6, Tables 6.1–6.2 and Fig 6.18: the coordinator against LQR, PQ (and the MPC).

Runs :func:`qpcoord.ddl.compare.compare` on the thesis coordinator (``SisoCoordinator``), the
discrete LQR with integral action and Kalman observer (``LQR``), the PQ-method design
(``PQ``), the prioritised-stack ``MPC`` and the PI-linearised and flatness-based coarse
controls (:func:`qpcoord.ddl.compare.default_controllers`), all with default arguments, on the
same cases: the ``paranal_250hz`` Kolmogorov OPD (one realisation per seed), the two 5 mm
steps of Fig 6.19, the Kolmogorov reference on a plant ±20 % off in piezo gain, flexure
stiffness and friction (controllers designed on the nominal plant) and, beyond the thesis,
with two periods of command latency (``latency2``). Writes the Table 6.1-style
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
    compare,
    default_controllers,
    format_grid,
    format_table,
    qualitative_grid,
)
from qpcoord.report import TextLog, write_json

FS = 8000.0


def _clean(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {str(k): _clean(x) for k, x in v.items()}
    if isinstance(v, (np.floating, np.integer)):
        return _clean(v.item())
    return v


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="short runs (CI, < 30 s)")
    p.add_argument("--seeds", type=int, default=None, help="number of Kolmogorov seeds")
    p.add_argument("--out", type=Path, default=Path("out/ch6_compare"))
    args = p.parse_args(argv)
    log = TextLog()
    say = log.say
    duration, step_duration = (1.0, 3.0) if args.quick else (10.0, 6.0)
    nseeds = args.seeds if args.seeds is not None else (1 if args.quick else 3)
    seeds = tuple(range(nseeds))
    ctls = default_controllers()
    say(
        f"DDL comparison at {FS:.0f} Hz: {', '.join(ctls)}; Kolmogorov {duration:g} s × "
        f"{nseeds} seed(s), steps {step_duration:g} s, mismatch ±20 %, latency 2 periods"
    )
    rows = compare(
        ctls,
        seeds=seeds,
        duration=duration,
        fs=FS,
        step_duration=step_duration,
        keep_runs=True,
    )
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
    rep = {"LQR": lq.report(), "PQ": pq.report()}
    say("LQR design: " + ", ".join(f"{k} {v:.4g}" for k, v in rep["LQR"].items()))
    say(
        "PQ design: "
        + ", ".join(f"{k} {v:.4g}" for k, v in rep["PQ"].items() if not isinstance(v, dict))
    )
    say(
        "PQ coarse share |PQ/(1+PQ)|: "
        + ", ".join(f"{f:g} Hz {s:.3f}" for f, s in rep["PQ"]["coarse_share"].items())
    )
    # figures
    try:
        from qpcoord.figures import _pyplot, save
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
    }
    write_json(args.out / "summary.json", summary)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
