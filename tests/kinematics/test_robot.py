"""Tests of :class:`qpcoord.Robot`: kinematics against finite differences, caching, errors."""

from __future__ import annotations

from importlib import resources

import numpy as np
import pinocchio as pin
import pytest

import qpcoord as qc
from qpcoord.robots import absolute_angle_map, planar_chain

#: Central-difference step (rad) and the agreement required (relative to max(1, |value|)).
FD_STEP = 1e-6
FD_TOL = 1e-6
#: Random configurations checked per robot.
NUM_CONFIGURATIONS = 4


# ---------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------


def placement(rpy, xyz) -> pin.SE3:
    """SE3 from roll-pitch-yaw angles (rad) and a translation (m)."""
    return pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.array(xyz, dtype=float))


def mixed_axes_model() -> pin.Model:
    """A 5-joint spatial chain with RX/RY/RZ joints, rotated joint placements, a prismatic
    joint and an end frame offset (translation and rotation) from its parent joint."""
    model = pin.Model()
    model.name = "mixed_axes"
    joints = [
        (pin.JointModelRZ(), placement((0.0, 0.0, 0.0), (0.0, 0.0, 0.3))),
        (pin.JointModelRY(), placement((0.2, -0.1, 0.4), (0.5, 0.1, 0.0))),
        (pin.JointModelRX(), placement((-0.3, 0.5, 0.1), (0.4, -0.2, 0.1))),
        (pin.JointModelPY(), placement((0.0, 0.0, 0.0), (0.0, 0.3, 0.2))),
        (pin.JointModelRY(), placement((0.7, 0.0, -0.2), (0.3, 0.0, -0.1))),
    ]
    parent = 0
    for i, (joint, joint_placement) in enumerate(joints):
        parent = model.addJoint(parent, joint, joint_placement, f"j{i + 1}")
        model.appendBodyToJoint(parent, pin.Inertia.Zero(), pin.SE3.Identity())
    tool = placement((0.3, -0.6, 1.1), (0.15, -0.25, 0.35))
    model.addFrame(pin.Frame("tool", parent, 0, tool, pin.FrameType.OP_FRAME))
    model.lowerPositionLimit[:] = -np.pi
    model.upperPositionLimit[:] = np.pi
    model.velocityLimit[:] = 2.0
    return model


#: A well-conditioned, non-triangular coordinate map for the mixed model.
MIXED_MAP = np.eye(5) + 0.3 * np.eye(5, k=1) - 0.2 * np.eye(5, k=-2)

ROBOT_FACTORIES = {
    "planar_3r": lambda: qc.robots.load("planar_3r"),
    "planar_1r": lambda: qc.robots.load("planar_nr", n=1),
    "planar_2r": lambda: qc.robots.load("planar_nr", n=2),
    "planar_5r": lambda: qc.robots.load("planar_nr", n=5),
    "panda": lambda: qc.robots.load("panda"),
    "ur5": lambda: qc.robots.load("ur5"),
    "spatial_5r": lambda: qc.robots.load("spatial_5r"),
    "mixed_axes": lambda: qc.Robot(mixed_axes_model(), "tool", name="mixed"),
    "mixed_axes_rows_xz": lambda: qc.Robot(mixed_axes_model(), "tool", rows=(2, 0)),
    "mixed_axes_mapped": lambda: qc.Robot(
        mixed_axes_model(), "tool", rows=(1, 2), coordinate_map=MIXED_MAP
    ),
}


@pytest.fixture(params=list(ROBOT_FACTORIES), ids=list(ROBOT_FACTORIES))
def any_robot(request) -> qc.Robot:
    return ROBOT_FACTORIES[request.param]()


def random_configurations(robot: qc.Robot, rng: np.random.Generator, count: int) -> np.ndarray:
    """``count`` configurations strictly inside the limits (``[-π, π]`` where unlimited)."""
    lo = np.where(np.isfinite(robot.lower), robot.lower, -np.pi)
    hi = np.where(np.isfinite(robot.upper), robot.upper, np.pi)
    margin = 0.05 * (hi - lo)
    return rng.uniform(lo + margin, hi - margin, size=(count, robot.nq))


def fd_jacobian(robot: qc.Robot, q: np.ndarray, h: float = FD_STEP) -> np.ndarray:
    cols = []
    for i in range(robot.nq):
        e = np.zeros(robot.nq)
        e[i] = h
        cols.append((robot.position(q + e) - robot.position(q - e)) / (2 * h))
    return np.stack(cols, axis=1)


def fd_hessian(robot: qc.Robot, q: np.ndarray, h: float = FD_STEP) -> np.ndarray:
    """``H[k, i, j]`` from central differences of the analytic Jacobian."""
    H = np.empty((robot.m, robot.nq, robot.nq))
    for j in range(robot.nq):
        e = np.zeros(robot.nq)
        e[j] = h
        H[:, :, j] = (robot.jacobian(q + e) - robot.jacobian(q - e)) / (2 * h)
    return H


def assert_close_relative(actual, expected, tol: float, what: str) -> None:
    actual, expected = np.asarray(actual), np.asarray(expected)
    scale = np.maximum(1.0, np.abs(expected))
    err = np.abs(actual - expected) / scale
    worst = np.unravel_index(int(np.argmax(err)), err.shape)
    assert err.max() <= tol, (
        f"{what}: relative error {err.max():.3g} at {worst} "
        f"(actual {actual[worst]!r}, expected {expected[worst]!r})"
    )


# ---------------------------------------------------------------------------------------
# kinematics of every robot
# ---------------------------------------------------------------------------------------


def test_shapes_of_kinematic_maps(any_robot, rng):
    q = random_configurations(any_robot, rng, 1)[0]
    assert any_robot.position(q).shape == (any_robot.m,)
    assert any_robot.jacobian(q).shape == (any_robot.m, any_robot.nq)
    assert any_robot.hessian(q).shape == (any_robot.m, any_robot.nq, any_robot.nq)
    y, J = any_robot.kinematics(q)
    assert y.shape == (any_robot.m,) and J.shape == (any_robot.m, any_robot.nq)


def test_jacobian_matches_finite_differences(any_robot, rng):
    for q in random_configurations(any_robot, rng, NUM_CONFIGURATIONS):
        assert_close_relative(any_robot.jacobian(q), fd_jacobian(any_robot, q), FD_TOL, "J")


def test_hessian_matches_finite_differences(any_robot, rng):
    for q in random_configurations(any_robot, rng, NUM_CONFIGURATIONS):
        assert_close_relative(any_robot.hessian(q), fd_hessian(any_robot, q), FD_TOL, "H")


def test_hessian_is_symmetric(any_robot, rng):
    for q in random_configurations(any_robot, rng, NUM_CONFIGURATIONS):
        H = any_robot.hessian(q)
        np.testing.assert_allclose(H, H.transpose(0, 2, 1), rtol=0, atol=1e-12)


def test_hessian_is_not_trivially_zero(any_robot, rng):
    """Guards the finite-difference test: the Hessians compared are not all zeros."""
    q = random_configurations(any_robot, rng, 1)[0]
    assert np.abs(any_robot.hessian(q)).max() > 1e-3


def test_kinematics_equals_position_and_jacobian(any_robot, rng):
    q = random_configurations(any_robot, rng, 1)[0]
    y, J = any_robot.kinematics(q)
    np.testing.assert_allclose(y, any_robot.position(q), rtol=0, atol=1e-15)
    np.testing.assert_allclose(J, any_robot.jacobian(q), rtol=0, atol=1e-15)


def test_interleaved_calls_give_the_same_values_as_a_fresh_robot(any_robot, rng):
    """The kinematics cache never returns numbers of another configuration or level."""
    qs = random_configurations(any_robot, rng, 3)
    expected = []
    for q in qs:
        fresh = rebuilt(any_robot)
        expected.append((fresh.position(q), fresh.jacobian(q), fresh.hessian(q)))
    order = [
        (0, "hessian"),
        (1, "position"),
        (0, "position"),
        (1, "hessian"),
        (2, "jacobian"),
        (2, "hessian"),
        (0, "jacobian"),
        (2, "position"),
    ]
    index = {"position": 0, "jacobian": 1, "hessian": 2}
    for k, what in order:
        value = getattr(any_robot, what)(qs[k])
        np.testing.assert_allclose(
            value,
            expected[k][index[what]],
            rtol=0,
            atol=1e-12,
            err_msg=f"{what} at configuration {k}",
        )


def rebuilt(robot: qc.Robot) -> qc.Robot:
    """A new robot on the same model (its own Pinocchio data: no shared cache)."""
    return qc.Robot(
        robot.model,
        robot.frame,
        rows=tuple(int(r) for r in robot.rows),
        coordinate_map=robot.coordinate_map,
        lower=robot.lower,
        upper=robot.upper,
        velocity_limit=robot.velocity_limit,
        name=robot.name,
    )


def test_caller_mutating_q_in_place_is_not_served_from_the_cache(rng):
    robot = qc.Robot(mixed_axes_model(), "tool")
    q = random_configurations(robot, rng, 1)[0]
    first = robot.position(q)
    q += 0.3
    np.testing.assert_allclose(robot.position(q), rebuilt(robot).position(q))
    assert not np.allclose(robot.position(q), first)


def test_returned_position_is_not_overwritten_by_a_later_call(any_robot, rng):
    q1, q2 = random_configurations(any_robot, rng, 2)
    y1 = any_robot.position(q1)
    kept = y1.copy()
    any_robot.position(q2)
    np.testing.assert_array_equal(y1, kept)


def test_kinematics_result_is_not_overwritten_by_a_later_call(rng):
    robot = qc.robots.load("planar_3r")
    y1, J1 = robot.kinematics([0.1, 0.2, 0.3])
    kept_y, kept_J = y1.copy(), J1.copy()
    robot.kinematics([1.0, 2.0, 3.0])
    np.testing.assert_array_equal(J1, kept_J)
    np.testing.assert_array_equal(y1, kept_y)


@pytest.mark.parametrize("coordinate_map", [None, [[2.0]]], ids=["plain", "mapped"])
def test_single_joint_robot_has_matrix_shaped_jacobian_and_hessian(coordinate_map):
    """nq = 1: Pinocchio's binding returns 6×1 matrices as vectors; shapes must not collapse."""
    robot = qc.Robot(planar_chain(1), "tip", rows=(0, 1), coordinate_map=coordinate_map)
    k = 1.0 if coordinate_map is None else 2.0  # q_pin = k q
    q = np.array([0.3])
    a = k * 0.3
    np.testing.assert_allclose(robot.position(q), [np.cos(a), np.sin(a)], atol=1e-15)
    J = robot.jacobian(q)
    assert J.shape == (2, 1)
    np.testing.assert_allclose(J, k * np.array([[-np.sin(a)], [np.cos(a)]]), atol=1e-15)
    H = robot.hessian(q)
    assert H.shape == (2, 1, 1)
    np.testing.assert_allclose(H, k**2 * np.array([[[-np.cos(a)]], [[-np.sin(a)]]]), atol=1e-15)
    y, J_pair = robot.kinematics(q)
    assert y.shape == (2,) and J_pair.shape == (2, 1)


def test_coordinate_map_is_a_change_of_joint_coordinates(rng):
    """``q_pin = M q``: position agrees with the unmapped robot at ``M q``; J and H follow
    the chain rule."""
    plain = qc.Robot(mixed_axes_model(), "tool")
    mapped = qc.Robot(mixed_axes_model(), "tool", coordinate_map=MIXED_MAP)
    for q in rng.uniform(-1.0, 1.0, size=(3, 5)):
        qp = MIXED_MAP @ q
        np.testing.assert_allclose(mapped.position(q), plain.position(qp), atol=1e-14)
        np.testing.assert_allclose(mapped.jacobian(q), plain.jacobian(qp) @ MIXED_MAP, atol=1e-13)
        expected_H = np.einsum("ia,kij,jb->kab", MIXED_MAP, plain.hessian(qp), MIXED_MAP)
        np.testing.assert_allclose(mapped.hessian(q), expected_H, atol=1e-12)


def test_rows_select_world_coordinates_in_the_given_order(rng):
    full = qc.Robot(mixed_axes_model(), "tool")
    zx = qc.Robot(mixed_axes_model(), "tool", rows=(2, 0))
    q = rng.uniform(-1.0, 1.0, 5)
    np.testing.assert_allclose(zx.position(q), full.position(q)[[2, 0]], atol=1e-15)
    np.testing.assert_allclose(zx.jacobian(q), full.jacobian(q)[[2, 0]], atol=1e-15)
    np.testing.assert_allclose(zx.hessian(q), full.hessian(q)[[2, 0]], atol=1e-15)


def test_frame_offset_is_applied():
    """At q = 0 the tool point is the composition of the placements and the tool offset."""
    model = mixed_axes_model()
    robot = qc.Robot(model, "tool")
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.zeros(5))
    expected = data.oMf[model.getFrameId("tool")].translation
    np.testing.assert_allclose(robot.position(np.zeros(5)), expected, atol=1e-15)
    parent = model.frames[model.getFrameId("tool")].parentJoint
    assert np.linalg.norm(expected - data.oMi[parent].translation) > 0.1


# ---------------------------------------------------------------------------------------
# limits
# ---------------------------------------------------------------------------------------


def test_default_limits_come_from_the_model():
    model = mixed_axes_model()
    robot = qc.Robot(model, "tool")
    np.testing.assert_array_equal(robot.lower, model.lowerPositionLimit)
    np.testing.assert_array_equal(robot.upper, model.upperPositionLimit)
    np.testing.assert_array_equal(robot.velocity_limit, model.velocityLimit)


def test_default_limits_with_a_coordinate_map_are_unlimited():
    robot = qc.Robot(mixed_axes_model(), "tool", coordinate_map=MIXED_MAP)
    assert np.all(robot.lower == -np.inf) and np.all(robot.upper == np.inf)
    assert np.all(robot.velocity_limit == np.inf)


def test_scalar_limits_broadcast():
    robot = qc.Robot(mixed_axes_model(), "tool", lower=-1.0, upper=2.0, velocity_limit=0.5)
    np.testing.assert_array_equal(robot.lower, np.full(5, -1.0))
    np.testing.assert_array_equal(robot.upper, np.full(5, 2.0))
    np.testing.assert_array_equal(robot.velocity_limit, np.full(5, 0.5))


# ---------------------------------------------------------------------------------------
# URDF
# ---------------------------------------------------------------------------------------


def test_from_urdf_with_a_locked_joint_removes_it():
    with resources.as_file(qc.robots.description_path("planar_3r.urdf")) as path:
        robot = qc.Robot.from_urdf(path, "tip", rows=(0, 1), locked_joints=("q3",))
    assert robot.nq == 2
    assert robot.name == "planar_3r"
    q1, q2 = 0.4, -1.1
    # relative angles; the locked third joint stays at 0
    expected = [
        np.cos(q1) + 2 * np.cos(q1 + q2),
        np.sin(q1) + 2 * np.sin(q1 + q2),
    ]
    np.testing.assert_allclose(robot.position([q1, q2]), expected, atol=1e-14)


def test_from_urdf_without_map_uses_relative_angles_and_file_limits():
    with resources.as_file(qc.robots.description_path("planar_3r.urdf")) as path:
        robot = qc.Robot.from_urdf(path, "tip", rows=(0, 1), name="rel")
    q = np.array([0.3, 0.2, -0.4])
    absolute = qc.robots.load("planar_3r")
    np.testing.assert_allclose(robot.position(q), absolute.position(np.cumsum(q)), atol=1e-14)
    np.testing.assert_array_equal(robot.upper, np.full(3, 1e6))
    assert robot.name == "rel"


def test_from_urdf_missing_file(tmp_path):
    missing = tmp_path / "nowhere.urdf"
    with pytest.raises(ValueError, match="does not exist") as info:
        qc.Robot.from_urdf(missing, "tip")
    assert "nowhere.urdf" in str(info.value)


@pytest.mark.parametrize(
    "content",
    ["this is not XML at all", "<robot name='x'><link name='a'/><joint", ""],
    ids=["text", "truncated-xml", "empty"],
)
def test_from_urdf_garbage_file(tmp_path, content):
    path = tmp_path / "garbage.urdf"
    path.write_text(content)
    with pytest.raises(ValueError, match="failed to parse") as info:
        qc.Robot.from_urdf(path, "tip")
    assert "garbage.urdf" in str(info.value)


def test_from_urdf_unknown_locked_joint_lists_joints():
    with resources.as_file(qc.robots.description_path("planar_3r.urdf")) as path:
        with pytest.raises(ValueError, match="locked joint 'elbow'") as info:
            qc.Robot.from_urdf(path, "tip", locked_joints=("elbow",))
    assert all(name in str(info.value) for name in ("q1", "q2", "q3"))


def test_from_urdf_unknown_frame_lists_frames():
    with resources.as_file(qc.robots.description_path("planar_3r.urdf")) as path:
        with pytest.raises(ValueError, match="no frame 'hand'") as info:
            qc.Robot.from_urdf(path, "hand")
    assert "tip" in str(info.value) and "link2" in str(info.value)


# ---------------------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------------------


@pytest.fixture
def planar() -> qc.Robot:
    return qc.robots.load("planar_3r")


@pytest.mark.parametrize(
    "method", ["position", "jacobian", "hessian", "kinematics", "check_configuration"]
)
@pytest.mark.parametrize(
    ("q", "message"),
    [
        ([0.1, 0.2], "must have 3 entries"),
        ([0.1, 0.2, 0.3, 0.4], "must have 3 entries"),
        ([], "must have 3 entries"),
        ([0.1, np.nan, 0.3], r"q\[1\] is .*nan.*must be finite"),
        ([0.1, 0.2, np.inf], r"q\[2\] is .*inf.*must be finite"),
        (["a", "b", "c"], "must be numeric"),
    ],
    ids=["short", "long", "empty", "nan", "inf", "text"],
)
def test_bad_configuration_is_rejected(planar, method, q, message):
    with pytest.raises(ValueError, match=message):
        getattr(planar, method)(q)


def test_unknown_frame_lists_the_frames():
    with pytest.raises(ValueError, match="no frame 'hand'") as info:
        qc.Robot(planar_chain(2), "hand")
    assert "frames are: universe, tip" in str(info.value)


def test_model_must_be_a_pinocchio_model():
    with pytest.raises(ValueError, match="pinocchio.Model"):
        qc.Robot("planar_3r", "tip")


def test_model_without_joints_is_rejected():
    model = pin.Model()
    model.addFrame(pin.Frame("tip", 0, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    with pytest.raises(ValueError, match="no joints"):
        qc.Robot(model, "tip")


def free_flyer_model() -> pin.Model:
    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
    model.appendBodyToJoint(joint, pin.Inertia.FromSphere(1.0, 0.1), pin.SE3.Identity())
    tip = placement((0.0, 0.0, 0.0), (0.3, 0.0, 0.0))
    model.addFrame(pin.Frame("tip", joint, 0, tip, pin.FrameType.OP_FRAME))
    return model


def test_free_flyer_joint_is_accepted_with_nv_columns():
    """A free-flyer root (nq = 7, nv = 6) is a whole model now; the one-point API gives
    nv columns."""
    robot = qc.Robot(free_flyer_model(), "tip")
    assert (robot.nq, robot.nv) == (7, 6)
    q = robot.neutral()
    np.testing.assert_allclose(robot.position(q), [0.3, 0.0, 0.0], atol=1e-15)
    assert robot.jacobian(q).shape == (3, 6)


def test_coordinate_map_and_hessian_need_a_vector_space():
    with pytest.raises(ValueError, match=r"coordinate_map needs .*nq = 7, nv = 6"):
        qc.Robot(free_flyer_model(), "tip", coordinate_map=np.eye(7))
    robot = qc.Robot(free_flyer_model(), "tip")
    with pytest.raises(ValueError, match=r"hessian\(\) needs a vector-space"):
        robot.hessian(robot.neutral())


@pytest.mark.parametrize("rows", [(), (0, 0), (3,), (0, 1, 2, 0), (-1,)])
def test_bad_rows(rows):
    with pytest.raises(ValueError, match="rows must be distinct"):
        qc.Robot(planar_chain(2), "tip", rows=rows)


@pytest.mark.parametrize(
    ("coordinate_map", "message"),
    [
        (np.ones((2, 2)), "singular"),
        (np.eye(3), "finite 2×2"),
        ([[1.0, np.nan], [0.0, 1.0]], "finite 2×2"),
    ],
    ids=["singular", "wrong-shape", "nan"],
)
def test_bad_coordinate_map(coordinate_map, message):
    with pytest.raises(ValueError, match=message):
        qc.Robot(planar_chain(2), "tip", coordinate_map=coordinate_map)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"lower": [0.0, 1.0], "upper": [1.0, 0.5]}, "lower > upper at joint 1"),
        ({"lower": [0.0, 0.0, 0.0]}, "lower must have 2 entries"),
        ({"upper": [np.nan, 1.0]}, "upper contains NaN"),
        ({"lower": np.inf}, "lower contains NaN or a wrong-signed infinity"),
        ({"velocity_limit": [1.0, 0.0]}, "velocity_limit must be > 0"),
        ({"velocity_limit": -np.inf}, "velocity_limit contains"),
    ],
)
def test_bad_limits(options, message):
    with pytest.raises(ValueError, match=message):
        qc.Robot(planar_chain(2), "tip", **options)


def test_absolute_angle_map_inverts_the_cumulative_sum():
    for n in range(1, 6):
        M = absolute_angle_map(n)
        np.testing.assert_array_equal(M @ np.tril(np.ones((n, n))), np.eye(n))


def test_repr_names_the_robot():
    text = repr(qc.Robot(planar_chain(2), "tip", rows=(0, 1), name="two"))
    assert text == "Robot('two', nq=2, frame='tip', rows=(0, 1))"
