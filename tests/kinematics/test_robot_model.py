"""Tests of :class:`qpcoord.Robot` as a whole Pinocchio model: every robot of
:func:`qpcoord.robots.names` loads, floating bases (nq ≠ nv), the configuration manifold,
frame and CoM Jacobians against finite differences on the manifold, SRDF reference
configurations, MJCF, and every bad input named in its ``ValueError``."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import qpcoord as qc
from qpcoord.robots.external import (
    EXAMPLE_ROBOTS,
    example_robot_data_package_dir,
    example_robot_data_urdf,
)

#: Central-difference step on the manifold (unit of v × s) and the agreement required.
FD_STEP = 1e-6
FD_TOL = 2e-6


# ---------------------------------------------------------------------------------------
# fixtures: each big robot is loaded once per module
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def talos() -> qc.Robot:
    return qc.robots.load("talos")


@pytest.fixture(scope="module")
def solo12() -> qc.Robot:
    return qc.robots.load("solo12")


@pytest.fixture(scope="module")
def manifold_robots(talos, solo12) -> dict[str, qc.Robot]:
    """Floating bases (free flyer, planar), continuous joints and a fixed arm."""
    return {
        "talos": talos,
        "solo12": solo12,
        "panda_fingers": qc.robots.load("panda_fingers"),
        "kinova": qc.robots.load("kinova"),  # continuous joints: nq 9, nv 6
        "tiago_no_hand": qc.robots.load("tiago_no_hand"),  # planar root + continuous wheels
    }


MANIFOLD_NAMES = ["talos", "solo12", "panda_fingers", "kinova", "tiago_no_hand"]


def rotation_log(R: np.ndarray) -> np.ndarray:
    return np.asarray(pin.log3(R), dtype=float)


# ---------------------------------------------------------------------------------------
# every robot loads
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", qc.robots.names())
def test_every_name_loads(name):
    options = {"n": 4} if name == "planar_nr" else {}
    robot = qc.robots.load(name, **options)
    if name == "shoulder":
        assert isinstance(robot, qc.robots.shoulder.ShoulderModel)
        return
    assert isinstance(robot, qc.Robot)
    assert robot.nq == robot.model.nq >= 1 and robot.nv == robot.model.nv >= 1
    assert robot.lower.shape == robot.upper.shape == (robot.nq,)
    assert robot.velocity_limit.shape == (robot.nv,) and np.all(robot.velocity_limit > 0)
    q = robot.neutral()
    assert robot.check_configuration(q).shape == (robot.nq,)
    for ref in robot.reference_names():
        robot.check_configuration(robot.reference_configuration(ref))
    if robot.frame is not None:
        assert robot.frame in robot.frame_names()
        T = robot.frame_pose(q, robot.frame)
        assert T.shape == (4, 4) and np.all(np.isfinite(T))
        assert robot.jacobian(q).shape == (robot.m, robot.nv)
    if robot.mass > 0:
        assert np.all(np.isfinite(robot.com(q)))
    spec = EXAMPLE_ROBOTS.get(name)
    if spec is not None:
        assert robot.frame == spec.frame
        root = robot.model.joints[1].shortname()
        expected = {
            "fixed": None,
            "free_flyer": "JointModelFreeFlyer",
            "planar": "JointModelPlanar",
        }[spec.base]
        assert (root if expected else None) == expected
        assert robot.package_dirs == (str(example_robot_data_package_dir()),)


def test_names_contains_the_usual_robots():
    usual = {
        "panda", "ur3", "ur5", "ur10", "iiwa" if "iiwa" in qc.robots.names() else "kinova",
        "kinova", "talos", "talos_arm", "talos_legs", "solo8", "solo12", "go1", "go2",
        "anymal", "anymal_c", "hyq", "tiago", "g1", "h1" if "h1" in qc.robots.names() else "g1",
        "romeo", "icub", "baxter", "double_pendulum", "planar_3r", "planar_nr", "spatial_5r",
        "shoulder",
    }  # fmt: skip
    assert usual <= set(qc.robots.names())
    assert len(set(qc.robots.names())) == len(qc.robots.names())


@pytest.mark.parametrize(
    ("name", "nq", "nv"),
    [
        ("panda_fingers", 9, 9),
        ("panda", 7, 7),
        ("talos", 39, 38),
        ("solo12", 19, 18),
        ("solo8", 15, 14),
        ("talos_legs", 19, 18),
        ("kinova", 9, 6),
    ],
)
def test_sizes(name, nq, nv, manifold_robots):
    robot = manifold_robots.get(name) or qc.robots.load(name)
    assert (robot.nq, robot.nv) == (nq, nv)


def test_panda_urdf_has_nine_joints_and_the_bundled_panda_seven():
    path = example_robot_data_urdf("panda_description/urdf/panda.urdf")
    full = qc.Robot.from_urdf(path, frame="panda_hand_tcp")
    assert (full.nq, full.nv) == (9, 9)
    arm = qc.robots.load("panda")
    assert (arm.nq, arm.frame) == (7, "panda_hand_tcp")
    assert arm.reference_names() == ("default",)


def test_from_urdf_never_frees_a_base_silently():
    path = example_robot_data_urdf("solo_description/robots/solo12.urdf")
    fixed = qc.Robot.from_urdf(path)
    free = qc.Robot.from_urdf(path, floating_base=True)
    planar = qc.Robot.from_urdf(path, floating_base="planar")
    assert (fixed.nq, fixed.nv, fixed.frame) == (12, 12, None)
    assert (free.nq, free.nv) == (19, 18)
    assert (planar.nq, planar.nv) == (16, 15)
    assert free.model.names[1] == "root_joint"


def test_talos_legs_lock_the_upper_body_at_half_sitting(talos):
    legs = qc.robots.load("talos_legs")
    assert [n for n in legs.model.names if n.startswith(("arm", "torso", "head"))] == []
    q_full, q_legs = (r.reference_configuration("half_sitting") for r in (talos, legs))
    np.testing.assert_allclose(q_legs, q_full[:19], atol=1e-12)
    # the locked arm hangs where half_sitting puts it
    T_full = talos.frame_pose(q_full, "gripper_left_base_link")
    T_legs = legs.frame_pose(q_legs, "gripper_left_base_link")
    np.testing.assert_allclose(T_legs, T_full, atol=1e-12)


# ---------------------------------------------------------------------------------------
# the configuration manifold
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", MANIFOLD_NAMES)
def test_integrate_keeps_unit_norms_and_difference_round_trips(name, manifold_robots):
    robot = manifold_robots[name]
    rng = np.random.default_rng(3)
    q = robot.random_configuration(rng)
    for _ in range(200):
        v = rng.normal(scale=2.0, size=robot.nv)
        q = robot.integrate(q, v, 0.05)
        robot.check_configuration(q)  # unit quaternions / (cos, sin) pairs
    for start, stop, _, _ in robot._unit_blocks:
        assert abs(np.linalg.norm(q[start:stop]) - 1.0) < 1e-12
    v = rng.normal(size=robot.nv)
    q1 = robot.integrate(q, v, 0.1)
    np.testing.assert_allclose(robot.difference(q, q1), 0.1 * v, atol=1e-12)
    q2 = robot.random_configuration(rng)
    back = robot.integrate(q, robot.difference(q, q2), 1.0)
    np.testing.assert_allclose(robot.difference(q2, back), 0.0, atol=1e-12)
    np.testing.assert_allclose(robot.difference(q, q), 0.0, atol=0)


def test_neutral_and_reference_configuration_of_talos(talos):
    q0 = talos.neutral()
    np.testing.assert_array_equal(q0[3:7], [0.0, 0.0, 0.0, 1.0])
    q = talos.reference_configuration("half_sitting")
    assert q.shape == (39,)
    np.testing.assert_allclose(q[:7], [0.0, 0.0, 1.01927, 0.0, 0.0, 0.0, 1.0], atol=1e-9)
    # half sitting stands on the ground: both soles at z = 0 within a millimetre
    for sole in ("left_sole_link", "right_sole_link"):
        assert abs(talos.frame_pose(q, sole)[2, 3]) < 1e-3
    q[0] = 99.0  # a copy: the stored configuration is unchanged
    assert talos.reference_configuration("half_sitting")[0] == 0.0


def test_random_configuration_is_inside_the_limits_and_seeded(manifold_robots):
    for robot in manifold_robots.values():
        q = robot.random_configuration(7)
        robot.check_configuration(q)
        assert np.all(q >= robot.lower) and np.all(q <= robot.upper)
        np.testing.assert_array_equal(q, robot.random_configuration(7))


# ---------------------------------------------------------------------------------------
# Jacobians against finite differences on the manifold
# ---------------------------------------------------------------------------------------


def fd_frame_twist(robot, q, v, frame, h=FD_STEP):
    """(linear, angular) velocity of ``frame`` along ``v`` by central differences: the
    change of its origin / the log of its rotation change, over ``2h``."""
    Tp = robot.frame_pose(robot.integrate(q, v, h), frame)
    Tm = robot.frame_pose(robot.integrate(q, v, -h), frame)
    linear = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
    angular = rotation_log(Tp[:3, :3] @ Tm[:3, :3].T) / (2 * h)
    return linear, angular


def frames_to_check(robot):
    names = [f for f in robot.frame_names() if f != "universe"]
    picks = [names[len(names) // 3], names[-1]]
    if robot.frame is not None:
        picks.append(robot.frame)
    return picks


@pytest.mark.parametrize("name", MANIFOLD_NAMES)
def test_frame_jacobian_matches_finite_differences(name, manifold_robots):
    robot = manifold_robots[name]
    rng = np.random.default_rng(11)
    for _ in range(3):
        q = robot.random_configuration(rng)
        for frame in frames_to_check(robot):
            J = robot.frame_jacobian(q, frame)
            assert J.shape == (6, robot.nv)
            # column by column (every tangent direction) and along a random direction
            directions = [*np.eye(robot.nv)[: min(robot.nv, 9)], rng.normal(size=robot.nv)]
            for v in directions:
                linear, angular = fd_frame_twist(robot, q, v, frame)
                scale = max(1.0, float(np.abs(J @ v).max()))
                assert np.abs(J[:3] @ v - linear).max() <= FD_TOL * scale, (frame, "linear")
                assert np.abs(J[3:] @ v - angular).max() <= FD_TOL * scale, (frame, "angular")


@pytest.mark.parametrize("name", MANIFOLD_NAMES)
def test_com_jacobian_matches_finite_differences(name, manifold_robots):
    robot = manifold_robots[name]
    rng = np.random.default_rng(5)
    q = robot.random_configuration(rng)
    Jc = robot.com_jacobian(q)
    assert Jc.shape == (3, robot.nv)
    for v in [*np.eye(robot.nv)[:8], rng.normal(size=robot.nv)]:
        h = FD_STEP
        fd = (robot.com(robot.integrate(q, v, h)) - robot.com(robot.integrate(q, v, -h))) / (2 * h)
        assert np.abs(Jc @ v - fd).max() <= FD_TOL * max(1.0, float(np.abs(fd).max()))


def test_com_matches_pinocchio(talos):
    q = talos.reference_configuration("half_sitting")
    data = talos.model.createData()
    np.testing.assert_allclose(talos.com(q), pin.centerOfMass(talos.model, data, q), atol=1e-14)


def test_one_point_api_on_a_floating_base(talos):
    hand = talos.with_frame("gripper_left_base_link")
    q = talos.reference_configuration("half_sitting")
    y, J = hand.kinematics(q)
    np.testing.assert_allclose(y, talos.frame_pose(q, "gripper_left_base_link")[:3, 3])
    np.testing.assert_allclose(J, talos.frame_jacobian(q, "gripper_left_base_link")[:3])
    assert J.shape == (3, 38) and hand.position(q).shape == (3,)
    assert hand.reference_names() == ("half_sitting",)


def test_one_forward_kinematics_pass_per_configuration(talos, monkeypatch):
    calls = []
    original = pin.computeJointJacobians

    def counting(*args):
        calls.append(1)
        return original(*args)

    monkeypatch.setattr(pin, "computeJointJacobians", counting)
    robot = qc.robots.load("talos")
    q = robot.reference_configuration("half_sitting")
    for frame in ("left_sole_link", "right_sole_link", "gripper_left_base_link"):
        robot.frame_pose(q, frame)
        robot.frame_jacobian(q, frame)
    robot.com(q)
    robot.com_jacobian(q)
    assert len(calls) == 1
    robot.frame_pose(robot.integrate(q, np.ones(robot.nv), 0.01), "left_sole_link")
    assert len(calls) == 2


# ---------------------------------------------------------------------------------------
# MJCF
# ---------------------------------------------------------------------------------------

MJCF = """
<mujoco model="flyer_arm">
  <worldbody>
    <body name="base" pos="0 0 1">
      <freejoint name="root"/>
      <inertial pos="0 0 0" mass="2" diaginertia="0.1 0.1 0.1"/>
      <body name="link1" pos="0 0 0.1">
        <joint name="hinge1" type="hinge" axis="0 0 1"/>
        <inertial pos="0.2 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>
        <body name="link2" pos="0.4 0 0">
          <joint name="hinge2" type="hinge" axis="0 1 0"/>
          <inertial pos="0.15 0 0" mass="0.5" diaginertia="0.01 0.01 0.01"/>
          <site name="tip" pos="0.3 0 0"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_from_mjcf(tmp_path):
    path = tmp_path / "flyer_arm.xml"
    path.write_text(MJCF)
    robot = qc.Robot.from_mjcf(path, frame="link2")
    assert (robot.nq, robot.nv) == (9, 8)
    assert robot.name == "flyer_arm"
    q = robot.neutral()
    # a free body's pos is MuJoCo's initial qpos, not a fixed placement: at the neutral
    # configuration the base is at the origin
    np.testing.assert_allclose(robot.frame_pose(q, "link2")[:3, 3], [0.4, 0.0, 0.1], atol=1e-12)
    assert robot.mass == pytest.approx(3.5)
    rng = np.random.default_rng(2)
    q = robot.random_configuration(rng)
    J = robot.frame_jacobian(q, "link2")
    v = rng.normal(size=robot.nv)
    linear, angular = fd_frame_twist(robot, q, v, "link2")
    np.testing.assert_allclose(J[:3] @ v, linear, atol=1e-6)
    np.testing.assert_allclose(J[3:] @ v, angular, atol=1e-6)


def test_from_mjcf_bad_files(tmp_path):
    with pytest.raises(ValueError, match="path: MJCF file .* does not exist"):
        qc.Robot.from_mjcf(tmp_path / "missing.xml")
    bad = tmp_path / "bad.xml"
    bad.write_text("<mujoco><worldbody><body")
    with pytest.raises(ValueError, match="failed to parse"):
        qc.Robot.from_mjcf(bad)


def test_from_model_keeps_reference_configurations(talos):
    robot = qc.Robot.from_model(talos.model, frame="left_sole_link", name="t")
    assert robot.reference_names() == ("half_sitting",)
    assert robot.frame == "left_sole_link" and robot.nv == 38


# ---------------------------------------------------------------------------------------
# bad input: every ValueError names its argument
# ---------------------------------------------------------------------------------------


def test_unknown_frame_names_the_argument_and_close_names(talos):
    q = talos.neutral()
    for method in (talos.frame_pose, talos.frame_jacobian):
        with pytest.raises(ValueError, match=r"frame: robot 'talos' has no frame 'left_sole'"):
            method(q, "left_sole")
    with pytest.raises(ValueError, match=r"close names: .*left_sole_link"):
        talos.frame_pose(q, "left_sole")
    with pytest.raises(ValueError, match="frame: frame index 999 out of range"):
        talos.frame_jacobian(q, 999)
    with pytest.raises(ValueError, match="frame must be a frame name"):
        talos.frame_pose(q, 1.5)
    with pytest.raises(ValueError, match=r"frame: .*no frame 'hand'"):
        talos.with_frame("hand")


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda q: q[:-1], r"q0? must have 39 entries .*nq = 39, nv = 38"),
        (lambda q: np.append(q, 0.0), r"q0? must have 39 entries"),
        (lambda q: np.where(np.arange(39) == 12, np.nan, q), r"q0?\[12\] is nan"),
        (lambda q: np.where(np.arange(39) == 0, np.inf, q), r"q0?\[0\] is inf"),
        (
            lambda q: np.where(np.arange(39) == 6, 1.1, q),
            r"q0?\[3:7\] is the quaternion of joint 'root_joint' and has norm 1\.1",
        ),
        (lambda q: np.where(np.arange(39) == 6, 1.0 + 2e-6, q), r"q0?\[3:7\] is the quaternion"),
    ],
    ids=["short", "long", "nan", "inf", "quaternion", "quaternion-just-off"],
)
def test_bad_configuration_of_a_floating_base(talos, mutate, message):
    q = mutate(talos.reference_configuration("half_sitting"))
    for call in (
        lambda: talos.check_configuration(q),
        lambda: talos.frame_pose(q, "left_sole_link"),
        lambda: talos.frame_jacobian(q, "left_sole_link"),
        lambda: talos.com(q),
        lambda: talos.com_jacobian(q),
        lambda: talos.integrate(q, np.zeros(38), 0.1),
        lambda: talos.difference(q, talos.neutral()),
    ):
        with pytest.raises(ValueError, match=message):
            call()


def test_quaternion_tolerance_accepts_rounding(talos):
    q = talos.reference_configuration("half_sitting")
    q[6] = 1.0 + 5e-7
    talos.check_configuration(q)
    np.testing.assert_allclose(np.linalg.norm(talos.normalize(q)[3:7]), 1.0, atol=1e-15)


def test_non_unit_continuous_joint_is_rejected(manifold_robots):
    kinova = manifold_robots["kinova"]
    q = kinova.neutral()
    q[1] = 0.5  # the (cos, sin) pair of the continuous joint 'j2s6s200_joint_1'
    with pytest.raises(
        ValueError, match=r"q\[0:2\] is the \(cos, sin\) pair of joint 'j2s6s200_joint_1'"
    ):
        kinova.frame_pose(q, kinova.frame)


def test_difference_names_its_arguments(talos):
    q = talos.neutral()
    with pytest.raises(ValueError, match=r"q1 must have 39 entries"):
        talos.difference(q, q[:5])
    with pytest.raises(ValueError, match=r"q0\[2\] is nan"):
        talos.difference(np.where(np.arange(39) == 2, np.nan, q), q)


@pytest.mark.parametrize(
    ("v", "dt", "message"),
    [
        (np.zeros(39), 0.1, r"v must have nv = 38 entries"),
        (np.full(38, np.nan), 0.1, r"v\[0\] is nan"),
        (np.zeros(38), np.nan, "dt must be finite"),
        (np.zeros(38), "fast", "dt must be a number"),
        ("abc", 0.1, "v must be numeric"),
    ],
)
def test_bad_velocity_or_step(talos, v, dt, message):
    with pytest.raises(ValueError, match=message):
        talos.integrate(talos.neutral(), v, dt)


def test_unknown_reference_configuration_lists_the_known_ones(talos, solo12):
    with pytest.raises(ValueError, match=r"name: .*no reference configuration 'sitting'"):
        talos.reference_configuration("sitting")
    with pytest.raises(ValueError, match=r"known: standing, straight_standing"):
        solo12.reference_configuration("half_sitting")
    with pytest.raises(ValueError, match=r"known: none \(load the robot with an SRDF\)"):
        qc.robots.load("ur10").reference_configuration("home")


def test_one_point_api_without_a_default_frame(talos):
    for method in (talos.position, talos.jacobian, talos.kinematics, talos.hessian):
        with pytest.raises(ValueError, match="has no default frame: pass frame="):
            method(talos.neutral())


def test_centre_of_mass_of_a_massless_model():
    arm = qc.robots.load("planar_3r")
    with pytest.raises(ValueError, match="has no mass"):
        arm.com(np.zeros(3))


def test_unknown_robot_name_lists_the_names():
    with pytest.raises(ValueError, match="unknown robot 'atlas'") as info:
        qc.robots.load("atlas")
    assert "talos" in str(info.value) and "solo12" in str(info.value)
    with pytest.raises(ValueError, match=r"load\('talos'\) takes no options"):
        qc.robots.load("talos", n=3)


def test_from_urdf_bad_arguments(tmp_path):
    urdf = example_robot_data_urdf("solo_description/robots/solo12.urdf")
    with pytest.raises(ValueError, match="path: URDF file .* does not exist"):
        qc.Robot.from_urdf(tmp_path / "none.urdf")
    with pytest.raises(ValueError, match="srdf: SRDF file .* does not exist"):
        qc.Robot.from_urdf(urdf, srdf=tmp_path / "none.srdf")
    with pytest.raises(ValueError, match="package_dirs: .* is not a directory"):
        qc.Robot.from_urdf(urdf, package_dirs=[tmp_path / "nothing"])
    with pytest.raises(ValueError, match="floating_base must be False"):
        qc.Robot.from_urdf(urdf, floating_base="wheels")
    with pytest.raises(ValueError, match=r"frame \(the second argument of from_urdf\)"):
        qc.Robot.from_urdf(urdf, [str(tmp_path)])
    with pytest.raises(ValueError, match="lock_configuration: no reference configuration"):
        qc.Robot.from_urdf(urdf, locked_joints=("FL_KFE",), lock_configuration="sitting")
    with pytest.raises(ValueError, match="lock_configuration must be 12 finite numbers"):
        qc.Robot.from_urdf(urdf, locked_joints=("FL_KFE",), lock_configuration=[0.0])


def test_zero_urdf_velocity_limits_read_as_unlimited():
    robot = qc.robots.load("double_pendulum")
    assert np.all(robot.velocity_limit == np.inf)


def test_repr_shows_nv_when_it_differs(talos):
    assert repr(talos) == "Robot('talos', nq=39, nv=38, frame=None, rows=(0, 1, 2))"
