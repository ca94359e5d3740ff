"""The native rows of :class:`~qpcoord.kinematics.collision.CollisionAvoidance`.

:func:`native_kernel` gives the task's model -- every geometry's shape, placement and
broad-phase sphere, the watched pairs, the velocity columns that move each geometry -- to
``qpcoord._collision`` (``src/native/collision``) once, as data; a step is then one call that
runs the broad phase, coal's distance for each candidate pair and the rows of the pairs
inside the influence distance, reading the joints' placements and the joint Jacobian from
the robot's ``pinocchio.Data``. The task's Python rows stay the reference (the tests compare
the two on random configurations).

No kernel (``None``, the Python rows) when the module was not built (no coal C++ library at
install), when it was built against another coal than the one imported, for a robot with a
``coordinate_map``, or for a geometry the kernel does not rebuild (a mesh left as a BVH,
``convex=False``; a shape with a swept-sphere radius; a coal type other than sphere, box,
capsule, cylinder, cone, ellipsoid, half-space and triangle-faced convex hull).
"""

from __future__ import annotations

import importlib
from types import ModuleType
from typing import Any

import coal
import numpy as np


def _load() -> ModuleType | None:
    """``qpcoord._collision`` (an extension module, a leaf: it imports nothing of qpcoord's),
    or ``None`` where it was not built (no coal C++ library at install)."""
    try:
        return importlib.import_module("qpcoord._collision")
    except ImportError:
        return None


_collision = _load()

__all__ = ["native_kernel", "shape_data"]

#: the coal types the kernel rebuilds (a triangle-faced hull: coal.Convex, what
#: collision_geometry(convex=True) makes of a mesh)
_SHAPES = (
    coal.Sphere,
    coal.Box,
    coal.Capsule,
    coal.Cylinder,
    coal.Cone,
    coal.Ellipsoid,
    coal.Halfspace,
    coal.Convex,
)
_EMPTY_VERTICES = np.zeros((0, 3))
_EMPTY_TRIANGLES = np.zeros((0, 3), dtype=np.int64)


def shape_data(geometry: Any) -> tuple[str, np.ndarray, np.ndarray, np.ndarray] | None:
    """``(kind, dims, vertices, triangles)`` describing a coal shape to the kernel (m), or
    ``None`` for one it does not rebuild."""
    t = type(geometry)
    if t not in _SHAPES or geometry.getSweptSphereRadius() != 0.0:
        return None
    dims: list[float]
    if t is coal.Sphere:
        kind, dims = "sphere", [geometry.radius]
    elif t is coal.Box:
        kind, dims = "box", list(2.0 * np.asarray(geometry.halfSide))
    elif t in (coal.Capsule, coal.Cylinder, coal.Cone):
        kind, dims = t.__name__.lower(), [geometry.radius, 2.0 * geometry.halfLength]
    elif t is coal.Ellipsoid:
        kind, dims = "ellipsoid", list(np.asarray(geometry.radii))
    elif t is coal.Halfspace:
        kind, dims = "halfspace", [*np.asarray(geometry.n), geometry.d]
    else:  # coal.Convex
        vertices = np.array(geometry.points(), dtype=float).reshape(-1, 3)
        triangles = np.array(
            [[geometry.polygons(i)[j] for j in range(3)] for i in range(geometry.num_polygons)],
            dtype=np.int64,
        ).reshape(-1, 3)
        return "convex", np.zeros(0), vertices, triangles
    return kind, np.array(dims, dtype=float), _EMPTY_VERTICES, _EMPTY_TRIANGLES


def native_kernel(
    robot: Any,
    geometry_model: Any,
    centres: np.ndarray,
    radii: np.ndarray,
    first: np.ndarray,
    second: np.ndarray,
    columns: list[list[int]],
    min_distance: float,
    influence_distance: float,
) -> Any | None:
    """The ``qpcoord._collision.CollisionKernel`` of a task, or ``None`` (module docstring).

    ``centres`` / ``radii``: each geometry's bounding sphere (its parent joint's frame, m);
    ``first`` / ``second``: the pairs' geometry indices; ``columns``: per joint, the velocity
    columns that move it. The caller binds its output arrays (``bind``)."""
    if _collision is None or _collision.COAL_VERSION != coal.__version__:
        return None
    if robot.coordinate_map is not None:
        return None
    shapes = [shape_data(go.geometry) for go in geometry_model.geometryObjects]
    if any(s is None for s in shapes):
        return None
    data = robot.data
    oMi = data.oMi
    kernel = _collision.CollisionKernel(
        [oMi[j].rotation for j in range(robot.model.njoints)],
        [oMi[j].translation for j in range(robot.model.njoints)],
        data.J,
        min_distance,
        influence_distance,
    )
    for g, (go, s) in enumerate(zip(geometry_model.geometryObjects, shapes, strict=True)):
        kind, dims, vertices, triangles = s  # type: ignore[misc]
        joint = int(go.parentJoint)
        kernel.add_geometry(
            kind,
            dims,
            vertices,
            triangles,
            joint,
            np.asarray(go.placement.rotation, dtype=float),
            np.asarray(go.placement.translation, dtype=float),
            np.asarray(centres[g], dtype=float),
            float(radii[g]),
            columns[joint],
        )
    for a, b in zip(first, second, strict=True):
        kernel.add_pair(int(a), int(b))
    return kernel
