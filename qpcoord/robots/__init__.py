"""Robot descriptions shipped with qpcoord, turned into :class:`~qpcoord.Robot` objects.

>>> import qpcoord as qc
>>> arm = qc.robots.load("planar_3r")
>>> arm.position([0.0, 0.0, 0.0])          # x = Σ cos qᵢ, y = Σ sin qᵢ (m)
array([3., 0.])

Known names (:func:`names`):

- ``planar_3r`` -- thesis 3R2D arm, unit links, **absolute** joint angles (rad);
- ``spatial_5r`` -- thesis 5R3D arm, l0..l4 = 1 m, l5 = 0.5 m: yaw about z, then four
  pitch joints (why: :mod:`qpcoord.robots.spatial_5r`);
- ``planar_nr`` -- ``n`` unit links in the plane, absolute angles (``load("planar_nr", n=5)``);
- ``panda`` -- Franka Panda, 7 DoF, fingers locked, frame ``panda_hand_tcp``
  (``panda_fingers``: the same with its two finger joints, nq = nv = 9);
- ``ur5`` -- Universal Robots UR5, 6 DoF, frame ``tool0``;
- ``shoulder`` -- appendix A glenohumeral joint with 11 muscles, a
  :class:`~qpcoord.robots.shoulder.ShoulderModel` (not a ``Robot``; options of
  :func:`~qpcoord.robots.shoulder.build`);
- every robot of ``example-robot-data`` by its usual name (``talos``, ``solo12``, ``go2``,
  ``anymal_c``, ``tiago``, ``g1``, ``ur10``, ``kinova``, …: the table
  :data:`~qpcoord.robots.external.EXAMPLE_ROBOTS`). Legged robots, humanoids and drones get
  a free-flyer root joint (first in ``q``: position (m) and unit quaternion ``(x, y, z, w)``;
  ``nv = nq − 1``), wheeled mobile bases a planar root; each gets its SRDF's reference
  configurations (``robot.reference_configuration("half_sitting")``) and a default frame
  where the robot has one end effector (``None`` for legged robots and two-armed ones).

Every robot other than the thesis ones comes from the ``example-robot-data`` package (the
optional extra ``qpcoord[robots]``); its meshes are found through ``robot.package_dirs``.
"""

from __future__ import annotations

from importlib import resources

import numpy as np

from ..kinematics.robot import Robot
from . import shoulder, spatial_5r
from .builders import absolute_angle_map, planar_chain
from .external import (
    EXAMPLE_ROBOTS,
    example_robot_data_package_dir,
    example_robot_data_urdf,
)
from .files import description_path

__all__ = [
    "load",
    "names",
    "description_path",
    "planar_chain",
    "absolute_angle_map",
    "spatial_5r",
    "shoulder",
]

#: the thesis robots and the two arms ``load`` has always known, then example-robot-data's
_BUILTIN = ("planar_3r", "spatial_5r", "planar_nr", "panda", "ur5", "shoulder")
_NAMES = _BUILTIN + tuple(sorted(n for n in EXAMPLE_ROBOTS if n not in _BUILTIN))


def names() -> tuple[str, ...]:
    """Names accepted by :func:`load`."""
    return _NAMES


def load(name: str, **options: object) -> Robot:
    """Load a robot by name.

    Parameters
    ----------
    name : str
        One of :func:`names`.
    **options
        ``n`` (number of links) for ``planar_nr``; the options of
        :func:`~qpcoord.robots.shoulder.build` for ``shoulder``; none for the others.

    Raises
    ------
    ValueError
        Unknown name (the message lists the known ones), unexpected options, or
        ``example-robot-data`` missing for a robot of it.
    """
    if not isinstance(name, str) or name not in _NAMES:
        raise ValueError(f"unknown robot {name!r}; known robots: {', '.join(_NAMES)}")
    if name == "planar_nr":
        extra = set(options) - {"n"}
        if extra or "n" not in options:
            raise ValueError(f"load('planar_nr') takes exactly the option n=…, got {options!r}")
        n = options["n"]
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ValueError(f"planar_nr: n must be an integer >= 1, got {n!r}")
        return Robot(
            planar_chain(n),
            "tip",
            rows=(0, 1),
            coordinate_map=absolute_angle_map(n),
            name=f"planar_{n}r",
        )
    if name == "shoulder":
        return shoulder.build(**options)
    if options:
        raise ValueError(f"load({name!r}) takes no options, got {options!r}")
    if name == "planar_3r":
        with resources.as_file(description_path("planar_3r.urdf")) as path:
            return Robot.from_urdf(
                path, "tip", rows=(0, 1), coordinate_map=absolute_angle_map(3), name=name
            )
    if name == "spatial_5r":
        with resources.as_file(description_path("spatial_5r.urdf")) as path:
            # the thesis model has no joint limits
            return Robot.from_urdf(
                path, "tip", name=name, lower=-np.inf, upper=np.inf, velocity_limit=np.inf
            )
    if name == "panda":
        return Robot.from_urdf(
            example_robot_data_urdf("panda_description/urdf/panda.urdf"),
            "panda_hand_tcp",
            locked_joints=("panda_finger_joint1", "panda_finger_joint2"),
            name=name,
            srdf=example_robot_data_urdf("panda_description/srdf/panda.srdf"),
            package_dirs=example_robot_data_package_dir(),
        )
    if name == "ur5":
        return Robot.from_urdf(
            example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf"),
            "tool0",
            name=name,
            srdf=example_robot_data_urdf("ur_description/srdf/ur5.srdf"),
            package_dirs=example_robot_data_package_dir(),
        )
    spec = EXAMPLE_ROBOTS[name]
    return Robot.from_urdf(
        example_robot_data_urdf(spec.urdf),
        spec.frame,
        locked_joints=spec.locked_joints,
        name=name,
        srdf=None if spec.srdf is None else example_robot_data_urdf(spec.srdf),
        package_dirs=example_robot_data_package_dir(),
        floating_base=False if spec.base == "fixed" else spec.base,
        lock_configuration=spec.lock_configuration,
    )
