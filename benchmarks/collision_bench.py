"""Per-step cost of collision avoidance on the Panda: qpcoord vs Pink vs mink.

Scenario (same for every library): the Panda (7 DoF, fingers locked where the library allows
it) reaches a new random reachable pose every 0.5 s for 5 s at dt = 0.01 s (500 steps),
with self-collision on and one sphere obstacle in front of it, min distance 0.02 m,
influence / detection distance 0.10 m. Convex hulls of the collision meshes everywhere.

- qpcoord: ``CollisionAvoidance`` (44 self pairs after the SRDF + 17 robot-vs-sphere pairs)
  at level 0 above a pose task and a posture task (``IK.step``: strict priorities, the
  default engine), and, with
  ``--update``, the task's ``update`` alone (the per-step collision cost) with 0, 1 and 3
  obstacles.
- Pink: ``SelfCollisionBarrier`` over the same pairs (``Configuration.update`` computes every
  pair distance, no broad phase), ``solve_ik`` with the same QP solver (daqp).
- mink (if ``pip install mink mujoco`` worked): the MuJoCo Panda is built from the same URDF
  (MuJoCo's URDF import, visuals dropped; the MuJoCo Menagerie MJCF is not reachable
  offline), fingers free (9 DoF, MuJoCo has no joint locking), ``CollisionAvoidanceLimit``
  over all robot geoms (self) and robot-vs-sphere; mink skips welded and parent-child pairs
  but knows no SRDF, so it watches more pairs.

Times include each library's forward kinematics, distance queries and QP solve. Medians and
99th percentiles of the per-step wall time; no timed assertions. BLAS is single-threaded.

Run: ``python benchmarks/collision_bench.py [--steps 500] [--repeats 2] [--update]``
"""

from __future__ import annotations

import argparse
import os
import re
import tempfile
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
from _table import markdown, preamble  # noqa: E402

import qpcoord as qc  # noqa: E402
from qpcoord.kinematics.collision import Box, Capsule, CollisionAvoidance, Sphere  # noqa: E402

HAND = "panda_hand_tcp"
DT = 0.01
D_MIN, D_INFLUENCE = 0.02, 0.10


def scenario(robot, steps, seed=0):
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


def bench_qpcoord(robot, steps, repeats, method="hierarchical", collision=True):
    q0, targets, (c, r) = scenario(robot, steps)
    ca = CollisionAvoidance(
        robot, [Sphere(c, r)], min_distance=D_MIN, influence_distance=D_INFLUENCE
    )
    reach = qc.FrameTask(robot, HAND, None, gain=3.0)
    posture = qc.PostureTask(robot, q0, gain=0.5)
    levels = [ca, reach, posture] if collision else [reach, posture]
    ik = qc.IK(robot, levels, DT, method=method)  # qpcoord's default engine
    times, d_min = [], np.inf
    for _ in range(repeats):
        q = q0.copy()
        ik.reset()
        for k in range(steps):
            if k % 50 == 0:
                reach.set_target(targets[k // 50])
            t0 = time.perf_counter()
            v, _ = ik.step(q)
            times.append(time.perf_counter() - t0)
            q = robot.integrate(q, v, DT)
            d_min = min(d_min, float(ca.compute_distances(q).min()))
    return times, d_min, len(ca.pairs)


def bench_refresh(robot, steps, obstacles):
    """``update`` alone along the qpcoord trajectory."""
    q0, targets, _ = scenario(robot, steps)
    ca = CollisionAvoidance(robot, obstacles, min_distance=D_MIN, influence_distance=D_INFLUENCE)
    reach = qc.FrameTask(robot, HAND, None, gain=3.0)
    ik = qc.IK(robot, [ca, reach, qc.PostureTask(robot, q0, gain=0.5)], DT, solver="daqp")
    q, times, active = q0.copy(), [], []
    for k in range(steps):
        if k % 50 == 0:
            reach.set_target(targets[k // 50])
        robot._state = 0  # forget the cached kinematics: time the FK pass too
        t0 = time.perf_counter()
        ca.update(q, dt=DT)
        times.append(time.perf_counter() - t0)
        active.append(int(ca.active.sum()))
        v, _ = ik.step(q)
        q = robot.integrate(q, v, DT)
    return times, len(ca.pairs), float(np.mean(active))


def bench_pink(robot, steps, repeats):
    try:
        import pink
        from pink.barriers import SelfCollisionBarrier
        from pink.tasks import FrameTask, PostureTask
    except ImportError as exc:
        return None, f"pink not installed ({exc})"
    q0, targets, (c, r) = scenario(robot, steps)
    # the same geometry and pairs as qpcoord's (convex hulls, SRDF, sphere)
    ca = CollisionAvoidance(
        robot, [Sphere(c, r)], min_distance=D_MIN, influence_distance=D_INFLUENCE
    )
    gm = ca.geometry_model
    model = robot.model
    data = model.createData()
    config = pink.Configuration(model, data, q0, collision_model=gm)
    reach = FrameTask(HAND, position_cost=1.0, orientation_cost=1.0)
    posture = PostureTask(cost=1e-3)
    posture.set_target(q0)
    barrier = SelfCollisionBarrier(n_collision_pairs=len(gm.collisionPairs), gain=1.0, d_min=D_MIN)
    times, d_min = [], np.inf
    for _ in range(repeats):
        q = q0.copy()
        for k in range(steps):
            if k % 50 == 0:
                reach.set_target(pin.SE3(targets[k // 50]))
            t0 = time.perf_counter()
            config.update(q)
            v = pink.solve_ik(
                config, [reach, posture], DT, solver="daqp", barriers=[barrier], safety_break=False
            )
            times.append(time.perf_counter() - t0)
            q = pin.integrate(model, q, v * DT)
            d_min = min(d_min, float(ca.compute_distances(q).min()))
    return (times, d_min, len(gm.collisionPairs)), None


def _mujoco_panda(robot, sphere):
    import mujoco

    text = open(robot.urdf_path).read()
    text = re.sub(r"<visual>.*?</visual>", "", text, flags=re.S)  # .dae: not read by MuJoCo
    text = text.replace("package://", robot.package_dirs[0] + "/")
    folder = tempfile.mkdtemp(prefix="qpcoord-bench-")
    path = os.path.join(folder, "panda.urdf")
    with open(path, "w") as f:
        f.write(text)
    spec = mujoco.MjSpec.from_file(path)
    for k, geom in enumerate(spec.geoms):
        geom.name = f"robot_{k}"
    c, r = sphere
    spec.worldbody.add_geom(
        name="obstacle", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[r, 0, 0], pos=c
    )
    return spec.compile()


def bench_mink(robot, steps, repeats):
    try:
        import mink
        import mujoco  # noqa: F401
    except ImportError as exc:
        return None, f"mink/mujoco not installed ({exc})"
    q0, targets, sphere = scenario(robot, steps)
    try:
        model = _mujoco_panda(robot, sphere)
    except Exception as exc:  # the URDF import can fail on another MuJoCo version
        return None, f"no MuJoCo Panda could be built from the URDF ({exc})"
    robot_geoms = [f"robot_{k}" for k in range(model.ngeom - 1)]
    limit = mink.CollisionAvoidanceLimit(
        model,
        [(robot_geoms, robot_geoms), (robot_geoms, ["obstacle"])],
        minimum_distance_from_collisions=D_MIN,
        collision_detection_distance=D_INFLUENCE,
    )
    config = mink.Configuration(model)
    limits = [mink.ConfigurationLimit(model), limit]
    # the URDF's link frame of the TCP is fused into link7 by MuJoCo: track link7's pose,
    # offset as in the URDF (0.1034 m along z for panda_hand_tcp)
    reach = mink.FrameTask("panda_link7", "body", position_cost=1.0, orientation_cost=1.0)
    posture = mink.PostureTask(model, cost=1e-3)
    q_start = np.concatenate([q0, [0.02, 0.02]])[: model.nq]
    posture.set_target(q_start)
    T_tcp_link7 = np.linalg.inv(robot.frame_pose(q0, "panda_link7")) @ robot.frame_pose(q0, HAND)
    times = []
    for _ in range(repeats):
        q = q_start.copy()
        for k in range(steps):
            if k % 50 == 0:
                T = targets[k // 50] @ np.linalg.inv(T_tcp_link7)
                reach.set_target(mink.SE3.from_matrix(T))
            t0 = time.perf_counter()
            config.update(q)
            v = mink.solve_ik(config, [reach, posture], DT, solver="daqp", limits=limits)
            times.append(time.perf_counter() - t0)
            config.integrate_inplace(v, DT)
            q = config.q.copy()
    return (times, None, len(limit.geom_id_pairs)), None


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
    parser.add_argument("--steps", type=int, default=500)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument(
        "--update",
        action="store_true",
        help="first, CollisionAvoidance.update alone with 0, 1 and 3 obstacles",
    )
    args = parser.parse_args(argv)
    robot = qc.robots.load("panda")
    q0, _, (c, r) = scenario(robot, args.steps)
    p = robot.frame_pose(q0, HAND)[:3, 3]

    print(preamble())
    if args.update:
        update_table(robot, args.steps, c, r, p)
        print()

    rows = []
    res = bench_qpcoord(robot, args.steps, args.repeats)
    rows.append(("qpcoord IK.step, collision at level 0", res, None))
    weighted = bench_qpcoord(robot, args.steps, args.repeats, method="weighted")
    rows.append(("qpcoord IK.step, method='weighted'", weighted, None))
    free = bench_qpcoord(robot, args.steps, args.repeats, collision=False)
    rows.append(("qpcoord IK.step without collision (ref.)", free[:2] + (0,), None))
    pink_res, why = bench_pink(robot, args.steps, args.repeats)
    rows.append(("Pink solve_ik + SelfCollisionBarrier", pink_res, why))
    mink_res, why = bench_mink(robot, args.steps, args.repeats)
    rows.append(("mink solve_ik + CollisionAvoidanceLimit", mink_res, why))

    base = _stats(res[0])[0]
    print(
        f"Per control step, self-collision + 1 sphere ({args.steps} steps × {args.repeats}); "
        "ratio: median over qpcoord's; min d: the smallest pair distance over the run on "
        "qpcoord's hulls ('–' for mink: MuJoCo's distances are not comparable):\n"
    )
    table, skipped = [], []
    for label, out, why in rows:
        if out is None:
            skipped.append(f"{label} skipped: {why}.")
            continue
        times, d_min, pairs = out
        med, p99 = _stats(times)
        dm = "–" if d_min is None else f"{d_min:.4f}"
        table.append((label, pairs, f"{med:.1f}", f"{p99:.1f}", f"{med / base:.2f}", dm))
    head = ("library", "pairs", "median µs", "p99 µs", "ratio", "min d (m)")
    print(markdown(head, table, "lrrrrr"))
    if skipped:
        print("\n" + "\n".join(skipped))


if __name__ == "__main__":
    main()
