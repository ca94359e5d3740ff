"""Per-step time of the native IK step vs Python tasks + native solve vs the Python engine.

Scenarios (those of ``ik_peers.py``, 1 kHz): the Franka Panda's hand on a 0.1 m horizontal
circle run in 2 s through its start (``panda-position``: a ``FramePositionTask``;
``panda-pose``: a ``FrameTask`` holding the start orientation), deadbeat (gain ``1/dt``),
plus a posture task toward the start (gain ``0.05/dt``); hard ``JointLimits(gain=0.5)`` and
speed limits of 0.8 rad/s (they bind part of the time).

Paths, stepped in lockstep (one step of each in turn, the order rotating every step), each
from the same start with its own IK and tasks:

- ``native step``: ``IK(engine="native")`` (default): Pinocchio's ``computeJointJacobians``
  and one native call (task rows, limit box, strict hierarchy), then ``robot.integrate``;
- ``native step_integrate``: the same IK's ``step_integrate``: ``q_next`` written by the
  native call (no ``robot.integrate``);
- ``python tasks + native solve``: the tasks refreshed in Python, the stack solved natively:
  ``IK.refresh`` (the tasks' Python ``_refresh``, the limit boxes) then
  ``Stack.solve(engine="native")``;
- ``python engine``: ``IK(engine="python")`` (Python refresh, Python strict hierarchy, daqp).

A timed step is what a control loop does: ``set_target`` + the step + ``robot.integrate``
(``set_target`` + ``step_integrate`` for that path).
One BLAS thread. Printed: median / p90 / p99 (µs), each the range over the runs, and the
largest velocity difference to the native step over the runs (the three paths see the same
configurations: each steps from the native step's ``q``).

Run::

    python benchmarks/native_ik_step.py                 # 2000 steps, 3 runs, both scenarios
    python benchmarks/native_ik_step.py --steps 200 --runs 1
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from _table import markdown, preamble, span  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

import qpcoord as qc  # noqa: E402

DT = 1e-3  # s
ALPHA = 0.05  # posture: fraction of its error removed per step
PANDA_Q0 = np.array([0.0, -0.4, 0.0, -2.2, 0.0, 1.9, 0.8])  # rad
RADIUS, PERIOD = 0.1, 2.0  # m, s
SPEED = 0.8  # rad/s
FRAME = "panda_hand_tcp"
PATHS = ("native step", "native step_integrate", "python tasks + native solve", "python engine")


class Loop:
    """One path on one scenario: its own IK, tasks and configuration."""

    def __init__(self, robot: qc.Robot, pose: bool, path: str) -> None:
        self.robot, self.path = robot, path
        q0 = PANDA_Q0.copy()
        T0 = robot.frame_pose(q0, FRAME)
        self.rotation = T0[:3, :3].copy() if pose else None
        self.circle = qc.paths.HorizontalCircle(T0[:3, 3], radius=RADIUS, period=PERIOD)
        target = self._target(0)
        if pose:
            self.hand = qc.FrameTask(robot, FRAME, target, gain=1.0 / DT)
        else:
            self.hand = qc.FramePositionTask(robot, FRAME, target, gain=1.0 / DT)
        posture = qc.PostureTask(robot, q0, gain=ALPHA / DT)
        limits = [qc.JointLimits(robot, gain=0.5), qc.VelocityLimits(robot, SPEED)]
        engine = "python" if path == "python engine" else "native"
        if path == "python tasks + native solve":
            engine = "python"  # the IK refreshes in Python; its stack is solved natively
        self.ik = qc.IK(robot, [self.hand, posture], DT, limits=limits, engine=engine)
        self.native_solve = path == "python tasks + native solve"
        self.fused = path == "native step_integrate"

    def _target(self, k: int):
        p = self.circle.position((k + 1) * DT)
        if self.rotation is None:
            return p
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = self.rotation, p
        return T

    def step(self, k: int, q: np.ndarray) -> tuple[float, np.ndarray]:
        """Time (s) of set_target + step + integrate from q; the velocity."""
        ik, robot = self.ik, self.robot
        target = self._target(k)
        t0 = time.perf_counter()
        self.hand.set_target(target)
        if self.native_solve:
            qc_ = robot.check_configuration(q)
            ik.refresh(qc_)
            sol = ik.stack.solve(warm_start=ik.last, engine="native")
            ik.last = sol
            v = sol.x
        elif self.fused:
            _, v, _ = ik.step_integrate(q)
            return time.perf_counter() - t0, v
        else:
            v, _ = ik.step(q)
        robot.integrate(q, v, DT)
        return time.perf_counter() - t0, v


def run(robot: qc.Robot, pose: bool, steps: int) -> dict:
    loops = [Loop(robot, pose, p) for p in PATHS]
    times = {p: np.empty(steps) for p in PATHS}
    dv = dict.fromkeys(PATHS, 0.0)
    q = PANDA_Q0.copy()
    binding = 0
    for k in range(steps):
        order = [loops[(k + i) % len(loops)] for i in range(len(loops))]
        vs = {}
        for loop in order:
            dt, v = loop.step(k, q)
            times[loop.path][k] = dt
            vs[loop.path] = v
        for p in PATHS:
            dv[p] = max(dv[p], float(np.abs(vs[p] - vs["native step"]).max()))
        binding += bool(np.any(np.abs(vs["native step"]) >= SPEED - 1e-9))
        q = robot.integrate(q, vs["native step"], DT)
    return {"times": times, "dv": dv, "binding": binding}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    robot = qc.robots.load("panda")
    table, binding = [], {}
    with threadpool_limits(1):
        for name, pose in (("panda-position", False), ("panda-pose", True)):
            runs = [run(robot, pose, args.steps) for _ in range(args.runs)]
            binding[name] = [e["binding"] for e in runs]
            for p in PATHS:
                stats = np.array([np.percentile(e["times"][p] * 1e6, [50, 90, 99]) for e in runs])
                worst = max(e["dv"][p] for e in runs)
                dv = "–" if p == PATHS[0] else f"{worst:.1e}"
                table.append((name, p, *(span(stats[:, i]) for i in range(3)), dv))
    binds = ", ".join(f"{span(b, '{:.0f}')} of {name}" for name, b in binding.items())
    print(preamble())
    print(
        f"{args.steps} steps per run, lockstep, a speed limit binding on {binds} steps; each "
        f"cell the range over {args.runs} run(s) (µs); |Δv|: the largest velocity difference to "
        "the native step over all runs:\n"
    )
    head = ("scenario", "path", "median µs", "p90 µs", "p99 µs", "max |Δv| (rad/s)")
    print(markdown(head, table, "llrrrr"))


if __name__ == "__main__":
    main()
