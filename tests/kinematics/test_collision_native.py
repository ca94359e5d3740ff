"""CollisionAvoidance's native rows (``qpcoord._collision``) against its Python rows.

Both run coal's GJK/EPA on the same shapes and placements; coal keeps a support hint per pair
between calls, so two histories may stop at different points within its tolerance. Each
comparison therefore starts both from cold caches (a new kernel, a new GeometryData): the
same algorithm on the same data, equal up to the rounding of the world placements.
"""

from __future__ import annotations

import coal
import numpy as np
import pytest
from support.counting_malloc import native_malloc_counts
from support.native_engine import needs_collision_kernel, needs_native
from support.obstacle_ik import DT, configurations, obstacle_ik, obstacle_task, placed

import qpcoord as qc
from qpcoord.core import native
from qpcoord.kinematics import collision_kernel
from qpcoord.kinematics.collision import CollisionAvoidance, Obstacle, Sphere
from qpcoord.kinematics.native_step import TaskKind, native_kind

pytestmark = needs_collision_kernel


@pytest.fixture(scope="module")
def panda():
    return qc.robots.load("panda")


def _cold(task):
    """Both paths' coal caches and last distances anew (the kernel rebuilt from the task's
    data)."""
    task.geometry_data = task.geometry_model.createData()
    task._last_ok[:] = False
    robot = task.robot
    support = task._support
    columns = [[int(c) for c in np.flatnonzero(support[j])] for j in range(robot.model.njoints)]
    task._kernel = collision_kernel.native_kernel(
        robot,
        task.geometry_model,
        task._geom_centre,
        task._geom_radius,
        task._first,
        task._second,
        columns,
        task.min_distance,
        task.influence_distance,
    )
    task._kernel.bind(task._C, task._lower, task.distances, task.active.view(np.uint8))


def _rows(task, refresh, q):
    refresh(q, DT)
    return (
        task.task.C.copy(),
        task.task.lower.copy(),
        task.distances.copy(),
        task.active.copy(),
    )


def test_the_panda_task_runs_native(panda):
    task = obstacle_task(panda)
    assert task.native
    assert len(task.pairs) == 44 + 7 * 17


def test_native_rows_are_the_python_rows_on_random_configurations(panda):
    task = obstacle_task(panda)
    n_active = 0
    for q in configurations(panda, 60, seed=3):
        _cold(task)
        C1, lo1, d1, a1 = _rows(task, task._python_refresh, q)
        _cold(task)
        C2, lo2, d2, a2 = _rows(task, task._native_refresh, q)
        np.testing.assert_array_equal(a1, a2)
        np.testing.assert_array_equal(np.isinf(d1), np.isinf(d2))
        # the placements agree to rounding (m: scale 1 m, a few products of unit rotations)
        # and GJK stops after the same iterations: distances, rows and bounds to that scale
        tol = 1e-12
        f = np.isfinite(d1)
        np.testing.assert_allclose(d2[f], d1[f], rtol=0, atol=tol)
        np.testing.assert_allclose(C2, C1, rtol=0, atol=tol * max(1.0, np.abs(C1).max()))
        np.testing.assert_allclose(lo2[a1], lo1[a1], rtol=0, atol=tol / DT)
        assert np.all(lo2[~a2] == -np.inf) and not C2[~a2].any()
        n_active += int(a1.sum())
    assert n_active > 100  # the configurations reach the dampers, self and obstacles


def test_a_moved_obstacle_moves_in_the_native_rows(panda):
    task = obstacle_task(panda)
    q = panda.reference_configuration("default")
    p = panda.frame_pose(q, "panda_hand_tcp")[:3, 3]
    task.set_obstacle_pose(0, p + [0.0, 0.0, 0.08])
    _cold(task)
    py = _rows(task, task._python_refresh, q)
    _cold(task)
    nat = _rows(task, task._native_refresh, q)
    k = task.pairs.index(("panda_hand_0", "obstacle:sphere:0"))
    assert py[3][k] and nat[3][k]
    np.testing.assert_allclose(nat[2][k], py[2][k], rtol=0, atol=1e-12)


def test_native_step_clears_the_rows_a_python_step_left(panda):
    """The kernel clears the rows flagged active, whoever wrote them."""
    task = obstacle_task(panda)
    q = panda.reference_configuration("default")
    n_self = sum(not b.startswith("obstacle") for _, b in task.pairs)
    _rows(task, task._python_refresh, q)
    assert task.active[n_self:].any()
    for k, obs in enumerate(task.obstacles):  # all far away (the floor 5 m down)
        task.set_obstacle_pose(k, [0.0, 0.0, -5.0] if obs.name == "floor" else [5.0 + k, 5, 5])
    _cold(task)
    C, lower, _, active = _rows(task, task._native_refresh, q)
    assert not active[n_self:].any() and not C[n_self:].any()
    assert np.all(lower[n_self:] == -np.inf)


def test_meshes_and_swept_spheres_use_the_python_rows(panda):
    sphere = Sphere([0.5, 0.0, 0.5], 0.05)
    assert not CollisionAvoidance(panda, obstacles=[sphere], convex=False).native
    g = coal.Sphere(0.05)
    g.setSweptSphereRadius(0.01)
    assert not CollisionAvoidance(panda, obstacles=[Obstacle(g, placed([0.5, 0.0, 0.5]))]).native


def test_an_ik_step_with_native_rows_is_the_python_rows_step(panda):
    q = panda.reference_configuration("default")
    steps = []
    for with_kernel in (True, False):
        task = obstacle_task(panda)
        if not with_kernel:
            task._kernel = None
        T = panda.frame_pose(q, "panda_hand_tcp")
        T[:3, 3] += [0.1, 0.0, -0.05]
        hand = qc.FrameTask(panda, "panda_hand_tcp", T)
        ik = qc.IK(panda, [task, hand], DT, limits="robot")
        v, _ = ik.step(q)
        steps.append(v)
    # one GJK history each (a first call: cold caches): the same QP data to rounding
    np.testing.assert_allclose(steps[0], steps[1], rtol=0, atol=1e-9)


# ---------------------------------------------------------------------------------------
# the rows inside the native IK step (src/native/rows_kernel.h)
# ---------------------------------------------------------------------------------------


def _slot(ik, task):
    (k,) = [s.k for s in ik._native._slots if s.task is task]
    return k


@needs_native
def test_the_native_ik_step_computes_the_collision_rows(panda):
    task = obstacle_task(panda)
    ik = obstacle_ik(panda, task, panda.reference_configuration("default"), "native")
    assert task.native
    assert native_kind(task) == TaskKind.COLLISION and task in ik._native.kernel_tasks
    assert not ik._native._hybrid  # no Python task: the step's short path
    task._kernel = None  # no kernel: the Python rows, in the hybrid step
    assert not task.native and native_kind(task) is None
    ik = obstacle_ik(panda, task, panda.reference_configuration("default"), "native")
    assert task in ik._native._python_tasks


@needs_native
def test_set_rows_kernel_checks_its_kernel_and_capsule(panda):
    task = obstacle_task(panda)
    ik = obstacle_ik(panda, task, panda.reference_configuration("default"), "native")
    solver, k = ik._native._solver, _slot(ik, task)
    hand = next(s.k for s in ik._native._slots if isinstance(s.task, qc.FrameTask))
    with pytest.raises(ValueError, match="not a COLLISION kernel"):
        solver.set_rows_kernel(hand, task._kernel.entry())
    with pytest.raises(ValueError, match="expected a capsule named qpcoord.rows_kernel"):
        solver.set_rows_kernel(k, task._kernel)
    other = CollisionAvoidance(panda, obstacles=[Sphere([0.5, 0.0, 0.5], 0.05)])
    with pytest.raises(ValueError, match="shape is not"):  # another row count
        solver.set_rows_kernel(k, other._kernel.entry())


@needs_native
def test_native_step_rows_are_the_python_rows_on_random_configurations(panda):
    """The rows the native step writes (the task's Inequality and the stacked rows) are the
    task's Python rows, from cold caches (the module docstring), on random configurations."""
    task = obstacle_task(panda)
    ik = obstacle_ik(panda, task, panda.reference_configuration("default"), "native")
    k = _slot(ik, task)
    P = ik._native.P
    m = len(task.pairs)
    assert P.C.shape[0] == m  # the collision rows are the stack's only inequalities
    n_active = 0
    for q in configurations(panda, 40, seed=5):
        _cold(task)
        ik._native._solver.set_rows_kernel(k, task._kernel.entry())
        ik.step(q)
        C2, lo2, hi2 = task.task.C.copy(), task.task.lower.copy(), task.task.upper.copy()
        d2, a2 = task.distances.copy(), task.active.copy()
        np.testing.assert_array_equal(P.C, C2)
        np.testing.assert_array_equal(P.clo, lo2)
        assert np.all(P.chi == np.inf) and np.all(hi2 == np.inf)
        _cold(task)
        C1, lo1, d1, a1 = _rows(task, task._python_refresh, q)
        np.testing.assert_array_equal(a1, a2)
        # tolerances: as test_native_rows_are_the_python_rows_on_random_configurations
        tol = 1e-12
        f = np.isfinite(d1)
        np.testing.assert_array_equal(f, np.isfinite(d2))
        np.testing.assert_allclose(d2[f], d1[f], rtol=0, atol=tol)
        np.testing.assert_allclose(C2, C1, rtol=0, atol=tol * max(1.0, np.abs(C1).max()))
        np.testing.assert_allclose(lo2[a1], lo1[a1], rtol=0, atol=tol / DT)
        assert np.all(lo2[~a2] == -np.inf) and not C2[~a2].any()
        n_active += int(a1.sum())
    assert n_active > 60  # the configurations reach the dampers


@needs_native
@pytest.mark.parametrize("method", ["hierarchical", "weighted"])
def test_a_closed_loop_gives_the_python_engines_velocities(panda, method):
    """The native engine (rows inside its step) and the Python engine (rows by the task's
    update) along one loop: the same v at every step, through a gain change and a moved
    obstacle. Each IK has its own task, called at the same configurations: the same coal
    history, so the same rows. The engines then solve the same QP: v (~1 rad/s) agrees to
    double rounding times the stack's conditioning, within the native-vs-Python step tests'
    1e-9."""
    q = panda.reference_configuration("default")
    tasks = [obstacle_task(panda), obstacle_task(panda)]
    engines = ("native", "python")
    iks = [obstacle_ik(panda, t, q, e, method) for t, e in zip(tasks, engines, strict=True)]
    assert tasks[0] in iks[0]._native.kernel_tasks
    active = 0
    for step in range(60):
        if step == 20:
            for t in tasks:
                t.gain = 0.2
        if step == 40:
            p = panda.frame_pose(q, "panda_hand_tcp")[:3, 3]
            for t in tasks:
                t.set_obstacle_pose(0, p + [0.0, 0.0, 0.07])
        vn, _ = iks[0].step(q)
        vp, _ = iks[1].step(q)
        np.testing.assert_allclose(vn, vp, rtol=0, atol=1e-9, err_msg=f"step {step}")
        np.testing.assert_array_equal(tasks[0].active, tasks[1].active)
        active += int(tasks[0].active.sum())
        q = panda.integrate(q, vn, DT)
    assert active > 100


def _loop_configurations(robot, steps):
    """The configurations of a native closed loop on ``obstacle_task``'s stack (hand driven into the
    obstacles)."""
    q = robot.reference_configuration("default")
    ik = obstacle_ik(robot, obstacle_task(robot), q, None)
    out = []
    for _ in range(steps):
        v, _ = ik.step(q)
        q = robot.integrate(q, v, DT)
        out.append(q.copy())
    return out


@pytest.mark.parametrize("path", ["native", "python"])
def test_skipped_pairs_are_farther_than_the_influence_distance(panda, path):
    """Along a loop, each path on its own history: a pair without a distance (skipped by the
    spheres or by its last distance minus the motion since) is at d >= d_i (coal's distance
    at that configuration), every pair below d_i - 1e-5 m has a row (1e-5 m: above GJK's
    stopping error, 3e-6 m between two runs here); and the last-distance bound spares coal
    calls: on this loop (1 cm a step among seven obstacles) about a quarter of those of a
    kernel without history (a new one at each step), which makes them all."""
    task = obstacle_task(panda)
    if path == "python":
        task._kernel = None
    fresh = obstacle_task(panda)
    warm = cold = 0
    for q in _loop_configurations(panda, 60):
        task._refresh(q, 0.0, DT, None)
        exact = task.compute_distances(q)
        skipped = np.isinf(task.distances)
        assert np.all(exact[skipped] >= task.influence_distance)
        assert np.all(task.active[exact < task.influence_distance - 1e-5])
        warm += int((~skipped).sum())
        _cold(fresh)
        fresh._native_refresh(q, DT)
        cold += int(np.isfinite(fresh.distances).sum())
    assert warm < 0.9 * cold, (warm, cold)


@needs_native
def test_a_task_on_another_robots_data_keeps_its_python_refresh(panda):
    """A task whose robot is not the IK's (``with_frame``: its own Pinocchio data) is not
    read by the step's kernel call (its kernel reads that other data)."""
    other = panda.with_frame("panda_link7")
    task = obstacle_task(other)
    q = panda.reference_configuration("default")
    ik = obstacle_ik(panda, task, q, "native")
    assert task.native and task in ik._native._python_tasks
    ref = obstacle_ik(panda, obstacle_task(other), q, "python")
    np.testing.assert_allclose(ik.step(q)[0], ref.step(q)[0], rtol=0, atol=1e-9)


@needs_native
def test_a_nan_gain_raises_the_python_engines_message(panda):
    q = panda.reference_configuration("default")
    messages = []
    for engine in ("native", "python"):
        task = obstacle_task(panda)
        ik = obstacle_ik(panda, task, q, engine)
        ik.step(q)
        task.gain = float("nan")
        with pytest.raises(ValueError) as info:
            ik.step(q)
        messages.append(str(info.value))
        task.gain = 0.5  # usable again
        ik.step(q)
    assert messages[0] == messages[1] and "NaN" in messages[0]


_ALLOCATION_RUN = r"""
import numpy as np, pinocchio as pin, qpcoord as qc
from support.malloc_counts import mallocs_in
from support.obstacle_ik import configurations, obstacle_ik, obstacle_task
robot = qc.robots.load("panda")
task = obstacle_task(robot)
ik = obstacle_ik(robot, task, robot.reference_configuration("default"), "native")
assert task in ik._native.kernel_tasks
# a twin task's kernel alone, called at the same configurations: the same coal calls
call, kernel = ik._native._solver.step, obstacle_task(robot)._kernel
qs = list(configurations(robot, 8, seed=3))
for q in qs:  # first calls: every configuration once
    pin.computeJointJacobians(robot.model, robot.data, q)
    call(q, False, 10.0)
    kernel.update(0.5)
extra, active = 0, 0
for _ in range(20):
    for q in qs:
        pin.computeJointJacobians(robot.model, robot.data, q)
        in_step = mallocs_in(lambda: call(q, True, 10.0), runs=1)
        active += int(task.active.sum())
        extra += in_step - mallocs_in(lambda: kernel.update(0.5), runs=1)
assert active > 0, "no configuration activates a damper"
print("extra", extra)
"""


@pytest.mark.engine_independent
@needs_native
@pytest.mark.parametrize("build", native.built_variants() if native.available() else ())
def test_the_native_step_with_collision_rows_allocates_only_coals_own(tmp_path, build):
    """The native call with the collision kernel allocates nothing of its own after its first
    calls: exactly what a twin task's kernel alone allocates at the same configurations (the
    same coal calls; kinematics computed outside the counted calls), on configurations that
    activate dampers. That is not
    zero: coal 3.0.3's COAL_ASSERT builds its exception object (a std::string) even when the
    check holds, in GJK::reset and the witness-point extraction of every distance call. Each
    build of the extension."""
    assert native_malloc_counts(tmp_path, _ALLOCATION_RUN, build) == {"extra": 0}
