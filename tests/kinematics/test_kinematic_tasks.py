"""Tests of the kinematic tasks (:mod:`qpcoord.kinematics.tasks`): the numbers each task puts
into its Equality / Inequality on the joint velocity, and their input checks."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc
from qpcoord.kinematics.tasks import LIMIT_BAND


@pytest.fixture
def planar() -> qc.Robot:
    return qc.robots.load("planar_3r")


@pytest.fixture
def panda() -> qc.Robot:
    return qc.robots.load("panda")


#: A Panda configuration inside its limits (rad).
PANDA_Q = np.array([0.1, -0.4, 0.2, -2.0, 0.1, 1.6, 0.5])


# ---------------------------------------------------------------------------------------
# PositionTask
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("gain", [0.0, 1.0, 10.0, 37.5])
def test_position_task_fixed_target(panda, gain):
    target = np.array([0.4, -0.2, 0.5])
    task = qc.PositionTask(panda, target=target, gain=gain)
    eq = task.update(PANDA_Q, t=0.7, dt=0.01)
    assert eq is task.task and isinstance(eq, qc.Equality)
    np.testing.assert_allclose(eq.A, panda.jacobian(PANDA_Q), rtol=0, atol=1e-15)
    np.testing.assert_allclose(eq.b, gain * (target - panda.position(PANDA_Q)), atol=1e-14)


def test_position_task_follows_a_path(planar):
    circle = qc.paths.Circle()
    task = qc.PositionTask(planar, target=circle, gain=5.0)
    q = np.array([0.2, 0.9, -0.4])
    t = 0.3
    task.update(q, t=t)
    expected = circle.velocity(t) + 5.0 * (circle.position(t) - planar.position(q))
    np.testing.assert_allclose(task.task.b, expected, atol=1e-14)
    np.testing.assert_allclose(task.task.A, planar.jacobian(q), atol=1e-15)


def test_position_task_uses_the_run_reference_when_it_has_no_target(planar):
    circle = qc.paths.Circle(radius=0.3)
    task = qc.PositionTask(planar, gain=2.0)
    q = np.array([0.0, 0.5, 1.0])
    task.update(q, t=1.1, reference=circle)
    expected = circle.velocity(1.1) + 2.0 * (circle.position(1.1) - planar.position(q))
    np.testing.assert_allclose(task.task.b, expected, atol=1e-14)


def test_position_task_own_target_wins_over_the_reference(planar):
    task = qc.PositionTask(planar, target=[1.0, 1.0], gain=1.0)
    q = np.array([0.0, 0.5, 1.0])
    task.update(q, reference=qc.paths.Circle())
    np.testing.assert_allclose(task.task.b, np.array([1.0, 1.0]) - planar.position(q))


def test_position_task_set_target_replaces_the_target(planar):
    task = qc.PositionTask(planar, target=[1.0, 1.0], gain=3.0)
    q = np.array([0.4, 0.5, 0.6])
    task.set_target([2.0, -0.5])
    task.update(q)
    np.testing.assert_allclose(task.task.b, 3.0 * (np.array([2.0, -0.5]) - planar.position(q)))


def test_position_task_weight_and_name(planar):
    task = qc.PositionTask(planar, target=[1.0, 1.0], weight=[2.0, 3.0], name="hand")
    assert task.name == "hand"
    np.testing.assert_array_equal(task.task.weight, [2.0, 3.0])


@pytest.mark.parametrize(
    "reference",
    [[5.0], 5.0, [1.0, 2.0, 3.0], qc.paths.LissajousSphere()],
    ids=["one-element", "scalar", "3-d", "3-d-path"],
)
def test_position_task_reference_of_the_wrong_dimension(planar, reference):
    task = qc.PositionTask(planar, gain=1.0)
    with pytest.raises(ValueError, match="(?i)(reference|target).*2"):
        task.update([0.1, 0.2, 0.3], reference=reference)


def test_one_form_task_callable_changing_shape_is_rejected(planar):
    task = qc.OneFormTask(planar, lambda q: np.ones((1, 3)) if q[0] == 0 else np.ones((2, 3)))
    with pytest.raises(ValueError, match="changes A's shape"):
        task.update([0.5, 0.0, 0.0])


def test_position_task_without_target_or_reference(planar):
    task = qc.PositionTask(planar)
    with pytest.raises(ValueError, match="no target"):
        task.update([0.0, 0.5, 1.0])


@pytest.mark.parametrize(
    "target",
    [[1.0, 2.0, 3.0], [1.0], [[1.0, 2.0], [3.0, 4.0]], [np.nan, 1.0], [1.0, np.inf]],
    ids=["3-d", "1-d", "matrix", "nan", "inf"],
)
def test_position_task_bad_target(planar, target):
    with pytest.raises(ValueError, match="target must be 2 finite coordinates"):
        qc.PositionTask(planar, target=target)


def test_position_task_path_of_the_wrong_dimension(planar, panda):
    with pytest.raises(ValueError, match="target path is 3-D"):
        qc.PositionTask(planar, target=qc.paths.LissajousSphere())
    with pytest.raises(ValueError, match="target path is 2-D"):
        qc.PositionTask(panda, target=qc.paths.Circle())


@pytest.mark.parametrize("gain", [-1.0, np.nan, np.inf, "10", True, None])
def test_bad_gain(planar, gain):
    with pytest.raises(ValueError, match="gain must be"):
        qc.PositionTask(planar, target=[1.0, 1.0], gain=gain)
    with pytest.raises(ValueError, match="gain must be"):
        qc.PostureTask(planar, [0.0, 0.0, 0.0], gain=gain)


# ---------------------------------------------------------------------------------------
# PostureTask, PotentialTask, OneFormTask
# ---------------------------------------------------------------------------------------


def test_posture_task(panda):
    q_ref = np.zeros(7)
    task = qc.PostureTask(panda, q_ref, gain=2.5)
    task.update(PANDA_Q)
    np.testing.assert_array_equal(task.task.A, np.eye(7))
    np.testing.assert_allclose(task.task.b, 2.5 * (q_ref - PANDA_Q), atol=1e-15)


def test_posture_task_copies_its_reference(planar):
    q_ref = np.array([0.1, 0.2, 0.3])
    task = qc.PostureTask(planar, q_ref)
    q_ref[:] = 5.0
    task.update(np.zeros(3))
    np.testing.assert_allclose(task.task.b, [0.1, 0.2, 0.3])


@pytest.mark.parametrize("q_ref", [[0.0, 0.0], [0.0, np.nan, 0.0]], ids=["short", "nan"])
def test_posture_task_bad_reference(planar, q_ref):
    with pytest.raises(ValueError, match="q_ref"):
        qc.PostureTask(planar, q_ref)


def test_potential_task_descends_the_gradient(planar):
    centre = np.array([0.5, -0.2, 1.0])

    def gradient(q):
        return 2.0 * (q - centre)  # p(q) = ‖q − centre‖²

    task = qc.PotentialTask(planar, gradient, gain=0.5)
    q = np.array([1.0, 1.0, 1.0])
    task.update(q)
    np.testing.assert_array_equal(task.task.A, np.eye(3))
    np.testing.assert_allclose(task.task.b, -0.5 * 2.0 * (q - centre))


def test_potential_task_accepts_an_object_with_a_gradient_method(planar):
    class Potential:
        def gradient(self, q):
            return np.sin(q)

    task = qc.PotentialTask(planar, Potential(), gain=3.0)
    q = np.array([0.3, -0.7, 1.2])
    task.update(q)
    np.testing.assert_allclose(task.task.b, -3.0 * np.sin(q))


@pytest.mark.parametrize(
    "gradient",
    [lambda q: np.zeros(2), lambda q: np.zeros((3, 3)), lambda q: 1.0],
    ids=["short", "matrix", "scalar"],
)
def test_potential_task_gradient_of_the_wrong_shape(planar, gradient):
    task = qc.PotentialTask(planar, gradient)
    with pytest.raises(ValueError, match="gradient\\(q\\) must return 3 values"):
        task.update([0.0, 0.0, 0.0])


def test_potential_task_needs_a_callable(planar):
    with pytest.raises(ValueError, match="gradient must be callable"):
        qc.PotentialTask(planar, np.zeros(3))


def test_potential_task_non_finite_gradient(planar):
    task = qc.PotentialTask(planar, lambda q: np.array([0.0, np.nan, 0.0]))
    with pytest.raises(ValueError, match="non-finite"):
        task.update([0.0, 0.0, 0.0])


def test_one_form_task_constant_forms(planar):
    form = np.array([[1.0, 0.0, 1.0], [0.0, 2.0, -1.0]])
    task = qc.OneFormTask(planar, form, rate=[0.5, -0.25])
    task.update([0.3, 0.2, 0.1])
    np.testing.assert_array_equal(task.task.A, form)
    np.testing.assert_array_equal(task.task.b, [0.5, -0.25])
    np.testing.assert_array_equal(task.rate, [0.5, -0.25])


def test_one_form_task_single_row_and_default_rate(planar):
    task = qc.OneFormTask(planar, [1.0, -1.0, 0.0])
    assert task.task.shape == (1, 3)
    np.testing.assert_array_equal(task.task.b, [0.0])


def test_one_form_task_callable_form_is_refreshed(planar):
    def form(q):
        return np.array([[np.cos(q[0]), np.sin(q[1]), q[2]]])

    task = qc.OneFormTask(planar, form)
    np.testing.assert_allclose(task.task.A, form(np.zeros(3)))
    q = np.array([0.4, -1.0, 2.0])
    task.update(q)
    np.testing.assert_allclose(task.task.A, form(q))


@pytest.mark.parametrize(
    "form",
    [np.ones((2, 4)), np.ones(2), np.ones((2, 3, 1)), lambda q: np.ones((1, 2))],
    ids=["4-columns", "2-vector", "3-d", "callable-2-columns"],
)
def test_one_form_task_wrong_number_of_columns(planar, form):
    with pytest.raises(ValueError, match="form must have 3 columns"):
        qc.OneFormTask(planar, form)


# ---------------------------------------------------------------------------------------
# limits
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("gain", [0.25, 1.0])
@pytest.mark.parametrize("dt", [0.001, 0.05])
def test_joint_limits_box(panda, gain, dt):
    limits = qc.JointLimits(panda, gain=gain)
    lo, hi = limits.box(PANDA_Q, dt)
    # a step may cover max(K D, D - (1 - K) b) of a distance D, band b = LIMIT_BAND v_max dt;
    # the same differences, products and quotient in another order: each side is within a
    # few roundings of the exact value (D - (1 - K) b > D/2 here: no cancellation), so the
    # two agree to 8 eps relative
    band = LIMIT_BAND * panda.velocity_limit * dt

    def step(D):
        return np.maximum(gain * D, D - (1 - gain) * band)

    rel = 8 * np.finfo(float).eps
    np.testing.assert_allclose(lo, -step(PANDA_Q - panda.lower) / dt, rtol=rel)
    np.testing.assert_allclose(hi, step(panda.upper - PANDA_Q) / dt, rtol=rel)
    assert np.all(lo < 0) and np.all(hi > 0)
    ineq = limits.update(PANDA_Q, dt=dt)
    assert isinstance(ineq, qc.Inequality) and ineq is limits.task
    np.testing.assert_array_equal(ineq.C, np.eye(7))
    np.testing.assert_array_equal(ineq.lower, lo)
    np.testing.assert_array_equal(ineq.upper, hi)


def test_joint_limits_band(panda):
    # a full step toward the limit leaves (1 - K) min(D, b): from beyond the band the joint
    # stops (1 - K) b short of its limit (the one-step box K = 1: on it), within the band
    # it covers the fraction K
    dt, K = 0.01, 0.5
    b = LIMIT_BAND * panda.velocity_limit[0] * dt  # 4.35e-3 rad
    for D, left in [(0.3, (1 - K) * b), (2 * b, (1 - K) * b), (b, (1 - K) * b), (b / 3, b / 6)]:
        q = PANDA_Q.copy()
        q[0] = panda.upper[0] - D
        _, hi = qc.JointLimits(panda, gain=K).box(q, dt)
        # D - dt hi: the rounding of a difference of numbers of size D (~1e-16 rad)
        assert panda.upper[0] - (q[0] + dt * hi[0]) == pytest.approx(left, abs=1e-15)
        _, hi = qc.JointLimits(panda, gain=1.0).box(q, dt)
        assert panda.upper[0] - (q[0] + dt * hi[0]) == pytest.approx(0.0, abs=1e-15)


def test_joint_limits_custom_limits(planar):
    limits = qc.JointLimits(planar, gain=1.0, lower=[-1.0, -2.0, -3.0], upper=2.0)
    lo, hi = limits.box(np.zeros(3), 0.5)
    np.testing.assert_allclose(lo, [-2.0, -4.0, -6.0])
    np.testing.assert_allclose(hi, [4.0, 4.0, 4.0])


def test_joint_limits_euler_step_lands_at_most_on_the_limit(panda):
    dt = 0.02
    q = panda.upper - 0.01
    _, hi = qc.JointLimits(panda, gain=1.0).box(q, dt)
    np.testing.assert_allclose(q + dt * hi, panda.upper, rtol=0, atol=1e-12)


def test_joint_limits_outside_a_limit_pushes_back(planar):
    limits = qc.JointLimits(planar, gain=1.0, lower=-1.0, upper=1.0)
    q = np.array([1.5, -1.2, 0.0])  # above, below, inside
    lo, hi = limits.box(q, 0.1)
    assert np.all(lo <= hi)
    assert hi[0] < 0, "above the upper limit the joint must move down"
    assert lo[1] > 0, "below the lower limit the joint must move up"
    assert lo[2] < 0 < hi[2]
    np.testing.assert_allclose([lo[0], hi[0]], [-25.0, -5.0])
    np.testing.assert_allclose([lo[1], hi[1]], [2.0, 22.0])


@pytest.mark.parametrize("gain", [0.0, 1.5, -0.5, np.nan, True])
def test_joint_limits_gain_outside_zero_one(planar, gain):
    with pytest.raises(ValueError, match="gain must be"):
        qc.JointLimits(planar, gain=gain)


@pytest.mark.parametrize("band", [-0.1, np.nan, True, "wide"])
def test_joint_limits_bad_band(planar, band):
    with pytest.raises(ValueError, match="band must be"):
        qc.JointLimits(planar, band=band)


def test_joint_limits_band_ends(panda):
    # band 0: the one-step box at any gain; band inf: the damper K D at every distance
    dt, D = 0.01, 0.3
    q = PANDA_Q.copy()
    q[0] = panda.upper[0] - D
    _, hi = qc.JointLimits(panda, gain=0.5, band=0.0).box(q, dt)
    assert hi[0] == pytest.approx(D / dt, rel=1e-15)
    _, hi = qc.JointLimits(panda, gain=0.5, band=np.inf).box(q, dt)
    assert hi[0] == pytest.approx(0.5 * D / dt, rel=1e-15)


def test_joint_limits_lower_above_upper(planar):
    with pytest.raises(ValueError, match="lower > upper"):
        qc.JointLimits(planar, lower=[0.0, 0.0, 2.0], upper=1.0)


def test_joint_limits_assigned_keep_the_limited_joints(planar):
    # the limited joints (a native step's index of them) are fixed at construction: a finite
    # limit assigned on a joint built without one is refused, not silently unused
    limits = qc.JointLimits(planar, lower=[-1.0, -np.inf, -np.inf], upper=[1.0, np.inf, np.inf])
    limits.upper = [0.5, np.inf, np.inf]
    limits.lower = -np.inf  # a limit removed: its side of the box is free
    lo, hi = limits.box(np.zeros(3), 0.1)
    assert lo[0] == -np.inf and hi[0] == pytest.approx(limits.gain * 0.5 / 0.1)
    with pytest.raises(ValueError, match=r"JointLimits: upper is finite at q index \[1\]"):
        limits.upper = [0.5, 2.0, np.inf]
    np.testing.assert_array_equal(limits.upper, [0.5, np.inf, np.inf])


def test_joint_limits_of_an_unlimited_robot_are_infinite(planar):
    lo, hi = qc.JointLimits(planar).box(np.zeros(3), 0.01)
    assert np.all(lo == -np.inf) and np.all(hi == np.inf)


def test_velocity_limits_default_to_the_robot(panda):
    limits = qc.VelocityLimits(panda)
    lo, hi = limits.box(PANDA_Q, 0.01)
    np.testing.assert_array_equal(hi, panda.velocity_limit)
    np.testing.assert_array_equal(lo, -panda.velocity_limit)
    limits.update(PANDA_Q, dt=0.01)
    np.testing.assert_array_equal(limits.task.upper, panda.velocity_limit)


def test_velocity_limits_scalar_and_vector(planar):
    lo, hi = qc.VelocityLimits(planar, 0.5).box(np.zeros(3), 0.01)
    np.testing.assert_array_equal(hi, [0.5, 0.5, 0.5])
    np.testing.assert_array_equal(lo, [-0.5, -0.5, -0.5])
    lo, hi = qc.VelocityLimits(planar, [1.0, 2.0, 3.0]).box(np.zeros(3), 0.01)
    np.testing.assert_array_equal(hi, [1.0, 2.0, 3.0])


@pytest.mark.parametrize("limit", [0.0, -1.0, [1.0, 0.0, 1.0], [1.0, 1.0], np.nan])
def test_velocity_limits_bad_limit(planar, limit):
    with pytest.raises(ValueError, match="limit"):
        qc.VelocityLimits(planar, limit)


# ---------------------------------------------------------------------------------------
# PositionBand
# ---------------------------------------------------------------------------------------


def test_position_band_rows(panda):
    band = qc.PositionBand(panda, lower=[-np.inf, -0.1, 0.3], upper=[0.5, np.inf, np.inf], gain=4.0)
    task = band.update(PANDA_Q)
    y, J = panda.position(PANDA_Q), panda.jacobian(PANDA_Q)
    np.testing.assert_array_equal(task.C, J)
    np.testing.assert_allclose(task.lower, [-np.inf, 4.0 * (-0.1 - y[1]), 4.0 * (0.3 - y[2])])
    np.testing.assert_allclose(task.upper, [4.0 * (0.5 - y[0]), np.inf, np.inf])
    version = task.matrix_version
    band.update(PANDA_Q + 0.1)
    assert task.matrix_version > version  # C changed: a persistent workspace sees it


@pytest.mark.parametrize(
    ("lower", "upper", "message"),
    [
        ([0.0, 0.0], 1.0, "lower must have 3"),
        (0.0, [np.nan, 1.0, 1.0], "upper must have 3"),
        ([0.0, 2.0, 0.0], 1.0, r"lower > upper on row\(s\) \[1\]"),
    ],
)
def test_position_band_bad_faces(panda, lower, upper, message):
    with pytest.raises(ValueError, match=message):
        qc.PositionBand(panda, lower=lower, upper=upper)


def test_position_band_in_a_three_level_panda_stack(panda):
    """Three levels on the Panda: z ≥ floor (priority 0), a target 5 cm below the floor
    (priority 1), posture (priority 2). The end effector reaches the target's x and y and
    stops on the floor."""
    q = PANDA_Q.copy()
    y0 = panda.position(q)
    floor = y0[2] - 0.05
    target = y0 + [0.05, 0.05, -0.10]  # 5 cm below the floor
    band = qc.PositionBand(panda, lower=[-np.inf, -np.inf, floor], gain=50.0)
    ee = qc.PositionTask(panda, target=target, gain=20.0)
    ik = qc.IK(panda, [band, ee, qc.PostureTask(panda, q, gain=1.0)], dt=1e-3)
    for _ in range(1500):
        qdot, sol = ik.step(q)
        q = q + 1e-3 * qdot
    y = panda.position(q)
    assert y[2] >= floor - 1e-4  # the band (priority 0) holds
    np.testing.assert_allclose(y[:2], target[:2], atol=1e-4)  # x, y reached
    assert abs(y[2] - floor) < 1e-3  # z stops on the floor, as close as it can


# ---------------------------------------------------------------------------------------
# update() input checks, for every kind of task
# ---------------------------------------------------------------------------------------

TASK_FACTORIES = {
    "position": lambda r: qc.PositionTask(r, target=[1.0, 1.0]),
    "posture": lambda r: qc.PostureTask(r, [0.0, 0.0, 0.0]),
    "potential": lambda r: qc.PotentialTask(r, lambda q: q),
    "one-form": lambda r: qc.OneFormTask(r, [1.0, 0.0, 1.0]),
    "joint-limits": lambda r: qc.JointLimits(r, lower=-1.0, upper=1.0),
    "velocity-limits": lambda r: qc.VelocityLimits(r, 1.0),
    "position-band": lambda r: qc.PositionBand(r, lower=[0.0, -np.inf], upper=2.0),
}


@pytest.mark.parametrize("kind", list(TASK_FACTORIES))
@pytest.mark.parametrize(
    ("q", "message"),
    [
        ([0.0, 0.0], "must have 3 entries"),
        ([0.0, 0.0, 0.0, 0.0], "must have 3 entries"),
        ([0.0, np.nan, 0.0], r"q\[1\] is .*must be finite"),
        ([np.inf, 0.0, 0.0], r"q\[0\] is .*must be finite"),
    ],
    ids=["short", "long", "nan", "inf"],
)
def test_update_rejects_bad_configurations(planar, kind, q, message):
    task = TASK_FACTORIES[kind](planar)
    with pytest.raises(ValueError, match=message):
        task.update(q)


@pytest.mark.parametrize("kind", list(TASK_FACTORIES))
@pytest.mark.parametrize("dt", [0.0, -0.01, np.nan, np.inf, "0.01", True])
def test_update_rejects_bad_dt(planar, kind, dt):
    task = TASK_FACTORIES[kind](planar)
    with pytest.raises(ValueError, match="dt must be"):
        task.update([0.1, 0.2, 0.3], dt=dt)


@pytest.mark.parametrize("kind", list(TASK_FACTORIES))
def test_update_returns_the_task_it_owns(planar, kind):
    task = TASK_FACTORIES[kind](planar)
    assert task.update([0.1, 0.2, 0.3], t=0.0, dt=0.01) is task.task
    assert task.task.shape[1] == 3
