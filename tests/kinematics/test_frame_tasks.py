"""Tests of the frame, CoM, support-polygon and joint-space tasks
(:mod:`qpcoord.kinematics.frame_tasks`): every task's Jacobian against central finite
differences of its error on the configuration manifold (fixed arm, continuous joints, two
free-flyer robots), closed-loop convergence, the band rows, nv-sized regularisers on a
floating base, and every bad input named in its ``ValueError``."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import qpcoord as qc
from qpcoord.kinematics.frame_tasks import (
    ComBand,
    ComTask,
    DampingTask,
    FramePositionTask,
    FrameTask,
    JointCouplingTask,
    LowAccelerationTask,
    OrientationTask,
    RelativeFrameTask,
    SupportPolygon,
    _hull,
    _parse_mask,
)

#: Central-difference step along ``integrate(q, ε δv)`` (unit of v × s). The truncation
#: error is ε²/6 · |e'''| ≈ 1e-12 · O(10) and the rounding error ≈ 1e-16 · |e| / ε ≈ 1e-10
#: for errors of order 1 (m, rad); measured disagreements are ≤ 2e-8 (the largest near a
#: rotation error close to π, where Jlog grows like 1/(π − θ)).
FD_STEP = 1e-6
#: Agreement required, relative to ``1 + ‖J δv‖∞`` (a 50× margin over the measured worst).
FD_TOL = 1e-6

#: Half length / half width of a Talos sole (m), for its contact corners.
SOLE = np.array([[x, y, 0.0] for x in (-0.1, 0.1) for y in (-0.05, 0.05)])


# ---------------------------------------------------------------------------------------
# robots (loaded once per module) and a task factory per robot
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def robots() -> dict[str, qc.Robot]:
    return {name: qc.robots.load(name) for name in ("panda", "kinova", "solo12", "talos")}


#: (controlled frame, second frame, contact frames, contact points, two 1-DoF joints)
SETUP = {
    "panda": (
        "panda_hand_tcp",
        "panda_link4",
        ["panda_link2", "panda_link4", "panda_link6"],
        None,
        ["panda_joint2", "panda_joint4"],
    ),
    "kinova": (
        "j2s6s200_end_effector",
        "j2s6s200_link_3",
        ["j2s6s200_link_2", "j2s6s200_link_4", "j2s6s200_end_effector"],
        None,
        ["j2s6s200_joint_2", "j2s6s200_joint_3"],
    ),
    "solo12": (
        "FL_FOOT",
        "HR_FOOT",
        ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"],
        None,
        ["FL_HFE", "FL_KFE"],
    ),
    "talos": (
        "gripper_left_base_link",
        "gripper_right_base_link",
        ["left_sole_link", "right_sole_link"],
        SOLE,
        ["arm_left_4_joint", "arm_right_4_joint"],
    ),
}

TASK_KINDS = [
    "frame",
    "frame_masked",
    "frame_weighted",
    "frame_split",
    "frame_split_masked",
    "position",
    "position_masked",
    "orientation",
    "orientation_yaw",
    "relative",
    "com",
    "com_xy",
    "com_band",
    "support_polygon",
    "coupling",
    "damping",
    "low_acceleration",
]


def make_task(kind: str, robot: qc.Robot, name: str, q_target: np.ndarray):
    frame, other, contacts, points, joints = SETUP[name]
    if kind == "frame":
        task = FrameTask(robot, frame)
    elif kind == "frame_masked":
        task = FrameTask(robot, frame, mask="z yaw")
    elif kind == "frame_weighted":
        task = FrameTask(robot, frame, position_weight=2.0, orientation_weight=0.0)
    elif kind == "frame_split":
        task = FrameTask(robot, frame, error="split")
    elif kind == "frame_split_masked":
        task = FrameTask(robot, frame, mask="z rx", error="split")
    elif kind == "position":
        task = FramePositionTask(robot, frame)
    elif kind == "position_masked":
        task = FramePositionTask(robot, frame, mask="xz")
    elif kind == "orientation":
        task = OrientationTask(robot, frame)
    elif kind == "orientation_yaw":
        task = OrientationTask(robot, frame, mask="yaw")
    elif kind == "relative":
        task = RelativeFrameTask(robot, frame, other)
    elif kind == "com":
        task = ComTask(robot)
    elif kind == "com_xy":
        task = ComTask(robot, mask="xy")
    elif kind == "com_band":
        return ComBand(robot, [-0.1, -np.inf, 0.2], [0.1, np.inf, np.inf])
    elif kind == "support_polygon":
        return SupportPolygon(robot, contacts, margin=0.01, contact_points=points)
    elif kind == "coupling":
        return JointCouplingTask(robot, joints, [1.0, -0.5], offset=0.1)
    elif kind == "damping":
        task = DampingTask(robot)
        task.update(q_target)  # holds q_target: the error is difference(q_target, q)
        return task
    elif kind == "low_acceleration":
        task = LowAccelerationTask(robot)
        task.update(q_target)
        return task
    else:  # pragma: no cover
        raise AssertionError(kind)
    if kind.startswith("com"):
        task.set_target_from_configuration(q_target)
    else:
        task.set_target_from_configuration(q_target)
    return task


def fd_check(task, robot: qc.Robot, q: np.ndarray, seed: int) -> None:
    rng = np.random.default_rng(seed)
    J = task.compute_jacobian(q)
    e = task.compute_error(q)
    assert J.shape == (e.size, robot.nv)
    for _ in range(3):
        dv = rng.normal(size=robot.nv)
        plus = task.compute_error(robot.integrate(q, dv, FD_STEP))
        minus = task.compute_error(robot.integrate(q, dv, -FD_STEP))
        fd = (plus - minus) / (2 * FD_STEP)
        exact = J @ dv
        scale = 1.0 + float(np.abs(exact).max())
        assert np.abs(fd - exact).max() <= FD_TOL * scale, (fd, exact)


@pytest.mark.parametrize("name", ["panda", "kinova", "solo12", "talos"])
@pytest.mark.parametrize("kind", TASK_KINDS)
def test_jacobian_matches_finite_differences(robots, name, kind):
    robot = robots[name]
    for seed in (1, 2):
        q = robot.random_configuration(seed)
        q_target = robot.random_configuration(seed + 10)
        task = make_task(kind, robot, name, q_target)
        fd_check(task, robot, q, seed)
        # the refreshed rows are the Jacobian and −K e (+ the band's bounds)
        t = task.update(q)
        J, e = task.compute_jacobian(q), task.compute_error(q)
        if isinstance(t, qc.Equality):
            assert t.A.shape == (e.size, robot.nv)
            np.testing.assert_allclose(t.A, J, atol=1e-12)
            if kind == "low_acceleration":
                continue  # b = v_prev (the last step's velocity), checked below
            np.testing.assert_allclose(t.b, -task.gain * e, atol=1e-12)
        else:
            assert t.C.shape == (e.size, robot.nv)
            np.testing.assert_allclose(t.C, J, atol=1e-12)


# ---------------------------------------------------------------------------------------
# feed-forward of moving targets: ff = −∂e/∂t along the target's motion (v = 0)
# ---------------------------------------------------------------------------------------


def feed_forward(task, q):
    t = task.update(q)
    return t.b + task.gain * task.compute_error(q)


def test_feed_forward_of_moving_targets(robots):
    robot = robots["panda"]
    q, q1 = robot.random_configuration(3), robot.random_configuration(4)
    frame = "panda_hand_tcp"
    T0 = pin.SE3(robot.frame_pose(q1, frame))
    nu = np.array([0.1, -0.2, 0.3, 0.5, -0.4, 0.2])
    h = 1e-6

    def error_at(task, s, make):
        task.set_target(*make(s))
        return task.compute_error(q)

    cases = [
        (FrameTask(robot, frame, gain=2.0), lambda s: (T0 * pin.exp6(s * nu), nu)),
        (
            FrameTask(robot, frame, gain=2.0, error="split"),
            lambda s: (T0 * pin.exp6(s * nu), nu),
        ),
        (
            OrientationTask(robot, frame, gain=2.0),
            lambda s: (T0.rotation @ pin.exp3(s * nu[3:]), nu[3:]),
        ),
        (
            FramePositionTask(robot, frame, gain=2.0),
            lambda s: (T0.translation + s * nu[:3], nu[:3]),
        ),
        (ComTask(robot, gain=2.0), lambda s: (np.ones(3) * 0.3 + s * nu[:3], nu[:3])),
    ]
    for task, make in cases:
        fd = (error_at(task, h, make) - error_at(task, -h, make)) / (2 * h)
        task.set_target(*make(0.0))
        np.testing.assert_allclose(feed_forward(task, q), -fd, atol=1e-7)


# ---------------------------------------------------------------------------------------
# convergence in a closed loop
# ---------------------------------------------------------------------------------------


def pose_error(robot, q, frame, T):
    E = pin.SE3(T).actInv(pin.SE3(robot.frame_pose(q, frame)))
    return float(np.linalg.norm(E.translation)), float(np.linalg.norm(pin.log3(E.rotation)))


def test_panda_frame_task_converges(robots):
    robot = robots["panda"]
    frame = "panda_hand_tcp"
    q = robot.random_configuration(5)
    T = robot.frame_pose(robot.random_configuration(6), frame)  # reachable
    dt = 0.01
    task = FrameTask(robot, frame, T, gain=50.0)  # K dt = 0.5
    damping = DampingTask(robot, weight=1e-3)
    stack = qc.Stack([task.task, damping.task])
    for _ in range(150):
        task.update(q, dt=dt)
        damping.update(q, dt=dt)
        v = stack.solve().x
        q = robot.integrate(q, v, dt)
    dp, dr = pose_error(robot, q, frame, T)
    assert dp <= 1e-6 and dr <= 1e-6, (dp, dr)
    assert np.abs(task.compute_error(q)).max() <= 1e-6


def test_panda_frame_task_converges_with_ik_and_hard_limits(robots):
    robot = robots["panda"]
    frame = "panda_hand_tcp"
    q = robot.neutral() * 0 + 0.5 * (robot.lower + robot.upper)
    T = robot.frame_pose(robot.random_configuration(7), frame)
    dt = 0.01
    task = FrameTask(robot, frame, T, gain=50.0)
    ik = qc.IK(robot, [[task]], dt)
    for _ in range(200):
        v, _sol = ik.step(q)
        q = robot.integrate(q, v, dt)
        assert np.all(q >= robot.lower - 1e-9) and np.all(q <= robot.upper + 1e-9)
    dp, dr = pose_error(robot, q, frame, T)
    assert dp <= 1e-6 and dr <= 1e-6, (dp, dr)


def test_masked_frame_task_moves_only_its_axes(robots):
    """``mask="z"`` with ``error="split"`` brings the origin to the target's height (along
    the target's z) while the orientation is free; under ``"se3"`` the z row of log₆ is
    zeroed but, the rotation having drifted, the height is not (the documented caveat)."""
    robot = robots["panda"]
    frame = "panda_hand_tcp"
    q0 = robot.random_configuration(8)
    T = robot.frame_pose(q0, frame)
    T[:3, 3] += 0.05 * T[:3, 2]  # 5 cm along the frame's own z, same orientation
    dt = 0.01
    heights = {}
    for error in ("split", "se3"):
        q = q0.copy()
        task = FrameTask(robot, frame, T, gain=50.0, mask="z", error=error)
        assert task.task.shape == (1, robot.nv)
        for _ in range(150):
            t = task.update(q, dt=dt)
            q = robot.integrate(q, np.linalg.lstsq(t.A, t.b, rcond=None)[0], dt)
        assert abs(task.compute_error(q)[0]) <= 1e-8
        p = robot.frame_pose(q, frame)[:3, 3]
        heights[error] = float(T[:3, 2] @ (p - T[:3, 3]))
    assert abs(heights["split"]) <= 1e-8
    assert abs(heights["se3"]) > 1e-4


def test_solo12_base_moves_with_feet_fixed(robots):
    """Four point feet held at level 0, the base pose at level 1, damping last (nv-sized)."""
    robot = robots["solo12"]
    q = robot.neutral()
    q[2] = 0.25
    q[7:] = np.tile([0.0, 0.8, -1.6], 4)
    feet = [FramePositionTask(robot, f, gain=100.0) for f in SETUP["solo12"][2]]  # points
    for f in feet:
        f.set_target_from_configuration(q)
    base = FrameTask(robot, "base_link", gain=50.0)
    T = robot.frame_pose(q, "base_link")
    T[2, 3] -= 0.03
    base.set_target(T)
    damping = DampingTask(robot)
    accel = LowAccelerationTask(robot, weight=1e-2)
    assert damping.task.shape == accel.task.shape == (robot.nv, robot.nv) == (18, 18)
    stack = qc.Stack([[f.task for f in feet], base.task, [damping.task, accel.task]])
    dt = 0.01
    for _ in range(100):
        for task in (*feet, base, damping, accel):
            task.update(q, dt=dt)
        q = robot.integrate(q, stack.solve().x, dt)
    for f in feet:
        assert np.abs(f.compute_error(q)).max() <= 1e-6
    assert np.abs(base.compute_error(q)).max() <= 1e-6


# ---------------------------------------------------------------------------------------
# damping / low acceleration on a floating base (Pink 4.4's LowAccelerationTask fails here)
# ---------------------------------------------------------------------------------------


def test_regularisers_are_nv_sized_on_a_floating_base(robots):
    robot = robots["solo12"]
    assert (robot.nq, robot.nv) == (19, 18)
    q0 = robot.random_configuration(0)
    dt = 0.01
    v = np.random.default_rng(0).normal(size=robot.nv)
    q1 = robot.integrate(q0, v, dt)
    for cls in (DampingTask, LowAccelerationTask):
        task = cls(robot, weight=np.linspace(1, 2, robot.nv))
        t = task.update(q0, dt=dt)
        assert t.A.shape == (18, 18) and t.b.shape == (18,)
        np.testing.assert_array_equal(t.A, np.eye(18))
        np.testing.assert_array_equal(t.b, 0.0)
        assert task.compute_error(q1).shape == (18,)
        assert task.compute_jacobian(q1).shape == (18, 18)
        np.testing.assert_allclose(task.compute_error(q1), dt * v, atol=1e-12)
        sol = qc.Stack([t]).solve()
        assert sol.x.shape == (18,)
    # low acceleration: v_prev measured from the last two updates, or given
    task = LowAccelerationTask(robot)
    task.update(q0, dt=dt)
    np.testing.assert_allclose(task.update(q1, dt=dt).b, v, atol=1e-9)
    w = np.arange(18.0)
    task.set_previous(w)
    np.testing.assert_array_equal(task.update(q1, dt=dt).b, w)
    np.testing.assert_allclose(qc.Stack([task.task]).solve().x, w, atol=1e-9)


def test_damping_picks_the_slowest_motion(robots):
    robot = robots["panda"]
    q = robot.random_configuration(9)
    pos = FramePositionTask(robot, "panda_hand_tcp", gain=1.0)
    pos.set_target(robot.frame_pose(q, "panda_hand_tcp")[:3, 3] + [0.0, 0.0, 0.01])
    damping = DampingTask(robot)
    pos.update(q)
    damping.update(q)
    v = qc.Stack([pos.task, damping.task]).solve().x
    J = pos.task.A
    np.testing.assert_allclose(v, np.linalg.pinv(J) @ pos.task.b, atol=1e-9)


# ---------------------------------------------------------------------------------------
# CoM band and support polygon
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def talos_standing(robots):
    robot = robots["talos"]
    return robot, robot.reference_configuration("half_sitting")


def test_com_band_inside_does_not_bind_outside_pushes_back(talos_standing):
    robot, q = talos_standing
    c = robot.com(q)
    band = ComBand(robot, c - [0.05, 0.05, np.inf], c + [0.05, 0.05, np.inf], gain=10.0)
    t = band.update(q)
    assert np.all(t.lower[:2] < 0) and np.all(t.upper[:2] > 0)  # v = 0 is feasible
    assert t.lower[2] == -np.inf and t.upper[2] == np.inf
    np.testing.assert_allclose(t.lower[:2], 10.0 * (-0.05), atol=1e-12)
    # a CoM 2 cm beyond the upper x face: the row asks for c_x to come back at rate K
    band.set_box(c - 0.2, c - [0.02, -0.1, -0.1])
    t = band.update(q)
    assert t.lower[0] > 0 or t.upper[0] < 0
    np.testing.assert_allclose(t.upper[0], 10.0 * -0.02, atol=1e-12)
    # closed loop: the CoM is brought into the band and stays there
    dt = 0.01
    damping = DampingTask(robot)
    stack = qc.Stack([band.task, damping.task])
    for _ in range(100):
        band.update(q, dt=dt)
        damping.update(q, dt=dt)
        q = robot.integrate(q, stack.solve().x, dt)
    c_end = robot.com(q)
    assert c_end[0] <= band.upper[0] + 1e-6 and c_end[0] >= band.lower[0] - 1e-6


def test_support_polygon_rows(talos_standing):
    robot, q = talos_standing
    soles = ["left_sole_link", "right_sole_link"]
    poly = SupportPolygon(robot, soles, margin=0.01, contact_points=SOLE, gain=10.0)
    t = poly.update(q)
    assert t.C.shape == (8, robot.nv)
    # two level soles side by side: the hull is a rectangle (collinear corners dropped)
    assert poly.edges == 4
    P = poly.contact_positions(q)
    c = robot.com(q)
    x_lo, x_hi = P[:, 0].min(), P[:, 0].max()
    y_lo, y_hi = P[:, 1].min(), P[:, 1].max()
    expected = sorted([x_lo - c[0], c[0] - x_hi, y_lo - c[1], c[1] - y_hi])
    e = poly.compute_error(q)
    np.testing.assert_allclose(sorted(e[:4]), expected, atol=1e-9)
    assert np.all(e[4:] == 0) and np.all(t.C[4:] == 0) and np.all(np.isinf(t.upper[4:]))
    # inside: every upper bound > 0 (v = 0 feasible, rows do not bind)
    assert np.all(t.upper[:4] > 0) and np.all(t.lower == -np.inf)
    np.testing.assert_allclose(t.upper[:4], 10.0 * (-0.01 - e[:4]), atol=1e-12)


@pytest.mark.parametrize("engine", ["python", "native"])
def test_support_polygon_holds_the_com_with_feet_fixed(talos_standing, engine, monkeypatch):
    """Feet (level 0), polygon (level 1), CoM pulled 30 cm forward (level 2): the CoM
    stops at the shrunk front edge; a polygon ahead of the CoM pulls it in. Both engines
    are regression tests: the native active set cycled on the CoM level (a working set
    numerically rank-deficient to 6e-16 relative, counted as full rank); the Python
    engine's refinement, on two front edges parallel to 4e-10, returned a joint velocity
    of 4e6 at step 9 (tests/core/test_hierarchy_regressions.py). This test ran the Python
    engine as "default" until the native engine became the default."""
    if engine == "native":
        _native_default(monkeypatch)
    else:
        from qpcoord.core import native

        monkeypatch.setattr(native, "DEFAULT_ENGINE", "python")
    robot, q0 = talos_standing
    soles = ["left_sole_link", "right_sole_link"]
    dt = 0.01
    for points, pull in ((SOLE, 0.3), (SOLE + [0.25, 0.0, 0.0], 0.0)):
        q = q0.copy()
        feet = [FrameTask(robot, s, gain=100.0) for s in soles]
        for f in feet:
            f.set_target_from_configuration(q)
        poly = SupportPolygon(robot, soles, margin=0.02, contact_points=points, gain=20.0)
        com = ComTask(robot, robot.com(q) + [pull, 0.0, 0.0], gain=5.0, mask="xy")
        damping = DampingTask(robot)
        levels = [[f.task for f in feet], poly.task, com.task, damping.task]
        if pull == 0.0:
            levels = [levels[0], levels[1], levels[3]]
        stack = qc.Stack(levels)
        violations = []
        for _ in range(150):
            for task in (*feet, poly, com, damping):
                task.update(q, dt=dt)
            q = robot.integrate(q, stack.solve().x, dt)
            violations.append(float(np.max(poly.compute_error(q)[: poly.edges] + 0.02)))
        for f in feet:
            assert np.abs(f.compute_error(q)).max() <= 1e-6
        if pull:
            # measured: the CoM approaches the shrunk front edge monotonically and rests on
            # it (max violation -2e-16 m); the criterion is at most 1e-9 m at any step
            assert max(violations) <= 1e-9
            assert abs(violations[-1]) <= 1e-6  # resting on the shrunk edge
        else:
            assert violations[0] > 0.1  # started far outside
            assert violations[-1] <= 1e-6  # pushed back in
            assert np.all(np.diff(violations[:50]) < 0)


def _native_default(monkeypatch) -> None:
    """Make the native engine the default of every ``Stack.solve`` (skip if not built)."""
    from qpcoord.core import native

    if not native.available():
        pytest.skip(f"the native engine is not built: {native._load_error}")
    monkeypatch.setattr(native, "DEFAULT_ENGINE", "native")


def test_hull():
    pts = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5], [0.5, 0.0]], dtype=float)
    hull = _hull(pts)
    assert sorted(hull) == [0, 1, 2, 3]
    area = 0.5 * sum(
        pts[a, 0] * pts[b, 1] - pts[b, 0] * pts[a, 1]
        for a, b in zip(hull, hull[1:] + hull[:1], strict=True)
    )
    assert area == pytest.approx(1.0)  # counter-clockwise
    assert len(_hull(np.array([[0, 0], [1, 1], [2, 2.0]]))) == 2


# ---------------------------------------------------------------------------------------
# masks, weights, coupling
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("spec", "expected"),
    [
        ("z", [0, 0, 1, 0, 0, 0]),
        ("yaw", [0, 0, 0, 0, 0, 1]),
        ("xy", [1, 1, 0, 0, 0, 0]),
        ("x, rz", [1, 0, 0, 0, 0, 1]),
        ("position", [1, 1, 1, 0, 0, 0]),
        ("z+roll+pitch", [0, 0, 1, 1, 1, 0]),
        ("orientation", [0, 0, 0, 1, 1, 1]),
        ([True, False, False, False, False, True], [1, 0, 0, 0, 0, 1]),
    ],
)
def test_mask_specs(spec, expected):
    axes = ("x", "y", "z", "rx", "ry", "rz")
    np.testing.assert_array_equal(_parse_mask(spec, axes), np.array(expected, dtype=bool))


def test_orientation_mask_letters_are_rotation_axes():
    np.testing.assert_array_equal(_parse_mask("z", ("rx", "ry", "rz")), [False, False, True])


def test_weights_per_row(robots):
    robot = robots["panda"]
    task = FrameTask(
        robot, "panda_hand_tcp", np.eye(4), position_weight=4.0, orientation_weight=0.5
    )
    np.testing.assert_array_equal(task.task.weight, [4, 4, 4, 0.5, 0.5, 0.5])
    only_position = FrameTask(robot, "panda_hand_tcp", np.eye(4), orientation_weight=0.0)
    assert only_position.task.shape == (3, robot.nv)


def test_joint_coupling_converges(robots):
    robot = robots["talos"]
    q = robot.reference_configuration("half_sitting")
    task = JointCouplingTask(
        robot, ["arm_left_4_joint", "arm_right_4_joint"], [1.0, -1.0], gain=50.0
    )
    dt = 0.01
    for _ in range(100):
        t = task.update(q, dt=dt)
        q = robot.integrate(q, np.linalg.lstsq(t.A, t.b, rcond=None)[0], dt)
    assert abs(task.compute_error(q)[0]) <= 1e-9
    task.set_offset_from_configuration(q)
    assert task.offset == pytest.approx(0.0, abs=1e-9)


# ---------------------------------------------------------------------------------------
# bad input: each a ValueError naming the argument
# ---------------------------------------------------------------------------------------


def bad_transforms():
    R = pin.exp3(np.array([0.1, 0.2, 0.3]))
    T = np.eye(4)
    T[:3, :3] = R
    skewed = T.copy()
    skewed[0, 1] += 1e-3
    reflection = T.copy()
    reflection[:3, 0] *= -1
    last_row = T.copy()
    last_row[3, 0] = 0.1
    nan = T.copy()
    nan[1, 3] = np.nan
    inf = T.copy()
    inf[0, 3] = np.inf
    return [
        (np.eye(3), "4×4"),
        (np.zeros(16), "4×4"),
        ("pose", "4×4"),
        (skewed, "orthonormal"),
        (reflection, "det"),
        (last_row, "last row"),
        (nan, "NaN"),
        (inf, "inf"),
    ]


@pytest.mark.parametrize(("target", "words"), bad_transforms())
def test_bad_targets(robots, target, words):
    robot = robots["panda"]
    with pytest.raises(ValueError, match="target") as info:
        FrameTask(robot, "panda_hand_tcp", target)
    assert words in str(info.value)
    task = FrameTask(robot, "panda_hand_tcp", np.eye(4))
    with pytest.raises(ValueError, match="target"):
        task.set_target(target)
    np.testing.assert_array_equal(task.target.homogeneous, np.eye(4))  # unchanged
    with pytest.raises(ValueError, match="target"):
        RelativeFrameTask(robot, "panda_hand_tcp", "panda_link4", target)
    if np.shape(target) == (4, 4):
        with pytest.raises(ValueError, match="target"):
            OrientationTask(robot, "panda_hand_tcp", target)


def test_unknown_frames_list_close_names(robots):
    robot = robots["talos"]
    cases = [
        (lambda: FrameTask(robot, "left_sole"), "frame"),
        (lambda: FramePositionTask(robot, "gripper_left_base"), "frame"),
        (lambda: OrientationTask(robot, "left_sole"), "frame"),
        (lambda: RelativeFrameTask(robot, "left_sole_link", "right_sole"), "reference_frame"),
        (lambda: SupportPolygon(robot, ["left_sole_link", "right_sole"]), r"contact_frames\[1\]"),
    ]
    for build, what in cases:
        with pytest.raises(ValueError, match=what) as info:
            build()
        assert "close names" in str(info.value)
    with pytest.raises(ValueError, match="frame"):
        FrameTask(robot, 3.5)


@pytest.mark.parametrize(
    ("build", "what"),
    [
        (lambda r: FrameTask(r, "panda_hand_tcp", gain=-1.0), "gain"),
        (lambda r: FrameTask(r, "panda_hand_tcp", gain=np.nan), "gain"),
        (lambda r: FrameTask(r, "panda_hand_tcp", gain="fast"), "gain"),
        (lambda r: FrameTask(r, "panda_hand_tcp", position_weight=-1.0), "position_weight"),
        (lambda r: FrameTask(r, "panda_hand_tcp", orientation_weight=np.inf), "orientation_weight"),
        (
            lambda r: FrameTask(r, "panda_hand_tcp", position_weight=0, orientation_weight=0),
            "weight",
        ),
        (lambda r: FrameTask(r, "panda_hand_tcp", mask="up"), "mask"),
        (lambda r: FrameTask(r, "panda_hand_tcp", mask=[True] * 5), "mask"),
        (lambda r: FrameTask(r, "panda_hand_tcp", mask=[False] * 6), "mask"),
        (lambda r: FrameTask(r, "panda_hand_tcp", mask=[0, 2, 0, 0, 0, 0]), "mask"),
        (lambda r: FramePositionTask(r, "panda_hand_tcp", mask="yaw"), "mask"),
        (lambda r: FramePositionTask(r, "panda_hand_tcp", [0, 0]), "target"),
        (lambda r: FramePositionTask(r, "panda_hand_tcp", [0, np.nan, 0]), "target"),
        (lambda r: FramePositionTask(r, "panda_hand_tcp", weight=0.0), "weight"),
        (lambda r: OrientationTask(r, "panda_hand_tcp", np.eye(3) * 2), "target"),
        (lambda r: OrientationTask(r, "panda_hand_tcp", np.eye(2)), "target"),
        (lambda r: OrientationTask(r, "panda_hand_tcp", mask="x w"), "mask"),
        (lambda r: RelativeFrameTask(r, "panda_link4", "panda_link4"), "reference_frame"),
        (lambda r: ComTask(r, [0, 0, np.inf]), "target"),
        (lambda r: ComTask(r, gain=-2), "gain"),
        (lambda r: ComBand(r, [0, 0, 1], [1, 1, 0]), "lower > upper"),
        (lambda r: ComBand(r, [0, np.nan, 0], 1), "lower"),
        (lambda r: ComBand(r, np.inf, np.inf), "lower"),
        (lambda r: ComBand(r, -1, -np.inf), "upper"),
        (lambda r: ComBand(r, -1, [1, 1]), "upper"),
        (lambda r: SupportPolygon(r, ["panda_link2", "panda_link4"]), "contact_frames"),
        (lambda r: SupportPolygon(r, "panda_link2"), "contact_frames"),
        (lambda r: SupportPolygon(r, ["panda_link2"] * 3), "contact_frames"),
        (
            lambda r: SupportPolygon(r, ["panda_link2", "panda_link4", "panda_link6"], margin=-1),
            "margin",
        ),
        (
            lambda r: SupportPolygon(r, ["panda_link2"], contact_points=[[0, 0, np.nan]] * 3),
            "contact_points",
        ),
        (lambda r: SupportPolygon(r, ["panda_link2"], contact_points=[[0, 0]]), "contact_points"),
        (lambda r: JointCouplingTask(r, ["panda_joint1", "panda_jiont2"], [1, 1]), "joints"),
        (lambda r: JointCouplingTask(r, ["panda_joint1"], [1, 1]), "ratios"),
        (lambda r: JointCouplingTask(r, ["panda_joint1", "panda_joint2"], [0, 0]), "ratios"),
        (lambda r: JointCouplingTask(r, ["panda_joint1", "panda_joint1"], [1, 1]), "joints"),
        (lambda r: JointCouplingTask(r, ["panda_joint1"], [1], offset=np.nan), "offset"),
        (lambda r: DampingTask(r, weight=0.0), "weight"),
        (lambda r: DampingTask(r, weight=[1.0, 2.0]), "weight"),
        (lambda r: LowAccelerationTask(r).set_previous(np.zeros(3)), "v"),
        (lambda r: FrameTask(r, "panda_hand_tcp").update(r.neutral()), "no target"),
        (lambda r: ComTask(r).compute_error(r.neutral()), "no target"),
        (lambda r: FrameTask(r, "panda_hand_tcp", np.eye(4)).update(np.zeros(3)), "q"),
        (lambda r: FrameTask(r, "panda_hand_tcp", np.eye(4)).compute_error([np.nan] * 7), "q"),
        (
            lambda r: FrameTask(r, "panda_hand_tcp", np.eye(4)).set_target(np.eye(4), [1, 2]),
            "velocity",
        ),
        (lambda r: FrameTask(object(), "panda_hand_tcp"), "robot"),
        (lambda r: FrameTask(r, "panda_hand_tcp", error="log"), "error"),
    ],
)
def test_bad_inputs(robots, build, what):
    robot = robots["panda"]
    with pytest.raises(ValueError, match=what):
        build(robot)


def test_floating_base_bad_inputs(robots):
    robot = robots["solo12"]
    with pytest.raises(ValueError, match=r"joints\[0\].*nq = 7"):
        JointCouplingTask(robot, ["root_joint", "FL_HFE"], [1, 1])
    q = robot.neutral()
    q[3:7] = [0.0, 0.0, 0.0, 2.0]  # not a unit quaternion
    task = ComTask(robot, [0, 0, 0.2])
    with pytest.raises(ValueError, match="q.*unit norm"):
        task.update(q)
    # contact points whose ground projections are collinear
    poly = SupportPolygon(robot, ["FL_HFE", "FL_KFE", "FL_FOOT"])  # a straight leg
    q = robot.neutral()
    with pytest.raises(ValueError, match="collinear"):
        poly.update(q)


def test_the_robot_tasks_page_snippets_run():
    """Every ``python`` block of docs/robot-tasks.md runs, in order, in one namespace, and
    the page's Talos scenario keeps its feet and its CoM where the page says."""
    import contextlib
    import io

    from support.pages import ROOT, run_blocks, run_page

    page = ROOT / "docs" / "robot-tasks.md"
    assert len(run_blocks(page)) >= 5
    with contextlib.redirect_stdout(io.StringIO()):
        ns = run_page(page)

    feet, polygon, q = ns["feet"], ns["polygon"], ns["q"]
    assert max(np.abs(f.compute_error(q)).max() for f in feet) <= 1e-5
    assert polygon.compute_error(q)[: polygon.edges].max() + 0.02 <= 1e-6


def _exact_cases():
    R = pin.exp3(np.array([0.1, 0.2, 0.3]))
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, [0.3, 0.1, 0.5]
    skewed, reflection, last_row = T.copy(), T.copy(), T.copy()
    skewed[0, 1] += 1e-3
    reflection[:3, 0] *= -1
    last_row[3, 0] = 0.1
    skewed3 = R.copy()
    skewed3[2, 2] += 2e-6
    inf = T.copy()
    inf[0, 0] = np.inf
    rigid = "(must be 1: a reflection is not a rigid transform)"
    return [
        (FrameTask, skewed, "target: rotation part is not orthonormal (max |RᵀR − I| = "
         "0.000936 > 1e-06); not a rigid transform"),
        (FrameTask, reflection, f"target: rotation part has det = -1 {rigid}"),
        (FrameTask, last_row, "target: last row must be [0, 0, 0, 1], got [0.1, 0.0, 0.0, 1.0]"),
        (FrameTask, inf, f"target contains NaN or inf: {inf.tolist()}"),
        (FrameTask, R, "target must be a 4×4 homogeneous matrix or a pinocchio.SE3, got "
         "shape (3, 3)"),
        (OrientationTask, skewed3, "target: rotation part is not orthonormal (max |RᵀR − I| = "
         "3.9e-06 > 1e-06); not a rigid transform"),
        (OrientationTask, -R, f"target: rotation part has det = -1 {rigid}"),
        (FramePositionTask, np.array([0.1, np.nan, 0.2]), "target must be finite (m), got "
         "[0.1 nan 0.2]"),
        (FramePositionTask, np.array([0.1, np.inf, 0.2]), "target must be finite (m), got "
         "[0.1 inf 0.2]"),
        (FramePositionTask, np.zeros(4), "target must be 3 numbers (m), got shape (4,)"),
    ]  # fmt: skip


@pytest.mark.parametrize(("cls", "target", "message"), _exact_cases())
def test_bad_targets_exact_messages(robots, cls, target, message):
    """The messages of the set_target fast paths' fallbacks (float64 arrays, the common case)."""
    robot = robots["panda"]
    with pytest.raises(ValueError) as info:
        cls(robot, "panda_hand_tcp", target)
    assert str(info.value) == message


def test_set_target_keeps_a_copy_and_accepts_the_tolerance(robots):
    robot = robots["panda"]
    R = pin.exp3(np.array([0.1, 0.2, 0.3]))
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, [0.3, 0.1, 0.5]
    task = FrameTask(robot, "panda_hand_tcp", T)
    position = FramePositionTask(robot, "panda_hand_tcp", T[:3, 3].copy())
    orientation = OrientationTask(robot, "panda_hand_tcp", R.copy())
    np.testing.assert_array_equal(task.target.homogeneous, T)
    np.testing.assert_allclose(task._target_inv.homogeneous, np.linalg.inv(T), atol=1e-15)
    p, R2 = position.target, orientation.target
    T[0, 3] = R[0, 0] = 9.0  # the caller's arrays change: the targets do not
    assert task.target.translation[0] == 0.3 and p[0] == 0.3 and R2[0, 0] != 9.0
    near = np.eye(4)
    near[0, 0] = 1.0 + 0.4e-6  # |RᵀR − I| = 0.8e-6 < RIGID_TOLERANCE: accepted as given
    task.set_target(near)
    assert task.target.rotation[0, 0] == near[0, 0]
    near[0, 0] = 1.0 + 3e-6
    with pytest.raises(ValueError, match="orthonormal"):
        task.set_target(near)
    huge = np.array([1e308, 1e308, 0.0])  # the fast path's sum overflows: the full checks
    position.set_target(huge)
    np.testing.assert_array_equal(position.target, huge)
