"""Robot descriptions from the ``example-robot-data`` distribution.

Its PyPI wheel (6.0.0) ships the URDF / SRDF files under
``cmeel.prefix/share/example-robot-data/robots`` but no importable module, so the files are
found through the distribution's metadata; ``package_dirs`` is ``cmeel.prefix/share`` (where
``package://<robot>_description/...`` mesh URIs resolve).

:data:`EXAMPLE_ROBOTS` maps each name of :func:`qpcoord.robots.load` to its files, its root
joint and its default end-effector frame. The names are those of example-robot-data's own
(Python) loader where it has one, plus the robots it ships without a loader entry.

Root joints: a URDF cannot say whether its root link is free, so the table does. Legged
robots, humanoids and drones get a **free-flyer** root (``nq = 7 + joints``,
``nv = 6 + joints``); wheeled mobile manipulators (Tiago, PR2) a **planar** root (x, y,
yaw: ``nq + 4``, ``nv + 3``) -- their wheels are joints of the file, but the base's motion on
the floor is not; arms and hands keep a fixed base.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

__all__ = [
    "EXAMPLE_ROBOTS",
    "ExampleRobot",
    "example_robot_data_urdf",
    "example_robot_data_package_dir",
]

_SHARE = "cmeel.prefix/share/"
_PREFIX = _SHARE + "example-robot-data/robots/"


@dataclass(frozen=True)
class ExampleRobot:
    """Where one robot of example-robot-data lives and how it is loaded.

    Attributes
    ----------
    urdf : str
        URDF path relative to the ``robots`` folder.
    srdf : str or None
        SRDF path (reference configurations), if the data set has one for this robot.
    base : str
        ``"fixed"``, ``"free_flyer"`` or ``"planar"`` root joint.
    frame : str or None
        Default end-effector frame (``None`` for robots without a single one: legged
        robots, humanoids, two-armed robots, hands).
    locked_joints : tuple of str
        Joints frozen at ``lock_configuration``.
    lock_configuration : str or None
        SRDF reference configuration the locked joints are frozen at (default neutral).
    """

    urdf: str
    srdf: str | None = None
    base: str = "fixed"
    frame: str | None = None
    locked_joints: tuple[str, ...] = ()
    lock_configuration: str | None = None


def _ur(stem: str, srdf: str | None = None) -> ExampleRobot:
    return ExampleRobot(f"ur_description/urdf/{stem}.urdf", srdf, frame="tool0")


_TALOS_SRDF = "talos_data/srdf/talos.srdf"
_TALOS_UPPER_BODY = (
    "torso_1_joint",
    "torso_2_joint",
    *(f"arm_{side}_{i}_joint" for side in ("left", "right") for i in range(1, 8)),
    "gripper_left_joint",
    "gripper_right_joint",
    "head_1_joint",
    "head_2_joint",
)
_FF = "free_flyer"

#: name -> files, root joint and default frame (see the module docstring).
EXAMPLE_ROBOTS: dict[str, ExampleRobot] = {
    # arms
    "panda_fingers": ExampleRobot(
        "panda_description/urdf/panda.urdf",
        "panda_description/srdf/panda.srdf",
        frame="panda_hand_tcp",
    ),
    "panda_collision": ExampleRobot(
        "panda_description/urdf/panda_collision.urdf",
        "panda_description/srdf/panda.srdf",
        frame="panda_hand_tcp",
    ),
    "ur3": _ur("ur3_robot"),
    "ur3_gripper": _ur("ur3_gripper", "ur_description/srdf/ur3_gripper.srdf"),
    "ur3_limited": _ur("ur3_joint_limited_robot"),
    "ur5_gripper": _ur("ur5_gripper", "ur_description/srdf/ur5_gripper.srdf"),
    "ur5_limited": _ur(
        "ur5_joint_limited_robot", "ur_description/srdf/ur5_joint_limited_robot.srdf"
    ),
    "ur10": _ur("ur10_robot"),
    "ur10_limited": _ur("ur10_joint_limited_robot"),
    "kinova": ExampleRobot(
        "kinova_description/robots/kinova.urdf",
        "kinova_description/srdf/kinova.srdf",
        frame="j2s6s200_end_effector",
    ),
    "z1": ExampleRobot(
        "z1_description/urdf/z1.urdf", "z1_description/srdf/z1.srdf", frame="gripperMover"
    ),
    "xarm7": ExampleRobot(
        "xarm_description/urdf/xarm7.urdf", "xarm_description/srdf/xarm7.srdf", frame="link_eef"
    ),
    "so100": ExampleRobot("so_arm_description/urdf/so100.urdf", frame="gripper"),
    "so101": ExampleRobot("so_arm_description/urdf/so101.urdf", frame="gripper_frame_link"),
    "talos_arm": ExampleRobot(
        "talos_data/robots/talos_left_arm.urdf", _TALOS_SRDF, frame="gripper_left_base_link"
    ),
    "finger_edu": ExampleRobot(
        "finger_edu_description/robots/finger_edu.urdf",
        "finger_edu_description/srdf/finger_edu.srdf",
        frame="finger_tip_link",
    ),
    "asr_twodof": ExampleRobot("asr_twodof_description/urdf/TwoDofs.urdf", frame="EE"),
    "double_pendulum": ExampleRobot("double_pendulum_description/urdf/double_pendulum.urdf"),
    "double_pendulum_continuous": ExampleRobot(
        "double_pendulum_description/urdf/double_pendulum_continuous.urdf"
    ),
    "double_pendulum_simple": ExampleRobot(
        "double_pendulum_description/urdf/double_pendulum_simple.urdf", frame="link3"
    ),
    "baxter": ExampleRobot(
        "baxter_description/urdf/baxter.urdf", "baxter_description/srdf/baxter_manipulation.srdf"
    ),
    "alex_nub_hands": ExampleRobot(
        "alex_description/urdf/alex_nub_hands.urdf", "alex_description/srdf/alex_nub_hands.srdf"
    ),
    "alex_psyonic_hands": ExampleRobot(
        "alex_description/urdf/alex_psyonic_hands.urdf",
        "alex_description/srdf/alex_psyonic_hands.srdf",
    ),
    "alex_sake_hands": ExampleRobot(
        "alex_description/urdf/alex_sake_hands.urdf",
        "alex_description/srdf/alex_sake_hands.srdf",
    ),
    # hands
    "allegro_right_hand": ExampleRobot("allegro_hand_description/urdf/allegro_right_hand.urdf"),
    "allegro_left_hand": ExampleRobot("allegro_hand_description/urdf/allegro_left_hand.urdf"),
    # humanoids
    "talos": ExampleRobot("talos_data/robots/talos_reduced.urdf", _TALOS_SRDF, _FF),
    "talos_box": ExampleRobot("talos_data/robots/talos_reduced_box.urdf", _TALOS_SRDF, _FF),
    "talos_full": ExampleRobot("talos_data/robots/talos_full_v2.urdf", _TALOS_SRDF, _FF),
    "talos_full_box": ExampleRobot("talos_data/robots/talos_full_v2_box.urdf", _TALOS_SRDF, _FF),
    "talos_legs": ExampleRobot(
        "talos_data/robots/talos_reduced.urdf",
        _TALOS_SRDF,
        _FF,
        locked_joints=_TALOS_UPPER_BODY,
        lock_configuration="half_sitting",
    ),
    "romeo": ExampleRobot(
        "romeo_description/urdf/romeo.urdf", "romeo_description/srdf/romeo.srdf", _FF
    ),
    "romeo_small": ExampleRobot(
        "romeo_description/urdf/romeo_small.urdf", "romeo_description/srdf/romeo_small.srdf", _FF
    ),
    "icub": ExampleRobot(
        "icub_description/robots/icub.urdf", "icub_description/srdf/icub.srdf", _FF
    ),
    "icub_reduced": ExampleRobot(
        "icub_description/robots/icub_reduced.urdf", "icub_description/srdf/icub.srdf", _FF
    ),
    "g1": ExampleRobot("g1_description/urdf/g1_29dof_rev_1_0.urdf", base=_FF),
    "g1_with_hand": ExampleRobot("g1_description/urdf/g1_29dof_with_hand_rev_1_0.urdf", base=_FF),
    "simple_humanoid": ExampleRobot(
        "simple_humanoid_description/urdf/simple_humanoid.urdf",
        "simple_humanoid_description/srdf/simple_humanoid.srdf",
        _FF,
    ),
    "simple_humanoid_classical": ExampleRobot(
        "simple_humanoid_description/urdf/simple_humanoid_classical.urdf",
        "simple_humanoid_description/srdf/simple_humanoid_classical.srdf",
        _FF,
    ),
    "alexander": ExampleRobot(
        "alexander_description/urdf/alexander_v1.lowerBodyOnly.urdf",
        "alexander_description/srdf/alexander.srdf",
        _FF,
    ),
    "human": ExampleRobot("human_description/robots/human.urdf", base=_FF),
    "bolt": ExampleRobot(
        "bolt_description/robots/bolt.urdf", "bolt_description/srdf/bolt.srdf", _FF
    ),
    # quadrupeds (and legged manipulators)
    "solo8": ExampleRobot(
        "solo_description/robots/solo.urdf", "solo_description/srdf/solo.srdf", _FF
    ),
    "solo12": ExampleRobot(
        "solo_description/robots/solo12.urdf", "solo_description/srdf/solo.srdf", _FF
    ),
    "go1": ExampleRobot("go1_description/urdf/go1.urdf", "go1_description/srdf/go1.srdf", _FF),
    "go2": ExampleRobot("go2_description/urdf/go2.urdf", "go2_description/srdf/go2.srdf", _FF),
    "a1": ExampleRobot("a1_description/urdf/a1.urdf", "a1_description/srdf/a1.srdf", _FF),
    "b1": ExampleRobot("b1_description/urdf/b1.urdf", "b1_description/srdf/b1.srdf", _FF),
    "b1_z1": ExampleRobot(
        "b1_description/urdf/b1-z1.urdf", "b1_description/srdf/b1-z1.srdf", _FF, "gripperMover"
    ),
    "laikago": ExampleRobot("laikago_description/urdf/laikago.urdf", base=_FF),
    "anymal": ExampleRobot(
        "anymal_b_simple_description/robots/anymal.urdf",
        "anymal_b_simple_description/srdf/anymal.srdf",
        _FF,
    ),
    "anymal_c": ExampleRobot(
        "anymal_c_simple_description/urdf/anymal.urdf",
        "anymal_c_simple_description/srdf/anymal.srdf",
        _FF,
    ),
    "anymal_kinova": ExampleRobot(
        "anymal_b_simple_description/robots/anymal-kinova.urdf",
        "anymal_b_simple_description/srdf/anymal-kinova.srdf",
        _FF,
        "j2s6s200_end_effector",
    ),
    "hyq": ExampleRobot(
        "hyq_description/robots/hyq_no_sensors.urdf", "hyq_description/srdf/hyq.srdf", _FF
    ),
    "quadruped": ExampleRobot("quadruped_description/urdf/quadruped.urdf", base=_FF),
    "centauro": ExampleRobot(
        "centauro_description/urdf/centauro.urdf", "centauro_description/srdf/centauro.srdf", _FF
    ),
    # wheeled mobile manipulators: planar root
    "tiago": ExampleRobot(
        "tiago_description/robots/tiago.urdf", base="planar", frame="arm_tool_link"
    ),
    "tiago_no_hand": ExampleRobot(
        "tiago_description/robots/tiago_no_hand.urdf", base="planar", frame="arm_tool_link"
    ),
    "tiago_dual": ExampleRobot("tiago_description/robots/tiago_dual.urdf", base="planar"),
    "tiago_pro": ExampleRobot("tiago_pro_description/robots/tiago_pro.urdf", base="planar"),
    "pr2": ExampleRobot("pr2_description/urdf/pr2.urdf", "pr2_description/srdf/pr2.srdf", "planar"),
    # aerial robots
    "hector": ExampleRobot("hector_description/robots/quadrotor_base.urdf", base=_FF),
    "iris": ExampleRobot("iris_description/robots/iris_simple.urdf", base=_FF),
    "borinot": ExampleRobot(
        "borinot_description/urdf/borinot_flying_arm_2.urdf",
        "borinot_description/srdf/borinot_flying_arm_2.srdf",
        _FF,
        "flying_arm_2__ee",
    ),
    "hextilt": ExampleRobot(
        "hextilt_description/urdf/hextilt_flying_arm_5.urdf",
        "hextilt_description/srdf/hextilt_flying_arm_5.srdf",
        _FF,
        "flying_arm_5__gripper",
    ),
}


def _distribution() -> metadata.Distribution:
    try:
        return metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        raise ValueError(
            "this robot needs the 'example-robot-data' package: pip install 'qpcoord[robots]'"
        ) from None


def example_robot_data_urdf(relative: str) -> Path:
    """Absolute path of ``robots/<relative>`` inside the installed example-robot-data.

    Raises
    ------
    ValueError
        The distribution is not installed (install ``qpcoord[robots]``) or lacks the file.
    """
    dist = _distribution()
    path = Path(dist.locate_file(_PREFIX + relative))
    if not path.is_file():
        raise ValueError(f"example-robot-data {dist.version} has no file {relative!r}")
    return path


def example_robot_data_package_dir() -> Path:
    """The ``share`` folder that resolves example-robot-data's ``package://`` mesh URIs."""
    return Path(_distribution().locate_file(_SHARE))
