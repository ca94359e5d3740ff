"""``qpcoord demo``: a small end-to-end stack solve with a readable report.

The thesis's 3R planar arm (unit links, absolute joint angles, ``x = Σ cos qᵢ``,
``y = Σ sin qᵢ``) tracks one period of a circle with velocity-level IK. Each control step
solves a three-level stack:

0. end-effector velocity (Equality, 2 rows, m/s);
1. keep joint 1 within a band around π/2 (Inequality on the next position, rad);
2. pull all joints towards a rest posture (Equality, rad/s);

with joint-velocity Bounds (rad/s). The same loop runs with the strict hierarchy and with
one weighted QP, and the report compares tracking error and band violation.
"""

from __future__ import annotations

import numpy as np

from ..core.stack import Stack
from ..core.tasks import Bounds, Equality, Inequality

__all__ = ["planar_3r_position", "planar_3r_jacobian", "run_demo"]


def planar_3r_position(q: np.ndarray) -> np.ndarray:
    """End-effector position (m) of the unit-link 3R arm with absolute angles ``q`` (rad)."""
    return np.array([np.cos(q).sum(), np.sin(q).sum()])


def planar_3r_jacobian(q: np.ndarray) -> np.ndarray:
    """Position Jacobian (m/rad, 2 × 3) of the 3R arm in absolute angles."""
    return np.vstack((-np.sin(q), np.cos(q)))


def _track(method: str, solver: str | None, steps: int, dt: float):
    period = steps * dt
    w = 2 * np.pi / period
    centre, radius = np.array([1.0, 1.2]), 0.5
    q = np.array([np.pi / 2, 0.3, -0.6])
    # start on the circle: Newton steps on joints 2 and 3 (joint 1 stays at π/2)
    target0 = centre + radius * np.array([1.0, 0.0])
    for _ in range(50):
        J = planar_3r_jacobian(q)[:, 1:]
        q[1:] += np.linalg.solve(J, target0 - planar_3r_position(q))
    q_rest = np.array([np.pi / 2, np.pi / 2, np.pi / 2])
    band = (np.pi / 2 - 0.6, np.pi / 2 + 0.6)
    ee = Equality(np.zeros((2, 3)), np.zeros(2), name="end effector")
    keep = Inequality(np.array([[dt, 0.0, 0.0]]), lower=0.0, upper=0.0, name="joint-1 band")
    posture = Equality(np.eye(3), np.zeros(3), name="posture")
    stack = Stack([ee, keep, posture], bounds=Bounds(-2.0, 2.0, name="joint speed"))
    sol = None
    err_max, band_viol, qp_calls, t_solve = 0.0, 0.0, 0, []
    q_start = q.copy()
    for k in range(steps):
        t = k * dt
        p_ref = centre + radius * np.array([np.cos(w * (t + dt)), np.sin(w * (t + dt))])
        v = (p_ref - planar_3r_position(q)) / dt  # feed-forward + correction, m/s
        ee.update(A=planar_3r_jacobian(q), b=v)
        keep.update(lower=band[0] - q[0], upper=band[1] - q[0])
        posture.update(b=1.0 * (q_rest - q))
        sol = stack.solve(solver=solver, method=method, warm_start=sol)
        q = q + dt * sol.x
        err_max = max(err_max, float(np.linalg.norm(planar_3r_position(q) - p_ref)))
        band_viol = max(band_viol, band[0] - q[0], q[0] - band[1])
        qp_calls += sol.info.get("qp_calls", 0)
        t_solve.append(sol.solve_time)
    return {
        "method": method,
        "solver": sol.solver,
        "max tracking error (m)": err_max,
        "max band violation (rad)": max(band_viol, 0.0),
        "joint closure after 1 period (rad)": float(np.linalg.norm(q - q_start)),
        "QPs per step": qp_calls / steps,
        "median solve (µs)": float(np.median(t_solve) * 1e6),
    }


def run_demo(solver: str | None = None, steps: int = 400, period: float = 4.0) -> str:
    """Run the demo and return its report (plain text).

    Parameters
    ----------
    solver : str, optional
        QP backend (default: fastest installed).
    steps : int
        Control steps over one period of the circle.
    period : float
        Period of the circle, s.
    """
    if steps < 2:
        raise ValueError(f"steps must be >= 2, got {steps}")
    dt = period / steps
    rows = [_track(m, solver, steps, dt) for m in ("hierarchical", "weighted")]
    keys = list(rows[0])
    width = max(len(k) for k in keys)
    lines = [
        "qpcoord demo: 3R planar arm (thesis §3.1.2) tracking a circle, "
        f"{steps} steps of {dt * 1e3:.1f} ms",
        "stack: 0) end-effector velocity  1) joint-1 band [π/2 ± 0.6]  2) rest posture;"
        " |dq| ≤ 2 rad/s",
        "",
    ]
    for k in keys:
        cells = []
        for r in rows:
            v = r[k]
            cells.append(f"{v:>14.3e}" if isinstance(v, float) else f"{v!s:>14}")
        lines.append(f"{k:<{width}}  " + "".join(cells))
    lines.append("")
    lines.append(
        "Both methods track the circle to the Euler-integration error (the end-effector "
        "level is met at every step). The strict hierarchy keeps the joint-1 band "
        "(priority 1) against the posture (priority 2); the weighted QP trades them off and "
        "leaves the band by the violation shown."
    )
    return "\n".join(lines)
