"""The native band kernels of :class:`~qpcoord.ComBand` and :class:`~qpcoord.SupportPolygon`
(``src/native/support_kernels.hpp``) against the tasks' Python ``_refresh``: rows, Jacobians,
closed loops, errors and allocations."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from support.counting_malloc import native_malloc_counts
from support.native_engine import needs_native
from support.talos_balance import CORNERS, DT, SOLES, balance_stack

import qpcoord as qc
from qpcoord.core import native
from qpcoord.kinematics.frame_tasks import ComBand, SupportPolygon
from qpcoord.kinematics.native_step import TaskKind, native_kind
from qpcoord.robots import absolute_angle_map, planar_chain

#: points off every axis (the offsets' rotation and z terms)
SKEW_POINTS = [[0.08, -0.03, 0.04], [-0.05, 0.06, -0.02], [0.02, 0.01, 0.07]]


@pytest.fixture(scope="module")
def talos() -> qc.Robot:
    try:
        return qc.robots.load("talos")
    except ValueError:  # example-robot-data missing
        pytest.skip("talos not available")


@pytest.fixture(scope="module")
def planar() -> qc.Robot:
    """A 4R arm in the (x, y) plane with masses, absolute angles (a coordinate map), and a
    contact frame on every link."""
    model = planar_chain(4)
    for j in range(1, model.njoints):
        model.appendBodyToJoint(
            j,
            pin.Inertia(1.0 + j, np.array([0.5, 0.02 * j, 0.0]), np.eye(3) * 0.01),
            pin.SE3.Identity(),
        )
        placement = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.3 * j), np.array([0.6, 0.1, 0.0]))
        model.addFrame(pin.Frame(f"c{j}", j, 0, placement, pin.FrameType.OP_FRAME))
    return qc.Robot(model, "tip", coordinate_map=absolute_angle_map(4), name="planar_4r_mass")


def _talos_q(robot: qc.Robot, moved: bool) -> np.ndarray:
    q = robot.reference_configuration("half_sitting")
    if moved:  # a generic configuration: no two contact points share a coordinate
        q = robot.integrate(q, np.random.default_rng(3).normal(scale=0.3, size=robot.nv), 0.1)
    return q


def _talos_tasks(robot: qc.Robot, q: np.ndarray, kind: str) -> list:
    if kind == "soles":
        return [SupportPolygon(robot, list(SOLES), margin=0.02, gain=40.0, contact_points=CORNERS)]
    if kind == "frames":  # four frame origins, one of them off the ground plane
        frames = [*SOLES, "gripper_left_base_link", "gripper_right_base_link"]
        return [SupportPolygon(robot, frames, margin=0.01, gain=7.0, weight=3.0)]
    if kind == "skew":
        return [SupportPolygon(robot, list(SOLES), gain=5.0, contact_points=SKEW_POINTS)]
    if kind == "band":
        c = robot.com(q)
        return [
            ComBand(robot, c - [0.01, 0.5, np.inf], c + [0.2, -0.005, 0.01], gain=9.0, weight=2.0)
        ]
    raise AssertionError(kind)


def _planar_tasks(robot: qc.Robot, q: np.ndarray, kind: str) -> list:
    if kind == "soles":
        return [SupportPolygon(robot, ["c1", "c2", "c3", "c4"], margin=0.05, gain=3.0)]
    if kind == "skew":
        return [SupportPolygon(robot, ["c2", "c4"], gain=2.0, contact_points=SKEW_POINTS)]
    if kind == "band":
        c = robot.com(q)
        return [ComBand(robot, c - 0.1, c + [0.05, -0.02, 0.1], gain=4.0)]
    raise AssertionError(kind)


def _planar_q(robot: qc.Robot, moved: bool) -> np.ndarray:
    return np.array([0.3, 1.4, 2.9, -1.9]) + (0.1 if moved else 0.0)


CASES = [
    ("talos", "soles"),
    ("talos", "frames"),
    ("talos", "skew"),
    ("talos", "band"),
    ("planar", "soles"),
    ("planar", "skew"),
    ("planar", "band"),
]


def _setup(request, name: str, kind: str, moved: bool):
    robot = request.getfixturevalue(name)
    q = (_talos_q if name == "talos" else _planar_q)(robot, moved)
    factory = _talos_tasks if name == "talos" else _planar_tasks
    return robot, q, lambda: factory(robot, q, kind)


# ---------------------------------------------------------------------------------------
# the rows
# ---------------------------------------------------------------------------------------


@needs_native
@pytest.mark.parametrize(("name", "kind"), CASES)
def test_native_band_rows_equal_the_python_refresh(request, name, kind):
    robot, q, make = _setup(request, name, kind, moved=False)
    tn, tp = make(), make()
    ikn = qc.IK(robot, [tn, qc.PostureTask(robot, q, gain=2.0)], DT, limits=None, engine="native")
    ikp = qc.IK(robot, [tp, qc.PostureTask(robot, q, gain=2.0)], DT, limits=None, engine="python")
    band = tn[0]
    assert native_kind(band) in (TaskKind.COM_BAND, TaskKind.SUPPORT_POLYGON)
    assert band in ikn._native.kernel_tasks
    assert not ikn._native._hybrid
    for step in range(3):
        qs = q if step == 0 else robot.integrate(q, 0.2 * np.sin(np.arange(robot.nv) + step), 0.1)
        version = band.task.matrix_version
        ikn.step(qs)
        assert band.task.matrix_version == version + 1  # a new C, as _assign counts it
        ikp.refresh(qs)
        Pn, Pp = ikn.stack._compiled, ikp.stack._compiled
        Pp.refresh_stacked()
        a, b = band.task, tp[0].task
        scale = max(1.0, float(np.abs(b.C).max()))
        np.testing.assert_allclose(a.C, b.C, rtol=0, atol=1e-12 * scale)
        for mine, ref in (
            (a.lower, b.lower),
            (a.upper, b.upper),
            (Pn.clo, Pp.clo),
            (Pn.chi, Pp.chi),
        ):
            np.testing.assert_array_equal(np.isinf(mine), np.isinf(ref))
            f = np.isfinite(ref)
            np.testing.assert_allclose(mine[f], ref[f], rtol=1e-12, atol=1e-12)
            assert np.all(mine[~f] == ref[~f])
        np.testing.assert_allclose(Pn.C, Pp.C, rtol=0, atol=1e-12 * scale)
        np.testing.assert_array_equal(Pn.csw, Pp.csw)
        if isinstance(band, SupportPolygon):
            assert band.edges == tp[0].edges >= 3


@needs_native
def test_the_soles_hull_at_half_sitting_drops_the_collinear_corners(talos):
    """Both soles aligned: their front (back) corners are exactly collinear; the native hull
    drops the middle ones as frame_tasks._hull does (4 edges, the same rows)."""
    q = talos.reference_configuration("half_sitting")
    task = SupportPolygon(talos, list(SOLES), gain=10.0, contact_points=CORNERS)
    ik = qc.IK(talos, [task], DT, limits=None, engine="native")
    ik.step(q)
    C, upper = task.task.C.copy(), task.task.upper.copy()
    assert task.edges == 4
    task._refresh(q, 0.0, DT, None)  # the Python rows into the same arrays
    assert task.edges == 4
    np.testing.assert_allclose(C, task.task.C, rtol=0, atol=1e-12)
    np.testing.assert_allclose(upper, task.task.upper, rtol=1e-12, atol=1e-12)


# ---------------------------------------------------------------------------------------
# Jacobians: finite differences of the measured quantities of the native rows
# ---------------------------------------------------------------------------------------


def _measured(ik: qc.IK, task, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(e, C)`` of the band from a native step: e = -upper / K - margin (polygon) or
    lower_face - lower / K (CoM band)."""
    ik.step(q)
    C = np.array(task.task.C)
    if isinstance(task, SupportPolygon):
        h = task.edges
        return -task.task.upper[:h] / task.gain - task.margin, C[:h]
    return task.lower - task.task.lower / task.gain, C


@needs_native
@pytest.mark.parametrize(("name", "kind"), CASES)
def test_native_band_jacobians_match_finite_differences(request, name, kind):
    robot, q, make = _setup(request, name, kind, moved=True)
    if kind == "band":  # finite faces on every axis: every row's quantity is read
        c = robot.com(q)
        task = ComBand(robot, c - 1.0, c + 1.0, gain=3.0)
    else:
        task = make()[0]
    ik = qc.IK(robot, [task], DT, limits=None, engine="native")
    e0, J = _measured(ik, task, q)
    edges = getattr(task, "edges", None)
    rng = np.random.default_rng(4)
    h = 1e-6
    for _ in range(3):
        d = rng.normal(size=robot.nv)
        ep, _ = _measured(ik, task, robot.integrate(q, d, h))
        em, _ = _measured(ik, task, robot.integrate(q, d, -h))
        assert getattr(task, "edges", None) == edges  # the same hull on both sides
        fd = (ep - em) / (2 * h)
        np.testing.assert_allclose(J @ d, fd, rtol=0, atol=1e-6 * max(1.0, np.abs(fd).max()))


# ---------------------------------------------------------------------------------------
# closed loops: native vs Python engine, the band / polygon binding
# ---------------------------------------------------------------------------------------


@needs_native
def test_talos_closed_loop_matches_the_python_engine_with_the_polygon_and_band_binding(talos):
    q0 = talos.reference_configuration("half_sitting")
    levels_n, poly, band = balance_stack(talos, q0)
    levels_p, _, _ = balance_stack(talos, q0)
    ikn = qc.IK(talos, levels_n, DT, limits="robot", engine="native")
    ikp = qc.IK(talos, levels_p, DT, limits="robot", engine="python")
    assert not ikn._native._hybrid and poly in ikn._native.kernel_tasks
    q = q0.copy()
    bound_poly = bound_band = 0
    for step in range(150):
        vn, sn = ikn.step(q)
        vp, sp = ikp.step(q)
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9, err_msg=f"step {step}")
        np.testing.assert_allclose(
            sn.level_residuals, sp.level_residuals, rtol=1e-9, atol=1e-9, err_msg=f"step {step}"
        )
        cv = poly.task.C @ vn
        bound_poly += bool(np.any(np.abs(cv - poly.task.upper) < 1e-9 * (1 + np.abs(cv))))
        cb = band.task.C @ vn
        bound_band += bool(
            np.any(np.abs(cb - band.task.upper) < 1e-9)
            or np.any(np.abs(cb - band.task.lower) < 1e-9)
        )
        q, _ = talos.integrate(q, vn, DT), None
    assert bound_poly > 10 and bound_band > 10, (bound_poly, bound_band)


@needs_native
@pytest.mark.parametrize("weight_ratio", [1e-3, 1e-2])
def test_talos_weighted_closed_loop_matches_the_python_engine(talos, weight_ratio):
    """``method="weighted"`` on the Talos stack: H is regular with cond ~1e12 at
    ``weight_ratio = 1e-3`` (posture weighted 1e-9). Both engines solve the QP in the
    whitened variables of the weighted rows' QR, so they agree to 1e-9 (with daqp on the
    formed H the Python engine was 2.3e-3 off in x on 137 of 150 steps)."""
    q0 = talos.reference_configuration("half_sitting")
    ikn = qc.IK(talos, balance_stack(talos, q0)[0], DT, limits="robot", method="weighted",
                weight_ratio=weight_ratio)  # fmt: skip
    ikp = qc.IK(talos, balance_stack(talos, q0)[0], DT, limits="robot", method="weighted",
                weight_ratio=weight_ratio, engine="python")  # fmt: skip
    q = q0.copy()
    qp_steps = 0
    for step in range(150):
        vn, sn = ikn.step(q)
        vp, sp = ikp.step(q)
        qp_steps += sp.info["qp_calls"] > 0
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9, err_msg=f"step {step}")
        np.testing.assert_allclose(
            sn.level_residuals, sp.level_residuals, rtol=1e-9, atol=1e-9, err_msg=f"step {step}"
        )
        q = talos.integrate(q, vn, DT)
    assert qp_steps > 100, qp_steps  # the constrained QP, not the closed form, is compared


@needs_native
def test_planar_closed_loop_matches_the_python_engine(planar):
    q = _planar_q(planar, moved=False)

    def build(engine):
        poly = SupportPolygon(planar, ["c1", "c2", "c3", "c4"], margin=0.05, gain=20.0)
        c = planar.com(q)
        band = ComBand(planar, c - [0.02, 1.0, 1.0], c + [1.0, 0.01, 1.0], gain=20.0)
        tip = qc.FramePositionTask(
            planar, "tip", planar.frame_pose(q, "tip")[:3, 3] + [-1.0, 0.5, 0.0], gain=20.0
        )
        return qc.IK(planar, [[poly, band], tip], 0.01, limits=None, engine=engine), poly

    (ikn, poly), (ikp, _) = build("native"), build("python")
    assert not ikn._native._hybrid
    binding = 0
    for step in range(60):
        vn, _ = ikn.step(q)
        vp, _ = ikp.step(q)
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9, err_msg=f"step {step}")
        cv = poly.task.C @ vn
        binding += bool(np.any(np.abs(cv - poly.task.upper) < 1e-9 * (1 + np.abs(cv))))
        q = planar.integrate(q, vn, 0.01)
    assert binding > 5


@needs_native
def test_hard_band_and_polygon_rows_are_native_and_match(planar):
    """The bands as hard constraints (the stack's hard inequality rows)."""
    q = _planar_q(planar, moved=False)

    def build(engine):
        poly = SupportPolygon(planar, ["c1", "c2", "c3", "c4"], margin=0.05, gain=20.0)
        c = planar.com(q)
        band = ComBand(planar, c - [0.02, 1.0, 1.0], c + [1.0, 0.01, 1.0], gain=20.0)
        tip = planar.frame_pose(q, "tip")[:3, 3] + [-1.0, 0.5, 0.0]
        task = qc.FramePositionTask(planar, "tip", tip, gain=20.0)
        ik = qc.IK(planar, [task], 0.01, limits=None, constraints=[poly, band], engine=engine)
        return ik, poly

    (ikn, poly), (ikp, polyp) = build("native"), build("python")
    assert not ikn._native._hybrid and poly in ikn._native.kernel_tasks
    for step in range(40):
        vn, _ = ikn.step(q)
        vp, _ = ikp.step(q)
        np.testing.assert_allclose(poly.task.C, polyp.task.C, rtol=0, atol=1e-12)
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9, err_msg=f"step {step}")
        q = planar.integrate(q, vn, 0.01)


class _PythonWall(qc.PositionBand):
    """A PositionBand the native step leaves to its Python refresh (kernels go by exact
    class)."""


@needs_native
def test_a_python_band_beside_the_native_ones_is_hybrid_and_matches(planar):
    """A band refreshed in Python (a PositionBand subclass: no kernel) in the same level as
    the native band kernels: the rows of both kinds land in their own places of the stacked
    arrays."""
    q = _planar_q(planar, moved=False)

    def build(engine):
        c = planar.com(q)
        band = ComBand(planar, c - [0.02, 1.0, 1.0], c + [1.0, 0.01, 1.0], gain=20.0)
        tip = planar.position(q)
        wall = _PythonWall(planar, lower=[tip[0] - 0.05, -np.inf, -np.inf], gain=10.0)
        poly = SupportPolygon(planar, ["c1", "c2", "c3", "c4"], margin=0.05, gain=20.0)
        task = qc.PositionTask(planar, tip + [-1.0, 0.5, 0.0], gain=20.0)
        return qc.IK(planar, [[band, wall, poly], task], 0.01, limits=None, engine=engine)

    ikn, ikp = build("native"), build("python")
    assert ikn._native._hybrid and len(ikn._native.kernel_tasks) == 3  # the position task too
    for step in range(40):
        vn, _ = ikn.step(q)
        vp, _ = ikp.step(q)
        Pn, Pp = ikn.stack._compiled, ikp.stack._compiled
        Pp.refresh_stacked()
        np.testing.assert_allclose(Pn.C, Pp.C, rtol=0, atol=1e-12)
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9, err_msg=f"step {step}")
        q = planar.integrate(q, vn, 0.01)


# ---------------------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------------------


@needs_native
def test_collinear_contacts_raise_the_tasks_message(talos):
    q = talos.reference_configuration("half_sitting")
    line = [[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.1, 0.0, 0.0]]
    task = SupportPolygon(talos, ["left_sole_link"], contact_points=line)
    ik = qc.IK(talos, [task], DT, limits=None, engine="native")
    assert task in ik._native.kernel_tasks
    with pytest.raises(ValueError, match="collinear"):
        ik.step(q)


@needs_native
def test_a_nan_gain_raises_the_tasks_message(talos):
    q = talos.reference_configuration("half_sitting")
    c = talos.com(q)
    band = ComBand(talos, c - 0.1, c + 0.1)
    ik = qc.IK(talos, [band], DT, limits=None, engine="native")
    ik.step(q)
    band.gain = float("nan")  # not validated on assignment: the step finds it
    with pytest.raises(ValueError, match="NaN"):
        ik.step(q)


@needs_native
def test_add_task_rejects_bad_band_data(talos):
    q = talos.reference_configuration("half_sitting")
    c = talos.com(q)
    band = ComBand(talos, c - 0.1, c + 0.1)
    poly = SupportPolygon(talos, list(SOLES), contact_points=CORNERS)
    ik = qc.IK(talos, [[band, poly]], DT, limits=None, engine="native")
    solver = ik._native._solver
    with pytest.raises(ValueError, match="ComBand has 3 rows"):
        solver.add_task(7, -1, [0, 1], 0, [])
    with pytest.raises(ValueError, match="unknown frame slot"):
        solver.add_task(8, -1, list(range(8)), 3, [0, 99])
    with pytest.raises(ValueError, match="frames x contact points"):
        solver.add_task(8, -1, list(range(7)), 3, [0, 1])
    with pytest.raises(ValueError, match="rows out of range"):
        solver.add_task(8, -1, list(range(8)), 9, [0])
    with pytest.raises(ValueError, match="unknown kind"):
        solver.add_task(max(TaskKind) + 1, -1, list(range(8)), 3, [0])


# ---------------------------------------------------------------------------------------
# no allocation per call
# ---------------------------------------------------------------------------------------

_ALLOCATION_RUN = r"""
import numpy as np, pinocchio as pin, qpcoord as qc
from support.malloc_counts import print_step_mallocs
from support.talos_balance import DT, balance_stack
robot = qc.robots.load("talos")
q = robot.reference_configuration("half_sitting")
levels, polygon, band = balance_stack(robot, q)
q = robot.integrate(q, np.random.default_rng(1).normal(scale=0.1, size=robot.nv), DT)
pin.computeJointJacobians(robot.model, robot.data, q)
pin.jacobianCenterOfMass(robot.model, robot.data, False)
for name, stack in (("bands", [[polygon, band]]), ("whole", levels)):
    ik = qc.IK(robot, stack, DT, limits="robot", engine="native")
    assert not ik._native._hybrid
    print_step_mallocs(name, ik, q)
"""


@pytest.mark.engine_independent
@needs_native
@pytest.mark.parametrize("build", native.built_variants() if native.available() else ())
def test_the_native_band_kernels_do_not_allocate(tmp_path, talos, build):
    """The native call with both band kernels (and the robot's limit box) makes no heap
    allocation on Talos, alone and in the whole Talos stack (feet, polygon and band, hand,
    posture: the hierarchy's equality levels made 3 mallocs per call before their buffers
    were made fixed-size). Each build of the extension, chosen by QPCOORD_NATIVE_ISA."""
    counts = native_malloc_counts(tmp_path, _ALLOCATION_RUN, build)
    assert counts == {"bands": 0, "whole": 0}


@needs_native
def test_the_task_kinds_are_the_extensions():
    """``TaskKind`` names the extension's task kernels with the same values (one kind, one
    kernel)."""
    ext = native.load().IKTaskKind
    assert {k.name: int(k) for k in TaskKind} == {
        name: int(getattr(ext, name)) for name in TaskKind.__members__
    }
    assert len(ext.__members__) == len(TaskKind)


@needs_native
def test_a_met_polygon_level_drops_its_far_working_rows_and_matches_the_python_engine(talos):
    """The benchmark's cell (feet, the CoM polygon at gain 1/dt, a far hand target, posture):
    the polygon's first corrections drive joints to their speed bounds, and at a level whose
    objective is zero (every row met) those rows carry zero multipliers. The native step
    stores the level's working set without its rows away from the start once the rest is
    verified (``pruned_working_sets``), and accepts a warm trial of zero objective whatever
    the rounding of its multipliers (``zero_objective_hits``: two near-parallel inherited
    polygon rows give multipliers ~5e-9 for a gradient ~3e-17). The posture level's warm
    trials step through its closed form's triangular factor (``range_trials``: a tall,
    full-rank, well-conditioned level, no factorisation of its projected objective). x stays
    the Python engine's to 1e-9, the tolerance of this file's closed loops: the engines stop
    on kkt_tol = 1e-9 of the gradient, on rows of unit scale (velocities ~0.5 rad/s, max
    deviation seen 1.6e-10)."""
    q0 = talos.reference_configuration("half_sitting")
    hand_target = talos.frame_pose(q0, "gripper_right_base_link")[:3, 3] + [0.4, 0.1, -0.3]

    def stack() -> list:
        feet = [qc.FrameTask(talos, s, gain=1.0 / DT) for s in SOLES]
        for foot in feet:
            foot.set_target_from_configuration(q0)
        polygon = SupportPolygon(
            talos, list(SOLES), margin=0.02, gain=1.0 / DT, contact_points=CORNERS
        )
        hand = qc.FramePositionTask(talos, "gripper_right_base_link", hand_target, gain=5.0)
        return [feet, polygon, hand, qc.PostureTask(talos, q0, gain=50.0)]

    ikn = qc.IK(talos, stack(), DT, limits="robot", engine="native")
    ikp = qc.IK(talos, stack(), DT, limits="robot", engine="python")
    q = q0.copy()
    pruned = zero_objective = range_trials = 0
    for step in range(200):
        vn, sn = ikn.step(q)
        vp, _ = ikp.step(q)
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9, err_msg=f"step {step}")
        counters = sn.info["stats"]
        pruned += counters.pruned_working_sets
        zero_objective += counters.zero_objective_hits
        range_trials += counters.range_trials
        q = talos.integrate(q, vn, DT)
    assert pruned > 0 and zero_objective > 0 and range_trials > 0, (
        pruned,
        zero_objective,
        range_trials,
    )
