"""IK on the velocity ``v`` (size ``nv``): floating bases (solo12, talos), limits from the robot
(position, speed, acceleration), the public task API (your own ``KinematicTask`` / ``Limit``),
several frames of one robot in one IK, and bad input."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc
from qpcoord.kinematics import (
    AccelerationLimits,
    JointLimits,
    KinematicTask,
    Limit,
    PositionBand,
    PositionTask,
    PostureTask,
    VelocityLimits,
)

DT = 0.01
PANDA_Q = np.array([0.1, -0.4, 0.2, -2.0, 0.1, 1.6, 0.5])


@pytest.fixture(scope="module")
def solo() -> qc.Robot:
    return qc.robots.load("solo12")


@pytest.fixture(scope="module")
def talos() -> qc.Robot:
    return qc.robots.load("talos")


@pytest.fixture
def panda() -> qc.Robot:
    return qc.robots.load("panda")


class Height(KinematicTask):
    """The docs' custom task: keep a frame's height ``z`` (m)."""

    def __init__(self, robot, frame, z, gain=10.0, **options):
        super().__init__(robot, 1, gain=gain, name="height", **options)
        self.frame, self.z = frame, z

    def compute_error(self, q):
        return self.robot.frame_pose(q, self.frame)[2:3, 3] - self.z

    def compute_jacobian(self, q):
        return self.robot.frame_jacobian(q, self.frame)[2:3]


def _fd_jacobian(robot, error, q, h=1e-7):
    """``∂e/∂v`` by central differences along ``robot.integrate`` (nv columns)."""
    cols = []
    for i in range(robot.nv):
        dv = np.zeros(robot.nv)
        dv[i] = h
        cols.append(error(robot.integrate(q, dv, 1.0)) - error(robot.integrate(q, -dv, 1.0)))
    return np.array(cols).T / (2 * h)


# ---------------------------------------------------------------------------------------
# floating base: sizes, the quaternion, limits
# ---------------------------------------------------------------------------------------


def test_posture_on_a_floating_base_leaves_the_root_out(solo):
    q_ref = solo.reference_configuration("standing")
    q = solo.random_configuration(3)
    task = PostureTask(solo, q_ref, gain=2.0)
    eq = task.update(q)
    assert eq.shape == (solo.nv - 6, solo.nv)
    np.testing.assert_array_equal(eq.A, np.eye(solo.nv)[6:])
    np.testing.assert_allclose(eq.b, 2.0 * solo.difference(q, q_ref)[6:], atol=1e-14)
    # public error / Jacobian: J v = −K e is the same task
    e, J = task.compute_error(q), task.compute_jacobian(q)
    np.testing.assert_allclose(-2.0 * e, eq.b, atol=1e-12)
    np.testing.assert_array_equal(J, eq.A)
    np.testing.assert_allclose(J, _fd_jacobian(solo, task.compute_error, q), atol=1e-6)


def test_posture_on_a_fixed_base_is_the_identity(panda):
    task = PostureTask(panda, np.zeros(7))
    assert task.task.is_identity
    np.testing.assert_allclose(task.compute_error(PANDA_Q), PANDA_Q)


def test_posture_and_limits_on_solo12(solo):
    q = solo.reference_configuration("standing")
    q_ref = solo.random_configuration(7)
    ik = qc.IK(solo, [PostureTask(solo, q_ref, gain=5.0)], dt=DT)
    assert [type(lim) for lim in ik.limits] == [JointLimits, VelocityLimits]
    for _ in range(200):
        v, sol = ik.step(q)
        assert v.shape == (solo.nv,) and sol.status == "optimal"
        q = solo.integrate(q, v, DT)
        assert abs(np.linalg.norm(q[3:7]) - 1.0) < 1e-12
    solo.check_configuration(q)  # still a valid configuration
    np.testing.assert_allclose(v[:6], 0.0, atol=1e-9)  # the base is left alone (min norm)
    np.testing.assert_allclose(solo.difference(q, q_ref)[6:], 0.0, atol=1e-3)


def test_talos_joint_limits_hold_against_the_posture(talos):
    """The posture pulls every joint 0.3 rad beyond its upper limit; position limits (with
    the dt look-ahead) and speed limits from the URDF hold at every step."""
    q = talos.reference_configuration("half_sitting")
    limits = JointLimits(talos)
    q_ref = q.copy()
    qi = limits._q_index
    q_ref[qi] = talos.upper[qi] + 0.3
    ik = qc.IK(talos, [PostureTask(talos, q_ref, gain=10.0)], dt=DT)
    vmax = VelocityLimits(talos).limit
    for _ in range(150):
        v, _ = ik.step(q)
        assert np.all(np.abs(v) <= vmax + 1e-9)
        q = talos.integrate(q, v, DT)
        assert np.all(q[qi] <= talos.upper[qi] + 1e-9)
        assert np.all(q[qi] >= talos.lower[qi] - 1e-9)
    assert abs(np.linalg.norm(q[3:7]) - 1.0) < 1e-12
    # the joints got to their limits
    np.testing.assert_allclose(q[qi], talos.upper[qi], atol=1e-3)


def test_joint_limits_map_q_to_v_indices(talos, solo):
    for robot in (talos, solo):
        lim = JointLimits(robot, gain=1.0)
        assert lim.joints.min() == 6  # the free-flyer (v 0..5) is unlimited
        np.testing.assert_array_equal(lim._q_index, lim._v_index + 1)  # 7 q vs 6 v entries
        q = robot.random_configuration(0)
        lo, hi = lim.box(q, DT)
        assert lo.shape == hi.shape == (robot.nv,)
        assert np.all(lo[:6] == -np.inf) and np.all(hi[:6] == np.inf)
        np.testing.assert_allclose(hi[lim.joints], (robot.upper - q)[lim._q_index] / DT)
        speed = VelocityLimits(robot)
        assert np.all(speed.limit[:6] == np.inf)  # ±1.8e308 reads as unlimited
        assert np.all(np.isfinite(speed.limit[6:]))


def test_continuous_and_spherical_joints_are_unlimited():
    import pinocchio as pin

    model = pin.Model()
    j1 = model.addJoint(0, pin.JointModelRUBZ(), pin.SE3.Identity(), "wheel")
    j2 = model.addJoint(j1, pin.JointModelSpherical(), pin.SE3.Identity(), "ball")
    j3 = model.addJoint(j2, pin.JointModelRY(), pin.SE3.Identity(), "hinge")
    model.addJointFrame(j3)
    model.lowerPositionLimit[:] = -1.0
    model.upperPositionLimit[:] = 1.0
    robot = qc.Robot(model)
    lim = JointLimits(robot, gain=1.0)
    assert (robot.nq, robot.nv) == (7, 5)
    np.testing.assert_array_equal(lim.joints, [4])  # only the revolute joint
    lo, hi = lim.box(robot.neutral(), 0.1)
    assert np.all(np.isinf(lo[:4])) and np.all(np.isinf(hi[:4]))
    np.testing.assert_allclose([lo[4], hi[4]], [-10.0, 10.0])


def test_acceleration_limits_hold_across_steps(panda):
    a_max = 2.0  # rad/s²
    acc = AccelerationLimits(panda, a_max)
    ee = PositionTask(panda, target=panda.position(PANDA_Q) + [0.2, -0.1, 0.1], gain=20.0)
    limits = [JointLimits(panda), VelocityLimits(panda), acc]
    ik = qc.IK(panda, [ee, PostureTask(panda, PANDA_Q)], dt=DT, limits=limits)
    q, v_prev = PANDA_Q.copy(), np.zeros(7)
    binding = 0
    for _ in range(400):
        v, _ = ik.step(q)
        dv = np.abs(v - v_prev)
        assert np.all(dv <= a_max * DT + 1e-9)
        binding += bool(np.any(dv > a_max * DT - 1e-6))
        np.testing.assert_array_equal(acc.v_prev, v)
        np.testing.assert_array_equal(ik.v_prev, v)
        v_prev = v
        q = panda.integrate(q, v, DT)
    assert binding > 10  # the limit did shape the motion
    assert np.linalg.norm(panda.position(q) - ee.target) < 1e-3  # and the target is reached
    ik.reset()
    np.testing.assert_array_equal(acc.v_prev, 0.0)
    lo, hi = acc.box(q, DT)
    np.testing.assert_allclose(hi, a_max * DT)


def test_acceleration_limits_on_a_floating_base(solo):
    a = np.r_[np.full(6, np.inf), np.full(solo.nv - 6, 5.0)]
    acc = AccelerationLimits(solo, a)
    q = solo.reference_configuration("standing")
    ik = qc.IK(solo, [PostureTask(solo, solo.random_configuration(2), gain=10.0)], dt=DT,
               limits=[JointLimits(solo), acc])  # fmt: skip
    v_prev = np.zeros(solo.nv)
    for _ in range(20):
        v, _ = ik.step(q)
        assert np.all(np.abs(v - v_prev)[6:] <= 5.0 * DT + 1e-9)
        v_prev = v
        q = solo.integrate(q, v, DT)


@pytest.mark.parametrize("limit", [0.0, -1.0, np.nan, [1.0, 2.0]])
def test_acceleration_limits_bad_limit(panda, limit):
    with pytest.raises(ValueError, match="limit"):
        AccelerationLimits(panda, limit)


# ---------------------------------------------------------------------------------------
# your own task / limit
# ---------------------------------------------------------------------------------------


def test_custom_task_keeps_the_base_height_of_solo12(solo):
    """Level 0: the four feet stay put (a custom task each, a band for the base height);
    the base height is brought to 0.2 m by an equality."""
    q = solo.reference_configuration("standing")
    z0 = solo.frame_pose(q, "base_link")[2, 3]
    height = Height(solo, "base_link", z=z0 - 0.05, gain=20.0)
    posture = PostureTask(solo, q, gain=1.0)
    ik = qc.IK(solo, [height, posture], dt=DT)
    for _ in range(100):
        v, sol = ik.step(q)
        q = solo.integrate(q, v, DT)
    assert abs(solo.frame_pose(q, "base_link")[2, 3] - (z0 - 0.05)) < 1e-6
    np.testing.assert_allclose(height.compute_error(q), 0.0, atol=1e-6)


def test_custom_task_jacobian_matches_finite_differences(solo):
    task = Height(solo, "FR_FOOT", z=0.0)
    q = solo.random_configuration(5)
    np.testing.assert_allclose(
        task.compute_jacobian(q), _fd_jacobian(solo, task.compute_error, q), atol=1e-6
    )


def test_custom_band_task(panda):
    """The hand may not go below a floor 3 cm under it: as a band at level 0 it stops the
    hand on the floor while the level below asks for 10 cm lower."""
    q = PANDA_Q.copy()
    y0 = panda.position(q)
    floor = y0[2] - 0.03
    band = Height(panda, "panda_hand_tcp", z=0.0, kind="band", lower=floor, gain=1 / DT)
    assert isinstance(band.task, qc.Inequality) and band.task.shape == (1, 7)
    ee = PositionTask(panda, target=y0 - [0, 0, 0.10], gain=10.0)
    ik = qc.IK(panda, [band, ee, PostureTask(panda, q)], dt=DT)
    for _ in range(300):
        v, _ = ik.step(q)
        q = panda.integrate(q, v, DT)
        assert panda.position(q)[2] >= floor - 1e-6
    assert abs(panda.position(q)[2] - floor) < 1e-4
    band.set_band(lower=floor - 0.01)
    np.testing.assert_array_equal(band.lower, [floor - 0.01])
    # the same band as a hard constraint
    ik = qc.IK(panda, [ee], dt=DT, constraints=[band])
    assert ik.step(PANDA_Q)[1].status == "optimal"


def test_default_refresh_equality_numbers(panda):
    task = Height(panda, "panda_link4", z=0.3, gain=4.0)
    eq = task.update(PANDA_Q)
    z = panda.frame_pose(PANDA_Q, "panda_link4")[2, 3]
    np.testing.assert_allclose(eq.b, [-4.0 * (z - 0.3)])
    np.testing.assert_allclose(eq.A, panda.frame_jacobian(PANDA_Q, "panda_link4")[2:3])
    assert "rows=1" in repr(task) and task.name == "height"


def test_a_task_without_its_methods_cannot_be_built(panda):
    class Half(KinematicTask):
        def compute_error(self, q):
            return np.zeros(1)

    with pytest.raises(TypeError, match="compute_jacobian"):
        Half(panda, 1)
    with pytest.raises(TypeError, match="compute_error"):
        KinematicTask(panda, 1)


@pytest.mark.parametrize(
    ("error", "jacobian", "message"),
    [
        (np.zeros(2), np.zeros((1, 7)), r"compute_error\(q\) must return 1 values"),
        (np.zeros(1), np.zeros((1, 6)), r"compute_jacobian\(q\) must return shape \(1, 7\)"),
        (np.zeros(1), np.zeros((7, 1)), r"compute_jacobian\(q\) must return shape \(1, 7\)"),
        ([np.nan], np.zeros((1, 7)), "non-finite"),
        (np.zeros(1), np.full((1, 7), np.inf), "non-finite"),
    ],
)
def test_custom_task_bad_outputs(panda, error, jacobian, message):
    class Bad(KinematicTask):
        def compute_error(self, q):
            return error

        def compute_jacobian(self, q):
            return jacobian

    with pytest.raises(ValueError, match=message):
        Bad(panda, 1).update(PANDA_Q)


def test_a_one_row_task_may_return_flat_arrays(panda):
    class Flat(KinematicTask):
        def compute_error(self, q):
            return 0.5

        def compute_jacobian(self, q):
            return np.ones(7)

    eq = Flat(panda, 1, gain=2.0).update(PANDA_Q)
    np.testing.assert_array_equal(eq.A, np.ones((1, 7)))
    np.testing.assert_array_equal(eq.b, [-1.0])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"rows": 0}, "rows must be a positive integer"),
        ({"rows": 1.5}, "rows must be a positive integer"),
        ({"rows": 1, "kind": "soft"}, "kind must be 'equality' or 'band'"),
        ({"rows": 1, "lower": 0.0}, "lower/upper are for kind='band'"),
        ({"rows": 1, "kind": "band", "gain": 0.0}, "band needs gain > 0"),
        ({"rows": 1, "kind": "band", "lower": 1.0, "upper": 0.0}, "lower > upper"),
        ({"rows": 2, "kind": "band", "lower": [0.0, 1.0, 2.0]}, "lower must have 2"),
        ({"rows": 1, "gain": -1.0}, "gain must be"),
    ],
)
def test_custom_task_bad_construction(panda, kwargs, message):
    class Plain(KinematicTask):
        def compute_error(self, q):
            return np.zeros(self.task.shape[0])

        def compute_jacobian(self, q):
            return np.zeros(self.task.shape)

    rows = kwargs.pop("rows")
    with pytest.raises(ValueError, match=message):
        Plain(panda, rows, **kwargs)


def test_set_band_is_for_bands(panda):
    with pytest.raises(ValueError, match="set_band is for kind='band'"):
        Height(panda, "panda_hand", 0.5).set_band(lower=0.0)


def test_custom_limit(panda):
    class Symmetric(Limit):
        """|v_i| ≤ 0.1 rad/s on joint 0 only."""

        def box(self, q, dt):
            lo, hi = np.full(7, -np.inf), np.full(7, np.inf)
            lo[0], hi[0] = -0.1, 0.1
            return lo, hi

    ee = PositionTask(panda, target=panda.position(PANDA_Q) + [0.0, 0.3, 0.0], gain=10.0)
    ik = qc.IK(panda, [ee], dt=DT, limits=[Symmetric(panda, "joint 0 speed")])
    v, _ = ik.step(PANDA_Q)
    assert abs(v[0]) <= 0.1 + 1e-9
    assert abs(v[0]) > 0.09  # binding
    assert ik.limits[0].update(PANDA_Q).upper[0] == 0.1


# ---------------------------------------------------------------------------------------
# several frames of one robot; other robots
# ---------------------------------------------------------------------------------------


def test_tasks_on_several_frames_of_one_robot(panda):
    elbow = panda.with_frame("panda_link4")
    q = PANDA_Q.copy()
    z4 = elbow.position(q)[2]
    ee = PositionTask(panda, target=panda.position(q) + [0.0, 0.0, -0.2], gain=10.0)
    keep_elbow = PositionBand(elbow, lower=[-np.inf, -np.inf, z4 - 0.01], gain=1 / DT)
    ik = qc.IK(panda, [keep_elbow, ee, PostureTask(panda, q)], dt=DT)
    for _ in range(200):
        v, _ = ik.step(q)
        q = panda.integrate(q, v, DT)
        assert elbow.position(q)[2] >= z4 - 0.01 - 1e-6


def test_task_of_another_model_is_rejected_with_a_clear_message(panda):
    other = qc.robots.load("panda")
    assert other.model is not panda.model
    with pytest.raises(ValueError, match=r"levels\[0\]: task 'position' belongs to another robot"):
        qc.IK(panda, [PositionTask(other, [0.3, 0.0, 0.5])], dt=DT)
    with pytest.raises(ValueError, match="another Pinocchio model.*with_frame"):
        qc.IK(panda, [], dt=DT, limits=[VelocityLimits(other)])


def test_constant_tasks_need_nv_columns(solo):
    with pytest.raises(ValueError, match=r"has 19 columns, the robot 18 velocity variables"):
        qc.IK(solo, [qc.Equality(np.eye(solo.nq), np.zeros(solo.nq), name="nq-wide")], dt=DT)
    ik = qc.IK(solo, [qc.Equality(np.eye(solo.nv), np.zeros(solo.nv))], dt=DT)
    assert ik.step(solo.neutral())[0].shape == (18,)


# ---------------------------------------------------------------------------------------
# bad input, unreachable targets, thesis tasks on a floating base, simulate
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda q: q[:-1], r"q must have 19 entries"),
        (lambda q: np.r_[q[:3], 2.0 * q[3:7], q[7:]], r"q\[3:7\] is the quaternion.*unit norm"),
        (lambda q: np.r_[q[:7], np.nan, q[8:]], r"q\[7\] is nan"),
    ],
    ids=["short", "non-unit-quaternion", "nan"],
)
def test_bad_configuration_on_the_ik_path(solo, mutate, message):
    ik = qc.IK(solo, [PostureTask(solo, solo.neutral())], dt=DT)
    q = mutate(solo.reference_configuration("standing"))
    with pytest.raises(ValueError, match=message):
        ik.step(q)
    with pytest.raises(ValueError, match=message):
        PostureTask(solo, solo.neutral()).update(q)


@pytest.mark.parametrize("limits", ["robot", None])
def test_unreachable_target_never_gives_nan(panda, limits):
    """The Panda at q ≈ 0 (stretched up) asked for a point 3 m away: every step is finite.
    With the robot's limits the speed limits hold; without them the speed is bounded by the
    stack's damping, ``‖v‖ ≤ ‖b_position‖ / (1e-4 σ_max(J)) + ‖b_posture‖``."""
    q = np.full(7, 1e-6)
    ee = PositionTask(panda, target=[3.0, 0.0, 0.5], gain=10.0)
    posture = PostureTask(panda, q)
    ik = qc.IK(panda, [ee, posture], dt=DT, limits=limits)
    for _ in range(300):
        v, sol = ik.step(q)
        assert np.all(np.isfinite(v))
        if limits is None:
            s0 = np.linalg.norm(panda.jacobian(q), 2)
            bound = np.linalg.norm(ee.task.b) / (qc.kinematics.DEFAULT_IK_DAMPING * s0)
            assert np.linalg.norm(v) <= bound + np.linalg.norm(posture.task.b)
        else:
            assert np.all(np.abs(v) <= panda.velocity_limit + 1e-9)
        q = panda.integrate(q, v, DT)
    assert np.all(np.isfinite(q))
    if limits is not None:
        assert panda.position(q)[0] > 0.5  # it moved toward the target


def test_thesis_tasks_take_nv_sized_gradients_and_forms(solo):
    pot = qc.PotentialTask(solo, lambda q: np.ones(solo.nv))
    assert pot.update(solo.neutral()).shape == (18, 18)
    bad = qc.PotentialTask(solo, lambda q: np.ones(solo.nq))
    with pytest.raises(ValueError, match="must return 18 values"):
        bad.update(solo.neutral())
    form = qc.OneFormTask(solo, lambda q: np.eye(solo.nv)[:2])
    assert form.task.shape == (2, 18)
    with pytest.raises(ValueError, match="form must have 18 columns"):
        qc.OneFormTask(solo, np.ones((1, 19)))


@pytest.mark.parametrize("integrator", ["euler", "rk4"])
def test_simulate_a_floating_base(solo, integrator):
    foot = solo.with_frame("FR_FOOT")
    q0 = solo.reference_configuration("standing")
    start = foot.position(q0)
    path = qc.paths.HorizontalCircle(start, radius=0.02, period=1.0)
    levels = [PositionTask(foot), PostureTask(foot, q0)]
    traj = qc.simulate(foot, levels, path, q0, 0.2, DT, integrator=integrator, start="q0")
    assert traj.q.shape == (21, 19) and traj.qdot.shape == (21, 18)
    np.testing.assert_allclose(np.linalg.norm(traj.q[:, 3:7], axis=1), 1.0, atol=1e-12)
    assert traj.max_error < 5e-3


# ---------------------------------------------------------------------------------------
# the built-in tasks' public error / Jacobian: finite differences, and J v = −K e
# ---------------------------------------------------------------------------------------

FRAMES = {"panda": "panda_hand_tcp", "solo12": "FR_FOOT", "talos": "gripper_left_base_link"}


@pytest.mark.parametrize("name", sorted(FRAMES))
def test_builtin_jacobians_match_finite_differences(name):
    robot = qc.robots.load(name).with_frame(FRAMES[name])
    q = robot.random_configuration(11)
    q_ref = robot.random_configuration(12)
    tasks = [
        PositionTask(robot, target=robot.position(q_ref)),
        PositionBand(robot, lower=-1.0, upper=1.0),
        PostureTask(robot, q_ref),
        Height(robot, FRAMES[name], z=0.1),
    ]
    for task in tasks:
        J = task.compute_jacobian(q)
        assert J.shape == (task.task.shape[0], robot.nv)
        fd = _fd_jacobian(robot, task.compute_error, q)
        np.testing.assert_allclose(J, fd, atol=2e-6, err_msg=task.name)


def test_builtin_tasks_are_minus_k_e(panda):
    target = panda.position(PANDA_Q) + [0.1, 0.0, -0.1]
    pos = PositionTask(panda, target=target, gain=7.0)
    eq = pos.update(PANDA_Q)
    np.testing.assert_allclose(eq.b, -7.0 * pos.compute_error(PANDA_Q), atol=1e-14)
    np.testing.assert_allclose(eq.A, pos.compute_jacobian(PANDA_Q), atol=1e-15)
    band = PositionBand(panda, lower=[-np.inf, -np.inf, 0.3], gain=5.0)
    ineq = band.update(PANDA_Q)
    np.testing.assert_allclose(ineq.lower[2], 5.0 * (0.3 - band.compute_error(PANDA_Q)[2]))
    # a path target: the error at time t
    circle = qc.paths.HorizontalCircle(target, radius=0.05, period=2.0)
    pos.set_target(circle)
    np.testing.assert_allclose(
        pos.compute_error(PANDA_Q, t=0.5), panda.position(PANDA_Q) - circle.position(0.5)
    )
