"""Per-step time of the native IK step with each task or limit kind beside a pose stack.

The stack (1 kHz): the Franka Panda's hand (``FrameTask``, gain ``0.5/dt``) toward a pose
10 cm from its start, above a posture task (gain ``0.05/dt``), with the robot's limits
(``JointLimits(gain=0.5)``, speed limits). Each row adds one kind to it:

- ``+ acceleration limits``: ``AccelerationLimits(50 rad/s²)`` (braking before the position
  limits);
- ``pose with lm_damping``: the hand task built with ``lm_damping=1`` (its damping rows);
- ``+ relative frame``: a ``RelativeFrameTask`` of the hand in ``panda_link3`` at the
  posture level;
- ``+ joint coupling``: a ``JointCouplingTask`` ``q1 + q3 = const`` at the posture level;
- ``+ damping task``: a ``DampingTask`` (weight 1e-2) at the posture level;
- ``+ low acceleration``: a ``LowAccelerationTask`` (weight 1e-2) at the posture level;
- ``ball-joint arm: pose + posture``: the same pose + posture stack on a 7-DoF arm of a
  spherical shoulder, a revolute elbow and a spherical wrist (:func:`ball_joint_arm`; the
  posture's rows over both quaternions).

Each row runs a closed loop of ``step_integrate`` calls (the native engine, and the Python
engine for reference), one BLAS thread. Printed: median and p99 (µs) per step, each the
range over the runs, and whether the native step still runs Python rows each step
(``hybrid``).

Run::

    python benchmarks/native_ik_kinds.py                # 1500 steps, 3 runs
    python benchmarks/native_ik_kinds.py --steps 300 --runs 1
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
from _table import markdown, preamble, span  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

import qpcoord as qc  # noqa: E402

DT = 1e-3  # s
PANDA_Q0 = np.array([0.0, -0.4, 0.0, -2.2, 0.0, 1.9, 0.8])  # rad
FRAME = "panda_hand_tcp"


BALL_ARM = "ball-joint arm: pose + posture"


def ball_joint_arm() -> qc.Robot:
    """Shoulder (spherical), elbow (revolute y, ±2.5 rad), wrist (spherical): 0.4 m links,
    the tool frame ``panda_hand_tcp`` 0.1 m past the wrist; unit-mass links."""
    model = pin.Model()
    parent = 0
    for i, joint in enumerate(
        (pin.JointModelSpherical(), pin.JointModelRY(), pin.JointModelSpherical())
    ):
        at = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.4 if i else 0.0]))
        parent = model.addJoint(parent, joint, at, f"joint{i + 1}")
        link = pin.Inertia.FromCylinder(1.0, 0.03, 0.4)
        model.appendBodyToJoint(parent, link, pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.2])))
    tool = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.1]))
    model.addFrame(pin.Frame(FRAME, parent, 0, tool, pin.OP_FRAME))
    model.lowerPositionLimit[4], model.upperPositionLimit[4] = -2.5, 2.5  # the elbow (rad)
    model.velocityLimit[:] = 2.0  # rad/s
    return qc.Robot(model)


def start(robot: qc.Robot) -> np.ndarray:
    """The Panda's start configuration, or the ball-joint arm's elbow bent by 1 rad."""
    if robot.nq == PANDA_Q0.size:
        return PANDA_Q0
    q = robot.neutral()
    q[4] = 1.0
    return q


def stack(robot: qc.Robot, variant: str) -> tuple[list, list]:
    """The levels and limits of ``variant``."""
    q0 = start(robot)
    T = robot.frame_pose(q0, FRAME).copy()
    T[:3, 3] += [0.1, 0.0, -0.05]
    lm = 1.0 if variant == "pose with lm_damping" else 0.0
    hand = qc.FrameTask(robot, FRAME, target=T, gain=0.5 / DT, lm_damping=lm)
    posture = qc.PostureTask(robot, q0, gain=0.05 / DT)
    low: list = [posture]
    if variant == "+ relative frame":
        rel = qc.RelativeFrameTask(robot, FRAME, "panda_link3", gain=0.05 / DT)
        rel.set_target_from_configuration(q0)
        low.append(rel)
    if variant == "+ joint coupling":
        low.append(
            qc.JointCouplingTask(
                robot, ["panda_joint1", "panda_joint3"], [1.0, 1.0], gain=0.05 / DT
            )
        )
    if variant == "+ damping task":
        low.append(qc.DampingTask(robot, weight=1e-2))
    if variant == "+ low acceleration":
        low.append(qc.LowAccelerationTask(robot, weight=1e-2))
    limits: list = [qc.JointLimits(robot), qc.VelocityLimits(robot)]
    if variant == "+ acceleration limits":
        limits.append(qc.AccelerationLimits(robot, 50.0, position_limits=limits[0]))
    return [[hand], low], limits


VARIANTS = (
    "pose + posture",
    "+ acceleration limits",
    "pose with lm_damping",
    "+ relative frame",
    "+ joint coupling",
    "+ damping task",
    "+ low acceleration",
    BALL_ARM,
)


def run(robot: qc.Robot, variant: str, engine: str, steps: int) -> tuple[np.ndarray, bool]:
    levels, limits = stack(robot, variant)
    ik = qc.IK(robot, levels, DT, limits=limits, engine=engine)
    hybrid = bool(ik._native is not None and (ik._native._hybrid or ik._native._python_limits))
    q = start(robot).copy()
    times = np.empty(steps)
    for k in range(steps):
        t0 = time.perf_counter()
        q, _, _ = ik.step_integrate(q)
        times[k] = time.perf_counter() - t0
    return times * 1e6, hybrid


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    panda, arm = qc.robots.load("panda"), ball_joint_arm()
    table = []
    with threadpool_limits(1):
        for variant in VARIANTS:
            robot = arm if variant == BALL_ARM else panda
            row: list[object] = [variant]
            for engine in ("native", "python"):
                runs = [run(robot, variant, engine, args.steps) for _ in range(args.runs)]
                stats = np.array([np.percentile(t, [50, 99]) for t, _ in runs])
                row += [span(stats[:, 0]), span(stats[:, 1])]
                if engine == "native":
                    hybrid = runs[0][1]
            table.append((*row, "yes" if hybrid else "no"))
    print(preamble())
    print(
        f"{args.steps} steps per run (closed loop, step_integrate); each cell the range over "
        f"{args.runs} run(s) (µs):\n"
    )
    head = ("stack", "native median", "native p99", "python median", "python p99", "hybrid")
    print(markdown(head, table, "lrrrrl"))


if __name__ == "__main__":
    main()
