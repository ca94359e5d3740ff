"""Tests of the differential IK layer (:mod:`qpcoord.kinematics.ik`): closed forms of the
pseudo-inverse
and of the two-level null-space scheme, limits, singularities, a closed loop and errors."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc

#: A Panda configuration inside its limits, away from singularities (rad).
PANDA_Q = np.array([0.1, -0.4, 0.2, -2.0, 0.1, 1.6, 0.5])
#: A 3R configuration away from singularities (absolute angles, rad).
PLANAR_Q = np.array([0.1, 0.6, 1.2])
#: Target displacements from the start position (m).
PANDA_OFFSET = np.array([0.3, -0.2, 0.25])
PLANAR_OFFSET = np.array([0.2, -0.3])

EXACT_METHODS = ["hierarchical", "nullspace"]


@pytest.fixture(scope="module")
def panda() -> qc.Robot:
    return qc.robots.load("panda")


@pytest.fixture(scope="module")
def planar() -> qc.Robot:
    return qc.robots.load("planar_3r")


@pytest.fixture(params=["panda", "planar_3r"])
def arm_case(request, panda, planar):
    """``(robot, q, target)`` for a well-conditioned start."""
    if request.param == "panda":
        return panda, PANDA_Q.copy(), panda.position(PANDA_Q) + PANDA_OFFSET
    return planar, PLANAR_Q.copy(), planar.position(PLANAR_Q) + PLANAR_OFFSET


def two_level_nullspace_solution(J, b1, A2, b2) -> np.ndarray:
    """Classical strict two-level solution ``x = J⁺b₁ + (A₂N)⁺(b₂ − A₂J⁺b₁)``, ``N = I − J⁺J``."""
    J_pinv = np.linalg.pinv(J)
    x1 = J_pinv @ b1
    N = np.eye(J.shape[1]) - J_pinv @ J
    return x1 + np.linalg.pinv(A2 @ N) @ (b2 - A2 @ x1)


# ---------------------------------------------------------------------------------------
# (a) one equality level: the Moore–Penrose solution (Thm 3.2)
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("gain", [1.0, 10.0])
def test_single_position_level_is_the_pseudo_inverse_solution(arm_case, solver, gain):
    robot, q, target = arm_case
    J = robot.jacobian(q)
    assert np.linalg.cond(J) < 1e3  # a regular configuration: no damping acts
    task = qc.PositionTask(robot, target=target, gain=gain)
    qdot, sol = qc.IK(robot, [task], dt=0.01, limits=None, solver=solver).step(q)
    expected = np.linalg.pinv(J) @ (gain * (target - robot.position(q)))
    np.testing.assert_allclose(qdot, expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(J @ qdot, gain * (target - robot.position(q)), atol=1e-9)
    assert sol.info["level_ranks"][0] == robot.m


def test_nullspace_method_gives_the_pseudo_inverse_solution(arm_case):
    robot, q, target = arm_case
    task = qc.PositionTask(robot, target=target, gain=3.0)
    qdot, sol = qc.IK(robot, [task], dt=0.01, limits=None, method="nullspace").step(q)
    expected = np.linalg.pinv(robot.jacobian(q)) @ (3.0 * (target - robot.position(q)))
    np.testing.assert_allclose(qdot, expected, rtol=0, atol=1e-9)
    assert sol.method == "nullspace"


# ---------------------------------------------------------------------------------------
# (b) strict priority: position above posture
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", EXACT_METHODS)
def test_position_above_posture_is_the_two_level_nullspace_solution(arm_case, solver, method):
    robot, q, target = arm_case
    position = qc.PositionTask(robot, target=target, gain=10.0)
    q_ref = q + np.linspace(-0.5, 0.5, robot.nq)
    posture = qc.PostureTask(robot, q_ref, gain=2.0)
    ik = qc.IK(robot, [position, posture], dt=0.01, limits=None, solver=solver, method=method)
    qdot, sol = ik.step(q)

    J, b1 = robot.jacobian(q), 10.0 * (target - robot.position(q))
    b2 = 2.0 * (q_ref - q)
    # the top level is met exactly ...
    np.testing.assert_allclose(J @ qdot, b1, rtol=0, atol=1e-9)
    # ... and the posture only inside its null space
    expected = two_level_nullspace_solution(J, b1, np.eye(robot.nq), b2)
    np.testing.assert_allclose(qdot, expected, rtol=0, atol=1e-8)
    assert np.linalg.norm(qdot - b2) > 1e-3, "the posture alone would have been met"
    np.testing.assert_allclose(sol.level_residuals[0], 0.0, atol=1e-9)


def test_weighted_method_is_close_to_but_not_strict(panda):
    """Sanity of the comparison below: with weights the top level is only approximate."""
    target = panda.position(PANDA_Q) + PANDA_OFFSET
    position = qc.PositionTask(panda, target=target, gain=10.0)
    posture = qc.PostureTask(panda, np.zeros(7), gain=5.0)
    qdot, _ = qc.IK(panda, [position, posture], dt=0.01, limits=None, method="weighted").step(
        PANDA_Q
    )
    residual = np.linalg.norm(position.task.A @ qdot - position.task.b)
    assert 1e-9 < residual < 1e-1


# ---------------------------------------------------------------------------------------
# (c) velocity limits that bind
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("limit", [0.5, 1.0, 1.5])
def test_velocity_limits_hold_and_priority_beats_weighting(panda, solver, limit):
    target = panda.position(PANDA_Q) + PANDA_OFFSET
    residuals = {}
    for method in ("hierarchical", "weighted"):
        position = qc.PositionTask(panda, target=target, gain=2.0)
        posture = qc.PostureTask(panda, np.zeros(7), gain=5.0)
        ik = qc.IK(
            panda,
            [position, posture],
            dt=0.01,
            limits=[qc.VelocityLimits(panda, limit)],
            solver=solver,
            method=method,
        )
        qdot, _ = ik.step(PANDA_Q)
        assert np.all(np.abs(qdot) <= limit * (1 + 1e-9)), (method, qdot)
        residuals[method] = np.linalg.norm(position.task.A @ qdot - position.task.b)
        if method == "hierarchical":  # the limit binds
            assert np.sum(np.abs(qdot) >= limit * (1 - 1e-9)) >= 1, qdot
    assert residuals["hierarchical"] <= residuals["weighted"] + 1e-9
    if limit >= 1.5:  # the position task is still feasible within the box
        assert residuals["hierarchical"] <= 1e-9
        assert residuals["weighted"] > residuals["hierarchical"] + 1e-6


def test_default_limits_use_the_robot_speed_limits(panda):
    """limits="robot" (default) applies the Panda's own joint speed limits."""
    far = panda.position(PANDA_Q) + np.array([1.0, -1.0, 1.0])
    qdot, _ = qc.IK(panda, [qc.PositionTask(panda, target=far, gain=50.0)], dt=0.01).step(PANDA_Q)
    assert np.all(np.abs(qdot) <= panda.velocity_limit * (1 + 1e-9))
    assert np.any(np.abs(qdot) >= panda.velocity_limit * (1 - 1e-9))


# ---------------------------------------------------------------------------------------
# (d) joint limits over an Euler loop
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("gain", [0.5, 1.0])
def test_joint_limits_are_never_crossed_by_euler_steps(panda, solver, gain):
    dt = 0.05
    q = PANDA_Q.copy()
    q[[1, 3, 5]] = panda.upper[[1, 3, 5]] - 0.05  # near three upper limits
    q_ref = panda.upper + 0.5  # beyond every upper limit
    posture = qc.PostureTask(panda, q_ref, gain=2.0)
    ik = qc.IK(
        panda,
        [posture],
        dt=dt,
        limits=[qc.JointLimits(panda, gain=gain), qc.VelocityLimits(panda)],
        solver=solver,
    )
    for _ in range(50):
        qdot, _ = ik.step(q)
        q = q + dt * qdot
        assert np.all(q <= panda.upper + 1e-9), q - panda.upper
        assert np.all(q >= panda.lower - 1e-9)
    # the limits bind: the joints end up at them, not short of them
    np.testing.assert_allclose(q, panda.upper, rtol=0, atol=1e-3)


def test_joint_limits_hold_against_a_position_task(planar, solver):
    dt = 0.02
    lower, upper = np.array([-0.2, 0.1, 0.4]), np.array([0.3, 0.8, 1.5])
    q = np.array([0.0, 0.5, 1.0])
    far = np.array([-2.0, 2.2])  # needs angles beyond the limits
    ik = qc.IK(
        planar,
        [qc.PositionTask(planar, target=far, gain=5.0)],
        dt=dt,
        limits=[qc.JointLimits(planar, lower=lower, upper=upper)],
        solver=solver,
    )
    touched = np.zeros(3, dtype=bool)
    for _ in range(50):
        q = q + dt * ik.step(q)[0]
        assert np.all(q <= upper + 1e-9) and np.all(q >= lower - 1e-9), q
        touched |= (q >= upper - 1e-6) | (q <= lower + 1e-6)
    assert touched.any()


@pytest.mark.parametrize(
    "side",
    ["below-lower", "above-upper"],
)
def test_outside_a_joint_limit_the_speed_limit_still_holds(panda, side):
    q = PANDA_Q.copy()
    q[3] = panda.lower[3] - 0.5 if side == "below-lower" else panda.upper[3] + 0.5
    ik = qc.IK(panda, [qc.PostureTask(panda, q)], dt=0.01)  # robot limits: joint + speed
    qdot, _ = ik.step(q)
    assert np.all(np.abs(qdot) <= panda.velocity_limit * (1 + 1e-9)), qdot
    # and the joint moves back towards its range at full speed
    direction = 1.0 if side == "below-lower" else -1.0
    assert qdot[3] * direction == pytest.approx(panda.velocity_limit[3], rel=1e-9)


# ---------------------------------------------------------------------------------------
# (e) singular configurations
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "target",
    [[3.5, 0.0], [-3.5, 0.0], [3.0, 0.5], [3.5, 0.5], [2.0, 0.0]],
    ids=["beyond-x", "behind-x", "along-y", "x-and-y", "inside-x"],
)
def test_stretched_planar_arm_reports_rank_loss(planar, solver, target):
    q = np.zeros(3)
    task = qc.PositionTask(planar, target=target, gain=10.0)
    qdot, sol = qc.IK(planar, [task], dt=0.01, limits=None, solver=solver).step(q)
    assert np.all(np.isfinite(qdot))
    assert np.linalg.norm(qdot) < 1e6
    assert sol.info["level_ranks"][0] < 2
    # the y row (1, 1, 1) is the only direction left: it is met exactly (minimum norm)
    b_y = 10.0 * target[1]
    np.testing.assert_allclose(qdot, np.full(3, b_y / 3.0), rtol=0, atol=1e-9)


@pytest.mark.parametrize("offset", [1e-5, 1e-7, 1e-9])
def test_near_singular_planar_arm_speed_is_bounded_by_damping(planar, solver, offset):
    q = np.array([offset, 0.0, -offset])
    task = qc.PositionTask(planar, target=[3.5, 0.0], gain=10.0)
    qdot, sol = qc.IK(planar, [task], dt=0.01, limits=None, solver=solver).step(q)
    assert np.all(np.isfinite(qdot))
    # damping 1e-4 · s₀ (s₀ = √3): ‖q̇‖ ≤ ‖b‖ / (1e-4 √3) ≈ 2.9e4
    bound = np.linalg.norm(task.task.b) / (1e-4 * np.sqrt(3.0))
    assert np.linalg.norm(qdot) <= bound * (1 + 1e-6)
    assert np.linalg.norm(qdot) < 1e6


# ---------------------------------------------------------------------------------------
# (f) closed loop
# ---------------------------------------------------------------------------------------


def test_closed_loop_on_the_panda_converges(panda, solver):
    dt = 0.05
    q = PANDA_Q.copy()
    target = panda.position(q) + np.array([0.1, -0.05, 0.08])
    ik = qc.IK(
        panda,
        [qc.PositionTask(panda, target=target, gain=10.0), qc.PostureTask(panda, PANDA_Q)],
        dt=dt,
        solver=solver,
    )
    errors = [np.linalg.norm(target - panda.position(q))]
    for _ in range(10):
        q = q + dt * ik.velocity(q)
        errors.append(np.linalg.norm(target - panda.position(q)))
        assert np.all(q <= panda.upper + 1e-9) and np.all(q >= panda.lower - 1e-9)
    assert all(b < a for a, b in zip(errors, errors[1:], strict=False)), errors
    assert errors[-1] < errors[0] / 2
    assert errors[-1] < 1e-2


def test_simulate_tracks_the_circle_with_a_position_task(planar):
    trajectory = qc.simulate(
        planar,
        [qc.PositionTask(planar, gain=20.0)],
        qc.paths.Circle(),
        q0=[0.0, np.pi / 3, -np.pi / 3],
        duration=1.0,
        dt=0.01,
    )
    assert trajectory.q.shape == (101, 3)
    assert trajectory.max_error < 1e-5
    np.testing.assert_allclose(trajectory.y[0], [2.0, 0.0], atol=1e-9)


# ---------------------------------------------------------------------------------------
# convenience entry points
# ---------------------------------------------------------------------------------------


def test_ik_step_equals_ik_step_method(panda):
    target = panda.position(PANDA_Q) + PANDA_OFFSET
    levels = [qc.PositionTask(panda, target=target), qc.PostureTask(panda, np.zeros(7))]
    qdot, sol = qc.ik_step(panda, PANDA_Q, levels, dt=0.01, method="hierarchical")
    expected, _ = qc.IK(panda, levels, dt=0.01).step(PANDA_Q)
    np.testing.assert_allclose(qdot, expected, rtol=0, atol=1e-12)
    assert isinstance(sol, qc.Solution)


def test_velocity_equals_step(planar):
    ik = qc.IK(planar, [qc.PositionTask(planar, target=[1.5, 1.0])], dt=0.01)
    np.testing.assert_allclose(ik.velocity(PLANAR_Q), ik.step(PLANAR_Q)[0], atol=1e-12)


def test_constant_equality_level_and_hard_constraint(planar):
    """A constant Equality as a level and a 1-form as a hard constraint (ω q̇ = 0)."""
    omega = qc.OneFormTask(planar, [1.0, 0.0, -1.0])
    level = qc.Equality(np.eye(3), [1.0, 2.0, 3.0])
    qdot, _ = qc.IK(planar, [level], dt=0.01, limits=None, constraints=[omega]).step(PLANAR_Q)
    np.testing.assert_allclose(qdot[0] - qdot[2], 0.0, atol=1e-9)
    np.testing.assert_allclose(qdot, [2.0, 2.0, 2.0], atol=1e-9)


@pytest.mark.parametrize("robot_name", ["planar_3r", "panda"])
def test_inverse_kinematics_reaches_a_reachable_target(robot_name, rng):
    robot = qc.robots.load(robot_name)
    q0 = PLANAR_Q if robot_name == "planar_3r" else PANDA_Q
    for _ in range(3):
        goal_q = q0 + rng.uniform(-0.3, 0.3, robot.nq)
        target = robot.position(goal_q)
        q = qc.inverse_kinematics(robot, target, q0)
        np.testing.assert_allclose(robot.position(q), target, rtol=0, atol=1e-10)
        # minimum-norm steps: no farther from q0 than the configuration that made the target
        assert np.linalg.norm(q - q0) <= np.linalg.norm(goal_q - q0) + 1e-6


@pytest.mark.parametrize("target", [[5.0, 0.0], [0.0, -3.2]])
def test_inverse_kinematics_unreachable_target(planar, target):
    with pytest.raises(ValueError, match="not reached"):
        qc.inverse_kinematics(planar, target, PLANAR_Q)


@pytest.mark.parametrize("target", [[1.0], [1.0, 2.0, 3.0], [np.nan, 1.0]])
def test_inverse_kinematics_bad_target(planar, target):
    with pytest.raises(ValueError, match="target must be 2 finite coordinates"):
        qc.inverse_kinematics(planar, target, PLANAR_Q)


def test_inverse_kinematics_bad_start(planar):
    with pytest.raises(ValueError, match=r"q0\[0\] is .*must be finite"):
        qc.inverse_kinematics(planar, [1.0, 1.0], [np.nan, 0.0, 0.0])


# ---------------------------------------------------------------------------------------
# (g) bad input
# ---------------------------------------------------------------------------------------


def test_robot_must_be_a_robot(planar):
    with pytest.raises(ValueError, match="robot must be a qpcoord.Robot, got Model"):
        qc.IK(planar.model, [], dt=0.01)
    with pytest.raises(ValueError, match="robot must be a qpcoord.Robot, got str"):
        qc.ik_step("planar_3r", PLANAR_Q, [], dt=0.01)


def test_task_of_another_robot(planar):
    other = qc.robots.load("planar_3r")
    with pytest.raises(ValueError, match=r"levels\[1\]: task 'position' belongs to another"):
        qc.IK(planar, [qc.PostureTask(planar, PLANAR_Q), qc.PositionTask(other, [1, 1])], 0.01)
    with pytest.raises(ValueError, match="constraints: task 'one-form' belongs to another"):
        qc.IK(planar, [], 0.01, constraints=[qc.OneFormTask(other, [1.0, 0.0, 0.0])])
    with pytest.raises(ValueError, match="belongs to another robot"):
        qc.IK(planar, [], 0.01, limits=[qc.VelocityLimits(other, 1.0)])


@pytest.mark.parametrize(
    "task",
    [
        qc.Equality(np.eye(2), [0.0, 0.0], name="small"),
        qc.Inequality(np.ones((1, 4)), upper=1.0, name="wide"),
    ],
    ids=["equality", "inequality"],
)
def test_constant_task_with_the_wrong_number_of_columns(planar, task):
    with pytest.raises(ValueError, match=f"levels\\[0\\]: .*{task.name}.* columns, the robot 3"):
        qc.IK(planar, [task], dt=0.01)


@pytest.mark.parametrize("item", [np.eye(3), "posture", None])
def test_level_item_that_is_not_a_task(planar, item):
    with pytest.raises(ValueError, match="expected kinematic tasks, Equality or Inequality"):
        qc.IK(planar, [item], dt=0.01)


@pytest.mark.parametrize(
    ("limits", "message"),
    [
        ("foo", "limits must be 'robot', a list of limits or None"),
        (["foo"], "JointLimits/VelocityLimits objects"),
        ([qc.Bounds(-1.0, 1.0)], "JointLimits/VelocityLimits objects"),
    ],
)
def test_bad_limits(planar, limits, message):
    with pytest.raises(ValueError, match=message):
        qc.IK(planar, [qc.PostureTask(planar, PLANAR_Q)], dt=0.01, limits=limits)


@pytest.mark.parametrize("dt", [0.0, -0.01, np.nan, np.inf, True])
def test_bad_dt(planar, dt):
    with pytest.raises(ValueError, match="dt must be"):
        qc.IK(planar, [qc.PostureTask(planar, PLANAR_Q)], dt=dt)


@pytest.mark.parametrize(
    ("q", "message"),
    [([0.0, np.nan, 0.0], r"q\[1\] is .*must be finite"), ([0.0, 0.0], "must have 3 entries")],
    ids=["nan", "short"],
)
def test_bad_configuration(planar, q, message):
    ik = qc.IK(planar, [qc.PostureTask(planar, PLANAR_Q)], dt=0.01)
    with pytest.raises(ValueError, match=message):
        ik.step(q)
    with pytest.raises(ValueError, match=message):
        ik.velocity(q)


def test_unknown_method_is_reported(planar):
    with pytest.raises(ValueError, match="unknown method 'magic'"):
        qc.IK(planar, [qc.PostureTask(planar, PLANAR_Q)], dt=0.01, method="magic")


def test_nullspace_method_refuses_limits(panda):
    with pytest.raises(ValueError, match="nullspace.*limits=None"):
        qc.IK(panda, [qc.PostureTask(panda, PANDA_Q)], dt=0.01, method="nullspace")
    ik = qc.IK(panda, [qc.PostureTask(panda, PANDA_Q)], dt=0.01, method="nullspace", limits=None)
    np.testing.assert_allclose(ik.step(PANDA_Q)[0], 0.0, atol=1e-12)
