"""The qpcoord side of ``benchmarks/mink_side.py``: the scenario it reads, built from a
qpcoord robot, and its answer, for ``edges.py`` and ``collision_bench.py``.

mink needs MuJoCo, which is not a qpcoord dependency: ``mink_side.py`` runs in mink's own
environment (:data:`MINK_VENV`, made by :data:`MINK_SETUP`) and speaks JSON on its standard
input and output (its docstring gives the fields).
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pinocchio as pin

HERE = Path(__file__).resolve().parent
#: mink's own environment (MuJoCo is not a qpcoord dependency): ``benchmarks/mink_side.py``
MINK_VENV = HERE / ".mink-venv"
MINK_SETUP = (
    "python3 -m venv benchmarks/.mink-venv && "
    "benchmarks/.mink-venv/bin/pip install -r benchmarks/mink-requirements.txt"
)


def joint_body(model, joint: int) -> str:
    """The URDF link a joint moves: the body frame at the joint's own frame."""
    for frame in model.frames:
        if (
            frame.type == pin.FrameType.BODY
            and frame.parentJoint == joint
            and frame.placement.isIdentity()
        ):
            return frame.name
    raise ValueError(f"no body frame at joint {model.names[joint]}")


def _plain(value):
    """A numpy array or number as JSON's list or float."""
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    raise TypeError(f"not JSON: {type(value).__name__}")


def call_mink_side(
    robot, frame: str, runs: list[dict], dt: float, check, velocity, collision: dict | None = None
) -> tuple[dict | None, str]:
    """``runs`` by mink on a MuJoCo model of ``robot``'s URDF with ``frame`` as its task site.

    Parameters
    ----------
    robot : qpcoord.Robot
        The robot (its URDF and package folder).
    frame : str
        The task frame, made a MuJoCo site on the link it is fixed to.
    runs : list of dict
        mink_side.py's runs (numpy arrays allowed).
    dt : float
        Time step, s.
    check : sequence of array
        Configurations (rad) at which mink gives the site's pose.
    velocity : array
        Speed limit of each joint, rad/s (mink's ``VelocityLimit``).
    collision : dict, optional
        mink_side.py's ``collision`` (fixed joints, the sphere, the distances, m).

    Returns
    -------
    (dict, str) or (None, str)
        mink_side.py's answer and ``""``, or ``None`` and why mink did not run
        (``mink: not run (...)`` or ``mink: failed (...)``, no full stop).
    """
    python = MINK_VENV / "bin" / "python"
    if not python.exists():
        return None, f"mink: not run (no benchmarks/.mink-venv; {MINK_SETUP})"
    model = robot.model
    site = model.frames[model.getFrameId(frame)]
    quat = pin.Quaternion(site.placement.rotation)
    scenario = {
        "urdf": str(robot.urdf_path),
        "package_dir": str(robot.package_dirs[0]),
        "site": {
            "body": joint_body(model, site.parentJoint),
            "pos": site.placement.translation,
            "quat": [quat.w, quat.x, quat.y, quat.z],
        },
        "joints": list(model.names[1:]),
        "velocity": velocity,
        "check": list(check),
        "dt": dt,
        "runs": runs,
    }
    if collision is not None:
        scenario["collision"] = collision
    done = subprocess.run(
        [str(python), str(HERE / "mink_side.py")],
        input=json.dumps(scenario, default=_plain) + "\n",
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        tail = done.stderr.strip().splitlines()[-1:] or ["no message"]
        return None, f"mink: failed ({tail[0]})"
    return json.loads(done.stdout), ""
