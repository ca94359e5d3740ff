"""Collision avoidance: velocity-damper inequalities from the robot's collision geometry.

:class:`CollisionAvoidance` keeps every watched pair of geometries -- the robot against itself
and the robot against obstacles (:class:`Sphere`, :class:`Box`, :class:`Capsule`, or any coal
geometry with a pose, :class:`Obstacle`) -- at least ``min_distance`` apart. It is one
:class:`~qpcoord.Inequality` on the velocity ``v`` (``robot.nv`` columns) with **one row per
candidate pair** (a constant shape, so a stack built once is re-solved every step): for a
pair at distance ``d`` (m) below the influence distance ``d_i`` the row is the velocity damper
(Faverjon & Tournassoud, Kanoun)

    ḋ = n · (J_p2 − J_p1) v  ≥  −ξ (d − d_s) / (d_i − d_s)

with ``d_s = min_distance`` (m), ``ξ = gain`` (**m/s**: the largest approach speed allowed
at the edge of the influence zone), ``p1, p2`` the witness points of the pair (world, m),
``n`` the unit normal from ``p1`` toward ``p2`` and ``J_p`` the Jacobian of the body point
at ``p`` (the frame Jacobian translated to the witness point). Rows of pairs at ``d ≥ d_i``
are inactive (zero row, ``±inf`` bounds).

Consistency with ``dt``
-----------------------
After one first-order step, ``d(t + dt) ≈ d + dt ḋ ≥ d_s + (d − d_s)(1 − ξ dt/(d_i − d_s))``:
the damper keeps ``d ≥ d_s`` **exactly when** ``ξ dt ≤ d_i − d_s``. The task enforces this
rule itself: the gain used at a step is ``ξ_eff = min(ξ, (d_i − d_s)/dt)``
(:meth:`CollisionAvoidance.effective_gain`), so a large gain never lets a step cross the
safety distance (the bound is a velocity, in m/s, never a displacement divided by ``dt``
twice). A pair outside ``d_i`` is free for one step: choose ``d_i − d_s`` larger than the
distance two bodies can close in one step (closing speed × dt).

Geometry and cost
-----------------
The robot's collision geometry is read from its URDF (``robot.urdf_path``,
``robot.package_dirs``; locked joints are handled because the geometry is attached to the
frames of the robot's own, reduced, model) or given as a ``pinocchio.GeometryModel``. Meshes
are replaced by their **convex hulls** by default (a hull contains its mesh, so a distance to
the hull is a lower bound of the distance to the mesh): coal's GJK on hulls costs about a
microsecond a pair, a mesh (BVH) distance tens to hundreds. The SRDF's disabled pairs are
removed (``pinocchio.removeCollisionPairs``), as are pairs on one joint or on two adjacent
joints. A broad phase skips, before calling coal, the pairs whose bounding spheres are
farther apart than ``d_i``, and those that cannot have come within ``d_i`` since their last
exact distance ``d0``: a point of a geometry whose bounding ball (radius ``r``) went from
rotation ``R0`` and centre ``c0`` to ``R1``, ``c1`` moved at most
``|c1 − c0| + ‖R1 − R0‖_F r``, so the pair's distance is at least ``d0`` minus both
geometries' bounds (a pair far from the others then costs no coal call while it moves
slowly).

Each step's rows -- the broad phase, coal's distance for each candidate pair, the witness
points and the Jacobian rows -- are computed in one native call (``qpcoord._collision``, on
coal's C++ library; :mod:`qpcoord.kinematics.collision_kernel`) or, where that module or a
shape is not available, by the same rows in Python (:attr:`CollisionAvoidance.native` says
which). In an :class:`~qpcoord.IK` on the native engine the native rows are computed from
inside its native step (the kernel handed over as a C entry point,
``src/native/rows_kernel.h``): no Python runs for them per step. Measured on the Panda
(2-core Xeon, OpenBLAS single-threaded,
``python benchmarks/collision_bench.py --update``, a 5 s random-target run at dt = 0.01 s): one
:meth:`~CollisionAvoidance.update` -- forward kinematics and Jacobians, then the rows --
costs a median **≈ 32 µs** with self-collision only (44 pairs) or with one sphere (61 pairs)
and **≈ 55 µs** with a sphere, a box and a capsule (95 pairs, more of them near each other);
the Python rows cost 82, 82 and 166 µs. Meshes instead of hulls (``convex=False``, Python
rows) cost milliseconds a step.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from ..core.tasks import Inequality
from .collision_kernel import native_kernel
from .robot import Robot
from .tasks import KinematicTask

__all__ = [
    "Sphere",
    "Box",
    "Capsule",
    "Obstacle",
    "CollisionAvoidance",
    "collision_geometry",
]


# ---------------------------------------------------------------------------- checks
def _finite_vector(value: Any, size: int, what: str, unit: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be {size} numbers ({unit}), got {value!r}") from None
    if arr.shape != (size,):
        raise ValueError(f"{what} must be {size} numbers ({unit}), got shape {np.shape(value)}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be finite ({unit}), got {arr.tolist()}")
    return arr


def _number(value: Any, what: str, unit: str, *, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{what} must be a number ({unit}), got {value!r}")
    x = float(value)
    if not np.isfinite(x):
        raise ValueError(f"{what} must be finite ({unit}), got {value!r}")
    if positive and x <= 0:
        raise ValueError(f"{what} must be > 0 ({unit}), got {value!r}")
    if not positive and x < 0:
        raise ValueError(f"{what} must be >= 0 ({unit}), got {value!r}")
    return x


def _rotation(value: Any, what: str) -> np.ndarray:
    if value is None:
        return np.eye(3)
    try:
        R = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a 3×3 rotation matrix, got {value!r}") from None
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise ValueError(f"{what} must be a finite 3×3 rotation matrix, got shape {R.shape}")
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
        raise ValueError(f"{what} must be a rotation matrix (RᵀR = I, det R = +1)")
    return R


def _pose(value: Any, what: str = "pose") -> np.ndarray:
    if isinstance(value, pin.SE3):
        return np.array(value.homogeneous)
    try:
        T = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a 4×4 homogeneous matrix or pin.SE3") from None
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"{what} must be a finite 4×4 homogeneous matrix, got shape {T.shape}")
    if np.abs(T[3] - (0, 0, 0, 1)).max() > 1e-12:
        raise ValueError(f"{what}: last row must be (0, 0, 0, 1)")
    _rotation(T[:3, :3], f"{what}[:3, :3]")
    return T


#: m: the broad phase's last-distance bound subtracts this from a pair's last distance:
#: coal's GJK stops within its tolerance of the true distance (two runs with other support
#: hints differ by up to 3e-6 m on the Panda)
_SKIP_MARGIN = 1e-4


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise ``a × b`` of (m, 3) arrays (np.cross costs ~10 µs of overhead a call)."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    return np.stack((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0), axis=1)


# ---------------------------------------------------------------------------- obstacles
class Obstacle:
    """A fixed obstacle: any coal geometry at a pose in the world.

    Parameters
    ----------
    geometry : coal.CollisionGeometry
        E.g. ``coal.Cylinder(r, h)``, ``coal.Convex``, ``coal.Halfspace`` (m).
    pose : array_like (4, 4) or pin.SE3
        Placement of the geometry's frame in the world (m).
    name : str
    """

    def __init__(self, geometry: Any, pose: Any = None, name: str = "obstacle") -> None:
        if not isinstance(geometry, coal.CollisionGeometry):
            raise ValueError(
                f"geometry must be a coal geometry (coal.Sphere, coal.Box, ...), got "
                f"{type(geometry).__name__}"
            )
        self._geometry = geometry
        self.pose = np.eye(4) if pose is None else _pose(pose)
        self.name = str(name)

    def geometry(self) -> coal.CollisionGeometry:
        """The coal geometry (in its own frame, m)."""
        return self._geometry

    @property
    def centre(self) -> np.ndarray:
        """Origin of the obstacle's frame in the world (m), (3,)."""
        return self.pose[:3, 3].copy()

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, centre={self.pose[:3, 3].tolist()})"


def _bounding_sphere(go: Any) -> tuple[np.ndarray, float]:
    """Bounding sphere of a geometry object for the broad phase: centre (m, in its parent
    joint's frame) and radius (m). An unbounded geometry (a half-space or a plane: coal gives
    it an infinite radius and a centre near 1e308) gets the origin and an infinite radius,
    so every pair with it is always a candidate (``gap = −inf``) instead of ``inf − inf``.
    A convex hull's radius is its farthest vertex from the box's centre (the hull is inside
    that ball), tighter than the box's half-diagonal: on the Panda's 1 kHz circle with
    self-collision and a sphere, 7.2 instead of 9.6 pairs a step reach coal, all farther than
    d_i. A shape's swept-sphere radius is added (coal's box leaves it out; its distances
    include it)."""
    g = go.geometry
    g.computeLocalAABB()
    centre = np.array(g.aabb_center, dtype=float)
    radius = float(g.aabb_radius)
    if not (np.isfinite(radius) and np.all(np.isfinite(centre)) and np.abs(centre).max() < 1e150):
        return np.zeros(3), np.inf
    if isinstance(g, coal.Convex) and g.num_points > 0:
        vertices = np.array(g.points(), dtype=float).reshape(-1, 3)
        radius = min(radius, float(np.linalg.norm(vertices - centre, axis=1).max()))
    if isinstance(g, coal.ShapeBase):
        radius += g.getSweptSphereRadius()
    return go.placement.act(centre), radius


class Sphere(Obstacle):
    """A ball of ``radius`` (m) centred at ``centre`` (m, world).

    Raises
    ------
    ValueError
        ``centre`` not 3 finite numbers, ``radius`` negative or not finite.
    """

    def __init__(self, centre: Any, radius: float, name: str = "sphere") -> None:
        c = _finite_vector(centre, 3, "centre", "m")
        self.radius = _number(radius, "radius", "m")
        T = np.eye(4)
        T[:3, 3] = c
        super().__init__(coal.Sphere(self.radius), T, name)


class Box(Obstacle):
    """A box of ``half_extents`` (m) centred at ``centre`` (m), axes ``rotation`` (3×3).

    Raises
    ------
    ValueError
        ``centre`` or ``half_extents`` not 3 finite numbers, a negative half extent, a
        ``rotation`` that is not a rotation matrix.
    """

    def __init__(
        self, centre: Any, half_extents: Any, rotation: Any = None, name: str = "box"
    ) -> None:
        c = _finite_vector(centre, 3, "centre", "m")
        h = _finite_vector(half_extents, 3, "half_extents", "m")
        if np.any(h < 0):
            raise ValueError(f"half_extents must be >= 0 (m), got {h.tolist()}")
        self.half_extents = h
        self.rotation = _rotation(rotation, "rotation")
        T = np.eye(4)
        T[:3, :3] = self.rotation
        T[:3, 3] = c
        super().__init__(coal.Box(*(2.0 * h)), T, name)


class Capsule(Obstacle):
    """A capsule: the points within ``radius`` (m) of the segment from ``start`` to ``end``
    (m, world).

    Raises
    ------
    ValueError
        ``start`` / ``end`` not 3 finite numbers, ``radius`` negative.
    """

    def __init__(self, start: Any, end: Any, radius: float, name: str = "capsule") -> None:
        a = _finite_vector(start, 3, "start", "m")
        b = _finite_vector(end, 3, "end", "m")
        self.radius = _number(radius, "radius", "m")
        self.start, self.end = a, b
        axis = b - a
        length = float(np.linalg.norm(axis))
        T = np.eye(4)
        T[:3, 3] = 0.5 * (a + b)
        if length > 0:
            z = axis / length
            # any rotation taking e_z to z
            x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
            x /= np.linalg.norm(x)
            T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
        super().__init__(coal.Capsule(self.radius, length), T, name)


def _as_obstacle(item: Any, k: int) -> Obstacle:
    if isinstance(item, Obstacle):
        return item
    if isinstance(item, coal.CollisionGeometry):
        return Obstacle(item, None, f"obstacle {k}")
    if isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], coal.CollisionGeometry):
        return Obstacle(item[0], _pose(item[1], f"obstacles[{k}] pose"), f"obstacle {k}")
    raise ValueError(
        f"obstacles[{k}] must be a qc.Sphere, qc.Box, qc.Capsule, qc.Obstacle or a "
        f"(coal geometry, 4×4 pose) pair, got {item!r}"
    )


# ---------------------------------------------------------------------------- geometry
def _load_geometry(robot: Robot) -> pin.GeometryModel:
    if robot.urdf_path is None:
        raise ValueError(
            f"robot {robot.name!r} was not read from a URDF (robot.urdf_path is None): pass "
            "its collision geometry as geometry_model=pinocchio.GeometryModel"
        )
    try:
        return pin.buildGeomFromUrdf(
            robot.model,
            str(robot.urdf_path),
            pin.COLLISION,
            package_dirs=list(robot.package_dirs),
        )
    except Exception as exc:  # pinocchio raises ValueError/RuntimeError by version
        raise ValueError(
            f"robot {robot.name!r}: the collision geometry of {str(robot.urdf_path)!r} could "
            f"not be loaded ({exc}); check robot.package_dirs"
        ) from None


def collision_geometry(
    robot: Robot, convex: bool = True, geometry_model: pin.GeometryModel | None = None
) -> pin.GeometryModel:
    """The robot's collision ``GeometryModel`` (a new one; no collision pairs).

    Read from ``robot.urdf_path`` against the robot's own Pinocchio model (locked joints
    included: the geometry hangs on the frames of the reduced model), or copied from
    ``geometry_model``. With ``convex=True`` every mesh (BVH) is replaced by its convex hull.

    Raises
    ------
    ValueError
        No URDF and no ``geometry_model``; meshes not found.
    """
    if geometry_model is None:
        gm = _load_geometry(robot)
    else:
        if not isinstance(geometry_model, pin.GeometryModel):
            raise ValueError(
                f"geometry_model must be a pinocchio.GeometryModel, got "
                f"{type(geometry_model).__name__}"
            )
        gm = pin.GeometryModel()
        for go in geometry_model.geometryObjects:
            gm.addGeometryObject(go.copy())
    for go in gm.geometryObjects:
        if go.parentJoint >= robot.model.njoints:
            raise ValueError(
                f"geometry_model: object {go.name!r} hangs on joint {go.parentJoint}, the robot "
                f"has {robot.model.njoints} joints"
            )
        if convex and isinstance(go.geometry, coal.BVHModelBase):
            go.geometry.buildConvexRepresentation(False)
            go.geometry = go.geometry.convex
    return gm


# ---------------------------------------------------------------------------- the task
class CollisionAvoidance(KinematicTask):
    """Keep the robot off itself and off obstacles: velocity dampers on pair distances.

    One row per candidate pair, ``n·(J_p2 − J_p1) v ≥ −ξ_eff (d − d_s)/(d_i − d_s)`` while
    ``d < d_i`` (inactive otherwise), with ``ξ_eff = min(ξ, (d_i − d_s)/dt)`` so that one
    first-order step never crosses ``d_s`` (see the module docstring). Like every task it can
    be hard (``IK(..., constraints=[task])``), the top level, or a lower level; a pair already
    closer than ``d_s`` gets a positive lower bound (pushed apart at most at
    ``(d_s − d)/dt``). Hard, such rows can conflict with the joint speed limits (an
    ``InfeasibleError``, e.g. when starting in contact); at level 0 their violation is
    minimised instead, the robust choice.

    Parameters
    ----------
    robot : Robot
        Read from a URDF (``robot.urdf_path``), or pass ``geometry_model``.
    obstacles : sequence
        :class:`Sphere`, :class:`Box`, :class:`Capsule`, :class:`Obstacle`, or
        ``(coal geometry, 4×4 pose)`` pairs: fixed in the world (m). Every selected robot
        geometry is paired with every obstacle. Move one with :meth:`set_obstacle_pose`.
    self_collision : bool
        Watch the robot's own pairs (default True): all pairs of geometries minus the SRDF's
        disabled pairs (``robot.srdf_path``), minus pairs on one joint or on adjacent joints.
    min_distance : float
        ``d_s`` (m), the safety distance, >= 0 (default 0.02).
    influence_distance : float
        ``d_i`` (m), > ``min_distance``: pairs farther apart have no active row (default 0.10).
    gain : float
        ``ξ`` (m/s), > 0: the approach speed allowed at ``d = d_i``; the distance above
        ``d_s`` then decays at most at the rate ``ξ/(d_i − d_s)`` (1/s). Default 0.5.
    convex : bool
        Replace meshes by their convex hulls (default True; a mesh distance costs
        milliseconds a step).
    frames : sequence of str, optional
        Robot frames (links) whose collision geometries take part (default all). A self pair
        is kept when both of its geometries are selected.
    ignore_pairs : sequence of (str, str)
        Further robot link pairs (frame names) to skip in self-collision.
    geometry_model : pinocchio.GeometryModel, optional
        The robot's collision geometry (default: read from the URDF); copied.
    name : str

    Attributes
    ----------
    pairs : list of (str, str)
        Geometry names of each row (robot geometry first; obstacles last).
    distances : numpy.ndarray
        Distance of each pair at the last update (m): exact for pairs that passed the broad
        phase, ``inf`` for pairs it skipped (proved farther than ``d_i``).
    active : numpy.ndarray of bool
        Rows with a damper at the last update.
    native : bool
        Whether a step computes the rows natively (``qpcoord._collision``: the broad phase,
        coal's distances and the rows in one call) or in Python (the same rows; see
        :mod:`qpcoord.kinematics.collision_kernel` for when the native rows are not used).
        Native rows in an :class:`~qpcoord.IK` on the native engine are computed inside its
        native step call (no Python per step) when the task's robot is the IK's.

    Raises
    ------
    ValueError
        ``min_distance`` < 0 or ``>= influence_distance``, ``gain`` <= 0, an unknown frame in
        ``frames`` or ``ignore_pairs``, a bad obstacle, no pair to watch, no geometry.
    """

    task: Inequality

    def __init__(
        self,
        robot: Robot,
        obstacles: Iterable[Any] = (),
        self_collision: bool = True,
        min_distance: float = 0.02,
        influence_distance: float = 0.10,
        gain: float = 0.5,
        *,
        convex: bool = True,
        frames: Sequence[str] | None = None,
        ignore_pairs: Sequence[tuple[str, str]] = (),
        geometry_model: pin.GeometryModel | None = None,
        name: str = "collision avoidance",
    ) -> None:
        if not isinstance(robot, Robot):
            raise ValueError(f"{name}: robot must be a qpcoord.Robot, got {type(robot).__name__}")
        d_s = _number(min_distance, "min_distance", "m")
        d_i = _number(influence_distance, "influence_distance", "m", positive=True)
        if d_s >= d_i:
            raise ValueError(f"min_distance ({d_s} m) must be < influence_distance ({d_i} m)")
        xi = _number(gain, "gain", "m/s", positive=True)
        if obstacles is None:
            obstacles = ()
        if isinstance(obstacles, (Obstacle, coal.CollisionGeometry)):
            obstacles = [obstacles]
        try:
            obstacle_list = [_as_obstacle(o, k) for k, o in enumerate(obstacles)]
        except TypeError:
            raise ValueError(
                f"obstacles must be a sequence of obstacles, got {obstacles!r}"
            ) from None
        self.min_distance, self.influence_distance = d_s, d_i
        self.obstacles = obstacle_list

        model = robot.model
        gm = collision_geometry(robot, convex=convex, geometry_model=geometry_model)
        n_robot = gm.ngeoms
        if n_robot == 0:
            raise ValueError(
                f"robot {robot.name!r} has no collision geometry (no <collision> element in its "
                "URDF): pass geometry_model=pinocchio.GeometryModel"
            )
        # which robot geometries take part
        selected = np.ones(n_robot, dtype=bool)
        if frames is not None:
            if isinstance(frames, str):
                frames = [frames]
            wanted = {robot.frame_index(f, "frames") for f in frames}
            carried = {int(go.parentFrame) for go in gm.geometryObjects}
            for f in frames:
                if robot.frame_index(f, "frames") not in carried:
                    raise ValueError(f"frames: frame {f!r} carries no collision geometry")
            selected = np.array([int(go.parentFrame) in wanted for go in gm.geometryObjects])
        ignored = set()
        for k, pair in enumerate(ignore_pairs):
            if not (isinstance(pair, (tuple, list)) and len(pair) == 2):
                raise ValueError(f"ignore_pairs[{k}] must be a pair of frame names, got {pair!r}")
            a, b = (robot.frame_index(f, f"ignore_pairs[{k}]") for f in pair)
            ignored.add(frozenset((a, b)))

        # self pairs: all, minus the SRDF's, minus same / adjacent joints and ignored links
        pairs: list[tuple[int, int]] = []
        if self_collision:
            gm.addAllCollisionPairs()
            if robot.srdf_path is not None:
                pin.removeCollisionPairs(model, gm, str(robot.srdf_path))
            parents = model.parents
            for cp in gm.collisionPairs:
                i, j = int(cp.first), int(cp.second)
                gi, gj = gm.geometryObjects[i], gm.geometryObjects[j]
                ji, jj = int(gi.parentJoint), int(gj.parentJoint)
                if ji == jj or parents[ji] == jj or parents[jj] == ji:
                    continue
                if not (selected[i] and selected[j]):
                    continue
                if frozenset((int(gi.parentFrame), int(gj.parentFrame))) in ignored:
                    continue
                pairs.append((i, j))
            gm.removeAllCollisionPairs()
        # obstacles hang on the universe (joint 0)
        for k, obs in enumerate(obstacle_list):
            go = pin.GeometryObject(
                f"obstacle:{obs.name}:{k}", 0, pin.SE3(obs.pose), obs.geometry()
            )
            idx = gm.addGeometryObject(go)
            pairs.extend((i, idx) for i in range(n_robot) if selected[i])
        if not pairs:
            raise ValueError(
                f"{name}: no pair to watch (self_collision={self_collision}, "
                f"{len(obstacle_list)} obstacles)"
            )
        for i, j in pairs:
            gm.addCollisionPair(pin.CollisionPair(i, j))
        self.geometry_model = gm
        self.geometry_data = gm.createData()
        self._obstacle_geometry = list(range(n_robot, gm.ngeoms))
        self.pairs = [(gm.geometryObjects[i].name, gm.geometryObjects[j].name) for i, j in pairs]
        self._first = np.array([p[0] for p in pairs], dtype=int)
        self._second = np.array([p[1] for p in pairs], dtype=int)

        super().__init__(robot, len(pairs), kind="band", gain=xi, name=name)
        self.gain = xi

        # per-geometry broad-phase data: joint, bounding-sphere centre in the joint frame, radius
        njoints = model.njoints
        self._geom_joint = np.array([int(go.parentJoint) for go in gm.geometryObjects])
        centres, radii = [], []
        for go in gm.geometryObjects:
            centre, radius = _bounding_sphere(go)
            centres.append(centre)
            radii.append(radius)
        self._geom_centre = np.array(centres)
        self._geom_radius = np.array(radii)
        self._joints = [int(j) for j in np.unique(self._geom_joint[self._geom_joint > 0])]
        self._R = np.tile(np.eye(3), (njoints, 1, 1))
        self._t = np.zeros((njoints, 3))
        # joint support masks over v: the columns of data.J that move each joint
        support = np.zeros((njoints, robot.nv), dtype=bool)
        for j in range(1, njoints):
            for s in model.supports[j]:
                if s > 0:
                    jm = model.joints[s]
                    support[j, jm.idx_v : jm.idx_v + jm.nv] = True
        self._support = support.astype(float)
        self._pair_radius = self._geom_radius[self._first] + self._geom_radius[self._second]
        m = len(pairs)
        self._C = np.zeros((m, robot.nv))
        self._lower = np.full(m, -np.inf)
        self._upper = np.full(m, np.inf)
        self.distances = np.full(m, np.inf)
        self.active = np.zeros(m, dtype=bool)
        # per pair, at its last exact distance: that distance and its geometries' world
        # rotations and ball centres (the broad phase's bound since then: module docstring)
        self._last_ok = np.zeros(m, dtype=bool)
        self._last_d = np.zeros(m)
        self._last_R = np.zeros((m, 2, 3, 3))
        self._last_c = np.zeros((m, 2, 3))
        self._geom_rotation = np.array([go.placement.rotation for go in gm.geometryObjects])
        self._P1 = np.zeros((m, 3))
        self._P2 = np.zeros((m, 3))
        self._N = np.zeros((m, 3))
        columns = [[int(c) for c in np.flatnonzero(support[j])] for j in range(njoints)]
        self._kernel: Any = native_kernel(
            robot,
            gm,
            self._geom_centre,
            self._geom_radius,
            self._first,
            self._second,
            columns,
            d_s,
            d_i,
        )
        if self._kernel is not None:
            self._kernel.bind(self._C, self._lower, self.distances, self.active.view(np.uint8))
        self._kernel_data = robot.data  # the Data whose memory the kernel reads

    @property
    def native(self) -> bool:
        """Whether a step computes the rows natively (the class docstring)."""
        return self._kernel is not None and self.robot.data is self._kernel_data

    # -- helpers ------------------------------------------------------------------------
    def effective_gain(self, dt: float) -> float:
        """``ξ_eff = min(ξ, (d_i − d_s)/dt)`` (m/s): the gain used at control period ``dt``
        (s), the largest one for which one first-order step cannot cross ``d_s``."""
        return min(self.gain, (self.influence_distance - self.min_distance) / float(dt))

    def set_obstacle_pose(self, index: int, pose: Any) -> None:
        """Move obstacle ``index`` to ``pose`` (4×4 / pin.SE3, m) or centre it at ``pose``
        (3 numbers, m; the orientation is kept). Its velocity is not fed forward."""
        if not 0 <= int(index) < len(self.obstacles):
            raise ValueError(f"index: {index} is not one of the {len(self.obstacles)} obstacles")
        obs = self.obstacles[int(index)]
        if np.size(pose) == 3 and not isinstance(pose, pin.SE3):
            T = obs.pose.copy()
            T[:3, 3] = _finite_vector(pose, 3, "pose", "m")
        else:
            T = _pose(pose)
        obs.pose = T
        g = self._obstacle_geometry[int(index)]
        self.geometry_model.geometryObjects[g].placement = pin.SE3(T)
        self._geom_rotation[g] = T[:3, :3]
        self._geom_centre[g] = _bounding_sphere(self.geometry_model.geometryObjects[g])[0]
        if self._kernel is not None:
            self._kernel.set_placement(g, T[:3, :3].copy(), T[:3, 3].copy(), self._geom_centre[g])

    def compute_distances(self, q: Any) -> np.ndarray:
        """Exact distance of every pair at ``q`` (m), shape (rows,), no broad phase (a
        monitoring call, not for the control loop). Negative: penetration depth."""
        q = self.robot.check_configuration(q)
        robot, gm, gd = self.robot, self.geometry_model, self.geometry_data
        robot._update(q, 1)
        pin.updateGeometryPlacements(robot.model, robot.data, gm, gd)
        return np.array(
            [pin.computeDistance(gm, gd, k).min_distance for k in range(len(self.pairs))]
        )

    # -- per step -----------------------------------------------------------------------
    def _refresh(self, q, t, dt, reference) -> Inequality:
        if self.native:
            return self._native_refresh(q, dt)
        return self._python_refresh(q, dt)

    def _native_refresh(self, q: np.ndarray, dt: float) -> Inequality:
        """The rows of :meth:`_python_refresh`, computed by ``qpcoord._collision``."""
        self.robot._update(q, 1)
        self._kernel.update(self.effective_gain(dt))
        return self.task._assign(self._lower, self._upper, C=self._C)

    def _python_refresh(self, q: np.ndarray, dt: float) -> Inequality:
        """The rows in Python: the reference of the native kernel."""
        robot, gm, gd = self.robot, self.geometry_model, self.geometry_data
        model, data = robot.model, robot.data
        robot._update(q, 1)
        # broad phase: bounding spheres in the world
        R, tr = self._R, self._t
        oMi = data.oMi
        for j in self._joints:
            M = oMi[j]
            R[j] = M.rotation
            tr[j] = M.translation
        gj = self._geom_joint
        centres = np.einsum("gab,gb->ga", R[gj], self._geom_centre) + tr[gj]
        diff = centres[self._first] - centres[self._second]
        gap = np.sqrt(np.einsum("ij,ij->i", diff, diff)) - self._pair_radius
        d_s, d_i = self.min_distance, self.influence_distance
        candidates = np.flatnonzero(gap < d_i)
        # the geometries' world rotations (R of a joint without geometry: unused)
        Rw = np.einsum("gab,gbc->gac", R[gj], self._geom_rotation)
        known = candidates[self._last_ok[candidates]]
        if known.size:  # pairs that cannot have come within d_i since their last distance
            a, b = self._first[known], self._second[known]
            c0, R0 = self._last_c[known], self._last_R[known]
            radius = self._geom_radius
            move_a = (
                np.linalg.norm(centres[a] - c0[:, 0], axis=1)
                + np.linalg.norm((Rw[a] - R0[:, 0]).reshape(-1, 9), axis=1) * radius[a]
            )
            move_b = (
                np.linalg.norm(centres[b] - c0[:, 1], axis=1)
                + np.linalg.norm((Rw[b] - R0[:, 1]).reshape(-1, 9), axis=1) * radius[b]
            )
            far = self._last_d[known] - _SKIP_MARGIN - move_a - move_b >= d_i
            candidates = np.setdiff1d(candidates, known[far], assume_unique=True)
        distances = self.distances
        distances.fill(np.inf)
        C, lower = self._C, self._lower
        C.fill(0.0)
        lower.fill(-np.inf)
        self.active.fill(False)
        if candidates.size:
            pin.updateGeometryPlacements(model, data, gm, gd)
            P1, P2, N = self._P1, self._P2, self._N
            for k in candidates:
                res = pin.computeDistance(gm, gd, int(k))
                d = distances[k] = res.min_distance
                if d < d_i:  # witness points and normal only for a row that gets written
                    P1[k] = res.getNearestPoint1()
                    P2[k] = res.getNearestPoint2()
                    N[k] = res.normal
            a, b = self._first[candidates], self._second[candidates]
            bounded = np.isfinite(self._geom_radius)
            self._last_ok[candidates] = bounded[a] & bounded[b] & np.isfinite(distances[candidates])
            self._last_d[candidates] = distances[candidates]
            self._last_R[candidates, 0], self._last_R[candidates, 1] = Rw[a], Rw[b]
            self._last_c[candidates, 0], self._last_c[candidates, 1] = centres[a], centres[b]
            act = candidates[distances[candidates] < d_i]
            if act.size:
                n, p1, p2 = N[act], P1[act], P2[act]
                norm = np.linalg.norm(n, axis=1)
                bad = ~(np.abs(norm - 1.0) < 1e-3)
                if bad.any():  # touching: no normal from coal; use the points or the centres
                    alt = p2[bad] - p1[bad]
                    small = np.linalg.norm(alt, axis=1) < 1e-9
                    alt[small] = (centres[self._second[act[bad]]] - centres[self._first[act[bad]]])[
                        small
                    ]
                    n[bad] = alt / np.maximum(np.linalg.norm(alt, axis=1), 1e-12)[:, None]
                J = data.J
                Jl, Ja = J[:3], J[3:]
                nJ = n @ Jl
                S1 = self._support[gj[self._first[act]]]
                S2 = self._support[gj[self._second[act]]]
                # n·J_p = n·J_lin + (p × n)·J_ang  (world Jacobian, point p)
                row2 = (nJ + _cross(p2, n) @ Ja) * S2
                row1 = (nJ + _cross(p1, n) @ Ja) * S1
                rows = row2 - row1
                if robot.coordinate_map is not None:
                    rows = rows @ robot.coordinate_map
                C[act] = rows
                xi = self.effective_gain(dt)
                lower[act] = -xi * (distances[act] - d_s) / (d_i - d_s)
                self.active[act] = True
        return self.task._assign(lower, self._upper, C=C)

    def __repr__(self) -> str:
        return (
            f"CollisionAvoidance(rows={len(self.pairs)}, obstacles={len(self.obstacles)}, "
            f"min_distance={self.min_distance}, influence_distance={self.influence_distance}, "
            f"gain={self.gain})"
        )
