"""Per-step solve time of a 3-level stack (7 and 30 variables), every method and backend.

Thin wrapper around :func:`qpcoord.studies.bench_stack.run_stack_bench` (same as ``qpcoord bench
stack``)::

    python benchmarks/stack_bench.py                 # full run, all installed backends (~1 min)
    python benchmarks/stack_bench.py --quick         # smoke run, a few seconds
    python benchmarks/stack_bench.py --solver daqp --steps 2000 --sizes 7
    python benchmarks/stack_bench.py --profile --solver daqp   # cProfile of the n=7 hot path

See benchmarks/README.md for the scenario and the measured table.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import platform
import pstats
import sys
import time

import numpy as np

import qpcoord as qc
from qpcoord.studies.bench_stack import format_table, run_loops, run_stack_bench


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
    versions = ", ".join(f"{k} {v}" for k, v in qc.solver_versions().items())
    print(
        f"qpcoord {qc.__version__}, numpy {np.__version__}, Python {platform.python_version()}, "
        f"{platform.machine()}; backends: {versions}"
    )
    print(format_table(rows))
    print(f"\nwall time {wall:.1f} s")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    return 1 if any(r["failures"] for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
