"""PlaCo's side of ``benchmarks/ik_peers.py``, run in PlaCo's own environment.

PlaCo 0.10 pins ``pin==3.8.0``, which cannot be installed beside qpcoord's ``pin>=4``: this
script (also ``benchmarks/collision_bench.py``'s PlaCo side) runs under
``benchmarks/.placo-venv/bin/python`` (created by
``python benchmarks/ik_peers.py --make-placo-venv`` from ``benchmarks/placo-requirements.txt``)
and talks to the benchmark over its standard input/output, one JSON line per message:

1. it reads the scenario (one line): ``robot`` (``"panda"`` or ``"talos"``), ``urdf``,
   ``dt`` (s), ``steps``, ``targets`` (steps × 3, m, the hand position at each step),
   ``rotation`` (3 × 3, or null for a position-only task), ``q0`` (joint name → rad),
   ``speed`` (rad/s, joint name → limit), ``posture_weight``, ``frame``, and for Talos
   ``soles`` and ``polygon`` (the support polygon's corners in the world, m) and ``margin``;
   optionally ``self_collision``: ``pairs`` (URDF link name pairs), ``margin`` and
   ``trigger`` (m) of PlaCo's hard self-collision constraint (its mesh distances; without it
   the robot is loaded with ``Flags.ignore_collisions``);
2. it answers ``{"ready": true, "joints": [names], "placo": version}``;
3. then, for every line ``{"k": step}``, it runs one control step (targets of step ``k``,
   ``solver.solve(True)``, ``robot.update_kinematics()``) timed with its own
   ``time.perf_counter`` around exactly that, and answers ``{"t": seconds, "q": [...]}``
   (the joints' positions, rad, in the order of ``joints``; for Talos the free-flyer's 7
   numbers first);
4. an empty line ends it.

In its lockstep table the benchmark interleaves these steps with its in-process solvers; back
to back it writes every step request at once (this side then never waits on the pipe between
steps) and reads the answers as they come. The pipe round trip is outside every timer.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from importlib.metadata import version

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import placo  # noqa: E402


def _send(obj: dict) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def build(sc: dict):
    """The robot, solver and per-step target setter of one scenario."""
    collision = sc.get("self_collision")
    robot = placo.RobotWrapper(sc["urdf"], 0 if collision else placo.Flags.ignore_collisions)
    if collision:  # these pairs only (PlaCo's default: every pair of links)
        with tempfile.TemporaryDirectory(prefix="qpcoord-placo-") as folder:
            path = os.path.join(folder, "collisions.json")
            with open(path, "w") as f:
                json.dump(collision["pairs"], f)
            robot.load_collision_pairs(path)
    for name, value in sc["q0"].items():
        robot.set_joint(name, value)
    if sc["robot"] == "talos":
        robot.set_T_world_frame(sc["soles"][0], np.array(sc["sole_poses"][0]))
    robot.update_kinematics()
    for name, value in sc["speed"].items():
        robot.set_velocity_limit(name, value)
    solver = placo.KinematicsSolver(robot)
    solver.dt = sc["dt"]
    solver.enable_joint_limits(True)
    solver.enable_velocity_limits(True)
    if sc["robot"] == "panda":
        solver.mask_fbase(True)
    else:
        for sole, pose in zip(sc["soles"], sc["sole_poses"], strict=True):
            foot = solver.add_frame_task(sole, np.array(pose))
            foot.configure(sole, "hard", 1.0, 1.0)
        com = solver.add_com_polygon_constraint(
            [np.array(c, dtype=float) for c in sc["polygon"]], sc["margin"]
        )
        com.configure("com", "hard")
    if collision:
        avoid = solver.add_avoid_self_collisions_constraint()
        avoid.self_collisions_margin = collision["margin"]
        avoid.self_collisions_trigger = collision["trigger"]
        avoid.configure("self-collision", "hard")
    if sc["rotation"] is None:
        hand = solver.add_position_task(sc["frame"], np.array(sc["targets"][0]))
        hand.configure("hand", "soft", 1.0)

        def set_target(k: int) -> None:
            hand.target_world = targets[k]

    else:
        T = np.eye(4)
        T[:3, :3] = np.array(sc["rotation"])
        T[:3, 3] = sc["targets"][0]
        hand = solver.add_frame_task(sc["frame"], T)
        hand.configure("hand", "soft", 1.0, 1.0)

        def set_target(k: int) -> None:
            T[:3, 3] = targets[k]
            hand.T_world_frame = T

    posture = solver.add_joints_task()
    posture.set_joints(dict(sc["q0"]))
    posture.configure("posture", "soft", sc["posture_weight"])
    targets = np.array(sc["targets"])
    return robot, solver, set_target


def main() -> int:
    sc = json.loads(sys.stdin.readline())
    robot, solver, set_target = build(sc)
    names = list(robot.joint_names())
    free = sc["robot"] == "talos"

    def q_out() -> list[float]:
        joints = [robot.get_joint(n) for n in names]
        return (list(robot.state.q[:7]) if free else []) + joints

    _send({"ready": True, "joints": names, "placo": version("placo")})

    def step(k: int) -> None:
        t0 = time.perf_counter()
        set_target(k)
        solver.solve(True)
        robot.update_kinematics()
        t = time.perf_counter() - t0
        _send({"t": t, "q": q_out()})

    for line in sys.stdin:
        if not line.strip():
            break
        msg = json.loads(line)
        if "run" in msg:  # back to back: steps 0 … run−1 with no request between them
            for k in range(msg["run"]):
                step(k)
        else:
            step(msg["k"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
