"""Native vs Python+daqp for ``method="weighted"`` and :class:`PersistentQP`.

    python benchmarks/weighted_bench.py                # 3 runs of every scenario (~2 min)
    python benchmarks/weighted_bench.py --quick        # a smoke run
    python benchmarks/weighted_bench.py --mpc          # and the DDL MPC on both engines
    python benchmarks/weighted_bench.py --json rows.json

Scenarios, each run 3 times (``--runs``), the two engines interleaved within a run:

* ``stack n=7`` / ``stack n=30``: the closed-loop chain of ``benchmarks/stack_bench.py``
  (:func:`qpcoord.studies.bench_stack.run_loops`: an end-effector twist, joint-limit rows, a
  posture, speed bounds; the Jacobian changes every step), ``Stack.solve(method="weighted")``
  with the native engine (``solver=None``) against ``solver="daqp"`` (the Python engine), the
  two loops stepped alternately.
* ``persistent n=12`` / ``persistent n=30``: a fixed-matrix stack (tracking, a soft band,
  effort; a hard inequality; a box) whose right-hand sides move every step:
  ``PersistentQP.solve_x`` (timed alone: the tasks' ``update`` calls are not) on the native
  workspace against the daqp workspace, stepped alternately on two copies of the stack.
* with ``--mpc``, ``DDL MPC kolmogorov`` / ``DDL MPC step``: the 8 kHz MPC of
  ``benchmarks/mpc_bench.py`` (``method="weighted"``, the parametric path with its
  critical-region cache) on the 250 Hz Kolmogorov case and on a 5 mm step, whole runs
  alternating between the engines (``MPC.solve_times``: state update + QP).

One BLAS thread. Times in µs per step: median, p90, p99 of each run and, in the table, the
median over runs with the spread (min–max over runs). This script reports; it asserts nothing.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import io
import json
import sys
import time

import numpy as np
from _table import preamble
from threadpoolctl import threadpool_limits

import qpcoord as qc
from qpcoord.core.persistent import PersistentQP
from qpcoord.studies.bench_stack import run_loops


def _stats(us: np.ndarray) -> dict:
    return {
        "median_us": float(np.percentile(us, 50)),
        "p90_us": float(np.percentile(us, 90)),
        "p99_us": float(np.percentile(us, 99)),
    }


def stack_runs(n: int, steps: int) -> dict:
    """One interleaved run of the stack-bench loop, native vs daqp."""
    rows = run_loops(n, [("weighted", None), ("weighted", "daqp")], steps)
    out = {}
    for row, engine in zip(rows, ("native", "python+daqp"), strict=True):
        out[engine] = {k: row[k] for k in ("median_us", "p90_us", "p99_us")}
        out[engine]["failures"] = row["failures"]
    return out


def _fixed_stack(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    m = max(6, n // 2)
    track = qc.Equality(rng.standard_normal((m, n)), np.zeros(m), weight=2.0, name="track")
    soft = qc.Inequality(rng.standard_normal((4, n)) / np.sqrt(n), -0.3, 0.3, name="band")
    effort = qc.Equality(np.eye(n), np.zeros(n), name="effort")
    hard = qc.Inequality(rng.standard_normal((2, n)) / np.sqrt(n), -1.0, 1.0, name="hard")
    s = qc.Stack(
        [track, soft, effort],
        bounds=qc.Bounds(-np.ones(n), np.ones(n)),
        constraints=[hard],
        weight_ratio=1e-2,
    )
    return s, track, effort


def persistent_run(n: int, steps: int) -> dict:
    """One interleaved run of two PersistentQP workspaces (native, daqp) on twin stacks."""
    loops = []
    for engine in ("native", "python"):
        s, track, effort = _fixed_stack(n)
        loops.append((engine, PersistentQP(s, engine=engine), track, effort))
    times = {e: np.empty(steps) for e, *_ in loops}
    worst = 0.0
    rng = np.random.default_rng(1)
    m = loops[0][2].b.shape[0]
    with threadpool_limits(limits=1):
        gc.collect()
        for k in range(steps):
            bt = 2.0 * np.sin(0.01 * k + np.arange(m))
            be = 0.1 * rng.standard_normal(n)
            xs = []
            order = loops if k % 2 == 0 else loops[::-1]
            for engine, pq, track, effort in order:
                track.update(b=bt)  # the tasks' updates (validation) are not timed
                effort.update(b=be)
                t0 = time.perf_counter()
                xs.append(pq.solve_x())
                times[engine][k] = time.perf_counter() - t0
            worst = max(worst, float(np.max(np.abs(xs[0] - xs[1]))))
    out = {("python+daqp" if e == "python" else e): _stats(t * 1e6) for e, t in times.items()}
    out["native"]["max_dx_vs_daqp"] = worst
    out["native"]["fallbacks"] = loops[0][1].fallbacks
    return out


def mpc_run(steps: int, case: str) -> dict:
    """One DDL MPC run per engine (the engines alternate between runs)."""
    import qpcoord.ddl as ddl
    from qpcoord.ddl import mpc as mpc_mod

    fs = 8000.0
    out = {}
    keep = mpc_mod.PersistentQP
    try:
        for engine in ("native", "python"):
            mpc_mod.PersistentQP = lambda stack, e=engine: keep(stack, engine=e)
            if case == "kolmogorov":
                r = ddl.kolmogorov_opd(steps / fs, fs, seed=0, preset="paranal_250hz")
            else:  # a 5 mm step: stroke margin and synchronism rate active
                r = ddl.references.fig619_steps(steps / fs, fs)["centre"]
            mpc = mpc_mod.MPC(method="weighted")
            with threadpool_limits(limits=1):
                gc.collect()
                ddl.simulate(ddl.DualStage(), mpc, r, fs)
            row = _stats(np.array(mpc.solve_times) * 1e6)
            row.update(
                region_steps=int(mpc._pq.region_steps),
                qp_steps=int(mpc._pq.qp_steps),
                fallbacks=int(mpc.fallback_steps),
            )
            out["python+daqp" if engine == "python" else engine] = row
    finally:
        mpc_mod.PersistentQP = keep
    return out


def table(results: dict) -> str:
    lines = [
        "| scenario | engine | median µs | p90 µs | p99 µs | notes |",
        "|---|---|---:|---:|---:|---|",
    ]
    for scen, runs in results.items():
        for engine in ("native", "python+daqp"):
            rs = [r[engine] for r in runs]
            med = [r["median_us"] for r in rs]
            p90 = [r["p90_us"] for r in rs]
            p99 = [r["p99_us"] for r in rs]

            def cell(v):
                return f"{np.median(v):.1f} ({min(v):.1f}–{max(v):.1f})"

            notes = []
            for key in ("max_dx_vs_daqp", "region_steps", "qp_steps", "fallbacks", "failures"):
                if key in rs[0]:
                    vals = [r[key] for r in rs]
                    v = max(vals)
                    notes.append(f"{key} {v:.2g}" if isinstance(v, float) else f"{key} {v}")
            lines.append(
                f"| {scen} | {engine} | {cell(med)} | {cell(p90)} | {cell(p99)} | "
                f"{'; '.join(notes)} |"
            )
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smoke run (few steps, 1 run)")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--steps", type=int, default=2000, help="steps per stack/persistent loop")
    ap.add_argument(
        "--mpc",
        action="store_true",
        help="also the DDL MPC of mpc_bench.py (Kolmogorov case, 5 mm step) on both engines",
    )
    ap.add_argument("--mpc-steps", type=int, default=8000, help="DDL MPC steps per run")
    ap.add_argument("--json", metavar="FILE")
    args = ap.parse_args(argv)
    runs, steps, mpc_steps = args.runs, args.steps, args.mpc_steps
    if args.quick:
        runs, steps, mpc_steps = 1, 50, 400
    results: dict = {}
    for _ in range(runs):
        for n in (7, 30):
            with contextlib.redirect_stdout(io.StringIO()):
                results.setdefault(f"stack n={n}", []).append(stack_runs(n, steps))
        for n in (12, 30):
            results.setdefault(f"persistent n={n}", []).append(persistent_run(n, steps))
        for case in ("kolmogorov", "step") if args.mpc else ():
            results.setdefault(f"DDL MPC {case}", []).append(mpc_run(mpc_steps, case))
    print(preamble())
    print(
        f"{runs} run(s), {steps} steps per loop"
        + (f", {mpc_steps} MPC steps" if args.mpc else "")
        + "; one BLAS thread; "
        "cells: the median over the runs (min–max):\n"
    )
    print(table(results))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
