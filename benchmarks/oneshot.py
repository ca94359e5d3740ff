"""One-shot solves: a new stack built and solved once, against one direct DAQP call.

The problem of ``hierarchy_bench.py``'s one-shot table: 7 variables, three equality levels of
3, 3 and 7 rows (random, seed 1) and the box ``-1 ≤ x ≤ 1``. Each step builds new tasks from
the same arrays and times, in turn (one BLAS thread):

- ``tasks + Bounds``: three ``qc.Equality`` and one ``qc.Bounds`` (their validation alone);
- ``qc.solve_stack``: new tasks and bounds, then ``qc.solve_stack(..., engine="native")``;
- ``Stack + solve``: new tasks and bounds, then ``qc.Stack(...).solve(engine="native")``;
- ``daqp.solve weighted QP``: the weighted QP of the same data (level weights 1, 1e-3, 1e-6,
  ``H = Σ wₖ AₖᵀAₖ + 1e-9 I``) built with numpy and solved by one ``daqp.solve`` call: the
  floor the one-shot calls are measured against (the goal: within 4×).

Then, with ``--parts``, the median of each part of one ``qc.solve_stack`` timed alone: the
tasks, the compile (``Stack(...)``), the native engine's construction (its C++
``Hierarchy(...)``, ``bind``, ``set_tasks``) and its first (cold) call; then, on an engine
already called once, a cold call again (the first call's cost less what it allocates or
sets up once) and the warm call that follows the first (a re-solve's first call).

    python benchmarks/oneshot.py                 # 3 000 steps, a few seconds
    python benchmarks/oneshot.py --runs 5 --parts

Printed: median / p90 µs per call and the ratio of medians to the direct DAQP call (with
``--runs N`` each cell is the range over N runs), then DAQP's exit flag and the largest
difference of its ``x`` to ``Stack.solve(method="weighted")``'s: the same QP.
"""

from __future__ import annotations

import argparse
import time

import daqp
import numpy as np
from threadpoolctl import threadpool_limits

import qpcoord as qc

try:
    from benchmarks._table import markdown, preamble, span
except ImportError:  # run as a script from benchmarks/
    from _table import markdown, preamble, span

N = 7
ROWS = (3, 3, 7)
WEIGHTS = (1.0, 1e-3, 1e-6)


def problem() -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray, np.ndarray]:
    rng = np.random.default_rng(1)
    A = [rng.standard_normal((m, N)) for m in ROWS]
    b = [rng.standard_normal(m) for m in ROWS]
    return A, b, -np.ones(N), np.ones(N)


def calls() -> dict[str, object]:
    """The timed calls, each a function of no argument."""
    A, b, lb, ub = problem()
    no_rows = np.zeros((0, N))
    sense = np.zeros(N, dtype=np.int32)

    def tasks():
        return [qc.Equality(Ai, bi) for Ai, bi in zip(A, b, strict=True)], qc.Bounds(lb, ub)

    def solve_stack():
        levels, bounds = tasks()
        return qc.solve_stack(levels, bounds=bounds, engine="native")

    def stack_solve():
        levels, bounds = tasks()
        return qc.Stack(levels, bounds=bounds).solve(engine="native")

    def direct():
        H = sum(w * Ai.T @ Ai for w, Ai in zip(WEIGHTS, A, strict=True)) + 1e-9 * np.eye(N)
        f = -sum(w * Ai.T @ bi for w, Ai, bi in zip(WEIGHTS, A, b, strict=True))
        return daqp.solve(H, f, no_rows, ub, lb, sense)

    return {
        "tasks + Bounds": tasks,
        "qc.solve_stack": solve_stack,
        "Stack + solve": stack_solve,
        "daqp.solve weighted QP": direct,
    }


def parts() -> dict[str, object]:
    """The parts of one ``qc.solve_stack``, each timed alone on fresh inputs."""
    from qpcoord.core.native import NativeHierarchy, load

    A, b, lb, ub = problem()
    mod = load()

    def build():
        levels = [qc.Equality(Ai, bi) for Ai, bi in zip(A, b, strict=True)]
        return qc.Stack(levels, bounds=qc.Bounds(lb, ub))

    def one_equality():
        return qc.Equality(A[2], b[2])

    def bounds():
        return qc.Bounds(lb, ub)

    levels = [qc.Equality(Ai, bi) for Ai, bi in zip(A, b, strict=True)]
    box = qc.Bounds(lb, ub)

    def compile_stack():
        return qc.Stack(levels, bounds=box)

    stacks: list = []

    def native_cpp_constructor():
        P = stacks[-1]._compiled
        blocks = [P.hard, *P.levels]
        return mod.Hierarchy(N, [B.m_eq for B in blocks], [B.m_in for B in blocks], True, 1e-7)

    def native_engine():
        return NativeHierarchy(stacks[-1]._compiled, 1e-7)

    engines: list = []

    def first_call():
        return engines[-1].solve(stacks[-1]._compiled, time_left=10.0)

    def cold_again():
        return engines[-1].solve(stacks[-1]._compiled, warm=False, time_left=10.0)

    def warm_after_first():
        return engines[-1].solve(stacks[-1]._compiled, time_left=10.0)

    def setup():
        stacks.append(build())
        engines.append(NativeHierarchy(stacks[-1]._compiled, 1e-7))
        if len(stacks) > 2:
            del stacks[0], engines[0]

    def setup_solved():
        setup()
        first_call()

    return {
        "Equality (7 × 7)": (one_equality, None),
        "Bounds (7)": (bounds, None),
        "Stack(...) compile (tasks built)": (compile_stack, None),
        "native engine: C++ Hierarchy(...) alone": (native_cpp_constructor, setup),
        "native engine: NativeHierarchy(...) in all": (native_engine, setup),
        "native engine: first (cold) call": (first_call, setup),
        "native engine: a cold call again (warm=False)": (cold_again, setup_solved),
        "native engine: the warm call after the first": (warm_after_first, setup_solved),
    }


def same_problem() -> str:
    """A line saying the direct call solves the weighted QP of the stack: DAQP's exit flag and
    the largest difference of its ``x`` to ``Stack.solve(method="weighted")``'s (the same
    level weights, ``weight_ratio=1e-3``, and regularisation, ``1e-9``)."""
    A, b, lb, ub = problem()
    x, _, flag, _ = calls()["daqp.solve weighted QP"]()
    levels = [qc.Equality(Ai, bi) for Ai, bi in zip(A, b, strict=True)]
    stack = qc.Stack(levels, bounds=qc.Bounds(lb, ub), weight_ratio=1e-3, regularization=1e-9)
    dx = float(np.max(np.abs(x - stack.solve(method="weighted", engine="python").x)))
    return (
        f"The direct call's QP is the stack's weighted QP: daqp exit flag {flag}, "
        f'max |dx| {dx:.1e} to `Stack.solve(method="weighted")`.'
    )


def median_p90(samples: list[float]) -> tuple[float, float]:
    a = np.array(samples[2:]) * 1e6  # the first calls warm the caches
    return float(np.median(a)), float(np.percentile(a, 90))


def run(steps: int) -> dict[str, tuple[float, float]]:
    fns = calls()
    times: dict[str, list[float]] = {k: [] for k in fns}
    pc = time.perf_counter
    for _ in range(steps):  # the calls in turn: the machine's load is shared alike
        for key, fn in fns.items():
            t = pc()
            fn()
            times[key].append(pc() - t)
    return {k: median_p90(v) for k, v in times.items()}


def run_parts(steps: int) -> dict[str, float]:
    fns = parts()
    times: dict[str, list[float]] = {k: [] for k in fns}
    pc = time.perf_counter
    for _ in range(steps):
        for key, (fn, setup) in fns.items():
            if setup is not None:
                setup()
            t = pc()
            fn()
            times[key].append(pc() - t)
    return {k: median_p90(v)[0] for k, v in times.items()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--runs", type=int, default=1, help="cells: the range over this many runs")
    ap.add_argument("--parts", action="store_true", help="also each part of a solve_stack")
    args = ap.parse_args(argv)
    if args.steps < 5:
        ap.error(f"--steps must be at least 5, got {args.steps}")
    if args.runs < 1:
        ap.error(f"--runs must be at least 1, got {args.runs}")
    print(preamble())
    with threadpool_limits(1):
        runs = [run(args.steps) for _ in range(args.runs)]
        floor = "daqp.solve weighted QP"
        body = []
        for key in runs[0]:
            med = [r[key][0] for r in runs]
            p90 = [r[key][1] for r in runs]
            ratio = [r[key][0] / r[floor][0] for r in runs]
            body.append((key, span(med), span(p90), span(ratio, "{:.2f}") + "×"))
        print(
            f"One-shot, 7 variables, 3 levels, new tasks every call; {args.steps} calls per "
            f"run, {args.runs} run(s):\n"
        )
        head = ("call", "median µs", "p90 µs", "median / direct daqp.solve")
        print(markdown(head, body, "lrrr"))
        print("\n" + same_problem())
        if args.parts:
            shares = [run_parts(args.steps) for _ in range(args.runs)]
            print("\nMedian µs of each part of a one-shot `qc.solve_stack`, timed alone:\n")
            rows = [(k, span([s[k] for s in shares])) for k in shares[0]]
            print(markdown(("part", "median µs"), rows, "lr"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
