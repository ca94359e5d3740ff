"""Per-step time of the DDL MPC (state update + QP) at 8 kHz: the 125 µs budget.

    python benchmarks/mpc_bench.py              # 20 000 steps each (2.5 s of control)
    python benchmarks/mpc_bench.py --quick      # 2 000 steps
    python benchmarks/mpc_bench.py --json rows.json

For each method (``weighted`` on the persistent daqp workspace, ``hierarchical`` through
``Stack.solve``) the MPC runs closed loop on the 250 Hz Kolmogorov preset and on a 5 mm step
(constraints active: stroke margin and synchronism rate), and ``MPC.step`` is timed on every
call (``MPC.solve_times``). BLAS is limited to one thread. The table reports median, p99 and
max per step, the share of steps over 125 µs, and the run's RMSE and fallback steps. This
script reports; it asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys

import numpy as np
from threadpoolctl import threadpool_limits

import qpcoord.ddl as ddl
from qpcoord.ddl.mpc import MPC

FS = 8000.0
BUDGET = 125e-6


def run_case(method: str, case: str, steps: int) -> dict:
    duration = steps / FS
    if case == "kolmogorov":
        r = ddl.kolmogorov_opd(duration, FS, seed=0, preset="paranal_250hz")
    else:
        r = ddl.references.fig619_steps(duration, FS)["centre"]
    mpc = MPC(method=method)
    run = ddl.simulate(ddl.DualStage(), mpc, r, FS)
    t = np.array(mpc.solve_times)
    return {
        "method": method,
        "case": case,
        "steps": int(t.size),
        "median_us": float(np.median(t) * 1e6),
        "p99_us": float(np.percentile(t, 99) * 1e6),
        "max_us": float(t.max() * 1e6),
        "over_budget": float(np.mean(t > BUDGET)),
        "rmse_nm": float(run.metrics["rmse"] * 1e9),
        "saturated_steps": int(run.metrics["saturated_steps"]),
        "fallback_steps": int(mpc.fallback_steps),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--json", default=None, help="also write the rows to this file")
    args = ap.parse_args(argv)
    steps = 2000 if args.quick else args.steps
    rows = []
    with threadpool_limits(limits=1):
        for method in ("weighted", "hierarchical"):
            for case in ("kolmogorov", "step 5 mm"):
                n = steps if method == "weighted" else max(steps // 10, 500)
                rows.append(run_case(method, case, n))
    print(f"python {platform.python_version()} on {platform.machine()}, {sys.platform}")
    head = (
        f"{'method':<13} {'case':<11} {'steps':>6} {'median µs':>10} {'p99 µs':>8} "
        f"{'max µs':>8} {'>125µs':>7} {'RMSE nm':>9} {'sat':>4} {'fallb':>5}"
    )
    print(head)
    print("-" * len(head))
    for r in rows:
        print(
            f"{r['method']:<13} {r['case']:<11} {r['steps']:>6} {r['median_us']:>10.1f} "
            f"{r['p99_us']:>8.1f} {r['max_us']:>8.0f} {100 * r['over_budget']:>6.2f}% "
            f"{r['rmse_nm']:>9.1f} {r['saturated_steps']:>4} {r['fallback_steps']:>5}"
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
