"""Strict hierarchies: Python vs native engine (cold, warm, bare) vs DAQP's hierarchical mode.

Scenarios (seeded):

* ``random50``: 50 variables, 10 levels of 20 rows (8 equality rows, 12 inequality rows, one-
  or two-sided), box ``|x| ≤ 1``; every row has unit norm, so DAQP's row-normalised soft
  penalty is the same lexicographic problem as qpcoord's. Per step the targets move a little.
* ``panda9``: the Panda's size, 9 variables: a 3-row position task above a 9-row posture task,
  box on the velocities (random well-conditioned 3 × 9 Jacobian, moving target).
* ``chain30``: 30 variables, 5 levels: joint-velocity box, then 3 / 3 / 6 / 6
  equality rows with a serial chain's structure (the rows of a point on link ``L`` depend on
  joints ``0..L`` only: tip, mid-chain, then two 6-row levels), unit rows, moving targets; the
  box binds.
* ``talos``: the Talos whole-body IK stack of ``ik_peers.py`` (38 velocity variables: both
  soles, the CoM in the shrunk support polygon — inequalities —, right hand on a min-jerk path,
  posture; the robot's position and speed limits as the box), stepped by its own native
  solution. Rows are not unit-norm: DAQP's soft penalty is another problem there, so DAQP is
  not run on it. Needs example-robot-data (skipped with a note if missing).
* ``talos_unit``: the same IK stack with every row scaled to unit norm (its target or bounds
  with it) and unit weights, refreshed from the IK stack each step outside the timers and
  stepped by its own native solution: DAQP's row-normalised soft penalty is then the same
  lexicographic problem (as the humanoid's unit rows in ``hierarchy_published.py``), so DAQP
  runs on it (its box the robot's limits, ±1e30 where open).
* ``soth_sot``: the published soth problem of ``hierarchy_published.py`` (30 variables: 30
  joint-limit rows as level 0, then 3 / 3 / 6 / 6 equality rows) with unit rows (DAQP's soft
  penalty is then the same problem), every right-hand side moved as that file's re-solve
  table does; DAQP gets the box ``±1e30`` (the problem has none).

Per step (interleaved, one BLAS thread): ``Stack.solve(engine="python")``, the native engine
cold (stored working sets ignored), "native warm" (``Stack.solve(engine="native")``), "native
bare" (the native call alone, ``Hierarchy.run``, on a second solver warm from its own previous
step, the stacked arrays already refreshed; warm and bare in alternating order, so
that bare does not always run right after warm and find the stacked arrays in cache) and
``daqp.solve(..., break_points=...)`` with
``H = I`` (minimum-norm completion; a positive-definite H avoids its −8 "unsupported" flag).
DAQP's solve is timed on its arrays built before the timer ("daqp.solve", as
``hierarchy_published.py --resolve`` times it) and also with the building of its arrays from
the tasks ("daqp.solve + arrays"): the native engine's times include copying the tasks'
numbers into its arrays. Also DAQP's own warm start, "daqp Model warm" (update + solve):
one ``daqp.Model`` kept across the steps, given the new right-hand sides (and ``A`` on a step
where it changed) by ``update`` and solved from its last working set, as
``hierarchy_published.py``'s "daqp Model warm"; the faster of DAQP's two paths is its best.
Each engine's level values are checked against the Python engine's (``max |Δr| / max(1, r)``).
With ``--no-python`` only the re-solve contenders are timed (native warm, native bare, DAQP):
the Python engine (and the native cold solve) evict the caches before the next step's native
call — "native warm" measured right after a Python-engine solve costs up to 2× its time alone
— so the Python engine runs as the oracle every 10th step only, after that step's timed
solves, and the step after it is not timed.
With ``--one-shot``, then the one-shot cost: ``qc.solve_stack`` of a 7-variable, 3-level stack
(each engine) vs one direct ``daqp.solve`` of the weighted QP, with the ratio of medians to
that direct call (the goal: within 4×). Here each native one-shot follows a Python-engine one
(which evicts the caches); ``benchmarks/oneshot.py`` times the native one-shot alone, and its
parts.

    python benchmarks/hierarchy_bench.py            # ~2–3 min
    python benchmarks/hierarchy_bench.py --quick    # a few seconds
    python benchmarks/hierarchy_bench.py --scenario panda9 --scenario random50 --steps 300
    python benchmarks/hierarchy_bench.py --steps 300 --no-python --runs 4

Printed: each engine's median µs per scenario, with ``--runs N`` the range over N runs (the
scenarios in turn within a run), the native warm solve over DAQP's faster path and the largest
level differences; ``--percentiles`` adds median / p90 / p99 per engine.

``--wrapper``: instead, the parts of one warm ``Stack.solve(engine="native")`` — engine and
time-limit resolution, the one native call ``Hierarchy.step`` (the tasks' numbers copied into
the stacked arrays, the solve, the output copies, the info dict), the ``Solution`` — each timed
on the stack's own solver, the whole call, and the parts of the Python path it replaced
(``refresh_stacked``, ``Hierarchy.run``, copies, ``NativeHierarchy._info``), one kind per moved
step in turn, timed alone (the Python around the native call)::

    python benchmarks/hierarchy_bench.py --wrapper --scenario chain30 --scenario soth_sot \
        --steps 2000
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import daqp
import numpy as np
from _table import markdown, preamble, sig3, span
from daqp_form import daqp_problem
from threadpoolctl import threadpool_limits

import qpcoord as qc
from qpcoord.core.backends import DEFAULT_TIME_LIMIT, time_left
from qpcoord.core.native import NativeHierarchy, resolve_engine
from qpcoord.core.polish import KKT_TOL


def _unit_rows(M: np.ndarray) -> np.ndarray:
    return M / np.linalg.norm(M, axis=1)[:, None]


def random50(rng, n=50, levels=10, m_eq=8, m_in=12):
    """Tasks of the 50-variable, 10-level stack and a function that moves its targets."""
    tasks = []
    for _ in range(levels):
        eq = qc.Equality(_unit_rows(rng.standard_normal((m_eq, n))), rng.standard_normal(m_eq))
        C = _unit_rows(rng.standard_normal((m_in, n)))
        lo = rng.uniform(-1.5, 0.5, m_in)
        hi = lo + rng.uniform(0.2, 1.5, m_in)
        hi[: m_in // 2] = np.inf  # one-sided half
        tasks.append([eq, qc.Inequality(C, lo, hi)])
    bounds = qc.Bounds(-np.ones(n), np.ones(n))

    def move(step):
        for eq, _ in tasks:
            eq.update(b=eq.b + 0.01 * np.sin(0.1 * step + np.arange(eq.b.shape[0])))

    return tasks, bounds, move


def panda9(rng, n=9):
    J = _unit_rows(rng.standard_normal((3, n)))
    pos = qc.Equality(J, np.zeros(3))
    q_ref = rng.uniform(-0.5, 0.5, n)
    posture = qc.Equality(np.eye(n), q_ref)
    bounds = qc.Bounds(-0.3 * np.ones(n), 0.3 * np.ones(n))

    def move(step):
        pos.update(b=np.array([np.sin(0.05 * step), np.cos(0.05 * step), 0.3]))

    return [pos, posture], bounds, move


def _chain_rows(rng, m: int, upto: int, n: int) -> np.ndarray:
    """``m`` unit rows of a point on link ``upto`` of an ``n``-joint chain: joints after it
    do not move the point (zero columns)."""
    J = np.zeros((m, n))
    J[:, :upto] = rng.standard_normal((m, upto))
    return _unit_rows(J)


def chain30(rng, n=30):
    """Bounds, then 3 / 3 / 6 / 6 equality rows with a chain's structure, moving targets."""
    sizes_upto = ((3, n), (3, n // 2 + 5), (6, n // 2), (6, n))
    tasks = [
        qc.Equality(_chain_rows(rng, m, upto, n), rng.uniform(-0.5, 0.5, m))
        for m, upto in sizes_upto
    ]
    base = [t.b.copy() for t in tasks]
    bounds = qc.Bounds(-0.5 * np.ones(n), 0.5 * np.ones(n))

    def move(step):
        for t, b0 in zip(tasks, base, strict=True):
            t.update(b=b0 + 0.2 * np.sin(0.05 * step + np.arange(b0.shape[0])))

    return tasks, bounds, move


def talos(rng):
    """The Talos IK stack of ``ik_peers.py``, stepped by its native solution: a dict with the
    stack and ``move(step, x)`` (integrate the last solution, new hand target, refresh)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import ik_peers

    sc = ik_peers.scenario("talos", 10_000, 0.0)
    loop = ik_peers.QpcoordLoop(sc, "hierarchical", "native", "qpcoord strict native")
    ik, robot = loop.ik, loop.robot
    state = {"q": loop.q}

    def move(step, x=None):
        if x is not None:
            state["q"] = robot.integrate(state["q"], x, ik_peers.DT)
        loop.hand.set_target(sc["targets"][step % len(sc["targets"])])
        ik.refresh(robot.check_configuration(state["q"]))

    return {"stack": ik.stack, "move": move, "daqp": None}


def _unit_task(t):
    """A copy of task ``t`` with every row scaled to unit norm (its target or bounds with it)
    and unit weights, and a function that refreshes the copy from ``t``'s current numbers."""

    def scaled():
        M = t.A if isinstance(t, qc.Equality) else t.C
        norms = np.linalg.norm(M, axis=1)
        s = 1.0 / np.where(norms > 0.0, norms, 1.0)
        if isinstance(t, qc.Equality):
            return {"A": M * s[:, None], "b": t.b * s}
        return {"C": M * s[:, None], "lower": t.lower * s, "upper": t.upper * s}

    first = scaled()
    u = qc.Equality(**first) if isinstance(t, qc.Equality) else qc.Inequality(**first)
    return u, lambda: u.update(**scaled())


def talos_unit(rng):
    """The Talos IK stack of :func:`talos` with every row scaled to unit norm and unit weights
    (DAQP's row-normalised soft penalty is then the same lexicographic problem, as the
    humanoid's unit rows of ``hierarchy_published.py``), stepped by its own native solution;
    the IK stack is refreshed at each step (new configuration, new hand target) and the copy
    from it, outside every timer. DAQP's box: the limits, ±1e30 where open."""
    base = talos(rng)
    ik_stack = base["stack"]
    bounds = ik_stack.compiled.bounds
    levels, refresh = [], []
    for lev in ik_stack.levels:
        lev = lev if isinstance(lev, list) else [lev]
        copies = [_unit_task(t) for t in lev]
        levels.append([u for u, _ in copies])
        refresh += [r for _, r in copies]
    box = qc.Bounds(bounds.lower.copy(), bounds.upper.copy())
    daqp_box = qc.Bounds(np.maximum(bounds.lower, -1e30), np.minimum(bounds.upper, 1e30))

    def move(step, x=None):
        base["move"](step, x)
        for r in refresh:
            r()
        box.update(lower=bounds.lower, upper=bounds.upper)
        daqp_box.update(lower=np.maximum(bounds.lower, -1e30), upper=np.minimum(bounds.upper, 1e30))

    move(0)
    return {"stack": qc.Stack(levels, bounds=box), "move": move, "daqp": (levels, daqp_box)}


def soth_sot(rng):
    """The published soth problem (unit rows), moved as hierarchy_published's re-solve."""
    del rng  # the published data; the motion is deterministic
    here = Path(__file__).resolve().parent
    sys.path[:0] = [str(here), str(here.parent / "tests")]
    import hierarchy_published as hp
    from support.hlsp import load

    prob = load("soth_sot")
    levels = hp.unit_rows(prob.levels)
    move = hp._mover(levels)
    n = prob.n
    box = qc.Bounds(np.full(n, -1e30), np.full(n, 1e30))
    return {
        "stack": qc.Stack(levels, bounds=prob.bounds),
        "move": lambda step, x=None: move(step),
        "daqp": (levels, box),
    }


SCENARIOS = {
    "random50": ("random50 (n=50, 10×20 rows)", random50),
    "panda9": ("panda9", panda9),
    "chain30": ("chain30 (n=30, box + 3/3/6/6 eq rows)", chain30),
    "talos": ("talos IK (n=38, 4 levels)", talos),
    "talos_unit": ("talos IK, unit rows (n=38, 4 levels)", talos_unit),
    "soth_sot": ("soth_sot (n=30, unit rows, 30 ineq + 3/3/6/6 eq rows)", soth_sot),
}


def _scenario(build, rng) -> dict:
    """A builder's scenario as a dict: stack, move(step, x), DAQP's data (or None)."""
    out = build(rng)
    if isinstance(out, dict):
        return out
    levels, bounds, move = out
    return {
        "stack": qc.Stack(levels, bounds=bounds),
        "move": lambda step, x=None: move(step),
        "daqp": (levels, bounds),
    }


def _levels_residuals(stack: qc.Stack, x: np.ndarray) -> np.ndarray:
    return np.array([L.residual(x) for L in stack.compiled.levels])


#: DAQP's columns: ``daqp.solve`` alone on the step's arrays built before the timer (what
#: hierarchy_published's re-solve table times), and the same call with the building of its
#: arrays from the tasks (``daqp_problem``)
DAQP = "daqp hierarchical (solve on built arrays)"
DAQP_BUILD = "daqp hierarchical + building its arrays"
#: DAQP's own warm start: one ``daqp.Model`` kept across the
#: steps, given the step's new numbers by ``update`` (the right-hand sides, and ``A`` only on
#: a step where it changed: DAQP then refactorises) and solved from its last working set;
#: ``update`` + ``solve`` timed, as hierarchy_published's "daqp Model warm"
DAQP_MODEL = "daqp Model warm (update + solve)"


def _model_step(model, A, bu, bl, A_changed: bool):
    """DAQP's warm path on the step's arrays: ``update`` (``A`` too if it changed), then
    ``solve`` from the model's last working set; ``(x, exit flag)``."""
    code = (
        model.update(A=A, bupper=bu, blower=bl) if A_changed else model.update(bupper=bu, blower=bl)
    )
    if code < 0:
        raise RuntimeError(f"daqp.Model.update failed (exit flag {code})")
    x, _f, flag, _info = model.solve()
    return x, flag


def run(name, build, steps, seed=0, python=True):
    """Per-engine percentiles of ``steps`` interleaved steps; ``python=False``: the re-solve
    contenders only, the Python engine the oracle of every 10th step (see the docstring)."""
    rng = np.random.default_rng(seed)
    sc = _scenario(build, rng)
    stack, move, dq = sc["stack"], sc["move"], sc["daqp"]
    n = stack.n
    P = stack.compiled
    cold = NativeHierarchy(P, stack.damping)
    bare = NativeHierarchy(P, stack.damping)
    run_bare = bare._solver.run
    keys = ["python", "native cold", "native warm", "native bare"] if python else []
    if not python:
        keys += ["native warm", "native bare"]
    if dq is not None:
        keys += [DAQP, DAQP_BUILD, DAQP_MODEL]
    model = None  # DAQP's warm model, set up at the first step
    A_model = None
    times = {k: [] for k in keys}
    worst = dict.fromkeys(times, 0.0)
    flags = set()
    x_prev = None
    skip = set()  # (python=False) steps right after an oracle step: not timed
    for step in range(steps):
        move(step, x_prev)
        if python:
            t = time.perf_counter()
            sp = stack.solve(engine="python")
            times["python"].append(time.perf_counter() - t)
            ref = sp.level_residuals
            t = time.perf_counter()
            P.refresh()
            xc, _, _ = cold.solve(P, warm=False)
            times["native cold"].append(time.perf_counter() - t)
        # native warm and bare in alternating order (the second finds the stacked arrays in
        # cache, so neither is always second)
        for which in ("warm", "bare") if step % 2 == 0 else ("bare", "warm"):
            if which == "warm":
                t = time.perf_counter()
                sw = stack.solve(engine="native")
                times["native warm"].append(time.perf_counter() - t)
                continue
            P.refresh_stacked()
            t = time.perf_counter()
            code = run_bare(bool(step), math.inf)
            times["native bare"].append(time.perf_counter() - t)
            if code:
                raise RuntimeError(f"{name}: native bare call, status {code}")
        got = [("python", sp.x), ("native cold", xc)] if python else []
        got += [("native warm", sw.x), ("native bare", bare.x.copy())]
        if dq is not None:
            # DAQP's solve timed on arrays built before the timer (as hierarchy_published's
            # re-solve table; the native engine's stacked arrays are refreshed inside its
            # time): DAQP is given the moved numbers as its own arrays, H and f too
            levels, bounds = dq
            t = time.perf_counter()
            A, bu, bl, sense, breaks = daqp_problem(levels, bounds, n)
            H, f = np.eye(n), np.zeros(n)
            t1 = time.perf_counter()
            xd, _f, flag, _info = daqp.solve(H, f, A, bu, bl, sense, break_points=breaks)
            t2 = time.perf_counter()
            times[DAQP].append(t2 - t1)
            times[DAQP_BUILD].append(t2 - t)
            flags.add(int(flag))
            got += [(DAQP, np.asarray(xd)), (DAQP_BUILD, np.asarray(xd))]
            if model is None:
                model = daqp.Model()
                if model.setup(H, f, A, bu, bl, sense, break_points=breaks)[0] < 0:
                    raise RuntimeError(f"{name}: daqp.Model.setup failed")
                A_model = A
            changed = not np.array_equal(A, A_model)
            A_model = A
            t = time.perf_counter()
            xm, flag = _model_step(model, A, bu, bl, changed)
            times[DAQP_MODEL].append(time.perf_counter() - t)
            flags.add(int(flag))
            got.append((DAQP_MODEL, np.asarray(xm)))
        if not python:
            if step % 10:
                x_prev = sw.x
                continue
            ref = stack.solve(engine="python").level_residuals  # after the timed solves
            skip.add(step + 1)
        for key, x in got:
            r = _levels_residuals(stack, x)
            worst[key] = max(worst[key], float(np.max(np.abs(r - ref) / np.maximum(1.0, ref))))
        x_prev = sw.x
    rows = []
    for key, ts in times.items():
        us = np.array([t for i, t in enumerate(ts) if i >= 2 and i not in skip]) * 1e6
        rows.append((name, key, *np.percentile(us, [50, 90, 99]), worst[key]))
    return rows, flags


#: The parts of one warm ``Stack.solve(engine="native")``, in its order (see :func:`wrapper`):
#: the refresh, the solve, the copies and the info dict are one native call
#: (``Hierarchy.step``); the parts of the Python path it replaced (still the path of a task
#: whose data is not float64 of its shape) are timed on other steps.
WRAPPER_PARTS = (
    "resolve_engine + time_left",
    "Hierarchy.step (refresh, solve, x/res copies, info)",
    "Solution",
    "sum of the parts",
    "Stack.solve (whole)",
    "Python path: refresh_stacked",
    "Python path: native call (Hierarchy.run)",
    "Python path: x, res copies",
    "Python path: info dict (Hierarchy.info)",
    "Python path: sum (without resolve_engine, Solution)",
)


def wrapper(name, build, steps):
    """Median µs of each part of one warm ``Stack.solve(engine="native")`` (the calls it
    makes, timed one by one on the stack's own native solver), of the whole call, and of
    the parts of the Python path (refresh in Python, ``Hierarchy.run``, copies, the Python
    info dict), on moved steps in turn (one kind per step, timed alone): what the Python
    around the native call costs."""
    sc = _scenario(build, np.random.default_rng(0))
    stack, move = sc["stack"], sc["move"]
    P = stack.compiled
    stack.solve(engine="native")
    nat = stack._native
    times = {k: [] for k in WRAPPER_PARTS}
    pc = time.perf_counter
    for step in range(steps):
        move(step, None)
        if step % 3 == 1:
            t = pc()
            stack.solve(engine="native")
            times["Stack.solve (whole)"].append(pc() - t)
            continue
        if step % 3 == 2:
            t0 = pc()
            P.refresh_stacked()
            t1 = pc()
            code = nat._run(True, DEFAULT_TIME_LIMIT)
            t2 = pc()
            x, res = nat.x.copy(), nat.res.copy()
            t3 = pc()
            nat._solver.info(KKT_TOL)
            t4 = pc()
            if code:
                raise RuntimeError(f"{name}: native call, status {code}")
            for key, dt in zip(
                WRAPPER_PARTS[5:], (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t4 - t0), strict=True
            ):
                times[key].append(dt)
            continue
        t0 = pc()
        resolve_engine("native", "hierarchical", None)
        time_left()
        t1 = pc()
        out = nat._step(True, DEFAULT_TIME_LIMIT, KKT_TOL)
        t2 = pc()
        if out.__class__ is not tuple:
            raise RuntimeError(f"{name}: native step, status {out}")
        x, res, info = out
        qc.Solution(x, "optimal", res, "native", t2 - t0, "hierarchical", info)
        t3 = pc()
        for key, dt in zip(WRAPPER_PARTS[:4], (t1 - t0, t2 - t1, t3 - t2, t3 - t0), strict=True):
            times[key].append(dt)
    return [(name, key, float(np.median(np.array(v[2:]) * 1e6))) for key, v in times.items()]


def one_shot(steps):
    rng = np.random.default_rng(1)
    n = 7
    A = [rng.standard_normal((m, n)) for m in (3, 3, 7)]
    b = [rng.standard_normal(m) for m in (3, 3, 7)]
    lb, ub = -np.ones(n), np.ones(n)
    times = {"solve_stack python": [], "solve_stack native": [], "daqp.solve weighted QP": []}
    w = (1.0, 1e-3, 1e-6)
    for _ in range(steps):
        for engine in ("python", "native"):
            t = time.perf_counter()
            qc.solve_stack(
                [qc.Equality(Ai, bi) for Ai, bi in zip(A, b, strict=True)],
                bounds=qc.Bounds(lb, ub),
                engine=engine,
            )
            times[f"solve_stack {engine}"].append(time.perf_counter() - t)
        t = time.perf_counter()
        H = sum(wi * Ai.T @ Ai for wi, Ai in zip(w, A, strict=True)) + 1e-9 * np.eye(n)
        f = -sum(wi * Ai.T @ bi for wi, Ai, bi in zip(w, A, b, strict=True))
        daqp.solve(H, f, np.zeros((0, n)), ub, lb, np.zeros(n, dtype=np.int32))
        times["daqp.solve weighted QP"].append(time.perf_counter() - t)
    return [(k, *np.percentile(np.array(v[2:]) * 1e6, [50, 90, 99])) for k, v in times.items()]


#: Short column names of :func:`run`'s keys in the summary table.
SHORT = {DAQP: "daqp.solve", DAQP_BUILD: "daqp.solve + arrays", DAQP_MODEL: "daqp Model warm"}


def summary(results: dict[str, list[list[tuple]]]) -> str:
    """Markdown table of the median µs of each engine per scenario, each cell the range over
    the runs (``results``: scenario -> one list of :func:`run` rows per run); then the native
    warm solve over DAQP's faster path (solve on built arrays or warm Model) per run, and the
    largest level difference to the Python engine over the runs (native, DAQP)."""
    keys: list[str] = []
    for runs in results.values():
        keys += [r[1] for r in runs[0] if r[1] not in keys]
    head = ("scenario", *(SHORT.get(k, k) for k in keys), "warm / best DAQP")
    head += ("level diff native", "level diff DAQP")
    body = []
    for name, runs in results.items():
        med = [{r[1]: r[2] for r in rows} for rows in runs]
        diff = [{r[1]: r[5] for r in rows} for rows in runs]
        cells = [span([m[k] for m in med], sig3) if k in med[0] else "–" for k in keys]
        if DAQP in med[0]:
            ratio = span([m["native warm"] / min(m[DAQP], m[DAQP_MODEL]) for m in med], "{:.2f}")
            ratio += "×"
        else:
            ratio = "–"

        def worst(which, diff=diff) -> str:
            v = [d[k] for d in diff for k in d if which(k)]
            return f"{max(v):.1e}" if v else "–"

        body.append(
            (name, *cells, ratio, worst(lambda k: k.startswith("native")),
             worst(lambda k: k.startswith("daqp")))
        )  # fmt: skip
    return markdown(head, body, "l" + "r" * (len(head) - 1))


def percentiles(results: dict[str, list[list[tuple]]]) -> str:
    """Markdown table of median / p90 / p99 µs per scenario and engine, each cell the range
    over the runs, and the largest level difference to the Python engine over the runs."""
    body = []
    for name, runs in results.items():
        for i, r in enumerate(runs[0]):
            per = [rows[i] for rows in runs]
            cells = (span([p[j] for p in per]) for j in (2, 3, 4))
            body.append((name, r[1], *cells, f"{max(p[5] for p in per):.1e}"))
    head = ("scenario", "engine", "median µs", "p90 µs", "p99 µs", "max level diff vs python")
    return markdown(head, body, "llrrrr")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="few steps (smoke run)")
    ap.add_argument("--steps", type=int, default=None)
    ap.add_argument(
        "--scenario",
        action="append",
        choices=sorted(SCENARIOS),
        help="run only these scenarios (repeatable; default: all)",
    )
    ap.add_argument(
        "--runs",
        type=int,
        default=1,
        help="run every scenario this many times (scenarios in turn); cells: the range over them",
    )
    ap.add_argument(
        "--percentiles",
        action="store_true",
        help="also the table of median / p90 / p99 per scenario and engine",
    )
    ap.add_argument(
        "--one-shot",
        action="store_true",
        help="after the re-solve table, the one-shot table: qc.solve_stack of a new stack "
        "(each engine) against one direct daqp.solve of the weighted QP",
    )
    ap.add_argument(
        "--no-python",
        action="store_true",
        help="time the re-solve contenders only (native warm, bare, DAQP); the Python engine "
        "the oracle of every 10th step",
    )
    ap.add_argument(
        "--wrapper",
        action="store_true",
        help="only the parts of one warm Stack.solve(engine='native'), timed alone",
    )
    args = ap.parse_args(argv)
    steps = args.steps or (20 if args.quick else 300)
    if steps < 5:
        ap.error(f"--steps must be at least 5, got {steps}")
    if args.runs < 1:
        ap.error(f"--runs must be at least 1, got {args.runs}")
    chosen = args.scenario or list(SCENARIOS)
    print(preamble())
    with threadpool_limits(1):
        if args.wrapper:
            print(f"Median µs of the parts of a warm `Stack.solve`, {steps} steps:\n")
            body, notes = [], []
            for key in chosen:
                try:
                    body += wrapper(*SCENARIOS[key], max(steps, 10))
                except FileNotFoundError as exc:  # example-robot-data missing
                    notes.append(f"{key} skipped: {exc}.")
            head = ("scenario", "part of a warm Stack.solve", "median µs")
            print(markdown(head, [(r[0], r[1], f"{r[2]:.2f}") for r in body], "llr"))
            print("\n".join(["", *notes]) if notes else "", end="")
            return 0
        results: dict[str, list[list[tuple]]] = {}
        notes = []
        for _ in range(args.runs):
            for key in chosen:
                name, build = SCENARIOS[key]
                k = steps if key not in ("random50", "talos") else max(steps // 3, 5)
                try:
                    rows, flags = run(name, build, k, python=not args.no_python)
                except FileNotFoundError as exc:  # example-robot-data missing
                    notes.append(f"{name} skipped: {exc}.")
                    continue
                results.setdefault(name, []).append(rows)
                if flags - {1, 2}:
                    notes.append(f"{name}: daqp exit flags {sorted(flags)}.")
        oracle = "the oracle of every 10th step" if args.no_python else "timed, every step"
        print(
            f"Median µs per step, {steps} steps per scenario (random50, talos: a third), "
            f"the range over {args.runs} run(s); Python engine {oracle}; level diff: "
            "max |Δr| / max(1, r) to the Python engine's level values:\n"
        )
        print(summary(results))
        if args.percentiles:
            print("\n" + percentiles(results))
        for line in dict.fromkeys(notes):
            print(line)
        if not args.one_shot:
            return 0
        print(
            "\nOne-shot: `qc.solve_stack` of a 7-variable, 3-level stack against one direct "
            "`daqp.solve` of the weighted QP:\n"
        )
        shots = one_shot(steps)
        floor = shots[-1][1]  # the direct daqp.solve of the weighted QP
        head = ("call", "median µs", "p90 µs", "p99 µs", "median / direct daqp.solve")
        body = [(r[0], *(f"{v:.1f}" for v in r[1:]), f"{r[1] / floor:.1f}×") for r in shots]
        print(markdown(head, body, "lrrrr"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
