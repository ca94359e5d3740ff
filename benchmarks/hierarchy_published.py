"""Solve time of the published hierarchical least-squares problems, every backend.

The problems of ``tests/data/hlsp`` (LexLS humanoid 88 variables / 5 levels, soth 1–30
variables, hdaqp basic; see its README), loaded by ``tests/support/hlsp.py``. Each is built
once as a ``qc.Stack`` with the default options and re-solved ``--repeats`` times (after
one untimed solve); the table gives the median time per solve, the solution's status and
the largest gap of a level value to the exact lexicographic reference (``tests/support/oracle.py``
with ``polish=True``), relative to the level value (floor 1e-9 of the level's scale).
BLAS is limited to one thread (threadpoolctl)::

    python benchmarks/hierarchy_published.py                      # every backend, 20 re-solves
    python benchmarks/hierarchy_published.py --solver daqp --solver quadprog --repeats 50
    python benchmarks/hierarchy_published.py --problem lexls_test01_humanoid

Backends that fail (e.g. the 10 s time limit) show the error's first words instead.

``--resolve``: the re-solve table instead — per problem, per step, interleaved:
the Python engine (default backend), the native engine warm (``Stack.solve``), cold
(stored working sets ignored) and bare (the native call alone on the refreshed buffers, warm
from its own last step), DAQP's hierarchical mode from Python (``daqp.solve`` with ``H = I``,
the bounds hard, one soft block per level; its arrays built outside the timer) and a
``daqp.Model`` kept across steps (``update`` of the right-hand sides + ``solve``: DAQP's warm
path). Its steps are ``moved`` (every right-hand side shifted by ``1e-3 sin(...)`` times its
row's norm); ``--same`` adds ``same`` steps (the unchanged stack solved again). Each solver's
level values are checked against the Python engine's at every step (``max |Δr| / max(1, r)``).
DAQP normalises each soft row, so on the published rows (norms 0.02–431 on the humanoid) it
solves another problem; the ``(unit rows)`` copies divide each row and its bounds by the row's norm,
where every solver solves the same problem. The solvers run in a new (seeded) random order
every step (``--order shuffle``, the default), so that each follows every
other about equally often: the solver right after the Python engine finds the caches evicted
(soth_sot: ``Stack.solve`` 1.7×, the bare call 1.3× its time timed alone). ``--order fixed``
runs one order (python, native warm, cold, bare, daqp.solve, daqp Model: the native
warm solve always right after the Python engine)::

    python benchmarks/hierarchy_published.py --resolve                 # ~1 min
    python benchmarks/hierarchy_published.py --resolve --steps 300 --problem soth_sot
    python benchmarks/hierarchy_published.py --resolve --steps 60 \
        --problem lexls_test01_humanoid --runs 2

Printed: per problem, variant and kind of step, each solver's median µs (with ``--runs N`` the
range over N runs, the problems in turn within a run), the native warm solve over DAQP's
faster path and the largest level gaps; ``--percentiles`` adds median / p90 / p99.

"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [HERE, os.path.join(HERE, "..", "tests")]

import math  # noqa: E402

import daqp  # noqa: E402
import numpy as np  # noqa: E402
from _table import markdown, preamble, sig3, span  # noqa: E402
from daqp_form import daqp_problem  # noqa: E402
from support.campaign import level_scales  # noqa: E402
from support.hlsp import NAMES, load  # noqa: E402
from support.oracle import lexicographic  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

import qpcoord as qc  # noqa: E402
from qpcoord.core.native import NativeHierarchy  # noqa: E402

#: The re-solve table's default problems: the two large ones, the rest are tiny.
RESOLVE_DEFAULT = ("lexls_test01_humanoid", "soth_sot", "hdaqp_basic", "soth_plus")


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


def _tasks(level) -> list:
    return level if isinstance(level, list) else [level]


def unit_rows(levels: list) -> list:
    """The same levels with each row and its bounds divided by the row's norm (new tasks):
    the problem DAQP's row-normalised soft penalty solves."""
    out = []
    for level in levels:
        tasks = []
        for t in _tasks(level):
            if isinstance(t, qc.Equality):
                s = np.linalg.norm(t.A, axis=1)
                tasks.append(qc.Equality(t.A / s[:, None], t.b / s))
            else:
                s = np.linalg.norm(t.C, axis=1)
                tasks.append(qc.Inequality(t.C / s[:, None], t.lower / s, t.upper / s))
        out.append(tasks if len(tasks) > 1 else tasks[0])
    return out


def _mover(levels: list):
    """``move(step)``: every right-hand side at its start plus ``1e-3 sin(0.1 step + i)``
    times its row's norm (inequalities: both sides shifted alike)."""
    start = []
    for level in levels:
        for t in _tasks(level):
            if isinstance(t, qc.Equality):
                start.append((t, t.b.copy(), None, np.linalg.norm(t.A, axis=1)))
            else:
                start.append((t, t.lower.copy(), t.upper.copy(), np.linalg.norm(t.C, axis=1)))

    def move(step: int) -> None:
        for t, lo, hi, norm in start:
            d = 1e-3 * norm * np.sin(0.1 * step + np.arange(norm.shape[0]))
            if hi is None:
                t.update(b=lo + d)
            else:
                t.update(lower=lo + d, upper=hi + d)

    return move


RESOLVE_KEYS = (
    "python",
    "native warm",
    "native cold",
    "native bare",
    "daqp.solve",
    "daqp Model warm",  # update + solve
)


def _update_solve(model, bu, bl):
    """DAQP's warm path: new right-hand sides (its solve of an un-updated model returns
    the −8 flag), then the solve from the last working set."""
    if model.update(bupper=bu, blower=bl) < 0:
        raise RuntimeError("daqp.Model.update failed")
    return model.solve()


def resolve(
    levels: list,
    bounds,
    n: int,
    steps: int,
    moved: bool,
    order: str = "shuffle",
) -> tuple[dict, dict, set]:
    """Per-step times (s) and worst level gap to the Python engine of every solver of
    :data:`RESOLVE_KEYS`, interleaved; and DAQP's exit flags."""
    stack = qc.Stack(levels, bounds=bounds)
    P = stack.compiled
    cold = NativeHierarchy(P, stack.damping)
    bare = NativeHierarchy(P, stack.damping)
    run_bare = bare._solver.run
    box = bounds if bounds is not None else qc.Bounds(np.full(n, -1e30), np.full(n, 1e30))
    H, f = np.eye(n), np.zeros(n)
    A, bu, bl, sense, breaks = daqp_problem(levels, box, n)
    model = daqp.Model()
    if model.setup(H, f, A, bu, bl, sense, break_points=breaks)[0] < 0:
        raise RuntimeError("daqp.Model.setup failed")
    move = _mover(levels)
    keys = RESOLVE_KEYS
    times = {k: [] for k in keys}
    worst = dict.fromkeys(keys, 0.0)
    flags: set = set()

    def timed(key, fn, *args, **kw):
        t = time.perf_counter()
        out = fn(*args, **kw)
        times[key].append(time.perf_counter() - t)
        return out

    out: dict = {}

    def native_cold():
        P.refresh()
        out["native cold"] = timed("native cold", cold.solve, P, warm=False)[0]

    def native_bare():
        P.refresh_stacked()
        code = timed("native bare", run_bare, step > 0, math.inf)
        if code:
            raise RuntimeError(f"native bare call, status {code}")

    def daqp_solve():
        out["daqp"] = timed("daqp.solve", daqp.solve, H, f, A, bu, bl, sense, break_points=breaks)

    def python():
        out["python"] = timed("python", stack.solve, engine="python")

    def native_warm():
        out["native warm"] = timed("native warm", stack.solve, engine="native")

    def daqp_model():
        out["model"] = timed("daqp Model warm", _update_solve, model, bu, bl)

    contenders = [python, native_warm, native_cold, native_bare, daqp_solve, daqp_model]
    contenders_idx = range(len(contenders))
    rng = np.random.default_rng(0)
    for step in range(steps):
        if moved:
            move(step)
            _, bu, bl, sense, _ = daqp_problem(levels, box, n)
        # each solver in turn; "shuffle": a new (seeded) order every step, so that every
        # solver follows every other one about equally often (the one right after the Python
        # engine finds the caches evicted; a rotation would keep who-follows-whom); "fixed":
        # always the order of RESOLVE_KEYS
        for i in rng.permutation(len(contenders)) if order == "shuffle" else contenders_idx:
            contenders[i]()
        sp, sw, xc = out["python"], out["native warm"], out["native cold"]
        xd, _, flag, _ = out["daqp"]
        xm, _, flag_m, _ = out["model"]
        flags.update((int(flag), int(flag_m)))
        ref = sp.level_residuals
        for key, x in (
            ("python", sp.x),
            ("native warm", sw.x),
            ("native cold", xc),
            ("native bare", bare.x),
            ("daqp.solve", np.asarray(xd)),
            ("daqp Model warm", np.asarray(xm)),
        ):
            r = np.array([L.residual(x) for L in P.levels])
            worst[key] = max(worst[key], float(np.max(np.abs(r - ref) / np.maximum(1.0, ref))))
    return times, worst, flags


def resolve_table(
    problems,
    steps: int,
    order: str = "shuffle",
    runs: int = 1,
    detail: bool = False,
    same: bool = False,
) -> str:
    """The re-solve table (see the module's docstring): per problem, variant and kind of
    step (``moved``; with ``same`` also ``same``), each solver's median µs, the range over
    ``runs`` runs (all problems in turn per run); ``detail``: also median / p90 / p99 per
    solver. ``order``: see :func:`resolve`."""
    how = (
        "solvers in a new random order every step"
        if order == "shuffle"
        else "fixed order python, native warm, cold, bare, daqp.solve, daqp Model"
    )
    variants = []
    for name in problems:
        P = load(name)
        variants.append((name, P))
        if name == "lexls_test01_humanoid":
            variants.append((name + " (box)", load(name, simple_as_bounds=True)))
    cases = [
        (label + (" (unit rows)" if unit else ""), P, unit, moved)
        for label, P in variants
        for unit in (False, True)
        for moved in ((False, True) if same else (True,))
    ]
    stats: dict[tuple[str, str], list[dict]] = {}
    worst: dict[tuple[str, str], dict] = {}
    flags: dict[tuple[str, str], set] = {}
    for _ in range(runs):
        for lab, P, unit, moved in cases:
            levels = unit_rows(P.levels) if unit else P.levels
            case = (lab, "moved" if moved else "same")
            times, gaps, fl = resolve(levels, P.bounds, P.n, steps, moved, order)
            us = {k: np.percentile(np.array(t[2:]) * 1e6, [50, 90, 99]) for k, t in times.items()}
            stats.setdefault(case, []).append(us)
            w = worst.setdefault(case, dict.fromkeys(gaps, 0.0))
            for k, g in gaps.items():
                w[k] = max(w[k], g)
            flags.setdefault(case, set()).update(fl)
    n_of = {lab: P.n for lab, P, _u, _m in cases}
    keys = list(next(iter(stats.values()))[0])
    head = ("problem", "n", "step", *keys, "warm / best DAQP", "gap native", "gap DAQP")
    body = []
    for (lab, kind), per in stats.items():
        w = worst[(lab, kind)]
        best = [u["native warm"][0] / min(u["daqp.solve"][0], u["daqp Model warm"][0]) for u in per]
        body.append(
            (
                lab,
                n_of[lab],
                kind,
                *(span([u[k][0] for u in per], sig3) for k in keys),
                span(best, "{:.2f}") + "×",
                f"{max(v for k, v in w.items() if k.startswith('native')):.1e}",
                f"{max(v for k, v in w.items() if k.startswith('daqp')):.1e}",
            )
        )
    out = [
        f"{steps} steps per problem and kind (first 2 dropped), {how}, BLAS 1 thread; median "
        f"µs, the range over {runs} run(s); gap: max |Δr| / max(1, r) to the Python engine's "
        "level values:",
        "",
        markdown(head, body, "lrl" + "r" * (len(head) - 3)),
    ]
    if detail:
        rows = [
            (lab, kind, k, *(span([u[k][i] for u in per]) for i in range(3)))
            for (lab, kind), per in stats.items()
            for k in keys
        ]
        head = ("problem", "step", "solver", "median µs", "p90 µs", "p99 µs")
        out += ["", markdown(head, rows, "lllrrr")]
    bad = {c: sorted(f) for c, f in flags.items() if f - {1, 2}}
    out += [f"{lab} {kind}: daqp exit flags {f}." for (lab, kind), f in bad.items()]
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--solver", action="append", help="backend (repeatable; default: all)")
    ap.add_argument("--problem", action="append", choices=NAMES, help="problem (repeatable)")
    ap.add_argument("--repeats", type=int, default=20, help="timed re-solves (default 20)")
    ap.add_argument("--resolve", action="store_true", help="the re-solve table")
    ap.add_argument("--steps", type=int, default=100, help="--resolve: steps (default 100)")
    ap.add_argument(
        "--order",
        choices=("shuffle", "fixed"),
        default="shuffle",
        help="--resolve: the solvers' order per step: a new random one each step (default) or "
        "fixed (the native engine right after the Python engine)",
    )
    ap.add_argument(
        "--runs",
        type=int,
        default=1,
        help="--resolve: run every problem this many times (in turn); cells: the range",
    )
    ap.add_argument(
        "--percentiles",
        action="store_true",
        help="--resolve: also the table of median / p90 / p99 per solver",
    )
    ap.add_argument(
        "--same",
        action="store_true",
        help="--resolve: also the 'same' steps (the unchanged stack solved again)",
    )
    args = ap.parse_args(argv)
    if args.resolve:
        if args.steps < 5:
            ap.error(f"--steps must be at least 5, got {args.steps}")
        if args.runs < 1:
            ap.error(f"--runs must be at least 1, got {args.runs}")
        print(preamble())
        version = qc.solver_versions().get("daqp", "?")
        print(f"DAQP {version}, hierarchical mode with H = I.", end=" ")
        with threadpool_limits(limits=1):
            print(
                resolve_table(
                    args.problem or RESOLVE_DEFAULT,
                    args.steps,
                    args.order,
                    args.runs,
                    args.percentiles,
                    args.same,
                )
            )
        return 0
    solvers = args.solver or qc.available_solvers()
    problems = args.problem or NAMES
    print(preamble())
    print(
        f"Median of {args.repeats} re-solves of a built Stack (default options, "
        "`solver=` the column), BLAS 1 thread; '*': status not optimal; max gap: the largest "
        "level gap to the exact reference, relative to the level value (floor 1e-3 of its scale):\n"
    )
    body = []
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
            body.append((label, P.n, len(P.levels), *cells, gap))
    head = ("problem", "n", "levels", *solvers, "max gap")
    print(markdown(head, body, "l" + "r" * (len(head) - 1)))
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
