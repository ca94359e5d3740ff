"""The native IK step's acceleration-limit box, Levenberg–Marquardt damping, relative-frame
and joint-coupling kernels (``src/native/braking.hpp``, ``ik_step/kernels.hxx``) against the
Python task classes, the oracle: the same box and rows on random configurations (a floating
base included) and the same velocities over closed loops."""

from __future__ import annotations

from functools import partial
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
from support.counting_malloc import native_malloc_counts
from support.kernel_tasks import DT, HAND, posture_levels, posture_robot, talos_kernel_stack
from support.kernel_tasks import acceleration as _acceleration
from support.kernel_tasks import braking_limits as _limits
from support.kernel_tasks import coupling_task as _coupling
from support.kernel_tasks import hand_task as _hand
from support.kernel_tasks import on_feet as _on_feet
from support.kernel_tasks import relative_task as _relative
from support.kernel_tasks import start as _start
from support.native_engine import needs_native
from support.native_ik import closed_loop_agrees, engine_pair, manifold_robot
from support.talos_balance import CORNERS, SOLES

import qpcoord as qc
from qpcoord.core import native
from qpcoord.kinematics.frame_tasks import (
    ComBand,
    ComTask,
    FramePositionTask,
    FrameTask,
    OrientationTask,
    SupportPolygon,
)
from qpcoord.kinematics.native_step import TaskKind, native_kind
from qpcoord.kinematics.tasks import LM_ERROR_FLOOR, LMDamping

EPS = np.finfo(float).eps


@pytest.fixture(scope="module")
def robots() -> dict[str, qc.Robot]:
    out = {"panda": qc.robots.load("panda")}
    try:
        out["talos"] = qc.robots.load("talos")
    except ValueError:  # example-robot-data missing
        pass
    return out


def _robot(robots: dict[str, qc.Robot], name: str) -> qc.Robot:
    if name not in robots:
        pytest.skip(f"{name} not available")
    return robots[name]


def _q_index(lim: qc.JointLimits) -> np.ndarray:
    """The q index of each joint a JointLimits limits."""
    return lim.joints if lim.q_index is None else lim.q_index


def _near_limits(robot: qc.Robot, rng: np.random.Generator) -> np.ndarray:
    """A random configuration with every limited 1-DoF joint within 0.05 rad of one of its
    limits, some up to 0.01 rad outside it (the braking rows, and the box's rule where
    they cannot hold)."""
    q = robot.random_configuration(rng)
    qi = _q_index(qc.JointLimits(robot))
    lo, hi = robot.lower[qi], robot.upper[qi]
    at = np.where(rng.random(qi.size) < 0.5, lo, hi)
    inward = np.sign((lo + hi) / 2 - at)
    q[qi] = at + inward * rng.uniform(-0.01, 0.05, qi.size)
    return q


def _finite(x: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(x), np.abs(x), 0.0)


def _refresh_pair(robot: qc.Robot, tn, tp, stack) -> tuple[qc.IK, qc.IK]:
    """IKs without limits of ``stack(tn)`` on the native step and of ``stack(tp)`` on the
    Python engine, every task of the native one on a kernel."""
    ikn = qc.IK(robot, stack(tn), DT, limits=None, engine="native")
    ikp = qc.IK(robot, stack(tp), DT, limits=None, engine="python")
    assert not ikn._native._hybrid
    return ikn, ikp


def _closed_loops_agree(robot: qc.Robot, levels, q0: np.ndarray, steps: int, **tol) -> None:
    """The stack ``levels()`` on both engines, every task of the native one on a kernel,
    stepped alike (:func:`support.native_ik.closed_loop_agrees`)."""
    ikn, ikp = engine_pair(robot, levels, DT)
    assert not ikn._native._hybrid
    closed_loop_agrees(ikn, ikp, q0, steps, **tol)


# ---------------------------------------------------------------------------------------
# the acceleration limits' box
# ---------------------------------------------------------------------------------------


@needs_native
@pytest.mark.parametrize("name", ["panda", "talos"])
@pytest.mark.parametrize(
    ("gain", "a", "brake"), [(0.5, 50.0, True), (1.0, 8.0, True), (0.7, 30.0, False)]
)
def test_the_acceleration_box_equals_the_python_limits(robots, name, gain, a, brake):
    robot = _robot(robots, name)
    limn, limp = _limits(robot, gain, a, brake), _limits(robot, gain, a, brake)
    ikn = qc.IK(robot, [qc.PostureTask(robot, _start(robot))], DT, limits=limn, engine="native")
    ikp = qc.IK(robot, [qc.PostureTask(robot, _start(robot))], DT, limits=limp, engine="python")
    assert not ikn._native._python_limits and not ikn._native._hybrid
    rng = np.random.default_rng(7)
    vmax = limp[1].limit
    jl = limp[0]
    for trial in range(25):
        q = _near_limits(robot, rng)
        v_prev = rng.uniform(-1.0, 1.0, robot.nv) * np.where(np.isfinite(vmax), vmax, 1.0)
        limn[2].reset(v_prev)
        limp[2].reset(v_prev)
        ikn.step(q)
        ikp.refresh(q)
        # each finite entry is a few roundings (a square root and a quotient in the braking
        # speed) of terms no larger than |v_prev| + a dt + v_max + (K/dt)(|q| + |limits|):
        # 64 eps of that scale bounds the difference of two evaluations
        qi = _q_index(jl)
        far = np.zeros(robot.nv)
        far[jl.joints] = (gain / DT) * (
            np.abs(q[qi]) + _finite(jl.lower[qi]) + _finite(jl.upper[qi])
        )
        scale = np.abs(v_prev) + _finite(limp[2].limit) * DT + _finite(vmax) + far
        for mine, ref in (
            (ikn.bounds.lower, ikp.bounds.lower),
            (ikn.bounds.upper, ikp.bounds.upper),
        ):
            f = np.isfinite(ref)
            assert np.array_equal(mine[~f], ref[~f]), trial
            err = np.abs(mine[f] - ref[f])
            assert np.all(err <= 64 * EPS * scale[f]), (trial, err.max())


@needs_native
def test_an_assigned_acceleration_or_position_limit_reaches_the_native_box(robots):
    robot = robots["panda"]
    limn, limp = _limits(robot, 0.5, 50.0), _limits(robot, 0.5, 50.0)
    ikn = qc.IK(robot, [qc.PostureTask(robot, _start(robot))], DT, limits=limn, engine="native")
    ikp = qc.IK(robot, [qc.PostureTask(robot, _start(robot))], DT, limits=limp, engine="python")
    q = _near_limits(robot, np.random.default_rng(2))
    for lims in (limn, limp):
        lims[2].limit = np.full(robot.nv, 5.0)  # a_max
        lims[0].gain = 0.9  # the braked limits' gain
        lims[0].upper = robot.upper - 0.02
        lims[2].v_prev = np.full(robot.nv, 0.3)  # copied into the bound array
    ikn.step(q)
    ikp.refresh(q)
    scale = 1e3 * (np.abs(q).max() + np.abs(robot.upper).max())  # (K/dt)(|q| + |limit|)
    np.testing.assert_allclose(ikn.bounds.lower, ikp.bounds.lower, rtol=0, atol=64 * EPS * scale)
    np.testing.assert_allclose(ikn.bounds.upper, ikp.bounds.upper, rtol=0, atol=64 * EPS * scale)
    with pytest.raises(ValueError, match="v_prev"):
        limn[2].v_prev = np.zeros(robot.nv + 1)


def _limit_run(robot: qc.Robot, levels, limits, engine: str) -> qc.IK:
    return qc.IK(robot, levels(), DT, limits=limits(), engine=engine)


@needs_native
@pytest.mark.parametrize("name", ["panda", "talos"])
def test_a_joint_driven_into_its_limit_brakes_alike_on_both_engines(robots, name):
    """The hand pulled far past the reach of a limited joint, with acceleration limits: the
    native step and the Python engine give the same v at every step, and the joint stops
    at its limit within the acceleration bound."""
    robot = _robot(robots, name)
    q0 = _start(robot)
    a = 40.0

    def levels():
        hand = _hand(robot, q0, [0.6, -0.4, 0.3], gain=0.5 / DT)
        return _on_feet(robot, q0, [[hand], [qc.PostureTask(robot, q0, gain=1.0)]])

    ikn = _limit_run(robot, levels, lambda: _limits(robot, 0.5, a), "native")
    ikp = _limit_run(robot, levels, lambda: _limits(robot, 0.5, a), "python")
    assert not ikn._native._python_limits
    q, v_last = q0.copy(), np.zeros(robot.nv)
    acc = _acceleration(robot, a)
    for step in range(600):
        vn, _ = ikn.step(q)
        vp, _ = ikp.step(q)
        # the same QP (rows and box to rounding) solved by two engines, each to its KKT
        # tolerance 1e-9 relative to the problem's scale: velocities ≤ the speed limits
        # (~2-6 rad/s)
        tol = 1e-9 * max(1.0, float(np.abs(vp).max()))
        np.testing.assert_allclose(vn, vp, rtol=0, atol=tol, err_msg=f"step {step}")
        # the acceleration bound holds (a dt per step), to the solver's tolerance
        assert np.all(np.abs(vn - v_last) <= acc * DT + tol), step
        v_last = vn
        ikp.limits[2].reset(vn)  # both engines brake from the same previous velocity
        q = robot.integrate(q, vn, DT)
    jl = ikn.limits[0]
    qi = _q_index(jl)
    assert np.all(q[qi] <= jl.upper[qi] + 1e-9) and np.all(q[qi] >= jl.lower[qi] - 1e-9)


# ---------------------------------------------------------------------------------------
# Levenberg–Marquardt damping rows
# ---------------------------------------------------------------------------------------


def _damped(robot: qc.Robot, kind: str, q: np.ndarray, lm: float) -> qc.KinematicTask:
    """A task of ``kind`` with ``lm_damping=lm``, its target or faces away from ``q``."""
    frame = HAND[robot.name]
    T = robot.frame_pose(q, frame).copy()
    T[:3, 3] += [0.05, -0.04, 0.03]
    T[:3, :3] = T[:3, :3] @ pin.exp3(np.array([0.12, -0.08, 0.36]))
    if kind == "position":
        ee = robot.with_frame(frame)
        return qc.PositionTask(ee, target=T[:3, 3], gain=7.0, weight=2.0, lm_damping=lm)
    if kind == "frame_position":
        return FramePositionTask(robot, frame, T[:3, 3], gain=3.0, mask="x z", lm_damping=lm)
    if kind == "pose":
        return FrameTask(robot, frame, T, gain=2.0, position_weight=2.0, lm_damping=lm)
    if kind == "pose_split":
        return FrameTask(robot, frame, T, gain=2.5, error="split", mask="x z rx ry", lm_damping=lm)
    if kind == "orientation":
        return OrientationTask(robot, frame, T[:3, :3], gain=1.5, weight=3.0, lm_damping=lm)
    if kind == "com":
        c = robot.com(q) + [0.01, -0.02, 0.005]
        return ComTask(robot, c, gain=2.0, mask="xy", weight=4.0, lm_damping=lm)
    if kind == "posture":
        return qc.PostureTask(robot, robot.random_configuration(5), gain=1.5, lm_damping=lm)
    if kind == "position_band":
        ee = robot.with_frame(frame)
        y = ee.position(q)
        return qc.PositionBand(ee, lower=y + [0.02, -1.0, -np.inf], gain=5.0, lm_damping=lm)
    if kind == "com_band":
        c = robot.com(q)
        return ComBand(robot, c + [0.01, -0.5, -np.inf], c + [0.2, -0.005, 0.01], lm_damping=lm)
    if kind == "support_polygon":
        return SupportPolygon(
            robot, list(SOLES), margin=0.02, gain=40.0, contact_points=CORNERS, lm_damping=lm
        )
    raise AssertionError(kind)


LM_KINDS = [
    "position", "frame_position", "pose", "pose_split", "orientation", "com", "posture",
    "position_band", "com_band",
]  # fmt: skip
LM_CASES = [("panda", k) for k in LM_KINDS] + [("talos", k) for k in [*LM_KINDS, "support_polygon"]]


@needs_native
@pytest.mark.parametrize(("name", "kind"), LM_CASES)
def test_native_damping_rows_equal_the_python_refresh(robots, name, kind):
    robot = _robot(robots, name)
    q0 = _start(robot)
    lm = 0.7
    tn, tp = _damped(robot, kind, q0, lm), _damped(robot, kind, q0, lm)
    posture = qc.PostureTask(robot, q0, gain=1.0)
    ikn, ikp = _refresh_pair(robot, tn, tp, lambda t: [[t], [posture]])
    assert native_kind(tn.lm_rows) == TaskKind.LM_DAMPING and isinstance(tn.lm_rows, LMDamping)
    rng = np.random.default_rng(11)
    seen = 0
    for trial in range(6):
        q = robot.integrate(q0, rng.normal(scale=0.15, size=robot.nv), 1.0)
        ikn.step(q)
        ikp.refresh(q)
        a, b = tn.lm_rows.task, tp.lm_rows.task
        # A = sqrt(mu) I with mu = lm * |e|_w^2: two evaluations of e (native kinematics and
        # Pinocchio's) differ by a few eps of the quantities e is made of (positions of at
        # most a few m, angles of at most pi: scale 10), so sqrt(mu) differs by at most
        # sqrt(lm * sum(w)) times that
        w = tp.task.weight
        tol = np.sqrt(lm * w.sum()) * 64 * EPS * 10.0
        np.testing.assert_allclose(a.A, b.A, rtol=0, atol=tol, err_msg=f"trial {trial}")
        assert not a.b.any() and not b.b.any()
        assert tn.lm_rows.mu == pytest.approx(tp.lm_rows.mu, rel=1e-6, abs=tol**2)
        seen += tp.lm_rows.mu > 0
    assert seen >= 3  # the rows were not all zero (below the floor)


@needs_native
@pytest.mark.parametrize(("offset", "zero"), [(0.1 * LM_ERROR_FLOOR, True), (0.01, False)])
def test_native_damping_rows_are_zero_below_the_error_floor(robots, offset, zero):
    robot = robots["panda"]
    q = _start(robot)
    task = _hand(robot, q, [offset, 0.0, 0.0], gain=1.0, lm=2.0)
    ik = qc.IK(robot, [[task], [qc.PostureTask(robot, q)]], DT, engine="native")
    assert native_kind(task.lm_rows) == TaskKind.LM_DAMPING
    ik.step(q)
    A = task.lm_rows.task.A
    if zero:
        assert not A.any()  # exactly zero, not tiny
    else:  # sqrt(2) * 0.01 on the diagonal, to the rounding of a ~1 m position
        np.testing.assert_allclose(np.diag(A), np.sqrt(2.0) * offset, rtol=0, atol=1e-12)


@needs_native
def test_an_assigned_lm_damping_reaches_the_native_rows(robots):
    robot = robots["panda"]
    q = _start(robot)
    task = _damped(robot, "pose", q, 1.0)
    ik = qc.IK(robot, [[task], [qc.PostureTask(robot, q)]], DT, engine="native")
    ik.step(q)
    mu = task.lm_rows.mu
    task.lm_damping = 4.0
    ik.step(q)
    assert task.lm_rows.mu == pytest.approx(4.0 * mu, rel=1e-9)


@needs_native
def test_a_python_task_keeps_its_damping_rows_in_python(robots):
    robot = robots["panda"]
    q = _start(robot)
    task = qc.PotentialTask(robot, lambda q: q - _start(robot), lm_damping=1.0)
    ik = qc.IK(robot, [[task], [qc.PostureTask(robot, q)]], DT, engine="native")
    assert native_kind(task) is None and native_kind(task.lm_rows) is None
    assert task.lm_rows in ik._native._python_tasks
    ik.step(q + 0.1)
    assert task.lm_rows.mu > 0


@needs_native
@pytest.mark.parametrize("name", ["panda", "talos"])
def test_an_unreachable_damped_target_runs_alike_on_both_engines(robots, name):
    """A hand target out of reach with lm_damping, a damped band and a damped posture: the
    same v from the native step and the Python engine at every step of a closed loop."""
    robot = _robot(robots, name)
    q0 = _start(robot)

    def levels():
        hand = _hand(robot, q0, [2.5, 0.0, 0.5], gain=0.2 / DT, lm=1.0)
        band = _damped(robot, "position_band", q0, 2.0)
        low = qc.PostureTask(robot, q0, gain=1.0, lm_damping=0.5)
        return _on_feet(robot, q0, [[band, hand], [low]])

    # the damping makes the last levels' rows near-dependent on the unreachable task's
    # (mu ~ 1 against rows of size ~1): the engines' answers agree to 1e-9 of the scale
    # times that level's conditioning, below 1e3 here
    _closed_loops_agree(robot, levels, q0, 400, rel_tol=1e-6)


# ---------------------------------------------------------------------------------------
# relative frames and joint couplings
# ---------------------------------------------------------------------------------------


@needs_native
@pytest.mark.parametrize("name", ["panda", "talos"])
@pytest.mark.parametrize("kind", ["relative", "relative_masked", "coupling"])
def test_native_relative_and_coupling_rows_equal_the_python_refresh(robots, name, kind):
    robot = _robot(robots, name)
    q0 = _start(robot)

    def make():
        if kind == "coupling":
            return _coupling(robot)
        return _relative(robot, q0, "x z ry rz" if kind == "relative_masked" else None)

    tn, tp = make(), make()
    expected = TaskKind.JOINT_COUPLING if kind == "coupling" else TaskKind.RELATIVE_FRAME
    assert native_kind(tn) == expected
    posture = qc.PostureTask(robot, q0, gain=1.0)
    ikn, ikp = _refresh_pair(robot, tn, tp, lambda t: [[t], [posture]])
    rng = np.random.default_rng(5)
    for trial in range(6):
        q = robot.integrate(q0, rng.normal(scale=0.3, size=robot.nv), 1.0)
        version = tn.task.matrix_version
        ikn.step(q)
        assert tn.task.matrix_version == version + 1
        ikp.refresh(q)
        # the rows are products of a few 3×3 and 6×6 factors (rotations, the log's
        # Jacobian at angles well above its series threshold) with entries no larger than
        # the rows' scale: the two evaluations differ by a few hundred eps of that scale
        scale = max(1.0, float(np.abs(tp.task.A).max()), float(np.abs(tp.task.b).max()))
        tol = 1e3 * EPS * scale
        np.testing.assert_allclose(tn.task.A, tp.task.A, rtol=0, atol=tol, err_msg=f"{trial}")
        np.testing.assert_allclose(tn.task.b, tp.task.b, rtol=0, atol=tol, err_msg=f"{trial}")


@needs_native
@pytest.mark.parametrize("name", ["panda", "talos"])
def test_relative_and_coupling_closed_loop_matches_the_python_engine(robots, name):
    """A relative frame and a joint coupling (both damped) below a hand task: the same v
    from the native step and the Python engine at every step."""
    robot = _robot(robots, name)
    q0 = _start(robot)

    def levels():
        hand = _hand(robot, q0, [0.05, 0.05, -0.05], gain=0.2 / DT)
        rel = _relative(robot, q0, "x y z", lm=0.5)
        low = [_coupling(robot, lm=0.3), rel, qc.PostureTask(robot, q0, gain=1.0)]
        return _on_feet(robot, q0, [[hand], low])

    _closed_loops_agree(robot, levels, q0, 300)


@needs_native
def test_an_assigned_offset_or_relative_target_reaches_the_native_rows(robots):
    robot = robots["panda"]
    q = _start(robot)
    coupling, rel = _coupling(robot), _relative(robot, q, None)
    ik = qc.IK(robot, [[coupling, rel], [qc.PostureTask(robot, q)]], DT, engine="native")
    coupling.set_offset_from_configuration(q)
    rel.set_target_from_configuration(q)
    ik.step(q)
    # both met at q: e is rounding of sums of ~1 rad and of a ~1 m pose
    assert abs(coupling.task.b[0]) < 1e3 * EPS * coupling.gain
    assert np.abs(rel.task.b).max() < 1e3 * EPS * rel.gain
    coupling.offset = 0.5
    ik.step(q)
    expected = -coupling.gain * (coupling.ratios @ q[coupling._iq] - 0.5)
    assert coupling.task.b[0] == pytest.approx(expected, rel=1e-12)


# ---------------------------------------------------------------------------------------
# bad data: the tasks' own messages
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), "0.3", True])
def test_a_bad_offset_assigned_is_named_and_kept_out(robots, bad):
    """The constructor's check, at the assignment: the old offset stays."""
    coupling = _coupling(robots["panda"])
    with pytest.raises(ValueError, match="offset must be"):
        coupling.offset = bad
    assert coupling.offset == 0.3


@needs_native
def test_a_relative_frame_without_target_raises_its_message_on_the_native_step(robots):
    robot = robots["panda"]
    task = qc.RelativeFrameTask(robot, "panda_hand_tcp", "panda_link3")
    ik = qc.IK(robot, [[task], [qc.PostureTask(robot, _start(robot))]], DT, engine="native")
    assert native_kind(task) == TaskKind.RELATIVE_FRAME
    with pytest.raises(ValueError, match="no target"):
        ik.step(_start(robot))
    task.set_target_from_configuration(_start(robot))
    ik.step(_start(robot))  # the kernel has its target now


@pytest.mark.parametrize("bad", [-1.0, np.nan, np.inf, "1"])
def test_an_assigned_bad_lm_damping_is_named(robots, bad):
    task = _damped(robots["panda"], "pose", _start(robots["panda"]), 1.0)
    with pytest.raises(ValueError, match="lm_damping"):
        task.lm_damping = bad
    assert task.lm_damping == 1.0


# ---------------------------------------------------------------------------------------
# damping tasks
# ---------------------------------------------------------------------------------------


@needs_native
@pytest.mark.parametrize("name", ["panda", "talos"])
def test_native_damping_task_rows_and_hold_equal_the_python_refresh(robots, name):
    robot = _robot(robots, name)
    q0 = _start(robot)
    w = np.linspace(0.5, 2.0, robot.nv)
    tn, tp = qc.DampingTask(robot, weight=w), qc.DampingTask(robot, weight=w)
    assert native_kind(tn) == TaskKind.DAMPING and tn.q_hold is None

    ikn, ikp = _refresh_pair(robot, tn, tp, lambda t: [[_hand(robot, q0, 0.0, gain=1.0)], [t]])
    rng = np.random.default_rng(4)
    for _ in range(3):
        q = robot.integrate(q0, rng.normal(scale=0.3, size=robot.nv), 1.0)
        version = tn.task.matrix_version
        ikn.step(q)
        assert tn.task.matrix_version == version  # a constant matrix, as the Python refresh
        ikp.refresh(q)
        # the same constant rows and the same held configuration, exactly (copies)
        np.testing.assert_array_equal(tn.task.A, tp.task.A)
        np.testing.assert_array_equal(tn.task.b, tp.task.b)
        np.testing.assert_array_equal(tn.q_hold, q)
        np.testing.assert_array_equal(tp.q_hold, q)
        Pn, Pp = ikn.stack._compiled, ikp.stack._compiled
        Pp.refresh_stacked()
        np.testing.assert_array_equal(Pn.Aeq[-robot.nv :], Pp.Aeq[-robot.nv :])


@needs_native
@pytest.mark.parametrize("name", ["panda", "talos"])
@pytest.mark.parametrize("cls", [qc.DampingTask, qc.LowAccelerationTask])
def test_a_damping_task_closed_loop_matches_the_python_engine(robots, name, cls):
    robot = _robot(robots, name)
    q0 = _start(robot)

    def levels():
        hand = _hand(robot, q0, [0.05, 0.05, -0.05], gain=0.2 / DT)
        return _on_feet(robot, q0, [[hand], [cls(robot, weight=1e-2)]])

    _closed_loops_agree(robot, levels, q0, 200)


@needs_native
@pytest.mark.parametrize("name", ["panda", "talos", "manifold"])
def test_native_low_acceleration_rows_equal_the_python_refresh(robots, name):
    """``v_prev`` (and the rows ``v = v_prev``) from the two last configurations on the
    configuration manifold (free-flyer, continuous and spherical joints on ``manifold``),
    or from ``set_previous``, as the Python refresh."""
    robot = manifold_robot() if name == "manifold" else _robot(robots, name)
    q0 = robot.neutral() if name == "manifold" else _start(robot)
    w = np.linspace(0.5, 2.0, robot.nv)
    tn, tp = qc.LowAccelerationTask(robot, weight=w), qc.LowAccelerationTask(robot, weight=w)
    assert native_kind(tn) == TaskKind.LOW_ACCELERATION
    frame = "tip" if name == "manifold" else HAND[name]

    def hand():
        return FramePositionTask(robot, frame, robot.frame_pose(q0, frame)[:3, 3])

    ikn, ikp = _refresh_pair(robot, tn, tp, lambda t: [[hand()], [t]])
    rng = np.random.default_rng(8)
    q = q0
    for step in range(6):
        if step == 3:  # a given previous velocity, for the next step only
            given = rng.normal(size=robot.nv)
            tn.set_previous(given)
            tp.set_previous(given)
        ikn.step(q)
        ikp.refresh(q)
        if step == 3:
            np.testing.assert_array_equal(tn.v_prev, given)
        # difference(q_hold, q) / dt: the two evaluations (a log of rotations of at most a
        # few rad, differences of coordinates of at most a few rad or m) differ by a few eps
        # of |q|, divided by dt
        tol = 64 * EPS * (1.0 + np.abs(q).max()) / DT
        np.testing.assert_allclose(tn.v_prev, tp.v_prev, rtol=0, atol=tol, err_msg=f"{step}")
        np.testing.assert_array_equal(tn.task.b, tn.v_prev)
        np.testing.assert_array_equal(tn.task.A, tp.task.A)
        np.testing.assert_array_equal(tn.q_hold, q)
        q = robot.integrate(q, rng.normal(scale=0.5, size=robot.nv), DT)
    assert np.abs(tp.v_prev).max() > 0.1  # measured, not the zero of the first step


# ---------------------------------------------------------------------------------------
# the weighted QP on the same kernels; no allocation on a floating base
# ---------------------------------------------------------------------------------------


@needs_native
def test_the_weighted_step_on_the_new_kernels_matches_the_python_engine(robots):
    robot = _robot(robots, "talos")
    q0 = _start(robot)
    iks = []
    for engine in ("native", "python"):
        levels, limits = talos_kernel_stack(robot, q0)
        iks.append(qc.IK(robot, levels, DT, limits=limits, method="weighted", engine=engine))
    ikn, ikp = iks
    assert ikn._native.weighted and not ikn._native._hybrid
    assert not ikn._native._python_limits
    # the same weighted QP solved by both engines in the whitened variables of the
    # weighted rows' QR (as test_native_support.py's Talos loop)
    closed_loop_agrees(ikn, ikp, q0, 150)


_ALLOCATION_RUN = r"""
import numpy as np, pinocchio as pin, qpcoord as qc
from support.malloc_counts import print_step_mallocs
from support.kernel_tasks import DT, posture_levels, posture_robot, start, talos_kernel_stack
from qpcoord.kinematics.native_step import integration_plan
robot = qc.robots.load("talos")
q0 = start(robot)
q = robot.integrate(q0, np.random.default_rng(1).normal(scale=0.1, size=robot.nv), DT)
for method in ("hierarchical", "weighted"):
    levels, limits = talos_kernel_stack(robot, q0)
    ik = qc.IK(robot, levels, DT, limits=limits, method=method, engine="native")
    assert not ik._native._hybrid and not ik._native._python_limits
    pin.computeJointJacobians(robot.model, robot.data, q)
    print_step_mallocs(method, ik, q)
for name in ("nested", "planar"):  # the posture's spherical, free-flyer, planar differences
    robot = posture_robot(name)
    q = robot.random_configuration(2)
    ik = qc.IK(robot, posture_levels(robot, q), DT, engine="native")
    assert not ik._native._hybrid and not ik._native._python_limits
    pin.computeJointJacobians(robot.model, robot.data, q)
    # a planar joint: q_next integrated in Python, not by the step
    print_step_mallocs(name, ik, q, integrate=integration_plan(robot) is not None)
"""


@pytest.mark.engine_independent
@needs_native
@pytest.mark.parametrize("build", native.built_variants() if native.available() else ())
def test_the_new_kernels_do_not_allocate_on_a_floating_base(tmp_path, robots, build):
    """The native call with the acceleration box, LM damping, relative-frame, coupling and
    low-acceleration kernels (a free-flyer difference) on Talos, and a damped posture over
    spherical, free-flyer and planar joints, makes no heap allocation after its first calls. Each
    build of the extension, chosen by QPCOORD_NATIVE_ISA."""
    _robot(robots, "talos")
    counts = native_malloc_counts(tmp_path, _ALLOCATION_RUN, build)
    assert counts == {"hierarchical": 0, "weighted": 0, "nested": 0, "planar": 0}


@needs_native
@pytest.mark.parametrize("kind", ["relative", "coupling"])
def test_native_relative_and_coupling_jacobians_match_finite_differences(robots, kind):
    """The native rows' ``A`` against central differences of their error ``e = −b/K`` (no
    feed-forward) along random velocities, on Talos (floating base)."""
    robot = _robot(robots, "talos")
    q0 = _start(robot)
    task = _coupling(robot) if kind == "coupling" else _relative(robot, q0, "x z ry rz")
    ik = qc.IK(robot, [[task], [qc.PostureTask(robot, q0)]], DT, limits=None, engine="native")
    assert native_kind(task) in (TaskKind.RELATIVE_FRAME, TaskKind.JOINT_COUPLING)
    rng = np.random.default_rng(12)
    h = 1e-6

    def error(q):
        ik.step(q)
        return -task.task.b / task.gain

    for _ in range(3):
        q = robot.integrate(q0, rng.normal(scale=0.3, size=robot.nv), 1.0)
        d = rng.normal(size=robot.nv)
        ik.step(q)
        Jd = task.task.A @ d
        fd = (error(robot.integrate(q, d, h)) - error(robot.integrate(q, d, -h))) / (2 * h)
        # central differences: truncation O(h²) and rounding O(eps |e| / h) ~ 1e-10
        np.testing.assert_allclose(Jd, fd, rtol=0, atol=1e-6 * max(1.0, np.abs(fd).max()))


ENGINES = ["python", pytest.param("native", marks=needs_native)]


def _limit_set(robot: qc.Robot, braking: bool, **given) -> list:
    """``[JointLimits, VelocityLimits]`` and, with ``braking``, ``AccelerationLimits`` braking
    before the JointLimits (a_max 1e4 rad/s²: its braking rows bind, not its box); ``given``
    the constructor arguments, keyed ``"<index>_<name>"``."""
    arg = {k.split("_", 1)[1]: v for k, v in given.items() if k.startswith("0_")}
    jl = qc.JointLimits(robot, **arg)
    out = [jl, qc.VelocityLimits(robot, given.get("1_limit"))]
    if braking:
        out.append(qc.AccelerationLimits(robot, given.get("2_limit", 1e4), position_limits=jl))
    return out


def _at_the_limits(robot: qc.Robot) -> tuple[np.ndarray, qc.PostureTask]:
    """Panda joints 1 to 3 mm inside a limit (alternately the upper and the lower one), each
    pulled past it at 100 rad/s by a posture: the step's v is the limit box on every joint."""
    rng = np.random.default_rng(5)
    side = np.where(np.arange(robot.nv) % 2 == 0, 1.0, -1.0)
    D = rng.uniform(1e-3, 3e-3, robot.nv)
    q = np.where(side > 0, robot.upper - D, robot.lower + D)
    return q, qc.PostureTask(robot, q + side, gain=100.0)


def _ik_step(robot: qc.Robot, limits: list, q: np.ndarray, engine: str) -> tuple:
    _, posture = _at_the_limits(robot)
    ik = qc.IK(robot, [posture], DT, limits=limits, engine=engine)
    return ik, *_stepped(ik, q)


def _stepped(ik: qc.IK, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One step from rest (``v_prev = 0``): ``v`` and the box."""
    for lim in ik.limits:
        if isinstance(lim, qc.AccelerationLimits):
            lim.reset()
    v, _ = ik.step(q)
    return v.copy(), ik.bounds.lower.copy(), ik.bounds.upper.copy()


#: (limit index, parameter, bad value or a function of the robot giving it, the message)
_BAD = [
    (0, "gain", np.nan, r"JointLimits: gain must be a number in \(0, 1\].*got nan"),
    (0, "gain", 0.0, r"JointLimits: gain must be .*got 0\.0"),
    (0, "gain", 1.5, r"JointLimits: gain must be .*got 1\.5"),
    (0, "gain", "0.5", r"JointLimits: gain must be .*got '0\.5'"),
    (0, "band", -1.0, r"JointLimits: band must be a number >= 0 .*got -1\.0"),
    (0, "band", np.nan, r"JointLimits: band must be .*got nan"),
    (0, "lower", np.nan, r"JointLimits: lower must be 7 numbers .*got nan"),
    (0, "upper", np.zeros(3), r"JointLimits: upper must be 7 numbers .*got array"),
    (0, "upper", lambda r: r.lower - 1.0, r"JointLimits: lower > upper at q index \[0, 1"),
    (1, "limit", 0.0, r"VelocityLimits: limit must be 7 numbers > 0 .*got 0\.0"),
    (1, "limit", np.nan, r"VelocityLimits: limit must be .*got nan"),
    (2, "limit", -1.0, r"AccelerationLimits: limit must be 7 numbers > 0 .*got -1\.0"),
    (2, "limit", np.nan, r"AccelerationLimits: limit must be .*got nan"),
    (2, "position_limits", lambda r: qc.JointLimits(r), r"AccelerationLimits: position_limits"),
    (2, "v_prev", np.full(7, np.nan), r"v_prev\[0\] is nan"),
]


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize(("i", "name", "bad", "message"), _BAD)
def test_a_bad_limit_parameter_assigned_is_named_and_kept_out(
    robots, engine, i, name, bad, message
):
    """An assignment is checked as the constructor checks the argument (the same message):
    it raises, the limit keeps its value, and the next step is the one before."""
    robot = robots["panda"]
    bad = bad(robot) if callable(bad) else bad
    q, _ = _at_the_limits(robot)
    limits = _limit_set(robot, braking=True)
    ik, *before = _ik_step(robot, limits, q, engine)
    old = getattr(limits[i], name)
    with pytest.raises(ValueError, match=message) as info:
        setattr(limits[i], name, bad)
    assert getattr(limits[i], name) is old or np.array_equal(getattr(limits[i], name), old)
    for mine, ref in zip(_stepped(ik, q), before, strict=True):
        np.testing.assert_array_equal(mine, ref)
    if name not in ("position_limits", "v_prev"):  # arguments of the constructor
        with pytest.raises(ValueError) as built:
            _limit_set(robot, braking=True, **{f"{i}_{name}": bad})
        assert str(built.value) == str(info.value)


#: (the limit set has braking rows, limit index, parameter, a good value or a function of
#: the robot giving it)
_GOOD = [
    (False, 0, "gain", 0.9),
    (False, 0, "band", np.inf),
    (False, 0, "band", 0.0),
    (False, 0, "lower", lambda r: r.lower + 1e-3),
    (False, 0, "upper", lambda r: r.upper - 1e-3),
    (False, 1, "limit", 0.5),
    (True, 0, "gain", 0.9),
    (True, 0, "upper", lambda r: r.upper - 1e-3),
    (True, 2, "limit", 5.0),
]


@needs_native
@pytest.mark.parametrize(("braking", "i", "name", "good"), _GOOD)
def test_an_assigned_limit_parameter_moves_both_engines_alike(robots, braking, i, name, good):
    """A limit's parameter assigned between two steps: the next step's box and v are those
    of the limits built with it, on both engines (and the box moved: it takes effect)."""
    robot = robots["panda"]
    good = good(robot) if callable(good) else good
    q, _ = _at_the_limits(robot)
    limn, limp = _limit_set(robot, braking), _limit_set(robot, braking)
    ikn, *before = _ik_step(robot, limn, q, "native")
    ikp, *_ = _ik_step(robot, limp, q, "python")
    setattr(limn[i], name, good)
    setattr(limp[i], name, good)
    native_after, python_after = _stepped(ikn, q), _stepped(ikp, q)
    _, *built = _ik_step(robot, _limit_set(robot, braking, **{f"{i}_{name}": good}), q, "python")
    assert not all(np.array_equal(a, b) for a, b in zip(python_after[1:], before[1:], strict=True))
    # every joint is pulled past its box at 100 rad/s: v is the box, whose entries are a few
    # roundings (a square root and quotients in the braking speed) of terms no larger than
    # (K/dt)(|q| + |limits|): 64 eps of that scale bounds two evaluations of it
    scale = (1.0 / DT) * (np.abs(q).max() + np.abs(robot.upper).max())
    for mine, ref, fresh in zip(native_after, python_after, built, strict=True):
        np.testing.assert_allclose(mine, ref, rtol=0, atol=64 * EPS * scale)
        np.testing.assert_allclose(ref, fresh, rtol=0, atol=64 * EPS * scale)


# ---------------------------------------------------------------------------------------
# a posture over continuous joints
# ---------------------------------------------------------------------------------------


@needs_native
def test_a_posture_over_continuous_joints_is_native_and_matches(robots):
    """The Kinova's continuous joints ((cos, sin) pairs): the posture's rows are the angle
    from q to q_ref (``pinocchio.difference``) natively, damped too, as the Python refresh;
    and a closed loop gives the same v on both engines."""
    try:
        robot = qc.robots.load("kinova")
    except ValueError:  # example-robot-data missing
        pytest.skip("kinova not available")
    assert any(j.shortname().startswith("JointModelRUB") for j in robot.model.joints)
    q0 = robot.neutral()
    frame = robot.frame

    def levels():
        q_ref = robot.random_configuration(6)
        hand = FramePositionTask(robot, frame, robot.frame_pose(q0, frame)[:3, 3] + 0.05)
        return [[hand], [qc.PostureTask(robot, q_ref, gain=2.0, lm_damping=0.3)]]

    ikn = qc.IK(robot, levels(), DT, engine="native")
    ikp = qc.IK(robot, levels(), DT, engine="python")
    assert not ikn._native._hybrid
    tn = next(t for t in ikn._native.kernel_tasks if isinstance(t, qc.PostureTask))
    tp = next(t for t in ikp._dynamic if isinstance(t, qc.PostureTask))
    rng = np.random.default_rng(3)
    q = q0
    for step in range(200):
        vn, _ = ikn.step(q)
        vp, _ = ikp.step(q)
        if step % 50 == 0:  # the rows: an atan2 of products of unit (cos, sin) pairs
            tol = 64 * EPS * tp.gain * np.pi
            np.testing.assert_allclose(tn.task.b, tp.task.b, rtol=0, atol=tol)
            np.testing.assert_allclose(tn.lm_rows.task.A, tp.lm_rows.task.A, rtol=0, atol=tol)
        # the same QP (rows to rounding) on two engines, each to its KKT tolerance 1e-9
        # relative to the velocities' scale (a few rad/s)
        tol = 1e-9 * max(1.0, float(np.abs(vp).max()))
        np.testing.assert_allclose(vn, vp, rtol=0, atol=tol, err_msg=f"step {step}")
        q = robot.integrate(q, vn + 0.01 * rng.normal(size=robot.nv), DT)


# ---------------------------------------------------------------------------------------
# a posture over spherical, free-flyer and planar joints; a joint without a native difference
# ---------------------------------------------------------------------------------------


def _turned(q: np.ndarray, joint: Any, angle: float) -> np.ndarray:
    """``q`` with a spherical or free-flyer joint's quaternion turned by ``angle`` (rad)
    about a fixed axis, or a planar joint's (cos, sin) pair by ``angle``."""
    out = q.copy()
    if joint.shortname() == "JointModelPlanar":
        c, s = q[joint.idx_q + 2 : joint.idx_q + 4]
        ca, sa = np.cos(angle), np.sin(angle)
        out[joint.idx_q + 2 : joint.idx_q + 4] = c * ca - s * sa, s * ca + c * sa
        return out
    iq = joint.idx_q + (3 if joint.shortname() == "JointModelFreeFlyer" else 0)
    x, y, z, w = q[iq : iq + 4]
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    R = pin.Quaternion(w, x, y, z).matrix() @ pin.exp3(angle * axis)
    out[iq : iq + 4] = pin.Quaternion(R).coeffs()
    return out


def _angle_rows(robot: qc.Robot, rows: np.ndarray) -> np.ndarray:
    """Per posture row: the row of the angle Pinocchio's SO(2) log gives it (a continuous
    joint's own row, a planar joint's rotation row for its three rows), else -1."""
    of_v = np.full(robot.nv, -1)
    for j in robot.model.joints[1:]:
        if j.shortname().startswith("JointModelRUB"):
            of_v[j.idx_v] = j.idx_v
        elif j.shortname() == "JointModelPlanar":
            of_v[j.idx_v : j.idx_v + 3] = j.idx_v + 2
    where = {int(v): r for r, v in enumerate(rows)}
    return np.array([where[int(v)] if v >= 0 else -1 for v in of_v[rows]])


_TURNING = ("JointModelSpherical", "JointModelFreeFlyer", "JointModelPlanar")


@needs_native
@pytest.mark.parametrize("name", ["manifold", "nested", "planar"])
def test_a_posture_over_spherical_and_planar_joints_is_native_and_matches(name):
    """The posture's rows over spherical, free-flyer (below the root) and planar joints are
    ``pinocchio.difference(q, q_ref)`` natively (Pinocchio's quaternion logs, SE(2)'s log),
    damped too, as the Python refresh: on random configurations and on injected ones where a
    log is delicate (a rotation near pi, a tiny one, the opposite quaternion of the same
    rotation)."""
    robot = posture_robot(name)
    q0 = robot.random_configuration(1)
    ikn = qc.IK(robot, posture_levels(robot, q0), DT, engine="native")
    ikp = qc.IK(robot, posture_levels(robot, q0), DT, engine="python")
    assert not ikn._native._hybrid
    tn = next(t for t in ikn._native.kernel_tasks if isinstance(t, qc.PostureTask))
    tp = next(t for t in ikp._dynamic if isinstance(t, qc.PostureTask))
    assert native_kind(tn) == TaskKind.POSTURE
    rows = {int(v) for v in tn.joints}  # a floating root is not in them
    turning = [j for j in robot.model.joints[1:] if j.shortname() in _TURNING and j.idx_v in rows]
    assert turning
    angle_row = _angle_rows(robot, tn.joints)
    pairs = [(robot.random_configuration(s), robot.random_configuration(s + 50)) for s in range(8)]
    for k, joint in enumerate(turning):
        q = robot.random_configuration(20 + k)
        # near pi a rotation-matrix log loses up to 3e-11 rad (at pi - 4e-3): not here. At
        # pi itself the sign of the log is the rounding's (±pi u): not compared
        for angle in (np.pi - 1e-7, np.pi - 4e-3, 3.0, 1e-3, 1e-9, 0.0):
            pairs.append((q, _turned(q, joint, angle)))
        if joint.shortname() != "JointModelPlanar":
            flipped = _turned(q, joint, 0.0)
            iq = joint.idx_q + (3 if joint.shortname() == "JointModelFreeFlyer" else 0)
            flipped[iq : iq + 4] *= -1.0  # the same rotation: a zero difference
            pairs.append((q, flipped))
    for i, (q, q_ref) in enumerate(pairs):
        tn.set_target(q_ref)
        tp.set_target(q_ref)
        ikn.step(q)
        ikp.refresh(q)
        # the rows K (q_ref ⊖ q): an angle of at most pi, or a coordinate difference of at
        # most 2 |q|∞ (turned by a rotation); the two evaluations take the same logs of the
        # same quaternion product and differ by its rounding (a few eps per component),
        # times log3's 1/sinc(theta/2) (at most pi) and the gain K. A continuous or planar
        # joint's rows: Pinocchio's SO(2) log is acos(cos d), whose rounding grows as
        # eps / |sin d| near pi (the kernel's atan2 does not), and a planar joint's
        # translation rows follow that angle: their tolerance grows so
        scale = max(np.pi, float(np.abs(q).max()), float(np.abs(q_ref).max()))
        d = tp.task.b / tp.gain
        angle = np.where(angle_row >= 0, d[np.maximum(angle_row, 0)], np.pi / 2)
        acos = np.maximum(np.abs(np.sin(angle)), np.sqrt(EPS)) ** -1 * (angle_row >= 0)
        tol = 32 * EPS * tp.gain * scale * (1.0 + acos)
        gap = np.abs(tn.task.b - tp.task.b)
        assert (gap <= tol).all(), (i, gap / tol)
        np.testing.assert_array_equal(tn.task.A, tp.task.A)
        # the damping rows √(λ Σ wᵢ eᵢ²) I, λ wᵢ ≤ 0.6: moved less than the rows' summed tol
        lm_tol = np.sum(tol) / tp.gain
        np.testing.assert_allclose(
            tn.lm_rows.task.A, tp.lm_rows.task.A, rtol=0, atol=lm_tol, err_msg=f"pair {i}"
        )
        if i < 8:  # a random pair: rows of every joint
            assert np.abs(tp.task.b).min() > 0, i


@needs_native
@pytest.mark.parametrize("name", ["manifold", "nested", "planar"])
def test_a_posture_over_spherical_and_planar_joints_closed_loop_matches(name):
    """The tip held, the posture pulled toward another configuration through the spherical
    (planar) joints: the same v on both engines over a closed loop."""
    robot = posture_robot(name)
    q0 = robot.random_configuration(1)
    ikn, ikp = engine_pair(robot, partial(posture_levels, robot, q0), DT)
    assert not ikn._native._hybrid
    q = closed_loop_agrees(ikn, ikp, q0, 200)
    # the posture moved the joints: the loop ran through their rows
    assert np.abs(robot.difference(q0, q)).max() > 1e-3


@needs_native
def test_a_posture_over_a_composite_joint_keeps_its_python_rows():
    """A composite joint (no native difference) is a posture row: that posture keeps its
    Python refresh in a hybrid step, and both engines give the same v."""
    robot = posture_robot("composite")
    q0 = robot.random_configuration(1)
    ikn, ikp = engine_pair(robot, partial(posture_levels, robot, q0), DT)
    posture = ikn._native._python_tasks
    assert [type(t) for t in posture] == [qc.PostureTask, LMDamping]
    assert native_kind(posture[0]) is None and ikn._native._hybrid
    closed_loop_agrees(ikn, ikp, q0, 50)


@needs_native
def test_add_task_rejects_a_bad_posture_plan():
    """A posture's plan: whole segments, disjoint, exactly over its rows."""
    robot = posture_robot("manifold")
    ik = qc.IK(robot, posture_levels(robot, robot.neutral()), DT, engine="native")
    solver = ik._native._solver
    ball = [2, 10, 8, 1]  # the spherical joint: q 10..13, v 8..10
    assert robot.model.joints[4].shortname() == "JointModelSpherical"
    assert (robot.model.joints[4].idx_q, robot.model.joints[4].idx_v) == (10, 8)
    posture = int(TaskKind.POSTURE)
    with pytest.raises(ValueError, match="4 ints per segment"):
        solver.add_task(posture, -1, [8, 9, 10], 3, ball[:3])
    with pytest.raises(ValueError, match="unknown segment kind"):
        solver.add_task(posture, -1, [8, 9, 10], 3, [9, 10, 8, 1])
    with pytest.raises(ValueError, match="segment out of range"):
        solver.add_task(posture, -1, [8, 9, 10], 3, [2, 10, 8, 2])
    with pytest.raises(ValueError, match="outside its plan"):
        solver.add_task(posture, -1, [8, 9, 10, 11], 3, ball)
    with pytest.raises(ValueError, match="overlap"):
        solver.add_task(posture, -1, [8, 9, 10], 3, ball + ball)
    with pytest.raises(ValueError, match="no row of"):
        solver.add_task(posture, -1, [8, 9, 10], 3, ball + [0, 14, 11, 1])
