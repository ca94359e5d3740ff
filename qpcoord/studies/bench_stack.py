"""Per-step benchmark of a 3-level stack in a closed control loop (``qpcoord bench stack``).

The scenario is a velocity-level IK loop of a spatial serial chain with ``n`` revolute
joints (7 and 30 by default), re-solving one :class:`~qpcoord.Stack` built once:

- level 0: ``Equality(J(q), v)`` -- 6-D end-effector twist tracking a smooth target
  (feed-forward plus proportional feedback on the pose error);
- level 1: ``Inequality(dt·I, q_min − q, q_max − q)`` -- joint-position limits on the next
  configuration ``q + dt·x``;
- level 2: ``Equality(I, k·(q_rest − q))`` -- posture;
- ``Bounds(−dq_max, dq_max)`` -- joint-velocity limits, always hard.

The loop integrates ``q ← q + dt·x`` with the method's own solution, so consecutive steps
are similar (realistic warm starts, ``warm_start`` = previous :class:`~qpcoord.Solution`)
and the velocity bounds and position limits become active part of the time. Every
method/backend pair runs its own closed loop from the same initial state and target.
``method="nullspace"`` cannot take inequalities or bounds: it runs the same loop on the
stack without level 1 and without bounds (a 2-level equality stack).

Each timed step is ``task.update(...)`` for the three tasks plus ``stack.solve(...)``
(kinematics and target generation are outside the timer), with BLAS limited to one
thread (threadpoolctl). Only ratios measured within one run are meaningful: absolute
times vary up to 2× between runs on a small shared machine.
"""

from __future__ import annotations

import contextlib
import gc
import io
import math
import time

import numpy as np

from ..core.backends import available_solvers
from ..core.errors import InfeasibleError, SolverError
from ..core.stack import Stack
from ..core.tasks import Bounds, Equality, Inequality

__all__ = [
    "ChainScenario",
    "SLOW_SOLVERS",
    "format_table",
    "hierarchical_weighted_ratios",
    "run_case",
    "run_loops",
    "run_stack_bench",
]

#: Backends that convert to sparse form (or iterate to tight tolerances) and are 10–100×
#: slower on these tiny dense QPs. The full run gives them all the steps (it still takes
#: about a minute here); ``slow_steps`` can cut them, and quick mode does.
SLOW_SOLVERS = ("osqp", "scs", "clarabel", "highs")
#: Steps per loop in quick mode (all backends / :data:`SLOW_SOLVERS`).
QUICK_STEPS = 25
QUICK_SLOW_STEPS = 5

#: Relative tolerance used to classify a bound / limit row as active (interior-point
#: backends stop 1e-12–1e-8 inside an active bound).
ACTIVE_TOL = 1e-6

#: Joint-speed limit of the 7-joint chain (rad/s); scaled by 7/n for other sizes.
DQ_MAX_7 = 1.2

METHOD_ORDER = ("hierarchical", "weighted", "nullspace")


def _rot(axis: int, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    if axis == 2:  # z
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    if axis == 1:  # y
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _vee_skew(M: np.ndarray) -> np.ndarray:
    """Rotation-error vector ``½ vee(M − Mᵀ)``."""
    return 0.5 * np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])


class ChainScenario:
    """Closed-loop IK scenario for a spatial chain of ``n`` revolute joints.

    Joint axes alternate z / y (a Panda-like 7-joint arm for ``n = 7``, a snake for
    ``n = 30``) and the link lengths add up to 1 m. The rest posture is the best-conditioned
    of 300 random postures (away from singularities); the joint-position limits are a
    random window of half-width (0.5–1.2)·7/n rad around it and the speed limits are
    (0.6–1.4)·1.2·7/n rad/s (joint motions shrink about as 1/n along a chain of fixed
    length), so that bounds and limits are active part of the time. The target pose moves
    along a smooth Lissajous curve (amplitude 0.12 m, 0.25 Hz) with a small orientation
    oscillation; the task twist is feed-forward plus proportional feedback.

    Parameters
    ----------
    n : int
        Number of joints (decision variables).
    seed : int
        Seed of the random limits and rest posture offsets.
    dt : float
        Control period in s (the loop integrates ``q += dt·x``).
    """

    task_dim = 6

    def __init__(self, n: int, seed: int = 0, dt: float = 0.01) -> None:
        n = int(n)
        if n < 6:
            raise ValueError(f"n must be >= 6 for a 6-D task, got {n}")
        rng = np.random.default_rng(seed + 1000 * n)
        self.n = n
        self.dt = float(dt)
        self.axes = [2 if i % 2 == 0 else 1 for i in range(n)]
        self.lengths = np.full(n, 1.0 / n)
        # rest posture: the best-conditioned of a few hundred random postures (keeps the
        # 6-D task away from singularities along the motion)
        spread = 1.5 * math.sqrt(7.0 / n)
        best = -1.0
        for _ in range(300):
            cand = rng.uniform(-spread, spread, n)
            smin = np.linalg.svd(self.kinematics(cand)[2], compute_uv=False)[-1]
            if smin > best:
                best, self.q_rest = smin, cand
        # joint speeds and excursions shrink about as 1/n along a chain of total length 1 m
        scale = 7.0 / n
        width = rng.uniform(0.5, 1.2, n) * scale
        shift = rng.uniform(-0.5, 0.5, n) * width
        self.q_min = self.q_rest + shift - width
        self.q_max = self.q_rest + shift + width
        self.dq_max = rng.uniform(0.6, 1.4, n) * DQ_MAX_7 * scale
        self.k_posture = 2.0
        self.kp = 5.0
        self.kr = 5.0
        self.amplitude = 0.12
        self.freq = 0.25  # Hz
        self.p0, self.R0, _ = self.kinematics(self.q_rest)
        self.reset()

    # -- state ------------------------------------------------------------------------
    def reset(self) -> None:
        """Back to the initial state (rest posture, t = 0)."""
        self.q = self.q_rest.copy()
        self.t = 0.0

    def advance(self, x: np.ndarray) -> None:
        """Integrate one control period with the joint velocity ``x``."""
        self.q = self.q + self.dt * x
        self.t += self.dt

    # -- models -----------------------------------------------------------------------
    def kinematics(self, q: np.ndarray):
        """End-effector position, orientation and 6×n geometric Jacobian (world frame)."""
        n = self.n
        R = np.eye(3)
        p = np.zeros(3)
        origins = np.empty((n, 3))
        w = np.empty((n, 3))
        for i in range(n):
            a = self.axes[i]
            origins[i] = p
            w[i] = R[:, a]
            R = R @ _rot(a, q[i])
            p = p + self.lengths[i] * R[:, 0]
        J = np.empty((6, n))
        J[:3] = np.cross(w, p - origins).T
        J[3:] = w.T
        return p, R, J

    def target(self, t: float):
        """Target position, its velocity, and target orientation at time ``t``."""
        om = 2 * math.pi * self.freq
        a = self.amplitude
        s1, c1 = math.sin(om * t), math.cos(om * t)
        s2, c2 = math.sin(2 * om * t), math.cos(2 * om * t)
        p = self.p0 + a * np.array([s1, 0.6 * s2, 0.5 * (1 - c1)])
        v = a * om * np.array([c1, 1.2 * c2, 0.5 * s1])
        R = self.R0 @ _rot(2, 0.2 * s1)
        return p, v, R

    def numbers(self):
        """Task numbers at the current state: ``(J, v, lim_lo, lim_hi, posture_b)``."""
        p, R, J = self.kinematics(self.q)
        pd, vd, Rd = self.target(self.t)
        v = np.empty(6)
        v[:3] = vd + self.kp * (pd - p)
        v[3:] = self.kr * _vee_skew(Rd @ R.T)
        lo = self.q_min - self.q
        hi = self.q_max - self.q
        return J, v, lo, hi, self.k_posture * (self.q_rest - self.q)

    # -- stacks -----------------------------------------------------------------------
    def build(self, inequalities: bool = True):
        """``(stack, tasks)`` at the current state; tasks = ``(main, limits|None, posture)``.

        ``inequalities=False`` gives the 2-level equality stack (no limits level, no
        bounds) that ``method="nullspace"`` accepts.
        """
        J, v, lo, hi, pb = self.numbers()
        n = self.n
        main = Equality(J, v, name="ee twist")
        posture = Equality(np.eye(n), pb, name="posture")
        if not inequalities:
            return Stack([main, posture]), (main, None, posture)
        limits = Inequality(self.dt * np.eye(n), lo, hi, name="joint limits")
        bounds = Bounds(-self.dq_max, self.dq_max, name="velocity")
        return Stack([main, limits, posture], bounds=bounds), (main, limits, posture)

    def active(self, x: np.ndarray) -> tuple[bool, bool]:
        """(some velocity bound active, some position-limit row active or violated) at ``x``."""
        bnd = bool(np.any(np.abs(x) >= self.dq_max * (1.0 - ACTIVE_TOL)))
        qn = self.q + self.dt * x
        tq = ACTIVE_TOL * self.dt * self.dq_max
        lim = bool(np.any(qn <= self.q_min + tq) or np.any(qn >= self.q_max - tq))
        return bnd, lim


def _percentile(a: np.ndarray, p: float) -> float:
    return float(np.percentile(a, p)) if a.size else float("nan")


class _Loop:
    """One closed loop (its own scenario, stack, warm start and statistics)."""

    def __init__(
        self, n: int, method: str, solver: str | None, steps: int, seed: int, record: bool
    ) -> None:
        self.sc = ChainScenario(n, seed=seed)
        self.method = method
        self.eq_only = method == "nullspace"
        self.solver = None if self.eq_only else solver
        self.stack, (self.main, self.limits, self.posture) = self.sc.build(
            inequalities=not self.eq_only
        )
        self.steps = steps
        self.times = np.empty(steps)
        self.qp = np.zeros(steps, dtype=int)
        self.bnd = np.zeros(steps, dtype=bool)
        self.lim = np.zeros(steps, dtype=bool)
        self.res0 = np.full(steps, np.nan)
        self.record = record
        if record:
            self.xs = np.zeros((steps, n))
            self.qs = np.zeros((steps, n))
            self.residuals = np.full((steps, self.stack.num_levels), np.nan)
        self.failures: list[str] = []
        self.max_bviol = 0.0
        self.prev = None

    def warm_up(self) -> None:
        """Untimed solve at the initial state (imports, first-call allocations)."""
        self.prev = self.stack.solve(solver=self.solver, method=self.method)

    def step(self, k: int) -> None:
        sc = self.sc
        J, v, lo, hi, pb = sc.numbers()  # kinematics + target: not timed
        perf = time.perf_counter
        sol = None
        t0 = perf()
        try:
            self.main.update(A=J, b=v)
            if self.limits is not None:
                self.limits.update(lower=lo, upper=hi)
            self.posture.update(b=pb)
            sol = self.stack.solve(solver=self.solver, method=self.method, warm_start=self.prev)
            self.times[k] = perf() - t0
        except (SolverError, InfeasibleError) as exc:
            self.times[k] = perf() - t0
            self.failures.append(f"step {k}: {type(exc).__name__}: {exc}")
        if sol is None:
            x = np.zeros(sc.n)  # stop for one period and carry on
        else:
            x = sol.x
            self.prev = sol
            self.qp[k] = sol.info.get("qp_calls", 0)
            self.res0[k] = sol.level_residuals[0]
            if self.record:
                self.residuals[k] = sol.level_residuals
        if self.record:
            self.xs[k] = x
            self.qs[k] = sc.q
        self.bnd[k], self.lim[k] = sc.active(x)
        if not self.eq_only:
            self.max_bviol = max(self.max_bviol, float(np.max(np.abs(x) - sc.dq_max)))
        sc.advance(x)

    def row(self) -> dict:
        steps = self.steps
        us = self.times * 1e6
        eq_only = self.eq_only
        row = {
            "n": self.sc.n,
            "method": self.method,
            "solver": "none" if eq_only else (self.solver or "default"),
            "stack": "2 eq levels, no limits/bounds" if eq_only else "3 levels + bounds",
            "steps": steps,
            "median_us": _percentile(us, 50),
            "p90_us": _percentile(us, 90),
            "p99_us": _percentile(us, 99),
            "mean_us": float(us.mean()),
            # median over the steps that solved at least one QP (active bounds / limits)
            "qp_step_median_us": _percentile(us[self.qp > 0], 50),
            "qp_steps": int(np.count_nonzero(self.qp)),
            "qp_calls_mean": float(self.qp.mean()),
            "qp_calls_max": int(self.qp.max()),
            # the equality-only stack has no bounds / limits that could be active
            "bounds_active": float("nan") if eq_only else float(self.bnd.mean()),
            "limits_active": float("nan") if eq_only else float(self.lim.mean()),
            "task_residual_median": (
                float(np.nanmedian(self.res0)) if np.any(np.isfinite(self.res0)) else float("nan")
            ),
            "max_bound_violation": 0.0 if eq_only else max(0.0, self.max_bviol),
            "failures": len(self.failures),
            "failure_messages": self.failures[:5],
            "note": "",
        }
        if self.record:
            row["xs"], row["qs"], row["residuals"] = self.xs, self.qs, self.residuals
        return row


def run_loops(n: int, specs, steps: int, seed: int = 0, record: bool = False) -> list[dict]:
    """Run several closed loops in lockstep; one result row per ``(method, solver)`` spec.

    Every loop has its own scenario, stack and warm start; at each step the loops are
    stepped one after the other, in an order that alternates, so that load from other
    processes on the machine falls on all of them alike (the ratios between loops are
    the robust output of a noisy machine). With ``record=True`` each row also holds
    ``"xs"`` (steps × n solutions), ``"qs"`` (configurations they were solved at) and
    ``"residuals"`` (steps × levels).
    """
    from threadpoolctl import threadpool_limits

    steps = int(steps)
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    loops = [_Loop(n, m, s, steps, seed, record) for m, s in specs]
    # osqp prints "Polishing not needed ..." through sys.stdout even with verbose=False
    with threadpool_limits(limits=1), contextlib.redirect_stdout(io.StringIO()):
        for lp in loops:
            lp.warm_up()
        gc.collect()
        rev = loops[::-1]
        for k in range(steps):
            for lp in loops if k % 2 == 0 else rev:
                lp.step(k)
    return [lp.row() for lp in loops]


def run_case(
    n: int, method: str, solver: str | None, steps: int, seed: int = 0, record: bool = False
) -> dict:
    """One closed loop of ``steps`` warm-started steps (see :func:`run_loops`)."""
    return run_loops(n, [(method, solver)], steps, seed, record)[0]


def run_stack_bench(
    sizes=(7, 30),
    steps: int = 1000,
    solvers=None,
    quick: bool = False,
    seed: int = 0,
    methods=METHOD_ORDER,
    slow_steps: int | None = None,
) -> list[dict]:
    """Benchmark the 3-level stack for every size, method and installed backend.

    For each size and backend, the hierarchical and weighted loops run interleaved step by
    step (:func:`run_loops`); the nullspace loop (no backend) is interleaved with the
    first backend's pair.

    Parameters
    ----------
    sizes : sequence of int
        Numbers of joints (variables), each >= 6.
    steps : int
        Warm-started steps per closed loop.
    solvers : str or sequence of str, optional
        Backends to run (default: :func:`~qpcoord.available_solvers`). The nullspace
        method needs none and runs once per size whatever this is.
    quick : bool
        Smoke-test mode: at most 25 steps (5 for the slow sparse backends); a few seconds.
    seed : int
        Seed of the scenario (joint limits, speed limits, rest posture).
    methods : sequence of str
        Subset of ``("hierarchical", "weighted", "nullspace")``.
    slow_steps : int, optional
        Steps for :data:`SLOW_SOLVERS` (default: ``steps``, or 5 in quick mode; never more
        than ``steps``). Rows that got fewer steps say so in their ``note``.

    Returns
    -------
    list of dict
        One row per loop: ``n, method, solver, stack, steps, median_us, p90_us, p99_us,
        mean_us, qp_calls_mean, qp_calls_max, bounds_active, limits_active`` (fractions of
        steps; NaN for the equality-only nullspace stack), ``task_residual_median``
        (level 0), ``max_bound_violation``, ``failures``, ``failure_messages``, ``note``.
    """
    if isinstance(solvers, str):
        solvers = [solvers]
    installed = available_solvers()
    names = installed if solvers is None else list(dict.fromkeys(solvers))
    for s in names:
        if s not in installed:
            raise ValueError(
                f"unknown or uninstalled solver {s!r}; installed: {', '.join(installed)}"
            )
    methods = list(dict.fromkeys(methods))
    for m in methods:
        if m not in METHOD_ORDER:
            raise ValueError(f"unknown method {m!r}; choose from {', '.join(METHOD_ORDER)}")
    steps = int(steps)
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    if quick:
        steps = min(steps, QUICK_STEPS)
    if slow_steps is None:
        slow_steps = QUICK_SLOW_STEPS if quick else steps
    slow_steps = max(1, min(int(slow_steps), steps))
    qp_methods = [m for m in methods if m != "nullspace"]
    rows = []
    for n in sizes:
        ns_pending = "nullspace" in methods
        groups = []
        for s in names:
            specs = [(m, s) for m in qp_methods]
            if ns_pending and s not in SLOW_SOLVERS:
                specs.append(("nullspace", None))
                ns_pending = False
            if specs:
                groups.append((s, specs))
        if ns_pending:
            groups.append((None, [("nullspace", None)]))
        by_key = {}
        for s, specs in groups:
            k = slow_steps if s in SLOW_SOLVERS else steps
            for row in run_loops(n, specs, k, seed):
                if row["method"] == "nullspace":
                    row["note"] = "no limits level, no bounds"
                elif k < steps:
                    row["note"] = f"slow sparse backend: {k} steps"
                by_key[(row["method"], row["solver"])] = row
        for m in methods:
            for s in ["none"] if m == "nullspace" else names:
                rows.append(by_key[(m, s)])
    return rows


def _fmt(v: float, digits: int = 0) -> str:
    if v != v:  # nan
        return "-"
    return f"{v:.{digits}f}"


def hierarchical_weighted_ratios(rows: list[dict]) -> list[tuple[int, str, float, int]]:
    """``(n, solver, hierarchical median / weighted median, min steps)`` per pair in ``rows``."""
    by = {(r["n"], r["method"], r["solver"]): r for r in rows}
    out = []
    for (n, m, s), h in by.items():
        w = by.get((n, "weighted", s))
        if m == "hierarchical" and w is not None:
            out.append((n, s, h["median_us"] / w["median_us"], min(h["steps"], w["steps"])))
    return out


#: Fewer steps than this per loop: the ratio is printed but not judged against the target.
MIN_STEPS_TO_JUDGE = 100


def format_table(rows: list[dict]) -> str:
    """Plain-text table of :func:`run_stack_bench` rows, then the hierarchical/weighted
    median ratio per size and backend (acceptance target: ≤ 2 at n = 7)."""
    head = (
        "n",
        "method",
        "solver",
        "steps",
        "median µs",
        "p90 µs",
        "p99 µs",
        "QP-step med.",
        "QP/step",
        "QP max",
        "bounds act.",
        "limits act.",
        "fails",
        "note",
    )
    body = []
    for r in rows:
        body.append(
            (
                str(r["n"]),
                r["method"],
                r["solver"],
                str(r["steps"]),
                _fmt(r["median_us"]),
                _fmt(r["p90_us"]),
                _fmt(r["p99_us"]),
                _fmt(r.get("qp_step_median_us", float("nan"))),
                _fmt(r["qp_calls_mean"], 2),
                str(r["qp_calls_max"]),
                f"{100 * r['bounds_active']:.0f}%"
                if r["bounds_active"] == r["bounds_active"]
                else "-",
                f"{100 * r['limits_active']:.0f}%"
                if r["limits_active"] == r["limits_active"]
                else "-",
                str(r["failures"]),
                r.get("note", ""),
            )
        )
    widths = [max([len(h)] + [len(b[i]) for b in body]) for i, h in enumerate(head)]
    right = {0, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12}

    def line(cells):
        out = []
        for i, c in enumerate(cells):
            out.append(c.rjust(widths[i]) if i in right else c.ljust(widths[i]))
        return "  ".join(out).rstrip()

    lines = [line(head), line(["-" * w for w in widths])]
    lines += [line(b) for b in body]
    ratios = hierarchical_weighted_ratios(rows)
    if ratios:
        lines.append("")
        lines.append("hierarchical median / weighted median (same backend; target <= 2 at n = 7):")
        for n, s, q, k in ratios:
            if n != 7:
                flag = ""
            elif k < MIN_STEPS_TO_JUDGE:
                flag = f"  (only {k} steps: not judged)"
            else:
                flag = "  ok" if q <= 2.0 else "  NOT MET"
            lines.append(f"  n={n:<3d} {s:<10s} {q:5.2f}{flag}")
    lines.append("")
    lines.append(
        "Timed: task.update(...) x3 + stack.solve(warm_start=previous), BLAS limited to 1 "
        "thread; hierarchical and weighted loops of one backend run interleaved step by step.\n"
        "QP-step med.: median over the steps that solved >= 1 QP. QP/step: mean QP calls "
        "(sol.info['qp_calls']). bounds act. / limits act.: fraction of steps with a velocity\n"
        "bound / a joint-position limit row active (or violated). nullspace runs the stack "
        "without the limits level and without bounds (it takes equalities only)."
    )
    return "\n".join(lines)
