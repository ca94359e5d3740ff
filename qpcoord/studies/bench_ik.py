"""Side-by-side differential IK on the Franka Panda: qpcoord vs Pink (``qpcoord bench ik``).

The same task for every controller, from the same start, stepping in lockstep (one step of
each controller in turn, the order rotating each step, so machine noise hits all alike):

- end-effector **position** target (frame ``panda_hand_tcp``), a waypoint that changes
  every quarter of the run (or, in the ``tight`` scenario, a horizontal circle of 0.1 m
  radius run in 2 s, with the speed bounds lowered to 0.8 rad/s so that they bind on about
  a third of the steps);
- **posture** task toward the start configuration;
- joint **position limits** (gain 0.5, as Pink's default) and joint **velocity bounds**
  (the Panda's, or 0.8 rad/s in ``tight``), hard.

Controllers:

- ``pink``: ``pink.solve_ik`` (one weighted QP: ``FrameTask`` with position cost 1 and no
  orientation cost, ``PostureTask`` cost ``1e-3``, Pink's configuration and velocity
  limits) and ``Configuration.integrate_inplace``;
- ``qpcoord hierarchical``: an :class:`~qpcoord.IK` with the position task strictly above
  the posture task, limits merged into hard bounds;
- ``qpcoord weighted``: the same stack solved as one weighted QP (``weight_ratio`` 1e-3).

Gains match Pink's convention (Pink's task gain ``α`` per step is a CLIK gain
``α/dt``; qpcoord's position task also gets the path's feed-forward velocity when the
target moves, Pink's cannot). The time of one step includes the kinematics update, the
task updates, the QP(s) and the integration. BLAS runs on one thread. Absolute times vary
up to 2× between runs on a small shared machine: compare ratios within one run.
"""

from __future__ import annotations

import time

import numpy as np

from ..kinematics.ik import IK
from ..kinematics.paths import HorizontalCircle, Path
from ..kinematics.tasks import JointLimits, PositionTask, PostureTask, VelocityLimits
from ..robots import load

__all__ = ["run_ik_bench", "format_ik_table", "PANDA_Q0", "pink_available"]

#: Start configuration of the Panda (rad), away from its limits.
PANDA_Q0 = np.array([0.0, -0.4, 0.0, -2.2, 0.0, 1.9, 0.8])
#: Waypoint offsets from the start position (m), one per quarter of the run.
WAYPOINTS = np.array([[0.15, 0.0, 0.0], [0.0, 0.15, -0.1], [-0.1, -0.1, 0.1], [0.05, 0.1, 0.0]])
#: Task gain per step (Pink's ``α``) of the position and posture tasks.
ALPHA = 0.05
POSTURE_COST = 1e-3
TIGHT_SPEED = 0.8  # rad/s
TIGHT_RADIUS = 0.1  # m
TIGHT_PERIOD = 2.0  # s


def pink_available() -> bool:
    """Is ``pin-pink`` importable (the ``bench`` extra)?"""
    try:
        import pink  # noqa: F401
    except ImportError:
        return False
    return True


class _QpcoordLoop:
    def __init__(self, method: str, robot, q0, dt, speed, solver) -> None:
        self.name = f"qpcoord {method}"
        self.robot = robot
        self.q = q0.copy()
        self.dt = dt
        self.ee = PositionTask(robot, gain=ALPHA / dt)
        posture = PostureTask(robot, q0, gain=ALPHA / dt)
        # Pink's ConfigurationLimit(model, 0.5): the damper at every distance
        limits = [JointLimits(robot, gain=0.5, band=np.inf), VelocityLimits(robot, speed)]
        self.ik = IK(robot, [self.ee, posture], dt, limits=limits, method=method, solver=solver)

    def step(self, t: float, target) -> np.ndarray:
        self.ee.set_target(target)  # validated, as Pink's set_target
        v, _ = self.ik.step(self.q, t)
        self.q = self.q + self.dt * v
        return v

    def position(self) -> np.ndarray:
        return self.robot.position(self.q)


class _PinkLoop:
    name = "pink"

    def __init__(self, robot, q0, dt, speed, solver) -> None:
        import pink
        import pinocchio as pin
        from pink.limits import ConfigurationLimit, VelocityLimit
        from pink.tasks import FrameTask, PostureTask

        self.pink, self.pin = pink, pin
        model = robot.model.copy() if hasattr(robot.model, "copy") else robot.model
        model.velocityLimit[:] = speed
        self.model = model
        self.frame = robot.frame
        self.conf = pink.Configuration(model, model.createData(), q0.copy())
        self.ee = FrameTask(robot.frame, position_cost=1.0, orientation_cost=0.0, gain=ALPHA)
        self.posture = PostureTask(cost=POSTURE_COST, gain=ALPHA)
        self.posture.set_target(q0.copy())
        self.limits = [ConfigurationLimit(model, 0.5), VelocityLimit(model)]
        self.dt = dt
        self.solver = solver
        self._goal = self.conf.get_transform_frame_to_world(self.frame).copy()

    def step(self, t: float, target) -> np.ndarray:
        p = target.position(t) if isinstance(target, Path) else target
        self._goal.translation = p
        self.ee.set_target(self._goal)
        v = self.pink.solve_ik(
            self.conf, [self.ee, self.posture], self.dt, solver=self.solver, limits=self.limits
        )
        self.conf.integrate_inplace(v, self.dt)
        return v

    def position(self) -> np.ndarray:
        return self.conf.get_transform_frame_to_world(self.frame).translation.copy()


def run_ik_bench(
    steps: int = 2000,
    solver: str = "daqp",
    scenario: str = "waypoints",
    dt: float = 1e-3,
    include_pink: bool | None = None,
) -> list[dict]:
    """Run the lockstep comparison; one result row per controller.

    Parameters
    ----------
    steps : int
        Control steps per controller (≥ 2000 for the published table).
    solver : str
        QP backend for every controller.
    scenario : {"waypoints", "tight"}
        Four position waypoints with the Panda's speed limits, or a fast circle with
        0.45 rad/s bounds (binding).
    dt : float
        Control period (s).
    include_pink : bool, optional
        Default: when ``pin-pink`` is installed.

    Returns
    -------
    list of dict
        ``controller``, ``median_us``, ``p90_us``, ``final_error_m`` (distance to the
        target at the end of the run), ``max_error_m`` (largest distance at the end of a
        waypoint segment, or along the circle after its first 10 % in ``tight``),
        ``bound_steps`` (steps with a joint speed at its bound), ``steps``,
        ``scenario``, ``solver``.
    """
    if scenario not in ("waypoints", "tight"):
        raise ValueError(f"scenario must be 'waypoints' or 'tight', got {scenario!r}")
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 8:
        raise ValueError(f"steps must be an integer >= 8, got {steps!r}")
    robot = load("panda")
    q0 = PANDA_Q0.copy()
    y0 = robot.position(q0)
    speed = robot.velocity_limit.copy() if scenario == "waypoints" else TIGHT_SPEED
    if include_pink is None:
        include_pink = pink_available()
    loops: list = [
        _QpcoordLoop("hierarchical", load("panda"), q0, dt, speed, solver),
        _QpcoordLoop("weighted", load("panda"), q0, dt, speed, solver),
    ]
    if include_pink:
        loops.append(_PinkLoop(load("panda"), q0, dt, speed, solver))
    circle = HorizontalCircle(y0, TIGHT_RADIUS, TIGHT_PERIOD)
    seg = max(1, steps // len(WAYPOINTS))
    times = np.zeros((len(loops), steps))
    errors = np.zeros((len(loops), steps))
    at_bound = np.zeros((len(loops), steps), dtype=bool)
    scored = np.zeros(steps, dtype=bool)
    limit = np.broadcast_to(speed, (robot.nq,))
    for k in range(steps):
        t = k * dt
        if scenario == "tight":
            target = circle
            scored[k] = t >= 0.1 * steps * dt
        else:
            i = min(k // seg, len(WAYPOINTS) - 1)
            target = y0 + WAYPOINTS[i]
            scored[k] = (k + 1) % seg == 0 or k == steps - 1  # end of each segment
        for j in range(len(loops)):
            idx = (j + k) % len(loops)
            t0 = time.perf_counter()
            v = loops[idx].step(t, target)
            times[idx, k] = time.perf_counter() - t0
            at_bound[idx, k] = bool(np.any(np.abs(v) >= limit * (1 - 1e-6)))
        for j, loop in enumerate(loops):
            goal = target.position(t + dt) if isinstance(target, Path) else target
            errors[j, k] = float(np.linalg.norm(loop.position() - goal))
    rows = []
    for j, loop in enumerate(loops):
        ts = times[j, steps // 10 :] * 1e6  # the first 10 % warm caches up
        rows.append(
            {
                "controller": loop.name,
                "median_us": float(np.median(ts)),
                "p90_us": float(np.percentile(ts, 90)),
                "final_error_m": float(errors[j, -1]),
                "max_error_m": float(errors[j, scored].max()),
                "bound_steps": int(at_bound[j].sum()),
                "steps": steps,
                "scenario": scenario,
                "solver": solver,
            }
        )
    return rows


def format_ik_table(rows: list[dict]) -> str:
    """Markdown table of :func:`run_ik_bench` rows, with time ratios to Pink."""
    pink = {r["scenario"]: r for r in rows if r["controller"] == "pink"}
    lines = [
        "| scenario | controller | solver | median µs/step | p90 µs/step | vs Pink (median) "
        "| final error (m) | max error (m) | steps at a speed bound |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        ref = pink.get(r["scenario"])
        ratio = f"{r['median_us'] / ref['median_us']:.2f}" if ref else "n/a"
        lines.append(
            f"| {r['scenario']} | {r['controller']} | {r['solver']} | {r['median_us']:.0f} "
            f"| {r['p90_us']:.0f} | {ratio} | {r['final_error_m']:.2e} "
            f"| {r['max_error_m']:.2e} | {r['bound_steps']}/{r['steps']} |"
        )
    return "\n".join(lines)
