"""Per-step cost and safety of collision avoidance on the Panda: qpcoord beside Pink, mink and
PlaCo in one run.

Scenario (``cell_stacks.py``'s "+ self-collision + sphere" stack on ``ik_peers.py``'s
``panda-pose``): the Panda (7 DoF, fingers locked) follows a 0.1 m horizontal circle with its
hand's pose at 1 kHz (``--steps``, default 1400), a posture task below, hard joint position
and speed limits; a table band keeps the hand at most 5 cm below its start; self-collision
(the SRDF's pairs removed, pairs on one or adjacent joints skipped) and one 5 cm sphere, here
centred on the hand's path (its target at t = 0.5 s: the sphere is in the way, unlike
``cell_stacks.py``'s, 20 cm ahead), safety distance 0.02 m, influence distance 0.10 m;
convex hulls of the collision meshes. What each library can pose of it:

- qpcoord: the band and ``CollisionAvoidance`` at level 0 above the pose and the posture
  (strict priorities, the default engine), ``set_target`` and ``IK.step_integrate``.
- Pink (``ik_peers.PinkLoop``, daqp): pose and posture as costs, its joint and speed limits,
  ``SelfCollisionBarrier`` over the same geometry and pairs (the sphere included) and a
  ``PositionBarrier`` on the hand's height for the table.
- mink (``benchmarks/mink_side.py`` in ``benchmarks/.mink-venv``, as ``edges.py``): a MuJoCo
  Panda from the same URDF (its collision meshes, fingers fixed), pose and posture as costs,
  ``ConfigurationLimit``, ``VelocityLimit`` and ``CollisionAvoidanceLimit`` over the robot's
  geoms against each other and the sphere (mink skips parent-child pairs, knows no SRDF);
  no table (mink has no limit on a frame's position).
- PlaCo (``benchmarks/placo_side.py`` in ``benchmarks/.placo-venv``, as ``ik_peers.py``):
  pose and posture as soft tasks, joint and speed limits, its hard self-collision
  constraint on qpcoord's self pairs (by link; PlaCo's Pinocchio 3.8 measures the meshes, not
  hulls); no sphere and no table (its kinematics solver poses neither).

Each step is timed by the library's own clock around target, solve and integration. Medians
and 99th percentiles of the per-step wall time; min d: the smallest distance over the run
between qpcoord's hulls (self and sphere pairs) at each library's configurations (below
0.02 m: the safety distance crossed; negative: penetration); table: the hand's smallest
height above the table face (m; negative: below it). No timed assertions; one BLAS thread.

Run: ``python benchmarks/collision_bench.py [--steps 1400] [--no-pink] [--no-mink]
[--no-placo] [--update]`` (``--update``: first, ``CollisionAvoidance.update`` alone on a
5 s random-target run at dt = 0.01 s with 0, 1 and 3 obstacles)
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from _mink import call_mink_side  # noqa: E402
from _table import markdown, preamble  # noqa: E402
from cell_stacks import PANDA_STACKS, SPHERE_RADIUS, TABLE_DROP, Loop  # noqa: E402
from ik_peers import (  # noqa: E402
    DT,
    HAND_ALPHA,
    POSTURE_WEIGHT,
    PinkLoop,
    PlacoLoop,
    placo_python,
)
from ik_peers import scenario as peers_scenario  # noqa: E402

import qpcoord as qc  # noqa: E402
from qpcoord.kinematics.collision import Box, Capsule, CollisionAvoidance, Sphere  # noqa: E402

HAND = "panda_hand_tcp"
D_MIN, D_INFLUENCE = 0.02, 0.10  # m: CollisionAvoidance's defaults, cell_stacks.py's task
FINGERS = ("panda_finger_joint1", "panda_finger_joint2")  # locked in qc.robots.load("panda")
SPHERE_STEP = 500  # the sphere's centre: the hand's target at this step (t = 0.5 s)


# --------------------------------------------------------------------------- the peers' run


class Watch:
    """The constraints at a library's configurations: the smallest pair distance on qpcoord's
    hulls (self and sphere pairs, m) and the hand's smallest height above the table (m)."""

    def __init__(self, sc: dict) -> None:
        robot = sc["robot"]
        T0 = robot.frame_pose(sc["q0"], HAND)
        self.robot = robot
        self.table = T0[2, 3] - TABLE_DROP
        self.centre = sc["targets"][SPHERE_STEP].copy()
        self.task = CollisionAvoidance(robot, obstacles=[Sphere(self.centre, SPHERE_RADIUS)])

    def __call__(self, qs: list[np.ndarray]) -> tuple[float, float]:
        d = min(float(self.task.compute_distances(q).min()) for q in qs)
        z = min(float(self.robot.frame_pose(q, HAND)[2, 3]) for q in qs)
        return d, z - self.table

    def self_links(self) -> list[list[str]]:
        """The self pairs as URDF link pairs (each once)."""
        gm, frames = self.task.geometry_model, self.robot.model.frames
        out: list[list[str]] = []
        for cp in gm.collisionPairs:
            a, b = (gm.geometryObjects[i] for i in (cp.first, cp.second))
            if a.parentJoint == 0 or b.parentJoint == 0:  # the sphere
                continue
            pair = [frames[a.parentFrame].name, frames[b.parentFrame].name]
            if pair not in out and pair[::-1] not in out:
                out.append(pair)
        return out


def run_qpcoord(sc: dict, watch: Watch, steps: int):
    loop = Loop(sc, PANDA_STACKS[3], sphere=watch.centre)
    (ca,) = [t for t in loop.ik._dynamic if isinstance(t, CollisionAvoidance)]
    native = loop.ik._native is not None and ca in loop.ik._native.kernel_tasks
    ts, qs = [], []
    for k in range(steps):
        ts.append(loop.step(k))
        qs.append(loop.q.copy())
    where = "inside the native step" if native else "native" if ca.native else "Python"
    return (ts, qs, len(ca.pairs)), f"qpcoord: the collision rows computed {where}."


def run_pink(sc: dict, watch: Watch, steps: int):
    try:
        from pink.barriers import PositionBarrier, SelfCollisionBarrier
    except ImportError as exc:
        return None, f"Pink: not run (pin-pink not installed: {exc})."
    gm = watch.task.geometry_model
    n = len(gm.collisionPairs)
    barriers = (
        SelfCollisionBarrier(n_collision_pairs=n, gain=1.0, d_min=D_MIN),
        PositionBarrier(HAND, indices=[2], p_min=np.array([watch.table]), gain=1.0),
    )
    loop = PinkLoop(sc, collision_model=gm, barriers=barriers)
    ts, qs = [], []
    for k in range(steps):
        ts.append(loop.step(k))
        qs.append(loop.q.copy())
    return (ts, qs, n), None


def run_placo(sc: dict, watch: Watch, steps: int):
    python = placo_python(None)
    if python is None:
        return None, (
            "PlaCo: not run (no benchmarks/.placo-venv: python benchmarks/ik_peers.py "
            "--make-placo-venv)."
        )
    pairs = watch.self_links()
    extra = {"self_collision": {"pairs": pairs, "margin": D_MIN, "trigger": D_INFLUENCE}}
    loop = PlacoLoop(sc, python, extra)
    try:
        loop.request_all(steps)
        ts, qs = [], []
        for _ in range(steps):
            ts.append(loop._answer())
            qs.append(loop.q.copy())
    finally:
        loop.close()
    note = (
        f"PlaCo {loop.version}: pairs counts the {len(pairs)} link pairs given to it "
        "(qpcoord's self pairs); no sphere constraint (min d includes the sphere pairs, as "
        "in every row)."
    )
    return (ts, qs, len(pairs)), note


def run_mink(sc: dict, watch: Watch, steps: int):
    robot = sc["robot"]
    q0 = sc["q0"]
    target = robot.frame_pose(q0, HAND)
    target[:3, :3] = sc["rotation"]
    run = {
        "label": "mink",
        "q0": q0,
        "steps": steps,
        "target": target,
        "path": sc["targets"][:steps],
        "position_only": False,
        "gain": HAND_ALPHA,
        "lm_damping": 0.0,
        "posture_cost": POSTURE_WEIGHT,
        "config_gain": 0.5,
    }
    collision = {
        "fixed": list(FINGERS),
        "sphere": [*watch.centre, SPHERE_RADIUS],
        "min_distance": D_MIN,
        "detection_distance": D_INFLUENCE,
    }
    out, why = call_mink_side(robot, HAND, [run], DT, [q0], sc["speed"], collision)
    if out is None:
        return None, why + "."
    same = float(np.abs(np.array(out["poses"][0]) - robot.frame_pose(q0, HAND)).max())
    run = out["runs"][0]
    qs = [np.array(q) for q in run["q"]]
    note = (
        f"mink {out['mink']} (MuJoCo {out['mujoco']}): the hand's pose agrees with qpcoord's to "
        f"{same:.1g} at the start"
    )
    if run["failed"] is not None:  # mink's QP had no solution: its run stops there
        note += f"; its QP had no solution at step {run['failed']} (the run stops there)"
    return (run["t"], qs, run["pairs"]), note + "."


def peers_table(steps: int, pink: bool, mink: bool, placo: bool) -> None:
    sc = peers_scenario("panda-pose", max(steps, SPHERE_STEP + 1), 0.8)
    watch = Watch(sc)
    rows, notes = [], []
    out, note = run_qpcoord(sc, watch, steps)
    rows.append(("qpcoord", "band + self + sphere, level 0", out))
    notes.append(note)
    peers = (
        ("Pink", "barriers: self + sphere, table", pink, run_pink),
        ("mink", "collision limit: self + sphere", mink, run_mink),
        ("PlaCo", "self-collision (hard)", placo, run_placo),
    )
    for name, what, wanted, fn in peers:
        if not wanted:
            continue
        out, note = fn(sc, watch, steps)
        if note:
            notes.append(note)
        if out is not None:
            rows.append((name, what, out))
    base = float(np.median(rows[0][2][0]))
    table = []
    for name, what, (ts, qs, pairs) in rows:
        t = np.asarray(ts) * 1e6
        d, z = watch(qs)
        med = float(np.median(t))
        table.append(
            (
                name,
                what,
                pairs,
                f"{med:.1f}",
                f"{float(np.percentile(t, 99)):.1f}",
                f"{med / (base * 1e6):.1f}×",
                f"{d:.4f}",
                f"{z:.4f}",
            )
        )
    print(
        f"Panda pose + posture + table band + self-collision + one sphere, 1 kHz, {steps} "
        "steps; ratio: median over qpcoord's; min d: the smallest pair distance on qpcoord's "
        "hulls (safety distance 0.02 m); table: the hand's smallest height above the table "
        "face (m):\n"
    )
    head = ("library", "constraints", "pairs", "median µs", "p99 µs", "ratio", "min d (m)",
            "table (m)")  # fmt: skip
    print(markdown(head, table, "llrrrrrr"))
    print("\n" + " ".join(notes))


# --------------------------------------------------------------------------- update alone


DT_UPDATE = 0.01  # s: the update-alone run


def scenario(robot, steps, seed=0):
    """The update-alone run: a new random reachable hand pose every 0.5 s."""
    q0 = robot.reference_configuration("default")
    rng = np.random.default_rng(seed)
    n_targets = steps // 50 + 1
    targets = [robot.frame_pose(robot.random_configuration(rng), HAND) for _ in range(n_targets)]
    p = robot.frame_pose(q0, HAND)[:3, 3]
    sphere = (p + [0.15, 0.1, 0.0], 0.05)
    return q0, targets, sphere


def _stats(times):
    t = np.asarray(times) * 1e6
    return float(np.median(t)), float(np.percentile(t, 99))


def bench_refresh(robot, steps, obstacles):
    """``update`` alone along the qpcoord trajectory."""
    q0, targets, _ = scenario(robot, steps)
    ca = CollisionAvoidance(robot, obstacles, min_distance=D_MIN, influence_distance=D_INFLUENCE)
    reach = qc.FrameTask(robot, HAND, None, gain=3.0)
    posture = qc.PostureTask(robot, q0, gain=0.5)
    ik = qc.IK(robot, [ca, reach, posture], DT_UPDATE, solver="daqp")
    q, times, active = q0.copy(), [], []
    for k in range(steps):
        if k % 50 == 0:
            reach.set_target(targets[k // 50])
        robot._state = 0  # forget the cached kinematics: time the FK pass too
        t0 = time.perf_counter()
        ca.update(q, dt=DT_UPDATE)
        times.append(time.perf_counter() - t0)
        active.append(int(ca.active.sum()))
        v, _ = ik.step(q)
        q = robot.integrate(q, v, DT_UPDATE)
    return times, len(ca.pairs), float(np.mean(active))


def update_table(robot, steps: int, c, r, p) -> None:
    """Print the table of ``CollisionAvoidance.update`` alone: self only, one sphere (centre
    ``c``, radius ``r``), and a sphere, a box and a capsule around the hand's start ``p``."""
    print("`CollisionAvoidance.update` alone (FK + broad phase + coal + rows), Panda:\n")
    cases = {
        "self only": [],
        "self + 1 sphere": [Sphere(c, r)],
        "self + sphere, box, capsule": [
            Sphere(c, r),
            Box(p + [0.0, -0.25, -0.1], [0.05, 0.05, 0.1]),
            Capsule(p + [-0.1, 0.25, -0.3], p + [-0.1, 0.25, 0.1], 0.03),
        ],
    }
    alone = []
    for label, obstacles in cases.items():
        times, pairs, active = bench_refresh(robot, steps, obstacles)
        med, p99 = _stats(times)
        alone.append((label, pairs, f"{active:.1f}", f"{med:.1f}", f"{p99:.1f}"))
    head = ("obstacles", "pairs", "active", "median µs", "p99 µs")
    print(markdown(head, alone, "lrrrr"))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1400, help="steps at 1 kHz (default 1400)")
    parser.add_argument("--no-pink", action="store_true", help="leave Pink out")
    parser.add_argument("--no-mink", action="store_true", help="leave mink out")
    parser.add_argument("--no-placo", action="store_true", help="leave PlaCo out")
    parser.add_argument(
        "--update",
        action="store_true",
        help="first, CollisionAvoidance.update alone with 0, 1 and 3 obstacles",
    )
    args = parser.parse_args(argv)
    if args.steps < 10:
        parser.error("--steps must be at least 10")
    print(preamble())
    if args.update:
        robot = qc.robots.load("panda")
        q0, _, (c, r) = scenario(robot, 500)
        update_table(robot, 500, c, r, robot.frame_pose(q0, HAND)[:3, 3])
        print()
    peers_table(args.steps, not args.no_pink, not args.no_mink, not args.no_placo)


if __name__ == "__main__":
    main()
