"""Per-step time of the DDL MPC (state update + QP) at 8 kHz: the 125 µs budget.

    python benchmarks/mpc_bench.py              # 20 000 steps each (2.5 s of control)
    python benchmarks/mpc_bench.py --quick      # 2 000 steps
    python benchmarks/mpc_bench.py --backends   # and the MPC's QPs through every backend
    python benchmarks/mpc_bench.py --json rows.json

For each method (``weighted`` on the persistent daqp workspace, ``hierarchical`` through
``Stack.solve``) the MPC runs closed loop on the 250 Hz Kolmogorov preset and on a 5 mm step
(constraints active: stroke margin and synchronism rate), and ``MPC.step`` is timed on every
call (``MPC.solve_times``). BLAS is limited to one thread. The table reports median, p99 and
max per step, the share of steps over 125 µs, the run's RMSE and fallback steps, and how
many steps a cached critical region answered (``PersistentQP.region_steps``) and how many
went to daqp (``qp_steps``). With ``--backends``, a second table solves the MPC's QPs of a
Kolmogorov run with every installed backend through the general
``Stack.solve(method="weighted")`` path (µs per QP, largest cost deviation from the persistent
daqp answer, relative to the cost of not moving). This script reports; it asserts nothing.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
from _table import markdown, preamble
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
        # weighted: steps answered by a cached critical region / by daqp
        "region_steps": int(mpc._pq.region_steps) if mpc._pq is not None else 0,
        "qp_steps": int(mpc._pq.qp_steps) if mpc._pq is not None else int(t.size),
    }


def backend_rows(steps: int, every: int = 20) -> list[dict]:
    """The MPC's weighted QPs of a Kolmogorov run, each also solved by every backend through
    ``Stack.solve(method="weighted")`` (every ``every``-th step): µs per solve and the
    difference of its cost from the persistent daqp answer's, relative to the cost of not
    moving (the optimal costs are ~1e-9 µm², near the regularisation's own size)."""
    import time

    import qpcoord as qc

    r = ddl.kolmogorov_opd(steps / FS, FS, seed=0, preset="paranal_250hz")
    plant = ddl.DualStage()
    y = plant.reset(FS, r[0])
    mpc = MPC()
    mpc.reset(plant, FS, y, r[0])
    rho = mpc.weight_ratio

    def cost(x):
        return float(
            np.sum((mpc.track.A @ x - mpc.track.b) ** 2)
            + rho * np.sum((mpc.centre.A @ x - mpc.centre.b) ** 2)
            + rho**2 * np.sum((mpc.effort.A @ x - mpc.effort.b) ** 2)
        )

    times: dict = {s: [] for s in qc.available_solvers()}
    dev: dict = {s: [] for s in times}
    fails: dict = {s: 0 for s in times}
    for k in range(steps):
        y = plant.step(*mpc.step(y, r[k]))
        if k % every:
            continue
        mpc.sync_tasks()  # the step's QP numbers into the tasks (θ-form otherwise)
        ref = cost(mpc._pq.solve().x)
        scale = max(cost(np.zeros(mpc.stack.n)), 1e-300)  # cost of not moving
        for s in times:
            t0 = time.perf_counter()
            try:
                x = mpc.stack.solve(method="weighted", solver=s).x
            except (RuntimeError, ValueError):
                fails[s] += 1
                continue
            times[s].append(time.perf_counter() - t0)
            dev[s].append(abs(cost(x) - ref) / scale)
    out = []
    for s in times:
        t = np.array(times[s]) if times[s] else np.array([np.nan])
        out.append(
            {
                "solver": s,
                "qps": len(times[s]),
                "failures": fails[s],
                "median_us": float(np.median(t) * 1e6),
                "p99_us": float(np.percentile(t, 99) * 1e6),
                "max_cost_dev": float(max(dev[s])) if dev[s] else float("nan"),
            }
        )
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument(
        "--backends",
        action="store_true",
        help="also the MPC's QPs through Stack.solve(method='weighted') with every backend",
    )
    ap.add_argument("--json", default=None, help="also write the rows to this file")
    args = ap.parse_args(argv)
    steps = 2000 if args.quick else args.steps
    rows = []
    with threadpool_limits(limits=1):
        for method in ("weighted", "hierarchical"):
            for case in ("kolmogorov", "step 5 mm"):
                n = steps if method == "weighted" else max(steps // 10, 500)
                rows.append(run_case(method, case, n))
    print(preamble())
    print("`MPC.step` at 8 kHz in closed loop (goal: p99 ≤ 125 µs, one period):\n")
    head = ("method", "case", "steps", "median µs", "p99 µs", "max µs", "> 125 µs", "RMSE nm")
    head += ("saturated", "fallback", "region", "QP")
    body = [
        (
            r["method"], r["case"], r["steps"], f"{r['median_us']:.1f}", f"{r['p99_us']:.1f}",
            f"{r['max_us']:.0f}", f"{100 * r['over_budget']:.2f}%", f"{r['rmse_nm']:.1f}",
            r["saturated_steps"], r["fallback_steps"], r["region_steps"], r["qp_steps"],
        )
        for r in rows
    ]  # fmt: skip
    print(markdown(head, body, "llrrrrrrrrrr"))
    brows = []
    if args.backends:
        with threadpool_limits(limits=1):
            brows = backend_rows(steps // 5)
        print("\nThe MPC's QPs through `Stack.solve(method='weighted')` with every backend:\n")
        head = ("solver", "QPs", "failures", "median µs", "p99 µs", "max cost dev.")
        body = [
            (b["solver"], b["qps"], b["failures"], f"{b['median_us']:.0f}",
             f"{b['p99_us']:.0f}", f"{b['max_cost_dev']:.1e}")
            for b in brows
        ]  # fmt: skip
        print(markdown(head, body, "lrrrrr"))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"mpc": rows, "backends": brows}, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
