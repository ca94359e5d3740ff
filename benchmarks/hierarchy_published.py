"""Solve time of the published hierarchical least-squares problems, every backend.

The problems of ``tests/data/hlsp`` (LexLS humanoid 88 variables / 5 levels, soth 1–30
variables, hdaqp basic; see its README), loaded by ``tests/core/hlsp.py``. Each is built
once as a ``qc.Stack`` with the default options and re-solved ``--repeats`` times (after
one untimed solve); the table gives the median time per solve, the solution's status and
the largest gap of a level value to the exact lexicographic reference (``tests/oracle.py``
with ``polish=True``), relative to the level value (floor 1e-9 of the level's scale).
BLAS is limited to one thread (threadpoolctl)::

    python benchmarks/hierarchy_published.py                      # every backend, 20 re-solves
    python benchmarks/hierarchy_published.py --solver daqp --solver quadprog --repeats 50
    python benchmarks/hierarchy_published.py --problem lexls_test01_humanoid

Backends that fail (e.g. the 10 s time limit) show the error's first words instead.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [os.path.join(HERE, "..", "tests"), os.path.join(HERE, "..", "tests", "core")]

import numpy as np  # noqa: E402
from campaign import level_scales  # noqa: E402
from hlsp import NAMES, load  # noqa: E402
from oracle import lexicographic  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

import qpcoord as qc  # noqa: E402


def cases(problems):
    """(label, problem) for each problem, the humanoid also with its simple bounds as box."""
    for name in problems:
        yield name, load(name)
        if name == "lexls_test01_humanoid":
            yield name + " (box)", load(name, simple_as_bounds=True)


def measure(P, ref, solver: str, repeats: int) -> dict:
    """Median time of ``repeats`` re-solves of one built stack, status and largest gap."""
    stack = P.stack()
    try:
        sol = stack.solve(solver=solver)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            sol = stack.solve(solver=solver)
            times.append(time.perf_counter() - t0)
    except qc.SolverError as exc:
        return dict(median=None, status="error: " + str(exc)[:40], gap=None)
    scale = level_scales(P.levels, ref.x)
    tol = np.maximum(ref.level_optima, 1e-3 * scale)  # relative to value, floor for zeros
    gap = float(np.max(np.abs(sol.level_residuals - ref.level_optima) / tol))
    return dict(median=statistics.median(times), status=sol.status, gap=gap)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--solver", action="append", help="backend (repeatable; default: all)")
    ap.add_argument("--problem", action="append", choices=NAMES, help="problem (repeatable)")
    ap.add_argument("--repeats", type=int, default=20, help="timed re-solves (default 20)")
    args = ap.parse_args(argv)
    solvers = args.solver or qc.available_solvers()
    problems = args.problem or NAMES
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, qpcoord {qc.__version__}")
    print(f"median of {args.repeats} re-solves of a built Stack (default options), BLAS 1 thread")
    print("cell: time per solve; '*' after it: status not optimal; gap = max level gap to the")
    print("exact reference, relative to the level value (floor 1e-3 of its scale ⇒ ≤ 1e-9 abs.)")
    header = "| problem | n | levels | " + " | ".join(solvers) + " | max gap |"
    print(header)
    print("|---|---:|---:|" + "---:|" * len(solvers) + "---:|")
    failed = False
    with threadpool_limits(limits=1):
        for label, P in cases(problems):
            ref = lexicographic(P.levels, P.bounds, polish=True)
            cells, gaps = [], []
            for s in solvers:
                m = measure(P, ref, s, args.repeats)
                if m["median"] is None:
                    cells.append(m["status"])
                    failed = True
                    continue
                t = m["median"]
                cell = f"{t * 1e6:.0f} µs" if t < 1e-2 else f"{t * 1e3:.1f} ms"
                cells.append(cell + ("" if m["status"] == "optimal" else " *"))
                gaps.append(m["gap"])
            gap = f"{max(gaps):.1e}" if gaps else "-"
            print(f"| {label} | {P.n} | {len(P.levels)} | " + " | ".join(cells) + f" | {gap} |")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
