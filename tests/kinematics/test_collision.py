"""Collision avoidance: velocity dampers from the robot's collision geometry."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

import qpcoord as qc
from qpcoord.kinematics.collision import (
    Box,
    Capsule,
    CollisionAvoidance,
    Obstacle,
    Sphere,
    _bounding_sphere,
    collision_geometry,
)

HAND = "panda_hand_tcp"
#: Largest accepted undershoot of the safety distance (m): first-order step error and
#: coal's GJK tolerance (1e-6 m).
TOL = 1e-4


@pytest.fixture(scope="module")
def panda():
    try:
        return qc.robots.load("panda")
    except (ValueError, ImportError, FileNotFoundError) as exc:  # example-robot-data missing
        pytest.skip(str(exc))


def _tight(task: CollisionAvoidance) -> None:
    """Tighten coal's tolerances (for finite differences of the distance)."""
    for req in task.geometry_data.distanceRequests:
        req.gjk_tolerance = 1e-12
        req.epa_tolerance = 1e-12


# ------------------------------------------------------------------------ construction
def test_panda_pairs_after_srdf(panda):
    ca = CollisionAvoidance(panda)
    assert len(ca.pairs) == 44  # 17 geometries, SRDF's disabled pairs removed
    assert ca.task.shape == (44, panda.nv)
    names = {n for pair in ca.pairs for n in pair}
    assert "panda_link0_0" in names and "panda_hand_0" in names
    # meshes are convex hulls by default
    kinds = {type(go.geometry).__name__ for go in ca.geometry_model.geometryObjects}
    assert "Convex" in kinds and not any("BVH" in k for k in kinds)
    # no pair on one joint or on adjacent joints
    model = panda.model
    for k in range(len(ca.pairs)):
        cp = ca.geometry_model.collisionPairs[k]
        ja = ca.geometry_model.geometryObjects[cp.first].parentJoint
        jb = ca.geometry_model.geometryObjects[cp.second].parentJoint
        assert ja != jb and model.parents[ja] != jb and model.parents[jb] != ja


def test_obstacle_rows_and_shapes(panda):
    obstacles = [
        Sphere([0.5, 0.0, 0.4], 0.05),
        Box([0.4, 0.3, 0.2], [0.05, 0.1, 0.02]),
        Capsule([0.3, -0.3, 0.0], [0.3, -0.3, 0.5], 0.03),
        (coal.Cylinder(0.05, 0.3), np.eye(4)),
    ]
    ca = CollisionAvoidance(panda, obstacles, self_collision=False)
    assert len(ca.pairs) == 4 * 17  # every robot geometry against every obstacle
    ca_hand = CollisionAvoidance(panda, obstacles[:1], self_collision=False, frames=["panda_hand"])
    assert ca_hand.pairs == [("panda_hand_0", "obstacle:sphere:0")]
    # shapes stay constant whatever is near
    for seed in range(3):
        task = ca.update(panda.random_configuration(seed), dt=0.01)
        assert task.C.shape == (68, panda.nv)
        far = ~ca.active
        assert np.all(task.C[far] == 0) and np.all(np.isneginf(task.lower[far]))
        assert np.all(np.isposinf(task.upper))


def test_locked_fingers_geometry_follows_the_reduced_model(panda):
    # the fingers of "panda" are locked: their boxes hang on joint 7 at the locked opening
    gm = collision_geometry(panda)
    fingers = [go for go in gm.geometryObjects if "finger" in go.name]
    assert fingers and all(go.parentJoint == 7 for go in fingers)
    full = qc.robots.load("panda_fingers")
    ca = CollisionAvoidance(full)
    assert len(ca.pairs) > 0 and ca.task.shape[1] == full.nv == 9


def test_geometry_model_argument(panda):
    gm = pin.GeometryModel()
    gm.addGeometryObject(
        pin.GeometryObject("ball", 7, pin.SE3(np.eye(3), np.array([0, 0, 0.1])), coal.Sphere(0.05))
    )
    ca = CollisionAvoidance(
        panda, [Sphere([0.5, 0, 0.5], 0.1)], self_collision=False, geometry_model=gm
    )
    assert ca.pairs == [("ball", "obstacle:sphere:0")]


# ------------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    "make, word",
    [
        (lambda: Sphere([0, 0, 0], -0.1), "radius"),
        (lambda: Sphere([np.nan, 0, 0], 0.1), "centre"),
        (lambda: Sphere([0, 0], 0.1), "centre"),
        (lambda: Box([0, 0, 0], [0.1, -0.1, 0.1]), "half_extents"),
        (lambda: Box([0, 0, 0], [0.1, 0.1, 0.1], rotation=2 * np.eye(3)), "rotation"),
        (lambda: Capsule([0, 0, 0], [0, 0, np.inf], 0.1), "end"),
        (lambda: Obstacle("ball"), "geometry"),
    ],
)
def test_bad_obstacles(make, word):
    with pytest.raises(ValueError, match=word):
        make()


@pytest.mark.parametrize(
    "kwargs, word",
    [
        (dict(min_distance=0.1, influence_distance=0.1), "min_distance"),
        (dict(min_distance=0.2, influence_distance=0.1), "influence_distance"),
        (dict(min_distance=-0.01), "min_distance"),
        (dict(influence_distance=np.nan), "influence_distance"),
        (dict(gain=0.0), "gain"),
        (dict(gain=-1.0), "gain"),
        (dict(frames=["panda_link99"]), "frames"),
        (dict(frames=["panda_joint1"]), "frames"),
        (dict(ignore_pairs=[("panda_link1", "nope")]), "ignore_pairs"),
        (dict(obstacles=["ball"]), "obstacles"),
        (dict(self_collision=False), "no pair"),
    ],
)
def test_bad_arguments(panda, kwargs, word):
    with pytest.raises(ValueError, match=word):
        CollisionAvoidance(panda, **kwargs)


def test_robot_without_urdf():
    arm = qc.robots.load("planar_3r")
    with pytest.raises(ValueError, match="geometry_model"):
        CollisionAvoidance(arm, [Sphere([1, 1, 0], 0.1)])


# ------------------------------------------------------------------------ distance Jacobian
def test_distance_jacobian_matches_finite_differences(panda):
    """Each active row is ḋ/v: central differences of d along robot.integrate, at pairs
    where the distance is smooth (two step sizes agree)."""
    ca = CollisionAvoidance(
        panda,
        [Sphere([0.45, 0.1, 0.35], 0.1), Box([0.3, -0.3, 0.3], [0.05, 0.08, 0.1])],
        influence_distance=0.3,
    )
    _tight(ca)
    rng = np.random.default_rng(0)
    checked = 0
    for seed in range(8):
        q = panda.random_configuration(seed)
        C = ca.update(q, dt=0.01).C.copy()
        d0 = ca.compute_distances(q)
        v = rng.normal(size=panda.nv)
        fd = []
        for h in (1e-4, 5e-5):
            plus = ca.compute_distances(panda.integrate(q, v, h))
            minus = ca.compute_distances(panda.integrate(q, v, -h))
            fd.append((plus - minus) / (2 * h))
        for k in np.flatnonzero(ca.active):
            assert ca.distances[k] == pytest.approx(d0[k], abs=1e-9)
            if d0[k] <= 0 or abs(fd[0][k] - fd[1][k]) > 1e-5 * (1 + abs(fd[0][k])):
                continue  # penetration (EPA) or a non-smooth point: no derivative
            assert C[k] @ v == pytest.approx(fd[0][k], abs=1e-5, rel=1e-4), ca.pairs[k]
            checked += 1
    assert checked >= 30


def test_inactive_rows_beyond_influence(panda):
    q = panda.reference_configuration("default")
    ca = CollisionAvoidance(panda, [Sphere([5.0, 0, 0], 0.1)])
    ca.update(q, dt=0.01)
    d = ca.compute_distances(q)
    assert np.array_equal(ca.active, np.isfinite(ca.distances) & (ca.distances < 0.1))
    assert np.all(d[~ca.active] >= 0.1 - 1e-9)  # broad phase skipped only far pairs
    assert not ca.active[-17:].any()  # the far sphere


# ------------------------------------------------------------------------ dt consistency
def test_bound_is_a_velocity_consistent_with_dt(panda):
    """The row bounds ḋ (m/s), not a displacement: the same at any dt while ξ dt ≤ d_i − d_s,
    and clamped to −(d − d_s)/dt beyond, so one first-order step never crosses d_s
    (mink 1.3's CollisionAvoidanceLimit bound is 1/dt too loose)."""
    q = panda.reference_configuration("default")
    p = panda.frame_pose(q, HAND)[:3, 3]
    sphere = Sphere(p + [0.11, 0.0, 0.0], 0.05)  # hand hull ≈ 6 cm from the sphere
    ca = CollisionAvoidance(panda, [sphere], self_collision=False, gain=0.5)
    lo_fast = ca.update(q, dt=0.001).lower.copy()
    lo_slow = ca.update(q, dt=0.01).lower.copy()
    act = ca.active
    assert act.any()
    d = ca.distances[act]
    assert np.allclose(lo_fast[act], lo_slow[act])
    assert np.allclose(lo_slow[act], -0.5 * (d - 0.02) / 0.08)
    # a gain too large for dt is clamped: ξ_eff = (d_i − d_s)/dt
    big = CollisionAvoidance(panda, [sphere], self_collision=False, gain=100.0)
    assert big.effective_gain(0.01) == pytest.approx(8.0)
    lo = big.update(q, dt=0.01).lower
    assert np.allclose(lo[act], -(d - 0.02) / 0.01)
    # the step that meets every bound ends at d ≥ d_s to first order
    assert np.all(d + 0.01 * lo[act] >= 0.02 - 1e-12)


class _LooseByOneOverDt(CollisionAvoidance):
    """The peer defect: a displacement bound used as a velocity bound (1/dt too loose)."""

    def effective_gain(self, dt):
        return self.gain / dt


def _drive_through_sphere(panda, gain, dt, hard, cls=CollisionAvoidance):
    q = panda.reference_configuration("default")
    start = panda.frame_pose(q, HAND)
    sphere = Sphere(start[:3, 3] + [0.25, 0.0, 0.0], 0.05)
    ca = cls(panda, [sphere], min_distance=0.02, influence_distance=0.10, gain=gain)
    obstacle_rows = np.array(["obstacle" in b for _, b in ca.pairs])
    target = start.copy()
    target[:3, 3] += [0.5, 0.0, 0.0]  # straight through the sphere, to its far side
    reach = qc.FrameTask(panda, HAND, target, gain=2.0)
    posture = qc.PostureTask(panda, q, gain=1.0)
    if hard:
        ik = qc.IK(panda, [reach, posture], dt, constraints=[ca])
    else:
        ik = qc.IK(panda, [ca, reach, posture], dt)
    d_min = np.inf
    for _ in range(int(2.0 / dt)):
        v, _ = ik.step(q)
        q = panda.integrate(q, v, dt)
        d_min = min(d_min, float(ca.compute_distances(q)[obstacle_rows].min()))
    travelled = panda.frame_pose(q, HAND)[0, 3] - start[0, 3]
    return d_min, float(ca.compute_distances(q)[obstacle_rows].min()), travelled


@pytest.mark.parametrize(
    "gain, dt, hard",
    [(0.5, 0.01, True), (0.5, 0.01, False), (100.0, 0.01, True), (100.0, 0.05, False)],
)
def test_hand_driven_through_a_sphere_stops_at_the_safety_distance(panda, gain, dt, hard):
    d_min, d_end, travelled = _drive_through_sphere(panda, gain, dt, hard)
    assert d_min >= 0.02 - TOL  # never closer than d_s, at any step
    assert d_end == pytest.approx(0.02, abs=2e-3)  # and it did come to the safety distance
    assert 0.1 < travelled < 0.25  # stopped in front of the sphere, not past it


def test_a_bound_one_over_dt_too_loose_lets_the_hand_in(panda):
    """Control of the test above: the same run with mink 1.3's scaling (the bound 1/dt too
    loose) crosses the safety distance (measured: 1.5 cm for d_s = 2 cm)."""
    d_min, _, _ = _drive_through_sphere(panda, 0.5, 0.01, False, _LooseByOneOverDt)
    assert d_min < 0.02 - 10 * TOL


@pytest.mark.parametrize("seed", [0, 3])
def test_panda_self_collision_random_targets(panda, seed):
    """5 s at dt = 0.01 s, a new random reachable pose target every 0.5 s: no self pair comes
    closer than min_distance (without the task, the same run collides or comes closer)."""
    rng = np.random.default_rng(seed)
    dt = 0.01
    q0 = panda.reference_configuration("default")
    ca = CollisionAvoidance(panda, min_distance=0.02)
    reach = qc.FrameTask(panda, HAND, None, gain=3.0)
    posture = qc.PostureTask(panda, q0, gain=0.5)
    targets = [panda.frame_pose(panda.random_configuration(rng), HAND) for _ in range(10)]
    d_min = {}
    for use in (True, False):
        ik = qc.IK(panda, [ca, reach, posture] if use else [reach, posture], dt)
        q, d_min[use], steps_active = q0.copy(), np.inf, 0
        for k in range(int(5.0 / dt)):
            if k % 50 == 0:
                reach.set_target(targets[k // 50])
            v, _ = ik.step(q)
            steps_active += bool(ca.active.any()) if use else 0
            q = panda.integrate(q, v, dt)
            d_min[use] = min(d_min[use], float(ca.compute_distances(q).min()))
        if use:
            assert steps_active > 0
    assert d_min[True] >= 0.02 - TOL
    assert d_min[False] < 0.02 - TOL  # the scenario does drive the arm into itself


def test_moving_an_obstacle(panda):
    q = panda.reference_configuration("default")
    p = panda.frame_pose(q, HAND)[:3, 3]
    ca = CollisionAvoidance(panda, [Sphere([3.0, 0, 0], 0.05)], self_collision=False)
    ca.update(q, dt=0.01)
    assert not ca.active.any()
    ca.set_obstacle_pose(0, p + [0.12, 0, 0])
    ca.update(q, dt=0.01)
    assert ca.active.any()
    assert ca.compute_distances(q).min() == pytest.approx(ca.distances[ca.active].min())
    with pytest.raises(ValueError, match="index"):
        ca.set_obstacle_pose(3, p)


def test_a_half_space_wall_stops_the_hand(panda):
    """A half-space obstacle (coal gives it an unbounded bounding sphere) is a broad-phase
    candidate at every step: the hand driven at a wall stops at the safety distance. Without
    the unbounded case the broad phase computed ``inf − inf`` and never checked the pair (the
    hand went 0.2 m into the wall)."""
    dt = 0.01
    q = panda.reference_configuration("default")
    start = panda.frame_pose(q, HAND)
    wall_x = float(start[0, 3]) + 0.15
    wall = Obstacle(coal.Halfspace(np.array([-1.0, 0.0, 0.0]), -wall_x), name="wall")
    ca = CollisionAvoidance(panda, [wall], self_collision=False, gain=0.5)
    target = start.copy()
    target[:3, 3] += [0.4, 0.0, 0.0]  # 25 cm behind the wall
    ik = qc.IK(
        panda,
        [qc.FrameTask(panda, HAND, target, gain=2.0), qc.PostureTask(panda, q, gain=1.0)],
        dt,
        constraints=[ca],
    )
    d_min = np.inf
    for _ in range(int(2.0 / dt)):
        v, _ = ik.step(q)
        q = panda.integrate(q, v, dt)
        d_min = min(d_min, float(ca.compute_distances(q).min()))
    assert d_min >= ca.min_distance - TOL  # never closer than d_s to the wall
    assert panda.frame_pose(q, HAND)[0, 3] < wall_x  # the hand stayed in front of it


def test_the_broad_phase_sphere_holds_the_geometry(panda):
    """The broad-phase ball of a shape contains it: a swept-sphere radius is added (coal's
    box leaves it out, its distances include it); a hull's ball reaches its farthest vertex
    from the box's centre (the Panda's base: 0.136 m against the box's half-diagonal 0.163)."""
    g = coal.Sphere(0.05)
    g.setSweptSphereRadius(0.01)
    centre, radius = _bounding_sphere(pin.GeometryObject("s", 0, pin.SE3.Identity(), g))
    assert radius == pytest.approx(0.06, abs=1e-15) and np.all(centre == 0)
    go = collision_geometry(panda).geometryObjects[0]  # panda_link0_0, a hull
    hull = go.geometry
    centre, radius = _bounding_sphere(go)
    vertices = np.array([go.placement.act(v) for v in np.array(hull.points())])
    far = np.linalg.norm(vertices - centre, axis=1).max()
    # the same distances computed in another frame: equal to the placement's rounding
    assert radius == pytest.approx(far, abs=1e-12)
    assert radius < hull.aabb_radius - 0.02
