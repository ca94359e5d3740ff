"""Per-step solve time of a 3-level stack (7 and 30 variables), every method and backend.

Thin wrapper around :func:`qpcoord.studies.bench_stack.run_stack_bench` (same as ``qpcoord bench
stack``)::

    python benchmarks/stack_bench.py                 # full run, all installed backends (~1 min)
    python benchmarks/stack_bench.py --quick         # smoke run, a few seconds
    python benchmarks/stack_bench.py --solver daqp --steps 2000 --sizes 7
    python benchmarks/stack_bench.py --profile --solver daqp   # cProfile of the n=7 hot path
    python benchmarks/stack_bench.py --one-shot      # and the one-shot table
    python benchmarks/stack_bench.py --one-shot-only   # only the one-shot table (~20 s)

With ``--one-shot``, after the re-solve table, a **one-shot** table: per step of the same
closed loop, a stack built from scratch and solved once (``qc.solve_stack`` of new tasks and
bounds, both engines) beside the floor, one direct ``daqp.solve`` of the weighted QP of the
same numbers (the soft limits as slack variables; ``H`` and ``f`` formed inside its timer),
with the ratio of each median to the floor's (the goal for the native engine: within 4×).
``oneshot.py`` measures the one-shot call on a fixed problem (the README's one-shot table).

See benchmarks/README.md for the scenario and the measured table.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import pstats
import sys
import time

import numpy as np
from _table import markdown, preamble
from threadpoolctl import threadpool_limits

import qpcoord as qc
from qpcoord.studies.bench_stack import (
    ChainScenario,
    format_table,
    run_loops,
    run_stack_bench,
)

#: the weighted method's default ratio between consecutive levels
WEIGHT_RATIO = 1e-3


def profile(n: int, solver: str, steps: int, top: int = 25) -> str:
    """cProfile of interleaved hierarchical + weighted loops (tottime, top functions).

    The scenario's own kinematics (not timed by the benchmark) is filtered out of the list.
    """
    specs = [("hierarchical", solver), ("weighted", solver)]
    run_loops(n, specs, 2)  # imports and first calls outside the profile
    pr = cProfile.Profile()
    pr.enable()
    rows = run_loops(n, specs, steps)
    pr.disable()
    out = io.StringIO()
    out.write(format_table(rows).split("\n\n")[0] + "\n(times inflated by the profiler)\n\n")
    not_scenario = r"^(?!.*(bench\.py|\(cross\)|moveaxis|normalize_axis_tuple|threadpoolctl))"
    pstats.Stats(pr, stream=out).sort_stats("tottime").print_stats(not_scenario, top)
    return out.getvalue()


def daqp_floor(J, v, dt, lo, hi, pb, dq_max):
    """One direct ``daqp.solve`` of the scenario's weighted QP in ``y = (x, s)``: the twist
    task (weight 1), the joint limits ``lo ≤ dt·x − s ≤ hi`` with the squared slack ``s``
    weighted by ``WEIGHT_RATIO``, the posture (``WEIGHT_RATIO²``; with it ``H`` is positive
    definite, so no regularisation, as qpcoord's weighted method) and the speed bounds as
    daqp's simple bounds on ``x``. Returns ``(x, exit flag)``."""
    import daqp

    n = J.shape[1]
    w1, w2 = WEIGHT_RATIO, WEIGHT_RATIO**2
    H = np.zeros((2 * n, 2 * n))
    H[:n, :n] = J.T @ J
    H[:n, :n].flat[:: n + 1] += w2
    H[n:, n:].flat[:: n + 1] = w1
    f = np.zeros(2 * n)
    f[:n] = -(J.T @ v + w2 * pb)
    A = np.hstack([dt * np.eye(n), -np.eye(n)])
    upper = np.concatenate([dq_max, hi])
    lower = np.concatenate([-dq_max, lo])
    y, _fval, flag, _info = daqp.solve(H, f, A, upper, lower, np.zeros(2 * n, dtype=np.int32))
    return np.asarray(y)[:n], int(flag)


def one_shot(sizes, steps: int, seed: int = 0) -> list[dict]:
    """Per step of the closed loop (driven by the native one-shot's ``x``), in turn: the
    native one-shot, the Python one-shot (default backend) and the daqp floor. Returns one
    row per size and call: median / p90 / p99 (µs, the first 10 % of steps dropped), the
    ratio of its median to the floor's, and the largest difference of the floor's ``x`` to
    qpcoord's weighted method on the same stack (a check that the floor solves that QP)."""
    rows = []
    for n in sizes:
        sc = ChainScenario(n, seed=seed)
        times = {"solve_stack native": [], "solve_stack python": [], "daqp.solve floor": []}
        worst, flags = 0.0, set()
        for k in range(steps):
            J, v, lo, hi, pb = sc.numbers()
            dt, eye, dq = sc.dt, np.eye(n), sc.dq_max
            xs = {}
            for label, engine in (("native", "native"), ("python", "python")):
                t = time.perf_counter()
                xs[label] = qc.solve_stack(
                    [qc.Equality(J, v), qc.Inequality(dt * eye, lo, hi), qc.Equality(eye, pb)],
                    bounds=qc.Bounds(-dq, dq),
                    engine=engine,
                ).x
                times[f"solve_stack {label}"].append(time.perf_counter() - t)
            t = time.perf_counter()
            xd, flag = daqp_floor(J, v, dt, lo, hi, pb, dq)
            times["daqp.solve floor"].append(time.perf_counter() - t)
            flags.add(flag)
            if k % 10 == 0:  # the weighted method on the same stack (outside every timer)
                xw = qc.solve_stack(
                    [qc.Equality(J, v), qc.Inequality(dt * eye, lo, hi), qc.Equality(eye, pb)],
                    bounds=qc.Bounds(-dq, dq),
                    method="weighted",
                    solver="daqp",
                ).x
                worst = max(worst, float(np.max(np.abs(xd - xw))))
            sc.advance(xs["native"])
        us = {key: np.array(ts[steps // 10 :]) * 1e6 for key, ts in times.items()}
        floor = float(np.median(us["daqp.solve floor"]))
        for key, u in us.items():
            rows.append(
                {
                    "n": n,
                    "call": key,
                    "steps": len(u),
                    "median_us": float(np.median(u)),
                    "p90_us": float(np.percentile(u, 90)),
                    "p99_us": float(np.percentile(u, 99)),
                    "ratio_to_floor": float(np.median(u)) / floor,
                    "floor_vs_weighted_max_dx": worst,
                    "daqp_flags": sorted(flags),
                }
            )
    return rows


def format_loops(rows: list[dict]) -> str:
    """Markdown table of :func:`run_stack_bench` rows."""

    def us(v: float, digits: int = 0) -> str:
        return "–" if v != v else f"{v:.{digits}f}"  # nan: no such step

    def share(v: float) -> str:
        return "–" if v != v else f"{100 * v:.0f}%"

    head = ("n", "method", "solver", "steps", "median µs", "p90 µs", "p99 µs", "QP-step med.")
    head += ("QP/step", "QP max", "bounds act.", "limits act.", "fails", "note")
    body = [
        (
            r["n"], r["method"], r["solver"], r["steps"], us(r["median_us"]), us(r["p90_us"]),
            us(r["p99_us"]), us(r.get("qp_step_median_us", float("nan"))),
            us(r["qp_calls_mean"], 2), r["qp_calls_max"], share(r["bounds_active"]),
            share(r["limits_active"]), r["failures"], r.get("note", ""),
        )
        for r in rows
    ]  # fmt: skip
    return markdown(head, body, "rllrrrrrrrrrrl")


def format_one_shot(rows: list[dict]) -> str:
    """Markdown table of :func:`one_shot` rows."""
    head = ("n", "one-shot call", "steps", "median µs", "p90 µs", "p99 µs", "median / daqp floor")
    body = [
        (r["n"], r["call"], r["steps"], f"{r['median_us']:.1f}", f"{r['p90_us']:.1f}",
         f"{r['p99_us']:.1f}", f"{r['ratio_to_floor']:.2f}×")
        for r in rows
    ]  # fmt: skip
    lines = [markdown(head, body, "rlrrrrr")]
    checks = {r["n"]: (r["floor_vs_weighted_max_dx"], r["daqp_flags"]) for r in rows}
    for n, (dx, fl) in checks.items():
        lines.append(
            f"<!-- n={n}: floor x vs qpcoord weighted, max |dx| {dx:.1e}; daqp exit flags {fl} -->"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smoke run (<= 25 steps per loop)")
    ap.add_argument("--steps", type=int, default=1000, help="steps per loop (default 1000)")
    ap.add_argument(
        "--slow-steps",
        type=int,
        default=None,
        help="steps for the slow sparse backends osqp/scs/clarabel/highs (default: --steps)",
    )
    ap.add_argument(
        "--solver",
        action="append",
        default=None,
        help="backend to run (repeatable; default: all installed)",
    )
    ap.add_argument("--sizes", type=int, nargs="+", default=[7, 30], help="numbers of variables")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", metavar="FILE", help="also write the rows as JSON")
    ap.add_argument(
        "--one-shot-steps",
        type=int,
        default=None,
        help="steps of the one-shot table (default 300, --quick 25)",
    )
    ap.add_argument(
        "--one-shot",
        action="store_true",
        help="after the closed loop, the one-shot table: qc.solve_stack of a new stack per "
        "step (both engines) against one direct daqp.solve of the same QP",
    )
    ap.add_argument("--one-shot-only", action="store_true", help="only the one-shot table")
    ap.add_argument(
        "--profile",
        action="store_true",
        help="instead of the table, cProfile the hierarchical and weighted loops "
        "(first --sizes value, first --solver or the default backend)",
    )
    args = ap.parse_args(argv)

    if args.profile:
        solver = args.solver[0] if args.solver else qc.default_solver()
        print(profile(args.sizes[0], solver, min(args.steps, 1000)))
        return 0

    shot_steps = args.one_shot_steps
    if shot_steps is None:
        shot_steps = 25 if args.quick else 300
    print(preamble())
    if args.one_shot_only:
        print()
        with threadpool_limits(1):
            print(format_one_shot(one_shot(args.sizes, max(shot_steps, 10), args.seed)))
        return 0

    t0 = time.perf_counter()
    rows = run_stack_bench(
        sizes=tuple(args.sizes),
        steps=args.steps,
        solvers=args.solver,
        quick=args.quick,
        seed=args.seed,
        slow_steps=args.slow_steps,
    )
    wall = time.perf_counter() - t0
    used = {r["solver"] for r in rows}
    versions = ", ".join(f"{k} {v}" for k, v in qc.solver_versions().items() if k in used)
    print(f"The closed loop, backends {versions} (wall time {wall:.0f} s):\n")
    print(format_loops(rows))
    shots = []
    if args.one_shot:
        with threadpool_limits(1):
            shots = one_shot(args.sizes, max(shot_steps, 10), args.seed)
        print("\nOne-shot (a new stack per step, solved once) vs one direct `daqp.solve`:\n")
        print(format_one_shot(shots))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows + [{"one_shot": r} for r in shots], fh, indent=1)
    return 1 if any(r["failures"] for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
