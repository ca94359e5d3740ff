"""CollisionAvoidance's native rows (``qpcoord._collision``) against its Python rows.

Both run coal's GJK/EPA on the same shapes and placements; coal keeps a support hint per pair
between calls, so two histories may stop at different points within its tolerance. Each
comparison therefore starts both from cold caches (a new kernel, a new GeometryData): the
same algorithm on the same data, equal up to the rounding of the world placements.
"""

from __future__ import annotations

import os

import coal
import numpy as np
import pytest

import qpcoord as qc
from qpcoord.kinematics import collision_kernel
from qpcoord.kinematics.collision import Box, Capsule, CollisionAvoidance, Obstacle, Sphere

BUILT = collision_kernel._collision is not None
if not BUILT and os.environ.get("QPCOORD_REQUIRE_NATIVE") == "1":
    raise RuntimeError("QPCOORD_REQUIRE_NATIVE=1 but qpcoord._collision is not built")
pytestmark = pytest.mark.skipif(not BUILT, reason="qpcoord._collision is not built")

DT = 0.01  # s


@pytest.fixture(scope="module")
def panda():
    return qc.robots.load("panda")


def _at(p):
    T = np.eye(4)
    T[:3, 3] = p
    return T


def _task(robot, **kw):
    q0 = robot.reference_configuration("default")
    p = robot.frame_pose(q0, "panda_hand_tcp")[:3, 3]
    obstacles = [
        Sphere(p + [0.05, 0.0, 0.0], 0.05),
        Box(p + [0.0, 0.1, -0.1], [0.1, 0.05, 0.02]),
        Capsule(p - [0.1, 0.0, 0.0], p + [0.0, 0.1, 0.1], 0.03),
        Obstacle(coal.Cylinder(0.04, 0.2), _at(p - [0.2, 0.0, 0.0]), "cylinder"),
        Obstacle(coal.Cone(0.05, 0.1), _at(p + [0.0, -0.15, 0.0]), "cone"),
        Obstacle(coal.Ellipsoid(0.03, 0.05, 0.08), _at(p + [0.1, -0.1, -0.1]), "ellipsoid"),
        Obstacle(coal.Halfspace(np.array([0.0, 0.0, 1.0]), -0.05), np.eye(4), "floor"),
    ]
    return CollisionAvoidance(robot, obstacles=obstacles, influence_distance=0.15, **kw)


def _cold(task):
    """Both paths' coal caches anew (the kernel rebuilt from the task's data)."""
    task.geometry_data = task.geometry_model.createData()
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


def _configurations(robot, n, seed):
    rng = np.random.default_rng(seed)
    q0 = robot.reference_configuration("default")
    lo, hi = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    for i in range(n):
        q = robot.random_configuration(rng) if i % 2 else q0 + 0.3 * rng.standard_normal(robot.nq)
        yield np.clip(q, lo, hi)


def test_the_panda_task_runs_native(panda):
    task = _task(panda)
    assert task.native
    assert len(task.pairs) == 44 + 7 * 17


def test_native_rows_are_the_python_rows_on_random_configurations(panda):
    task = _task(panda)
    n_active = 0
    for q in _configurations(panda, 60, seed=3):
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
    task = _task(panda)
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
    task = _task(panda)
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
    assert not CollisionAvoidance(panda, obstacles=[Obstacle(g, _at([0.5, 0.0, 0.5]))]).native


def test_an_ik_step_with_native_rows_is_the_python_rows_step(panda):
    q = panda.reference_configuration("default")
    steps = []
    for native in (True, False):
        task = _task(panda)
        if not native:
            task._kernel = None
        T = panda.frame_pose(q, "panda_hand_tcp")
        T[:3, 3] += [0.1, 0.0, -0.05]
        hand = qc.FrameTask(panda, "panda_hand_tcp", T)
        ik = qc.IK(panda, [task, hand], DT, limits="robot")
        v, _ = ik.step(q)
        steps.append(v)
    # one GJK history each (a first call: cold caches): the same QP data to rounding
    np.testing.assert_allclose(steps[0], steps[1], rtol=0, atol=1e-9)
