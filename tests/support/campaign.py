"""Seeded campaign of random and degenerate stacks, judged against the exact reference.

``make_stack(kind, seed)`` builds one stack of a degeneracy kind (:data:`KINDS`);
``judge(stack_spec, solver)`` solves it with qpcoord and compares every level with the
cvxpy lexicographic reference of :mod:`support.oracle` with ``polish=True`` (each equality
level made exact by BVLS / a verified active set). The normal suite runs a small sample
(``tests/core/test_campaign.py``), the ``slow`` marker 1 000 stacks of each kind;
``PYTHONPATH=tests python -m support.campaign N`` prints the counts per backend.

A level is *wrong* when its residual is above the reference's by more than ``WRONG_TOL``
of the level's scale (``‖b‖ + ‖A‖_F·‖x‖`` over its tasks, finite limits counted like
``b``); a wrong level on a solution whose ``status`` is ``"optimal"`` is *silent*. A level
is *worsened* when its squared residual is above the reference's by more than
``WORSEN_TOL`` of its squared scale while a lower level is better than the reference.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numpy as np

import qpcoord as qc

KINDS = (
    "random",
    "var_scaled",
    "row_scaled",
    "near_parallel",
    "active_bounds",
    "inequality_levels",
    "infeasible_soft",
)
WRONG_TOL = 1e-6
WORSEN_TOL = 1e-9


@dataclass
class Spec:
    kind: str
    seed: int
    levels: list
    bounds: object
    n: int


def _ineq(rng, C, x_feas, slack, kind_rng_open=0.3):
    """Inequality rows ``C`` around ``C x_feas`` with some sides open."""
    m = C.shape[0]
    cx = C @ x_feas
    lo = cx - slack * rng.uniform(0.0, 1.0, m)
    hi = cx + slack * rng.uniform(0.0, 1.0, m)
    lo[rng.uniform(size=m) < kind_rng_open] = -np.inf
    hi[rng.uniform(size=m) < kind_rng_open] = np.inf
    return lo, hi


def make_stack(kind: str, seed: int) -> Spec:
    """One seeded stack of the given degeneracy kind (see :data:`KINDS`)."""
    rng = np.random.default_rng([KINDS.index(kind), seed])
    n = int(rng.integers(3, 9))
    n_levels = int(rng.integers(1, 5))
    colscale = np.ones(n)
    if kind == "var_scaled":
        colscale = 10.0 ** rng.uniform(-3, 3, n)
    levels = []
    x_ref = rng.normal(size=n) / colscale  # a point in the natural units of the variables
    for _k in range(n_levels):
        tasks = []
        m = int(rng.integers(1, n + 1))
        A = rng.normal(size=(m, n))
        if kind == "near_parallel" and m >= 2:
            # one near-parallel pair per level (condition up to ~1e6, under the damping
            # threshold: a cluster of such rows makes levels of condition 1e9 that the
            # reference itself cannot solve to 1e-6)
            A[1] = A[0] + 10.0 ** rng.uniform(-6, -3) * rng.normal(size=n)
        if kind == "row_scaled":
            A *= 10.0 ** rng.uniform(-3, 3, m)[:, None]
        A = A / colscale  # x_j in units scaled by 1/colscale_j
        b = A @ x_ref + rng.normal(size=m) * float(np.abs(A @ x_ref).max() + 1.0)
        w = rng.uniform(0.5, 10.0, m) if rng.uniform() < 0.5 else 1.0
        tasks.append(qc.Equality(A, b, weight=w))
        if kind in ("inequality_levels", "infeasible_soft") or (
            kind == "random" and rng.uniform() < 0.3
        ):
            mi = int(rng.integers(1, n + 1))
            C = rng.normal(size=(mi, n)) / colscale
            if kind == "infeasible_soft" and mi >= 2:
                C[1] = -C[0]
                lo, hi = _ineq(rng, C, x_ref, 1.0, 0.0)
                lo[1] = -hi[0] + 0.5 + rng.uniform()  # C0 x ≤ hi0 and C0 x ≥ -lo1 > hi0
                hi[1] = np.inf
            else:
                lo, hi = _ineq(rng, C, x_ref + rng.normal(size=n) / colscale, 0.5)
            tasks.append(qc.Inequality(C, lo, hi, weight=float(rng.uniform(0.5, 5.0))))
        levels.append(tasks if len(tasks) > 1 else tasks[0])
    bounds = None
    if kind in ("active_bounds", "var_scaled", "row_scaled", "near_parallel") or (
        rng.uniform() < 0.5
    ):
        # var_scaled: half the stacks keep the box in unscaled units (tight on the large-
        # column variables, loose on the small ones, as in a 4x5 example)
        bscale = colscale if (kind != "var_scaled" or seed % 2) else np.ones(n)
        half = rng.uniform(0.005, 1.5, n) / bscale
        centre = rng.normal(scale=0.3, size=n) / bscale
        lb, ub = centre - half, centre + half
        lb[rng.uniform(size=n) < 0.3] = -np.inf
        ub[rng.uniform(size=n) < 0.3] = np.inf
        bounds = qc.Bounds(lb, ub)
    return Spec(kind, seed, levels, bounds, n)


def level_scales(levels, x) -> np.ndarray:
    """``‖b‖ + ‖A‖_F·‖x‖`` per level (finite inequality limits count like ``b``)."""
    out = []
    nx = float(np.linalg.norm(x))
    for lv in levels:
        tasks = lv if isinstance(lv, list) else [lv]
        s = 0.0
        for t in tasks:
            sw = np.sqrt(t.weight)
            if isinstance(t, qc.Equality):
                s += float(np.linalg.norm(sw * t.b) + np.linalg.norm(sw[:, None] * t.A) * nx)
            else:
                lim = np.concatenate([t.lower[np.isfinite(t.lower)], t.upper[np.isfinite(t.upper)]])
                s += float(np.linalg.norm(lim) * sw.max() + np.linalg.norm(sw[:, None] * t.C) * nx)
        out.append(max(s, 1e-300))
    return np.array(out)


@dataclass
class Verdict:
    wrong_level: int | None  # first level above the reference beyond WRONG_TOL (None: right)
    status: str  # solution status, or "error: ..."
    worsened: bool
    better: bool  # a level below the reference beyond WRONG_TOL (the reference is off?)
    time: float
    gap: float  # relative gap of the first wrong level


def reference(spec: Spec):
    from .oracle import lexicographic

    return lexicographic(spec.levels, spec.bounds, polish=True)


def bvls_level0(spec: Spec) -> float | None:
    """Exact level-0 residual by scipy's bounded least squares (BVLS, an active-set method
    independent of the library and of the conic reference), where level 0 is a bounded
    least-squares problem: equality tasks only. ``None`` where it does not apply."""
    from scipy.optimize import lsq_linear

    lv = spec.levels[0]
    tasks = lv if isinstance(lv, list) else [lv]
    if not all(isinstance(t, qc.Equality) for t in tasks):
        return None
    A = np.vstack([np.sqrt(t.weight)[:, None] * t.A for t in tasks])
    b = np.concatenate([np.sqrt(t.weight) * t.b for t in tasks])
    if spec.bounds is None:
        x = np.linalg.lstsq(A, b, rcond=None)[0]
    else:
        lb, ub = spec.bounds.resolve(spec.n)
        x = lsq_linear(A, b, bounds=(lb, ub), method="bvls", tol=1e-15).x
    return float(np.linalg.norm(A @ x - b))


def judge(spec: Spec, ref, solver: str, damping: float = 0.0, **solve_options) -> Verdict:
    """Solve ``spec`` with ``solver`` and compare it level by level with ``ref``.

    ``damping=0`` by default: the reference is the exact lexicographic optimum, and the
    damping of near-singular levels (condition above 1/damping) is a documented deviation
    from it (near-parallel rows reach 1e7 here).

    A stack flagged *worsened* whose level 0 is a bounded least-squares problem is
    re-judged at level 0 against scipy's BVLS (exact there): if the library's level 0 is
    within ``WORSEN_TOL`` of BVLS's, the reference's level 0 was the one off (it slid
    along a weak singular direction, see ``test_near_parallel_stacks_need_the_exact_
    reference``) and the stack is not counted as worsened at level 0. (With the polished
    reference, ``polish=True``, this no longer happens in the campaign; kept as a guard.)
    """
    t0 = time.perf_counter()
    try:
        stack = qc.Stack(spec.levels, bounds=spec.bounds, damping=damping)
        sol = stack.solve(solver=solver, **solve_options)
    except qc.SolverError as exc:
        return Verdict(None, f"error: {exc}", False, False, time.perf_counter() - t0, 0.0)
    dt = time.perf_counter() - t0
    ours = sol.level_residuals
    theirs = ref.level_optima
    scale = level_scales(spec.levels, ref.x)
    d = (ours - theirs) / scale
    wrong = None
    better = False
    for k in range(len(ours)):
        if d[k] > WRONG_TOL:
            wrong = k
            break
        if d[k] < -WRONG_TOL:
            better = True
            break
    worse2 = (ours**2 - theirs**2) / scale**2
    flagged = [
        k
        for k in range(len(ours))
        if worse2[k] > WORSEN_TOL and (worse2[k + 1 :] < -WORSEN_TOL).any()
    ]
    if flagged == [0]:
        exact = bvls_level0(spec)
        if exact is not None and (ours[0] ** 2 - exact**2) / scale[0] ** 2 <= WORSEN_TOL:
            flagged = []
            better = True  # the reference's level 0 is above the exact optimum
    gap = float(d[wrong]) if wrong is not None else 0.0
    return Verdict(wrong, sol.status, bool(flagged), better, dt, gap)


def _zero():
    return dict(
        stacks=0, silent=0, inaccurate=0, errors=0, worsened=0, better=0, over10=0, tmax=0.0
    )


def run(n_per_kind: int, solvers, seed0: int = 0, log=None, damping: float = 0.0, kinds=KINDS):
    """Judge ``n_per_kind`` stacks of each kind (seeds from ``seed0`` on, skipping those
    the reference cannot solve: infeasible, or its self-check failed) on every solver.

    Returns ``(counts, per_kind, bad)``: ``counts[solver]`` totals (silent wrong, flagged
    inaccurate, errors, worsened, reference beaten, solves over 10 s, times),
    ``per_kind[solver][kind]`` the same per kind, and the silent wrong levels as
    ``(solver, kind, seed, level, gap)``.
    """
    from .oracle import OracleError

    counts = {s: dict(_zero(), t=[]) for s in solvers}
    per_kind = {s: {k: _zero() for k in kinds} for s in solvers}
    bad = []
    worsened = []  # (solver, kind, seed)
    skipped = {k: 0 for k in kinds}
    for kind in kinds:
        done = 0
        seed = seed0
        while done < n_per_kind and seed < seed0 + 3 * n_per_kind:
            spec = make_stack(kind, seed)
            seed += 1
            try:
                ref = reference(spec)
            except (OracleError, qc.InfeasibleError):
                skipped[kind] += 1
                continue
            done += 1
            for s in solvers:
                v = judge(spec, ref, s, damping=damping)
                for c in (counts[s], per_kind[s][kind]):
                    c["stacks"] += 1
                    c["tmax"] = max(c["tmax"], v.time)
                    c["over10"] += v.time > 10.0
                    if v.status.startswith("error"):
                        c["errors"] += 1
                    elif v.wrong_level is not None and v.status == "optimal":
                        c["silent"] += 1
                    elif v.status != "optimal":
                        c["inaccurate"] += 1
                    c["worsened"] += v.worsened
                    c["better"] += v.better
                counts[s]["t"].append(v.time)
                if v.wrong_level is not None and v.status == "optimal":
                    bad.append((s, kind, spec.seed, v.wrong_level, v.gap))
                if v.worsened:
                    worsened.append((s, kind, spec.seed))
    if log is not None:
        print(f"reference skipped (infeasible or self-check): {skipped}", file=log)
        for s, c in counts.items():
            t = np.array(c["t"]) if c["t"] else np.zeros(1)
            print(
                f"{s:9s} stacks {c['stacks']:5d} silent-wrong {c['silent']:4d} "
                f"inaccurate {c['inaccurate']:4d} errors {c['errors']:3d} "
                f"worsened {c['worsened']:3d} ref-beaten {c['better']:3d} "
                f"over-10s {c['over10']} "
                f"median {np.median(t) * 1e3:.2f} ms max {t.max() * 1e3:.1f} ms",
                file=log,
            )
        print(
            "| backend | kind | stacks | silent wrong | inaccurate | errors | worsened "
            "| ref beaten | > 10 s | max time |",
            file=log,
        )
        print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|", file=log)
        for s in solvers:
            for k, c in per_kind[s].items():
                print(
                    f"| {s} | {k} | {c['stacks']} | {c['silent']} | {c['inaccurate']} | "
                    f"{c['errors']} | {c['worsened']} | {c['better']} | {c['over10']} | "
                    f"{c['tmax'] * 1e3:.1f} ms |",
                    file=log,
                )
        for w in worsened:
            print("worsened", w, file=log)
        log.flush()
    return counts, per_kind, bad


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    solvers = sys.argv[2].split(",") if len(sys.argv) > 2 else qc.available_solvers()
    damping = float(sys.argv[3]) if len(sys.argv) > 3 else 0.0
    t0 = time.perf_counter()
    _, _, bad = run(n, solvers, log=sys.stdout, damping=damping)
    print(f"wall time {time.perf_counter() - t0:.0f} s")
    for b in bad[:40]:
        print("silent", b)
