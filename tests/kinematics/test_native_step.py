"""The native IK step (:mod:`qpcoord.kinematics.native_step`) against the Python tasks and
engines: the rows it writes, its Jacobians, its closed-loop velocities, the hybrid step and
its errors."""

from __future__ import annotations

import warnings

import numpy as np
import pinocchio as pin
import pytest
from support.counting_malloc import native_malloc_counts
from support.native_engine import needs_native
from support.native_ik import (
    DT,
    FRAMES,
    KINDS,
    closed_loop_agrees,
    ee_robot,
    engine_pair,
    ik_robots,
    kind_levels,
    robot_or_skip,
    start_configuration,
    target_pose,
)

import qpcoord as qc
from qpcoord.core import native
from qpcoord.kinematics.frame_tasks import (
    ComTask,
    FramePositionTask,
    FrameTask,
    OrientationTask,
    RelativeFrameTask,
)
from qpcoord.kinematics.native_step import TaskKind, native_kind
from qpcoord.kinematics.paths import Circle
from qpcoord.kinematics.tasks import AccelerationLimits, PositionBand


@pytest.fixture(scope="module")
def robots() -> dict[str, qc.Robot]:
    return ik_robots()


# ---------------------------------------------------------------------------------------
# the rows: native kernels against the tasks' Python _refresh
# ---------------------------------------------------------------------------------------


@needs_native
@pytest.mark.parametrize("name", ["panda", "planar_3r", "talos"])
@pytest.mark.parametrize("kind", KINDS)
def test_native_rows_equal_the_python_refresh(robots, name, kind):
    robot = robot_or_skip(robots, name)
    if kind == "com" and robot.mass <= 0:
        pytest.skip("massless model")
    q = start_configuration(robot)
    ikn, ikp = engine_pair(robot, lambda: kind_levels(robot, kind, q))
    task = ikn._dynamic[0]
    assert native_kind(task) is not None and task in ikn._native.kernel_tasks
    assert ikn._dynamic[1] in ikn._native.kernel_tasks  # the posture too (1-DoF joints)
    assert not ikn._native._hybrid
    for step, t in enumerate((0.0, 0.37)):
        qs = q if step == 0 else robot.integrate(q, 0.1 * np.ones(robot.nv), DT)
        ikn.step(qs, t)
        ikp.refresh(qs, t)
        Pn, Pp = ikn.stack._compiled, ikp.stack._compiled
        Pp.refresh_stacked()
        scale = max(1.0, float(np.abs(Pp.Aeq).max()), float(np.abs(Pp.beq).max()))
        np.testing.assert_allclose(Pn.Aeq, Pp.Aeq, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(Pn.beq, Pp.beq, rtol=0, atol=1e-12 * scale)
        np.testing.assert_array_equal(Pn.lbs, Pp.lbs)
        np.testing.assert_array_equal(Pn.ubs, Pp.ubs)
        for tn, tp in zip(ikn._dynamic, ikp._dynamic, strict=True):  # the tasks' own rows
            np.testing.assert_allclose(tn.task.A, tp.task.A, rtol=0, atol=1e-12 * scale)
            np.testing.assert_allclose(tn.task.b, tp.task.b, rtol=0, atol=1e-12 * scale)


@needs_native
def test_position_task_follows_the_run_reference(robots):
    robot = robots["planar_3r"]
    q = np.array([0.2, 0.9, -0.4])
    ikn, ikp = engine_pair(robot, lambda: [qc.PositionTask(robot, gain=2.0)], limits=None)
    for t in (0.0, 0.4, 1.1):
        vn, _ = ikn.step(q, t, reference=Circle(radius=0.3))
        vp, _ = ikp.step(q, t, reference=Circle(radius=0.3))
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9)
        np.testing.assert_allclose(ikn._dynamic[0].task.b, ikp._dynamic[0].task.b, atol=1e-13)


@needs_native
def test_set_target_and_gain_are_followed(robots):
    robot = robots["panda"]
    q = start_configuration(robot)
    ikn, ikp = engine_pair(robot, lambda: kind_levels(robot, "pose_plain", q))
    for ik in (ikn, ikp):
        ik._dynamic[0].set_target(target_pose(robot, robot.random_configuration(11)))
        ik._dynamic[0].gain = 9.0
        ik._dynamic[1].set_target(robot.random_configuration(12))
    vn, _ = ikn.step(q)
    vp, _ = ikp.step(q)
    np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ikn._dynamic[0].task.b, ikp._dynamic[0].task.b, atol=1e-12)


@needs_native
def test_a_target_rewritten_in_place_is_followed(robots):
    """A control loop's one 4×4 target array rewritten in place and passed to set_target at
    every step (the benchmark's loop): the kernel reads the task's stored copy, whatever the
    caller does to its array afterwards, and the velocities are the Python engine's."""
    robot = robots["panda"]
    q = start_configuration(robot)
    ikn, ikp = engine_pair(robot, lambda: kind_levels(robot, "pose_plain", q))
    T = target_pose(robot, q)
    qn = qp = q
    for k in range(6):
        T[:3, 3] += [0.004, -0.003, 0.002 * k]
        for ik in (ikn, ikp):
            ik._dynamic[0].set_target(T)
        T[:3, 3] = 7.0  # the caller's array moves on: the targets do not
        vn, _ = ikn.step(qn)
        vp, _ = ikp.step(qp)
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9)
        np.testing.assert_allclose(ikn._dynamic[0].task.b, ikp._dynamic[0].task.b, atol=1e-12)
        T[:3, 3] = ikn._dynamic[0].target.translation
        qn = robot.integrate(qn, vn, DT)
        qp = robot.integrate(qp, vp, DT)
    task = ikn._dynamic[0]
    task.target = None  # no target: the task's own message
    with pytest.raises(ValueError, match="no target"):
        ikn.step(qn)
    task.target = pin.SE3(T)  # assigning is set_target
    vn, _ = ikn.step(qn)
    ikp._dynamic[0].set_target(T)
    np.testing.assert_allclose(vn, ikp.step(qn)[0], rtol=0, atol=1e-9)


@needs_native
@pytest.mark.parametrize("name", ["panda", "talos"])
def test_limit_boxes_equal_the_python_refresh(robots, name):
    robot = robot_or_skip(robots, name)
    q = start_configuration(robot).copy()
    limited = _limited_joints(robot)
    q[limited[0]] = robot.upper[limited[0]] + 0.05  # outside a limit: the boxes do not meet
    levels = lambda: [qc.PostureTask(robot, start_configuration(robot))]  # noqa: E731
    limits = lambda: [  # noqa: E731
        qc.JointLimits(robot, gain=0.5),
        qc.VelocityLimits(robot, 0.3 * np.minimum(robot.velocity_limit, 2.0)),
    ]
    ikn = qc.IK(robot, levels(), DT, limits=limits(), engine="native")
    ikp = qc.IK(robot, levels(), DT, limits=limits(), engine="python")
    ikn.step(q)
    ikp.refresh(q)
    Pn = ikn.stack._compiled
    lo, hi = ikp.bounds.lower, ikp.bounds.upper
    np.testing.assert_array_equal(Pn.lbs, lo)
    np.testing.assert_array_equal(Pn.ubs, hi)
    np.testing.assert_array_equal(ikn.bounds.lower, lo)
    assert np.any(lo == hi)  # the speed limit won where the boxes did not meet


def _limited_joints(robot: qc.Robot) -> list[int]:
    """q indices of the robot's limited 1-DoF joints."""
    return [
        int(j.idx_q)
        for j in robot.model.joints[1:]
        if j.nq == 1 and np.isfinite(robot.upper[j.idx_q]) and robot.upper[j.idx_q] < 1e300
    ]


# ---------------------------------------------------------------------------------------
# Jacobians: finite differences of the errors the native kernels compute
# ---------------------------------------------------------------------------------------


def _error_and_jacobian(ik: qc.IK, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(e, J)`` of the IK's first task from a native step (gain 1, no feed-forward)."""
    ik.step(q)
    task = ik._dynamic[0].task
    return -np.array(task.b), np.array(task.A)


@needs_native
@pytest.mark.parametrize("name", ["panda", "planar_3r", "talos"])
@pytest.mark.parametrize(
    "kind", ["position", "frame_position", "pose", "pose_split", "orientation", "com"]
)
def test_native_jacobians_match_finite_differences(robots, name, kind):
    robot = robot_or_skip(robots, name)
    if kind == "com" and robot.mass <= 0:
        pytest.skip("massless model")
    frame = FRAMES[robot.name]
    q = start_configuration(robot)
    T = target_pose(robot, q)
    task = {
        "position": lambda: qc.PositionTask(
            ee_robot(robot), target=ee_robot(robot).position(q), gain=1.0
        ),
        "frame_position": lambda: FramePositionTask(robot, frame, T[:3, 3], gain=1.0),
        "pose": lambda: FrameTask(robot, frame, T, gain=1.0),
        "pose_split": lambda: FrameTask(robot, frame, T, gain=1.0, error="split"),
        "orientation": lambda: OrientationTask(robot, frame, T, gain=1.0),
        "com": lambda: ComTask(robot, robot.com(q) + 0.01, gain=1.0),
    }[kind]()
    ik = qc.IK(robot, [task], DT, limits=None, engine="native")
    _, J = _error_and_jacobian(ik, q)
    rng = np.random.default_rng(4)
    h = 1e-6
    for _ in range(3):
        d = rng.normal(size=robot.nv)
        ep, _ = _error_and_jacobian(ik, robot.integrate(q, d, h))
        em, _ = _error_and_jacobian(ik, robot.integrate(q, d, -h))
        fd = (ep - em) / (2 * h)
        np.testing.assert_allclose(J @ d, fd, rtol=0, atol=1e-6 * max(1.0, np.abs(fd).max()))


def _rotations(
    rng: np.random.Generator, kind: str, count: int, pi_gap: tuple[float, float] = (-6, -2)
) -> list[np.ndarray]:
    out = []
    for _ in range(count):
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        if kind == "random":
            out.append(pin.exp3(rng.uniform(0.0, 3.0) * u))
        elif kind == "small":
            out.append(pin.exp3(10 ** rng.uniform(-9, -2) * u))
        else:  # near pi
            out.append(pin.exp3((np.pi - 10 ** rng.uniform(*pi_gap)) * u))
    return out


@needs_native
def test_native_rigid_check_is_the_python_check():
    """``spatial_rigid_ok`` (FrameTask.set_target's fast path) decides as the scalar Python
    checks on transforms at and around the tolerance (rotation, last row, NaN/inf, overflow,
    Fortran order and strided views)."""
    from qpcoord.kinematics import frame_tasks as ft

    mod = native.load()
    assert ft._native_rigid() is mod.spatial_rigid_ok
    rng = np.random.default_rng(8)
    tol = ft.RIGID_TOLERANCE
    cases = []
    for k in range(3000):
        T = np.eye(4)
        T[:3, :3] = pin.exp3(rng.normal(size=3) * 2)
        T[:3, 3] = rng.normal(size=3)
        where = k % 6
        eps = tol * rng.choice([0.3, 0.9, 0.999, 1.001, 1.1, 3.0])
        if where == 1:
            T[rng.integers(3), rng.integers(3)] += eps * rng.choice([-1, 1])
        elif where == 2:
            T[3, rng.integers(4)] += eps * rng.choice([-1, 1])
        elif where == 3:
            T[:3, :3] *= 1 + eps / 2  # the gram's diagonal moves by ~eps
        elif where == 4:
            T[:3, 0] *= -1  # a reflection
        elif where == 5:
            T[rng.integers(4), rng.integers(4)] = rng.choice([np.nan, np.inf, 1e308])
        cases.append(T)
    cases.append(np.asfortranarray(cases[0]))
    big = np.zeros((8, 8))
    big[::2, ::2] = cases[1]
    cases.append(big[::2, ::2])  # a strided view
    decided = set()
    for T in cases:
        with np.errstate(over="ignore", invalid="ignore"):
            expected = ft._rigid_ok(T)
        assert mod.spatial_rigid_ok(T, tol) == expected, T
        decided.add(expected)
    assert decided == {True, False}
    assert not mod.spatial_rigid_ok(np.eye(3), tol)


@needs_native
def test_native_rigid_copy_checks_then_copies():
    """``spatial_rigid_copy`` (FrameTask.set_target's fast path) decides as
    ``spatial_rigid_ok``; it copies the transform exactly when it accepts it and leaves
    ``out`` untouched otherwise (Fortran order and strided inputs too)."""
    from qpcoord.kinematics import frame_tasks as ft

    mod = native.load()
    assert ft._native_rigid_copy() is mod.spatial_rigid_copy
    rng = np.random.default_rng(9)
    tol = ft.RIGID_TOLERANCE
    big = np.zeros((8, 8))
    decided = set()
    for k in range(400):
        T = np.eye(4)
        T[:3, :3] = pin.exp3(rng.normal(size=3))
        T[:3, 3] = rng.normal(size=3)
        if k % 3 == 1:
            T[rng.integers(3), rng.integers(3)] += tol * rng.choice([0.5, 3.0])
        elif k % 3 == 2:
            T[rng.integers(4), rng.integers(4)] = np.nan
        if k % 4 == 1:
            T = np.asfortranarray(T)
        elif k % 4 == 2:
            big[::2, ::2] = T
            T = big[::2, ::2]
        out = np.full((4, 4), -5.0)
        ok = mod.spatial_rigid_copy(T, tol, out)
        assert ok == mod.spatial_rigid_ok(T, tol)
        np.testing.assert_array_equal(out, T if ok else np.full((4, 4), -5.0))
        decided.add(ok)
    assert decided == {True, False}
    out = np.zeros((4, 4))
    eye = np.eye(4)
    others = [np.eye(3), eye.astype(np.float32), eye.astype(">f8"), np.eye(4)[:3], [[1.0] * 4] * 4]
    for other in others:  # not a native-order float64 4x4: False (set_target's full path)
        assert not mod.spatial_rigid_copy(other, tol, out) and not out.any()
    for bad in (np.zeros((4, 4), order="F"), np.zeros((4, 4), np.float32), np.zeros(16), "x"):
        with pytest.raises(TypeError, match="out must be"):
            mod.spatial_rigid_copy(eye, tol, bad)
    frozen = np.zeros((4, 4))
    frozen.flags.writeable = False
    with pytest.raises(TypeError, match="out must be"):
        mod.spatial_rigid_copy(eye, tol, frozen)


@needs_native
@pytest.mark.parametrize(("kind", "tol"), [("random", 1e-11), ("small", 1e-11), ("pi", 1e-9)])
def test_spatial_logs_match_pinocchio(kind, tol):
    """The kernels against Pinocchio. Pinocchio renormalises R first: the acos near pi and
    the closed forms amplify that rounding to ~1e-12 (near pi ~1e-10). Below 0.05 rad the
    kernels' Jacobians use the series where Pinocchio's closed forms cancel (pin 4.1's Jlog6
    is off by 1e-5 at 1.5e-4 rad, by 3e-8 at 1e-3 rad; the finite-difference test below
    shows the kernels' are right): the Jacobians are compared where both use the series
    (below Pinocchio's switch, eps^(1/4) = 1.2e-4 rad) or both the closed form."""
    mod = native.load()
    rng = np.random.default_rng(5)
    for R in _rotations(rng, kind, 200):
        p = rng.normal(size=3)
        M = pin.SE3(R, p)
        np.testing.assert_allclose(mod.spatial_log3(R), pin.log3(R), rtol=0, atol=tol)
        np.testing.assert_allclose(mod.spatial_log6(R, p), pin.log6(M).vector, rtol=0, atol=tol)
        theta = np.linalg.norm(pin.log3(R))
        if 1e-4 < theta < 0.05:
            continue
        np.testing.assert_allclose(mod.spatial_jlog3(R), pin.Jlog3(R), rtol=0, atol=tol)
        np.testing.assert_allclose(mod.spatial_jlog6(R, p), pin.Jlog6(M), rtol=0, atol=tol)


@needs_native
@pytest.mark.parametrize(("kind", "tol"), [("random", 1e-8), ("small", 1e-8), ("pi", 1e-6)])
def test_spatial_log_jacobians_match_finite_differences(kind, tol):
    """``d log3(R exp(ε ω))/dε = Jlog3 ω`` and ``d log6(M exp6(ε ν))/dε = Jlog6 ν``.

    Near pi the log is ill-conditioned (rounding / (pi − θ)): checked from 1e-2 away."""
    mod = native.load()
    rng = np.random.default_rng(6)
    h = 1e-5
    for R in _rotations(rng, kind, 30, pi_gap=(-2, -1)):
        w = rng.normal(size=3)
        fd = (mod.spatial_log3(R @ pin.exp3(h * w)) - mod.spatial_log3(R @ pin.exp3(-h * w))) / (
            2 * h
        )
        np.testing.assert_allclose(mod.spatial_jlog3(R) @ w, fd, rtol=0, atol=tol)
        p, nu = rng.normal(size=3), rng.normal(size=6)
        M = pin.SE3(R, p)
        Mp, Mm = M * pin.exp6(h * nu), M * pin.exp6(-h * nu)
        fd6 = (
            mod.spatial_log6(Mp.rotation, Mp.translation)
            - mod.spatial_log6(Mm.rotation, Mm.translation)
        ) / (2 * h)
        np.testing.assert_allclose(mod.spatial_jlog6(R, p) @ nu, fd6, rtol=0, atol=tol)


# ---------------------------------------------------------------------------------------
# closed loop: the same velocities as the Python paths
# ---------------------------------------------------------------------------------------


@needs_native
@pytest.mark.parametrize("kind", ["position", "pose_plain", "orientation"])
def test_closed_loop_matches_the_python_engine_with_binding_limits(robots, kind):
    robot = robots["panda"]
    q = 0.5 * (robot.lower + robot.upper)
    q[3] = robot.lower[3] + 0.02  # near a limit
    far = robot.random_configuration(21)

    def levels():
        lv = kind_levels(robot, kind, far)
        lv[0].gain = 20.0  # fast: the speed and position limits bind
        return lv

    ikn, ikp = engine_pair(robot, levels)
    current = qc.IK(robot, levels(), DT, engine="python")  # Python tasks + native solve
    from support.native_info import (
        info_reference,  # tests/: not on the allocation subprocess's path
    )

    binding = 0
    other_path = 0
    for step in range(200):
        vn, sn = ikn.step(q)
        vp, _ = ikp.step(q)
        current.refresh(q)
        sc = current.stack.solve(engine="native")
        vc = sc.x
        assert sn.info.keys() == sc.info.keys()
        nh = ikn._native
        levels = nh.stats.shape[0] - 2
        assert sn.info == info_reference(nh.stats, nh.detail, levels, nh.counters), step
        if kind == "position":
            # the same rows to rounding: the same solver path, but where rounding breaks a
            # tie between rows tight at length zero (a wide freeze's Z comes from the closed
            # form's reflectors: 1 step of 200, 5 against 4 iterations, x equal to 3e-15;
            # checked below at 1e-9 every step); the counters ("stats") follow the path
            path = ("active_set_iterations", "stats")
            same = {k: v for k, v in sn.info.items() if k not in path}
            assert same == {k: v for k, v in sc.info.items() if k not in path}
            if sn.info["active_set_iterations"] != sc.info["active_set_iterations"]:
                other_path += 1
                assert sn.level_residuals == pytest.approx(sc.level_residuals, abs=1e-12)
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9, err_msg=f"step {step}")
        # the same rows but for Jlog6's series below 0.05 rad (Pinocchio's closed form)
        np.testing.assert_allclose(vn, vc, rtol=0, atol=1e-9, err_msg=f"step {step}")
        lo, hi = ikn.bounds.lower, ikn.bounds.upper
        binding += bool(np.any(np.minimum(vn - lo, hi - vn) < 1e-9))
        assert sn.solver == "native" and sn.status == "optimal"
        q = robot.integrate(q, vn, DT)
    assert 10 <= binding, binding
    assert other_path <= 2, other_path


@needs_native
def test_closed_loop_on_the_planar_arm(robots):
    robot = robots["planar_3r"]
    q = np.array([0.3, 0.8, 1.1])
    ikn, ikp = engine_pair(
        robot,
        lambda: [
            qc.PositionTask(robot, target=Circle(radius=0.4), gain=10.0),
            qc.PostureTask(robot, [0.0, 0.5, 1.0]),
        ],
        limits=[qc.VelocityLimits(robot, 1.5)],
    )
    for step in range(200):
        t = step * DT
        vn, _ = ikn.step(q, t)
        vp, _ = ikp.step(q, t)
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9, err_msg=f"step {step}")
        q = robot.integrate(q, vn, DT)


# ---------------------------------------------------------------------------------------
# hybrid steps: tasks without a kernel keep their Python refresh
# ---------------------------------------------------------------------------------------


class Height(qc.KinematicTask):
    """A user task (compute_error / compute_jacobian): keep the hand's height."""

    def __init__(self, robot, frame, z):
        super().__init__(robot, 1, gain=5.0, name="height")
        self.frame, self.z = frame, z

    def compute_error(self, q):
        return self.robot.frame_pose(q, self.frame)[2:3, 3] - self.z

    def compute_jacobian(self, q):
        return self.robot.frame_jacobian(q, self.frame)[2:3]


class HeightFD(Height):
    """The same with a finite-difference Jacobian: it leaves the robot's Pinocchio data at
    another configuration than the step's."""

    def compute_jacobian(self, q):
        h = 1e-6
        J = np.empty((1, self.robot.nv))
        for i in range(self.robot.nv):
            d = np.zeros(self.robot.nv)
            d[i] = h
            up = self.compute_error(self.robot.integrate(q, d, 1.0))
            down = self.compute_error(self.robot.integrate(q, -d, 1.0))
            J[0, i] = (up - down)[0] / (2 * h)
        return J


@needs_native
def test_a_python_task_moving_the_robot_data_does_not_disturb_the_kernels(robots):
    robot = robots["panda"]
    frame = FRAMES["panda"]
    q = robot.random_configuration(2)
    T = target_pose(robot, q)

    def levels():
        return [HeightFD(robot, frame, 0.5), FrameTask(robot, frame, T, gain=3.0)]

    ikn = qc.IK(robot, levels(), DT, engine="native")
    current = qc.IK(robot, levels(), DT, engine="python")  # Python tasks + native solve
    for step in range(20):
        vn, _ = ikn.step(q)
        current.refresh(q)
        vc = current.stack.solve(engine="native").x
        np.testing.assert_allclose(vn, vc, rtol=0, atol=1e-8, err_msg=f"step {step}")
        q = robot.integrate(q, vn, DT)


class HalfSpeed(qc.Limit):
    """A user's limit: half the robot's speed limits (its box is Python's)."""

    def box(self, q, dt):
        v = 0.5 * self.robot.velocity_limit
        return -v, v


@needs_native
def test_hybrid_step_matches_the_python_engine(robots):
    robot = robots["panda"]
    frame = FRAMES["panda"]
    q = robot.random_configuration(2)
    T = target_pose(robot, q)

    def levels():
        return [
            [
                PositionBand(robot, lower=[-np.inf, -np.inf, 0.3], gain=5.0),
                Height(robot, frame, 0.5),
            ],
            [FrameTask(robot, frame, T, gain=3.0, error="split", mask="z rx ry")],
            [RelativeFrameTask(robot, frame, "panda_link4", pin.SE3.Identity(), gain=0.0)],
            [qc.Equality(np.eye(robot.nv)[:2], [0.1, -0.1], name="constant")],
            qc.PostureTask(robot, robot.random_configuration(4)),
        ]

    limits = lambda: [  # noqa: E731
        qc.JointLimits(robot),
        qc.VelocityLimits(robot),
        AccelerationLimits(robot, 30.0),
        HalfSpeed(robot, "half speed"),
    ]
    ikn = qc.IK(robot, levels(), DT, limits=limits(), engine="native")
    ikp = qc.IK(robot, levels(), DT, limits=limits(), engine="python")
    hybrid = ikn._native
    assert hybrid._python_tasks and hybrid._python_limits
    assert [type(t) for t in hybrid.kernel_tasks] == [
        PositionBand,
        FrameTask,
        RelativeFrameTask,
        qc.PostureTask,
    ]
    for step in range(60):
        vn, _ = ikn.step(q)
        vp, _ = ikp.step(q)
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9, err_msg=f"step {step}")
        q = robot.integrate(q, vn, DT)


@needs_native
def test_floating_base_whole_body_is_native_and_matches(robots):
    robot = robot_or_skip(robots, "talos")
    q = start_configuration(robot)
    feet = ["left_sole_link", "right_sole_link"]

    def levels():
        tasks = [FrameTask(robot, s, gain=1.0 / DT) for s in feet]
        for t in tasks:
            t.set_target_from_configuration(q)
        com = ComTask(robot, robot.com(q) + [0.02, 0.0, -0.01], gain=5.0)
        return [tasks, com, qc.PostureTask(robot, q)]

    ikn, ikp = engine_pair(robot, levels)
    assert len(ikn._native.kernel_tasks) == 4 and not ikn._native._hybrid
    closed_loop_agrees(ikn, ikp, q, 30)


# ---------------------------------------------------------------------------------------
# method="weighted": the same kernels, then the native weighted QP, in one call
# ---------------------------------------------------------------------------------------

_WEIGHTED_INFO = ("engine", "iterations", "warm_start_hit", "regularized", "active_rows",
                  "qp_calls", "refactored")  # fmt: skip


@needs_native
@pytest.mark.parametrize("name", ["panda", "planar_3r", "talos"])
@pytest.mark.parametrize("kind", KINDS)
def test_weighted_step_matches_the_python_weighted_path(robots, name, kind):
    """One native call (kernels + weighted QP) against the previous path, Python refresh +
    native weighted QP (x to 1e-9, the same info dict), and the Python engine (daqp, to its
    accuracy), on a closed loop with binding limits on the Panda."""
    robot = robot_or_skip(robots, name)
    if kind == "com" and robot.mass <= 0:
        pytest.skip("massless model")
    q = start_configuration(robot)
    if name == "panda":
        q = 0.5 * (robot.lower + robot.upper)
        q[3] = robot.lower[3] + 0.02  # near a limit

    def levels():
        lv = kind_levels(robot, kind, q)
        if name == "panda":
            lv[0].gain = 20.0  # fast: the speed and position limits bind
        return lv

    ikn, ikp = engine_pair(robot, levels, method="weighted")
    assert ikn._native.weighted and not ikn._native._hybrid
    current = qc.IK(robot, levels(), DT, method="weighted", engine="python")
    binding = 0
    for step in range(60):
        t = step * DT
        vn, sn = ikn.step(q, t)
        vp, sp = ikp.step(q, t)
        current.refresh(q, t)
        sc = current.stack.solve(method="weighted", engine="native")
        assert sn.method == sp.method == "weighted" and sn.solver == "native"
        assert tuple(sn.info) == _WEIGHTED_INFO and sn.info["refactored"]
        assert sn.info == sc.info, step
        # the same QP as the native weighted QP on the Python rows (to rounding: Talos'
        # floating base, held by ε = 1e-9 only, amplifies rounding ~1e9 times); daqp's
        # answer (the Python engine) to its own accuracy
        tol = 1e-6 if name == "talos" else 1e-9
        np.testing.assert_allclose(vn, sc.x, rtol=0, atol=tol, err_msg=f"step {step}")
        np.testing.assert_allclose(
            sn.level_residuals, sc.level_residuals, rtol=1e-9, atol=1e-10, err_msg=str(step)
        )
        if name != "talos":  # Talos' floating base is held by ε = 1e-9 only: ill-conditioned
            np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-6, err_msg=f"step {step}")
        np.testing.assert_allclose(
            sn.level_residuals, sp.level_residuals, rtol=1e-6, atol=1e-9, err_msg=str(step)
        )
        if ikn.limits:
            lo, hi = ikn.bounds.lower, ikn.bounds.upper
            binding += bool(np.any(np.minimum(vn - lo, hi - vn) < 1e-9))
        q = robot.integrate(q, vn, DT)
    if name == "panda":
        assert binding >= 5, binding


@needs_native
def test_weighted_step_integrates_and_refactors_only_on_a_change(robots):
    """A stack whose rows no kernel rewrites (a posture: its A is constant) refactors the
    weighted QP only when a task's matrix or weight changed (``matrix_version``), as
    ``NativeWeighted``; ``step_integrate`` writes ``q_next`` in the same call."""
    robot = robots["panda"]
    q = start_configuration(robot)

    def levels():
        return [qc.PostureTask(robot, robot.random_configuration(9), gain=2.0)]

    ikn, ikp = engine_pair(robot, levels, method="weighted")
    refactored = []
    for step in range(6):
        if step == 3:
            for ik in (ikn, ikp):
                ik._dynamic[0].task.update(weight=np.linspace(1.0, 3.0, robot.nv))
        q_next, vn, sn = ikn.step_integrate(q)
        vp, _ = ikp.step(q)
        refactored.append(sn.info["refactored"])
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9, err_msg=f"step {step}")
        np.testing.assert_allclose(q_next, robot.integrate(q, vn, DT), rtol=0, atol=1e-14)
        q = q_next
    assert refactored == [True, False, False, True, False, False]


@needs_native
def test_weighted_hybrid_step_matches_the_python_engine(robots):
    robot = robots["panda"]
    frame = FRAMES["panda"]
    q = robot.random_configuration(2)
    T = target_pose(robot, q)

    def levels():
        return [
            [PositionBand(robot, lower=[-np.inf, -np.inf, 0.3], gain=5.0)],
            [Height(robot, frame, 0.5), FrameTask(robot, frame, T, gain=3.0, mask="z rx ry")],
            [qc.Equality(np.eye(robot.nv)[:2], [0.1, -0.1], name="constant")],
            qc.PostureTask(robot, robot.random_configuration(4)),
        ]

    limits = lambda: [  # noqa: E731
        qc.JointLimits(robot),
        AccelerationLimits(robot, 30.0),
        HalfSpeed(robot, "half speed"),
    ]
    ikn = qc.IK(robot, levels(), DT, limits=limits(), method="weighted")
    ikp = qc.IK(robot, levels(), DT, limits=limits(), method="weighted", engine="python")
    ikc = qc.IK(robot, levels(), DT, limits=limits(), method="weighted", engine="python")
    assert ikn._native.weighted and ikn._native._python_tasks and ikn._native._python_limits
    for step in range(40):
        vn, sn = ikn.step(q)
        vp, sp = ikp.step(q)
        ikc.refresh(q)
        sc = ikc.stack.solve(method="weighted", engine="native")  # Python rows, native QP
        for ik in (ikp, ikc):  # the acceleration limit's previous velocity: the native step's
            ik.reset(vn)
        assert sn.info == sc.info, step
        np.testing.assert_allclose(vn, sc.x, rtol=0, atol=1e-9, err_msg=f"step {step}")
        # the warm start gives the cold solve's optimum (step 16 once kept a bound whose
        # multiplier, ~1e-9 at the level weighted 1e-9, was negative)
        cold, _, _ = ikc.stack._native_weighted.solve(ikc.stack._compiled, warm=False)
        np.testing.assert_allclose(vn, cold, rtol=0, atol=1e-9, err_msg=f"step {step}")
        # four levels 1e-3 apart (the last weighted 1e-9): the Python engine's QP is in the
        # whitened variables u = T z of the weighted rows' QR, as the native one, so x and
        # the level values agree to 1e-9 (with the formed H, cond ~1e12: x
        # differed by up to 1e-3 on 6 of 40 steps, level 1 by 1.3e-4 relative)
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9, err_msg=f"step {step}")
        np.testing.assert_allclose(
            sn.level_residuals, sp.level_residuals, rtol=1e-9, atol=1e-11, err_msg=str(step)
        )
        q = robot.integrate(q, vn, DT)


@needs_native
def test_weighted_step_errors_are_those_of_the_stack(robots):
    robot = robots["panda"]
    q = start_configuration(robot)
    bad = [qc.Equality(np.ones((2, robot.nv)), [0.0, 1.0], name="clash")]
    msg = "hard equality constraints are inconsistent"
    for engine in ("native", None):
        ik = qc.IK(robot, [qc.PostureTask(robot, q)], DT, constraints=bad, method="weighted",
                   engine=engine)  # fmt: skip
        assert ik._native is not None
        with pytest.raises(qc.InfeasibleError, match=msg):
            ik.step(q)
    ik = qc.IK(robot, [FrameTask(robot, FRAMES["panda"])], DT, method="weighted")
    with pytest.raises(ValueError, match="no target"):
        ik.step(q)
    with pytest.raises(ValueError, match=r"q"):
        ik.step(q[:3])


# ---------------------------------------------------------------------------------------
# errors, engine choice, warm start
# ---------------------------------------------------------------------------------------


@needs_native
def test_bad_configurations_are_named(robots):
    robot = robots["panda"]
    ik = qc.IK(
        robot, kind_levels(robot, "pose_plain", start_configuration(robot)), DT, engine="native"
    )
    q = start_configuration(robot)
    bad = q.copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match=r"q\[3\] is nan"):
        ik.step(bad)
    with pytest.raises(ValueError, match="q must have 7 entries"):
        ik.step(q[:5])
    with pytest.raises(ValueError, match="q must be numeric"):
        ik.step(["a"] * 7)
    v, _ = ik.step(list(q))  # converted
    np.testing.assert_allclose(v, ik.step(q)[0], atol=1e-12)
    np.testing.assert_allclose(ik.step(q.astype(">f8"))[0], ik.step(q)[0], atol=1e-12)
    wide = np.zeros(2 * q.size)
    wide[::2] = q
    np.testing.assert_allclose(ik.step(wide[::2])[0], ik.step(q)[0], atol=1e-12)  # strided
    # the native call reads q through the buffer protocol: anything but nq float64 values
    # in native byte order is IK_BAD_Q (the Python side converts or names it first)
    call, mod = ik._native._solver.step, native.load()
    for other in (q.astype(np.float32), q.astype(">f8"), list(q), q[:5], np.stack([q, q]), 1.0):
        assert call(other, True, 10.0) == mod.IK_BAD_Q
    assert call(wide[::2], True, 10.0) == 0


@needs_native
def test_non_unit_quaternion_is_named(robots):
    robot = robot_or_skip(robots, "talos")
    q = start_configuration(robot).copy()
    ik = qc.IK(robot, [ComTask(robot, robot.com(q), gain=1.0)], DT, engine="native")
    q[3:7] *= 1.01
    with pytest.raises(ValueError, match=r"q\[3:7\] is the quaternion"):
        ik.step(q)


@needs_native
def test_missing_target_raises_the_tasks_message(robots):
    robot = robots["panda"]
    ik = qc.IK(robot, [FrameTask(robot, FRAMES["panda"])], DT, engine="native")
    with pytest.raises(ValueError, match="no target"):
        ik.step(start_configuration(robot))


@needs_native
def test_engine_choice(robots):
    robot = robots["panda"]
    levels = lambda: [qc.PostureTask(robot, start_configuration(robot))]  # noqa: E731
    assert qc.IK(robot, levels(), DT).engine == "native"  # the default where built
    assert qc.IK(robot, levels(), DT, engine="python").engine == "python"
    weighted = qc.IK(robot, levels(), DT, method="weighted")
    assert weighted.engine == "native" and weighted._native.weighted  # one native call
    assert qc.IK(robot, levels(), DT, method="weighted", engine="python")._native is None
    with pytest.raises(ValueError, match="method='nullspace' is not supported by the native"):
        qc.IK(robot, levels(), DT, method="nullspace", limits=None, engine="native")
    with pytest.raises(ValueError, match="solver='quadprog' is not supported"):
        qc.IK(robot, levels(), DT, method="weighted", solver="quadprog", engine="native")
    with pytest.raises(ValueError, match="solver='quadprog' is not supported"):
        qc.IK(robot, levels(), DT, solver="quadprog", engine="native")
    with pytest.raises(ValueError, match="unknown engine"):
        qc.IK(robot, levels(), DT, engine="fast")


@needs_native
def test_warm_start_reset_and_v_prev(robots):
    robot = robots["panda"]
    q = start_configuration(robot)
    ik = qc.IK(robot, kind_levels(robot, "position", q), DT, engine="native")
    v1, s1 = ik.step(q)
    np.testing.assert_array_equal(ik.v_prev, v1)
    assert ik.last is s1
    v2, _ = ik.step(q, warm_start=s1)
    np.testing.assert_allclose(v1, v2, atol=1e-12)
    with pytest.raises(ValueError, match="warm_start"):
        ik.step(q, warm_start=np.ones(3))
    ik.reset()
    assert ik.last is None and not ik.v_prev.any()
    np.testing.assert_allclose(ik.step(q)[0], v1, atol=1e-12)


def test_without_the_extension_the_python_path_warns_once(robots, missing_extension):
    robot = robots["panda"]
    q = start_configuration(robot)
    with pytest.warns(RuntimeWarning, match="native engine is not built") as rec:
        ik = qc.IK(robot, kind_levels(robot, "position", q), DT)
        v, sol = ik.step(q)
    assert len(rec) == 1
    assert ik.engine == "python" and sol.solver != "native"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ref = qc.IK(robot, kind_levels(robot, "position", q), DT, engine="python")
        np.testing.assert_allclose(v, ref.step(q)[0], atol=1e-12)
    with pytest.raises(native.NativeUnavailableError):
        qc.IK(robot, kind_levels(robot, "position", q), DT, engine="native")


@needs_native
def test_posture_over_a_continuous_joint_is_native_and_matches():
    model = pin.Model()
    parent = 0
    for i, joint in enumerate(
        [pin.JointModelRZ(), pin.JointModelRUBZ(), pin.JointModelRY(), pin.JointModelRZ()]
    ):
        placement = pin.SE3(np.eye(3), np.array([0.0 if i == 0 else 0.4, 0.0, 0.0]))
        parent = model.addJoint(parent, joint, placement, f"j{i}")
        model.appendBodyToJoint(parent, pin.Inertia.Random(), pin.SE3.Identity())
    model.addFrame(
        pin.Frame("tip", parent, 0, pin.SE3(np.eye(3), np.array([0.4, 0, 0])), pin.OP_FRAME)
    )
    robot = qc.Robot(model, "tip")
    q = robot.random_configuration(1)

    def levels():
        return [qc.PositionTask(robot, robot.position(q) + 0.05), qc.PostureTask(robot, q)]

    ikn, ikp = engine_pair(robot, levels, limits=[qc.VelocityLimits(robot, 1.0)])
    assert not ikn._native._hybrid  # the continuous joint's row: an atan2 natively
    assert native_kind(ikn._dynamic[1]) == TaskKind.POSTURE
    closed_loop_agrees(ikn, ikp, q, 30)


@needs_native
def test_hard_constraint_rows_are_native_and_match(robots):
    robot = robots["panda"]
    q = start_configuration(robot)
    frame = FRAMES["panda"]

    def build(engine):
        hold = FramePositionTask(robot, frame, robot.frame_pose(q, frame)[:3, 3], gain=10.0)
        pose = OrientationTask(robot, frame, target_pose(robot, q), gain=5.0)
        return qc.IK(robot, [pose, qc.PostureTask(robot, q)], DT, constraints=[hold], engine=engine)

    ikn, ikp = build("native"), build("python")
    assert len(ikn._native.kernel_tasks) == 3 and not ikn._native._hybrid
    for step in range(20):
        vn, _ = ikn.step(q)
        vp, _ = ikp.step(q)
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9, err_msg=f"step {step}")
        q = robot.integrate(q, vn, DT)


@needs_native
def test_a_path_of_the_wrong_dimension_raises_the_tasks_message(robots):
    robot = robots["panda"]
    task = qc.PositionTask(robot, gain=1.0)  # no target: the run's reference is used
    ik = qc.IK(robot, [task], DT, engine="native")
    with pytest.raises(ValueError, match="reference path is 2-D"):
        ik.step(start_configuration(robot), reference=Circle())
    with pytest.raises(ValueError, match="no target"):
        ik.step(start_configuration(robot))


_ALLOCATION_RUN = r"""
import numpy as np, pinocchio as pin, qpcoord as qc
from support.malloc_counts import print_step_mallocs
from support.native_ik import kind_levels, start_configuration, DT
robot = qc.robots.load("panda")
for kind, method in [(k, m) for m in ("hierarchical", "weighted")
                     for k in ("position", "frame_position", "pose", "orientation", "com")]:
    q = start_configuration(robot)
    ik = qc.IK(robot, kind_levels(robot, kind, q), DT, method=method, engine="native")
    assert ik._native.weighted == (method == "weighted")
    pin.computeJointJacobians(robot.model, robot.data, q)
    pin.jacobianCenterOfMass(robot.model, robot.data, False)
    assert ik._native.integrates  # the native call also writes q_next (integrate=True)
    print_step_mallocs(kind + "-" + method, ik, q)
# the acceleration limits' box (braking rows), the damping kernels (a task's, a band's and
# a posture's lm_damping rows), a relative frame, a joint coupling and the damping tasks
q = start_configuration(robot)
ee = robot.with_frame("panda_hand_tcp")
T = robot.frame_pose(q, "panda_hand_tcp")
stacks = {
    "acceleration": (kind_levels(robot, "pose", q), [
        qc.JointLimits(robot), qc.VelocityLimits(robot), qc.AccelerationLimits(robot, 50.0)]),
    "lm_damping": ([[qc.FrameTask(robot, "panda_hand_tcp", T, lm_damping=1.0),
                     qc.PositionBand(ee, lower=ee.position(q) + 0.1, lm_damping=2.0)],
                    [qc.PostureTask(robot, robot.random_configuration(4), lm_damping=0.5)]],
                   "robot"),
    "relative_coupling": ([qc.RelativeFrameTask(robot, "panda_hand_tcp", "panda_link3",
                                                np.eye(4), lm_damping=0.5),
                           qc.JointCouplingTask(robot, ["panda_joint1", "panda_joint3"],
                                                [1.0, -0.5], offset=0.2)], "robot"),
    "damping": ([qc.FramePositionTask(robot, "panda_hand_tcp", T[:3, 3]),
                 qc.DampingTask(robot, weight=0.1),
                 qc.LowAccelerationTask(robot, weight=0.1)], "robot"),
}
for name, (levels, limits) in stacks.items():
    ik = qc.IK(robot, levels, DT, limits=limits, engine="native")
    assert not ik._native._hybrid and not ik._native._python_limits
    print_step_mallocs(name, ik, q)
"""


@pytest.mark.engine_independent
@needs_native
@pytest.mark.parametrize("build", native.built_variants() if native.available() else ())
def test_the_native_call_does_not_allocate(tmp_path, build):
    """The per-step native call (kernels, box, hierarchy or weighted QP, q_next) on the Panda
    makes no heap allocation after its first calls: malloc is counted by a preloaded shim
    (glibc). Each build of the extension (baseline, x86-64-v3), chosen by
    QPCOORD_NATIVE_ISA."""
    counts = native_malloc_counts(tmp_path, _ALLOCATION_RUN, build)
    assert len(counts) == 14
    assert all(c == 0 for c in counts.values()), counts


@needs_native
@pytest.mark.parametrize("method", ["hierarchical", "weighted"])
def test_an_ik_with_the_native_step_pickles(robots, method):
    import pickle

    robot = robots["panda"]
    q = start_configuration(robot)
    ik = qc.IK(robot, kind_levels(robot, "pose_plain", q), DT, method=method, engine="native")
    v, _ = ik.step(q)
    copy = pickle.loads(pickle.dumps(ik))
    assert copy.engine == "native" and copy._native is not None
    assert copy._native.weighted == (method == "weighted")
    np.testing.assert_allclose(copy.step(q)[0], v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ik.step(q)[0], v, rtol=0, atol=1e-12)  # the original still runs
