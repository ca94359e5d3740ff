"""mink's side of ``benchmarks/edges.py``, run in mink's own environment.

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
  and ``config_gain`` (``ConfigurationLimit``'s gain, ``null`` for mink's default);
- out: ``mink`` and ``mujoco`` (versions), ``poses`` (the site's 4 × 4 pose at each ``check``
  configuration) and ``runs``: each ``label``, ``v`` (steps × nv, rad/s), ``q`` (steps × nq,
  rad) and ``failed`` (the step at which the QP had no solution, or ``null``).

The MuJoCo model is built from the same URDF as qpcoord's (visual and collision meshes
dropped: kinematics only), so the joints, limits and the task frame are the same.
"""

from __future__ import annotations

import json
import os
import re
import sys
import tempfile
from importlib.metadata import version

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import mink  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from mink.exceptions import NoSolutionFound  # noqa: E402


def model_of(sc: dict) -> mujoco.MjModel:
    """The MuJoCo model of the URDF, with the task frame as a site."""
    text = open(sc["urdf"]).read()
    text = re.sub(r"<(visual|collision)>.*?</\1>", "", text, flags=re.S)
    text = text.replace("package://", sc["package_dir"] + "/")
    with tempfile.TemporaryDirectory(prefix="qpcoord-mink-") as folder:
        path = os.path.join(folder, "robot.urdf")
        with open(path, "w") as f:
            f.write(text)
        spec = mujoco.MjSpec.from_file(path)
    site = sc["site"]
    spec.body(site["body"]).add_site(name="task", pos=site["pos"], quat=site["quat"])
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
    vs, qs, failed = [], [], None
    for k in range(r["steps"]):
        try:
            v = mink.solve_ik(config, [hand, posture], sc["dt"], "daqp", limits=limits)
        except NoSolutionFound:
            failed = k + 1  # the QP has no solution: the run stops here
            break
        config.integrate_inplace(v, sc["dt"])
        vs.append(v.tolist())
        qs.append(config.q.tolist())
    return {"label": r["label"], "v": vs, "q": qs, "failed": failed}


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
