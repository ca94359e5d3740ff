"""mink's side of ``benchmarks/edges.py`` and ``benchmarks/collision_bench.py``, run in mink's
own environment (by ``benchmarks/_mink.py``'s ``call_mink_side``).

mink needs MuJoCo, which is not a qpcoord dependency: this script runs under
``benchmarks/.mink-venv/bin/python`` (``python3 -m venv benchmarks/.mink-venv &&
benchmarks/.mink-venv/bin/pip install -r benchmarks/mink-requirements.txt``). It reads one
JSON object on its standard input and writes one JSON object on its standard output:

- in: ``urdf`` (the robot's URDF, ``package://`` resolved against ``package_dir``), ``site``
  (``body``, ``pos`` (m), ``quat`` (w, x, y, z): the task frame as a MuJoCo site on that
  body), ``joints`` (names, the order of ``q``), ``velocity`` (rad/s per joint), ``check``
  (configurations at which the site's pose is returned), ``dt`` (s), and ``runs``: each
  ``label``, ``q0`` (rad, also the posture's target), ``steps``, ``target`` (4 × 4),
  ``position_only``, ``gain`` (the frame task's, per step), ``lm_damping``, ``posture_cost``
  and ``config_gain`` (``ConfigurationLimit``'s gain, ``null`` for mink's default), and
  optionally ``path`` (steps × 3, m: the target's position at each step, its rotation
  ``target``'s); optionally ``collision``: ``fixed`` (joint names made fixed), ``sphere``
  (centre, m, and radius, m: an obstacle), ``min_distance`` and ``detection_distance`` (m)
  of a ``CollisionAvoidanceLimit`` over the robot's geoms against each other and the sphere;
- out: ``mink`` and ``mujoco`` (versions), ``poses`` (the site's 4 × 4 pose at each ``check``
  configuration) and ``runs``: each ``label``, ``v`` (steps × nv, rad/s), ``q`` (steps × nq,
  rad), ``t`` (s, each step's wall time: target, ``solve_ik`` and ``integrate_inplace``),
  ``failed`` (the step at which the QP had no solution, or ``null``) and ``pairs`` (the
  collision limit's geom pairs, 0 without ``collision``).

The MuJoCo model is built from the same URDF as qpcoord's (visual meshes dropped, and the
collision meshes unless ``collision`` is given), so the joints, limits and the task frame
are the same.
"""

from __future__ import annotations

import json
import os
import re
import sys
import tempfile
import time
from importlib.metadata import version

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import mink  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from mink.exceptions import NoSolutionFound  # noqa: E402


def model_of(sc: dict) -> mujoco.MjModel:
    """The MuJoCo model of the URDF, with the task frame as a site (and with ``collision``,
    the robot's collision geoms named ``robot_k`` and the sphere ``obstacle``)."""
    collision = sc.get("collision")
    text = open(sc["urdf"]).read()
    dropped = "visual" if collision else "visual|collision"
    text = re.sub(rf"<({dropped})>.*?</\1>", "", text, flags=re.S)
    text = text.replace("package://", sc["package_dir"] + "/")
    for name in collision["fixed"] if collision else ():
        text = re.sub(rf'(<joint name="{name}"[^>]*type=")\w+"', r'\1fixed"', text)
    with tempfile.TemporaryDirectory(prefix="qpcoord-mink-") as folder:
        path = os.path.join(folder, "robot.urdf")
        with open(path, "w") as f:
            f.write(text)
        spec = mujoco.MjSpec.from_file(path)
    site = sc["site"]
    spec.body(site["body"]).add_site(name="task", pos=site["pos"], quat=site["quat"])
    if collision:
        for k, geom in enumerate(spec.geoms):
            geom.name = f"robot_{k}"
        *centre, radius = collision["sphere"]
        spec.worldbody.add_geom(
            name="obstacle", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[radius, 0, 0], pos=centre
        )
    return spec.compile()


def run(model: mujoco.MjModel, sc: dict, r: dict) -> dict:
    q0 = np.array(r["q0"], dtype=float)
    config = mink.Configuration(model)
    config.update(q0)
    orientation = 0.0 if r["position_only"] else 1.0
    hand = mink.FrameTask(
        "task", "site", position_cost=1.0, orientation_cost=orientation, gain=r["gain"],
        lm_damping=r["lm_damping"],
    )  # fmt: skip
    hand.set_target(mink.SE3.from_matrix(np.array(r["target"], dtype=float)))
    posture = mink.PostureTask(model, cost=r["posture_cost"])
    posture.set_target(q0)
    config_limit = (
        mink.ConfigurationLimit(model)
        if r["config_gain"] is None
        else mink.ConfigurationLimit(model, gain=r["config_gain"])
    )
    speed = dict(zip(sc["joints"], sc["velocity"], strict=True))
    limits = [config_limit, mink.VelocityLimit(model, speed)]
    collision = sc.get("collision")
    pairs = 0
    if collision:
        robot = [model.geom(g).name for g in range(model.ngeom) if model.geom(g).name != "obstacle"]
        avoid = mink.CollisionAvoidanceLimit(
            model,
            [(robot, robot), (robot, ["obstacle"])],
            minimum_distance_from_collisions=collision["min_distance"],
            collision_detection_distance=collision["detection_distance"],
        )
        limits.append(avoid)
        pairs = len(avoid.geom_id_pairs)
    T = np.array(r["target"], dtype=float)
    path = r.get("path")
    vs, qs, ts, failed = [], [], [], None
    for k in range(r["steps"]):
        t0 = time.perf_counter()
        if path is not None:
            T[:3, 3] = path[k]
            hand.set_target(mink.SE3.from_matrix(T))
        try:
            v = mink.solve_ik(config, [hand, posture], sc["dt"], "daqp", limits=limits)
        except NoSolutionFound:
            failed = k + 1  # the QP has no solution: the run stops here
            break
        config.integrate_inplace(v, sc["dt"])
        ts.append(time.perf_counter() - t0)
        vs.append(v.tolist())
        qs.append(config.q.tolist())
    out = {"label": r["label"], "v": vs, "q": qs, "t": ts, "failed": failed}
    return {**out, "pairs": pairs}


def main() -> int:
    sc = json.loads(sys.stdin.readline())
    model = model_of(sc)
    names = [model.joint(j).name for j in range(model.njnt)]
    if names != sc["joints"]:
        raise SystemExit(f"mink_side: MuJoCo's joints {names} are not {sc['joints']}")
    data = mujoco.MjData(model)
    poses = []
    for q in sc["check"]:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        T = np.eye(4)
        T[:3, :3] = data.site("task").xmat.reshape(3, 3)
        T[:3, 3] = data.site("task").xpos
        poses.append(T.tolist())
    out = {
        "mink": version("mink"),
        "mujoco": mujoco.__version__,
        "poses": poses,
        "runs": [run(model, sc, r) for r in sc["runs"]],
    }
    sys.stdout.write(json.dumps(out) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
