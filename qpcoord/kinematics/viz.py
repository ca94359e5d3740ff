"""See a run: :func:`animate` writes one self-contained HTML animation of a robot.

The page is meshcat's static export: three.js (the viewer, 0.85 MB), the robot's visual
meshes and the animation are all inlined, so it opens from disk with no network and no
server -- send it by mail, attach it to a CI run, open it years later. Orbit with the mouse;
the panel on the right plays, pauses and scrubs the animation.

Requires the ``viz`` extra (``pip install "qpcoord[viz]"``: meshcat).

How it is written
-----------------
meshcat's own export (``Visualizer.static_html()``) asks a server subprocess (tornado + ZMQ
on two localhost ports) for the scene it has recorded. :func:`animate` starts no process and
opens no port: the meshcat commands go to an in-process recorder that keeps the same scene
tree as that server and writes the same page (meshcat's ``main.min.js`` then one
``handle_command_bytearray`` call per scene node, in the server's order). Nothing is left
running, nothing listens, nothing is printed, and the time is bounded by the work itself.

File size and time (pin 4.1, meshcat 0.3.2, a loaded 2-core machine)
--------------------------------------------------------------------
The meshes and the viewer dominate; each animation frame adds about 0.14 kB per visual
geometry (the Panda: 1.5 kB, Talos: 7.5 kB)::

    robot   visual geometries   frames   HTML size (gzipped)   write time
    panda   11 (.dae)           61       15.1 MB (5.2 MB)      0.5-1.0 s
    panda   11                  600      15.9 MB (5.5 MB)      1.2 s
    talos   52 (.stl)           61       12.0 MB (5.8 MB)      0.8 s
    talos   52                  600      16.0 MB (7.6 MB)      2.1-2.8 s

Edges: half-spaces (``{"normal": n, "offset": d}`` or ``qc.Obstacle(coal.Halfspace(n, d))``)
are drawn as a slab on their solid side, and ``annotations=annotate(ik, trajectory,
solutions, collision=avoid)`` shows per frame the nearest collision pairs (witness segments
coloured by distance), the joints at a limit and a text box listing the pair distances and
the rows the step was held by (:mod:`qpcoord.kinematics.viz_notes`).

Frames are subsampled to ``fps`` (default 30 per second of trajectory time) and at most
``max_frames`` (default 600: 20 s at 30 fps; a longer run is shown at a lower rate); three.js
interpolates between frames when it plays.
"""

from __future__ import annotations

import base64
import contextlib
import json
import math
import os
import tempfile
import warnings
from collections.abc import Iterable, Mapping
from importlib import resources
from os import PathLike
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from .collision import Obstacle
from .robot import Robot
from .viz_notes import (
    ActiveRow,
    Annotations,
    FrameNote,
    Witness,
    annotate,
    between,
    trajectory_samples,
)

__all__ = [
    "annotate",
    "Annotations",
    "FrameNote",
    "Witness",
    "ActiveRow",
    "OVERLAY_ID",
    "animate",
    "NoVisualGeometry",
    "DEFAULT_FPS",
    "DEFAULT_MAX_FRAMES",
    "PLANE_THICKNESS",
]


class NoVisualGeometry(ValueError):
    """The robot has no visual geometry that can be drawn (not read from a URDF, meshes not
    found, or none of a kind meshcat draws). A :class:`ValueError`, so existing handlers
    still catch it; callers that can go on without a picture catch this one alone."""


#: Frames per second of trajectory time kept in the page (1/s).
DEFAULT_FPS = 30.0
#: Largest number of frames kept in the page.
DEFAULT_MAX_FRAMES = 600

_TARGET_COLOUR = 0x22AA22  # green spheres / frames
_OBSTACLE_COLOUR = 0xDD2222  # red, half transparent
_TARGET_RADIUS = 0.02  # m
_TARGET_AXIS = 0.1  # m, length of a target pose's axes


def _meshcat():
    try:
        import meshcat
        import meshcat.geometry
        import umsgpack
        from meshcat.animation import Animation
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ImportError(
            'qpcoord.viz needs meshcat: pip install "qpcoord[viz]" (or pip install meshcat)'
        ) from exc
    return meshcat, meshcat.geometry, Animation, umsgpack


# ---------------------------------------------------------------------- in-process recorder
class _Node(dict):
    """One node of the scene tree, as kept by meshcat's server (``meshcat.servers.tree``)."""

    __slots__ = ("object", "transform", "properties", "animation")

    def __init__(self) -> None:
        super().__init__()
        self.object: bytes | None = None
        self.transform: bytes | None = None
        self.properties: list[bytes] = []
        self.animation: bytes | None = None

    def find(self, path: list[str]) -> _Node:
        node = self
        for name in path:
            node = node.setdefault(name, _Node())
        return node

    def walk(self):
        yield self
        for child in self.values():
            yield from child.walk()


class _Recorder:
    """Stands in for meshcat's ``ViewerWindow``: keeps the scene instead of sending it.

    ``send`` applies a command to the tree exactly as the server's ``handle_zmq`` does;
    ``html`` renders the page exactly as the server's ``get_scene`` does, plus ``script``
    (JavaScript run after the commands are issued).
    """

    def __init__(self, umsgpack) -> None:
        self._pack = umsgpack.packb
        self.tree = _Node()

    def send(self, command) -> None:
        data = command.lower()
        kind = data["type"]
        path = [p for p in data["path"].split("/") if p]
        payload = self._pack(data)
        if kind == "set_transform":
            self.tree.find(path).transform = payload
        elif kind == "set_object":
            node = self.tree.find(path)
            node.object = payload
            node.properties = []
        elif kind == "set_property":
            self.tree.find(path).properties.append(payload)
        elif kind == "set_animation":
            self.tree.find(path).animation = payload
        elif kind == "delete":
            if path:
                self.tree.find(path[:-1]).pop(path[-1], None)
            else:
                self.tree = _Node()
        else:  # pragma: no cover - meshcat 0.3 sends nothing else from Python
            raise RuntimeError(f"unexpected meshcat command {kind!r}")

    def html(self, script: str = "") -> str:
        commands = []
        for node in self.tree.walk():
            blobs = [node.object, *node.properties, node.transform, node.animation]
            for blob in blobs:
                if blob is not None:
                    commands.append(
                        'fetch("data:application/octet-binary;base64,'
                        + base64.b64encode(blob).decode("ascii")
                        + '")\n    .then(res => res.arrayBuffer())\n'
                        "    .then(buffer => viewer.handle_command_bytearray("
                        "new Uint8Array(buffer)));\n"
                    )
        js = resources.files("meshcat").joinpath("viewer/dist/main.min.js").read_text("utf-8")
        return _PAGE.format(mainminjs=js, commands="".join(commands) + script)


_PAGE = """<!DOCTYPE html>
<html>
    <head> <meta charset=utf-8> <title>MeshCat</title> </head>
    <body>
        <div id="meshcat-pane">
        </div>
        <script>
            {mainminjs}
        </script>
        <script>
            var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
            {commands}
        </script>
         <style>
            body {{margin: 0; }}
            #meshcat-pane {{
                width: 100vw;
                height: 100vh;
                overflow: hidden;
            }}
        </style>
        <script id="embedded-json"></script>
    </body>
</html>
"""


# ---------------------------------------------------------------------- inputs
def _output_path(path: Any) -> Path:
    try:
        p = Path(os.fspath(path))
    except TypeError:
        raise ValueError(f"path must be a file path (str or Path), got {path!r}") from None
    if p.is_dir():
        raise ValueError(f"path {str(p)!r} is a directory: give the HTML file's name")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise ValueError(f"path: folder {str(parent)!r} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"path: folder {str(parent)!r} is not writable")
    return p


def _samples(
    robot: Robot, trajectory: Any, dt: float | None, t: Any
) -> tuple[np.ndarray, np.ndarray]:
    """Times (s, shape (N,)) and configurations (robot coordinates, (N, nq))."""
    q, times = trajectory_samples(robot, trajectory, t)
    n = q.shape[0]
    if times is None:
        if dt is None:
            if n > 1:
                raise ValueError("trajectory: give the sample times t=... or the step dt=... (s)")
            dt = 1.0
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive time step (s), got {dt!r}")
        times = np.arange(n) * float(dt)
    else:
        if n > 1 and np.any(np.diff(times) <= 0):
            raise ValueError("t: sample times must increase")
    return times - times[0], q


def _frames(times: np.ndarray, fps: float, max_frames: int) -> np.ndarray:
    """Indices of the samples kept: nearest to a grid of ``fps`` per second, at most
    ``max_frames``, first and last always kept."""
    n = len(times)
    duration = float(times[-1])
    if n == 1 or duration == 0.0:
        return np.array([0])
    count = min(max_frames, int(math.floor(duration * fps + 1e-9)) + 1, n)
    count = max(count, 2)
    grid = np.linspace(0.0, duration, count)
    idx = np.clip(np.searchsorted(times, grid), 1, n - 1)
    idx = np.where(grid - times[idx - 1] <= times[idx] - grid, idx - 1, idx)
    return np.unique(idx)


def _visual_model(robot: Robot, visual_model: Any) -> pin.GeometryModel:
    if visual_model is not None:
        if not isinstance(visual_model, pin.GeometryModel):
            raise ValueError(
                f"visual_model must be a pinocchio.GeometryModel, got {type(visual_model)}"
            )
        geom = visual_model
    else:
        urdf = getattr(robot, "urdf_path", None)
        if urdf is None:
            raise NoVisualGeometry(
                f"robot {robot.name!r} was not read from a URDF: it has no visual geometry; "
                "pass visual_model=pin.buildGeomFromUrdf(robot.model, urdf, "
                "pin.GeometryType.VISUAL, package_dirs=...)"
            )
        try:
            # built on the robot's own model: for a robot with locked joints that is the
            # reduced model, whose frames keep the locked links at their locked placement
            geom = pin.buildGeomFromUrdf(
                robot.model,
                str(urdf),
                pin.GeometryType.VISUAL,
                package_dirs=list(robot.package_dirs),
            )
        except Exception as exc:  # pinocchio raises ValueError/RuntimeError by version
            raise NoVisualGeometry(
                f"robot {robot.name!r}: its visual geometry could not be read from "
                f"{str(urdf)!r} (package_dirs={list(robot.package_dirs)}): {exc}"
            ) from None
    if geom.ngeoms == 0:
        raise NoVisualGeometry(f"robot {robot.name!r} has no visual geometry to draw")
    return geom


def _targets(targets: Any) -> list[tuple[bool, np.ndarray]]:
    """Targets as ``(is_pose, T)`` with ``T`` a 4×4 pose (a point gets the identity
    rotation)."""
    if targets is None:
        return []
    if isinstance(targets, pin.SE3):
        targets = targets.homogeneous
    items: list[Any] | None = None
    try:
        arr = np.asarray(targets, dtype=float)
    except (TypeError, ValueError):  # a ragged list: points and poses mixed
        arr = None
    if arr is not None:
        if arr.shape in ((3,), (4, 4)):
            items = [arr]
        elif (arr.ndim == 2 and arr.shape[1] == 3) or arr.shape[1:] == (4, 4):
            items = list(arr)
        else:
            raise ValueError(
                "targets must be a 3-D point (m), a 4×4 pose, or a list or array of them, "
                f"got shape {arr.shape}"
            )
    else:
        items = list(targets)
    out = []
    for k, item in enumerate(items):
        if isinstance(item, pin.SE3):
            item = item.homogeneous
        try:
            a = np.asarray(item, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"targets[{k}] must be a 3-D point or a 4×4 pose") from None
        if a.shape not in ((3,), (4, 4)):
            raise ValueError(
                f"targets[{k}] must be a 3-D point (m) or a 4×4 pose, got shape {a.shape}"
            )
        if not np.all(np.isfinite(a)):
            raise ValueError(f"targets[{k}] must be finite")
        if a.shape == (3,):
            T = np.eye(4)
            T[:3, 3] = a
            out.append((False, T))
            continue
        R = a[:3, :3]
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError(f"targets[{k}]: a pose's rotation block must be a rotation")
        T = a.copy()
        T[3] = (0.0, 0.0, 0.0, 1.0)
        out.append((True, T))
    return out


def _field(obj: Any, names: Iterable[str]) -> Any:
    for name in names:
        if isinstance(obj, Mapping):
            if name in obj:
                return obj[name]
        elif hasattr(obj, name):
            return getattr(obj, name)
    return None


#: Thickness (m) of the slab drawn for a half-space: its top face is the plane, the slab
#: lies on the solid side.
PLANE_THICKNESS = 0.01
_SHEET = 0.002  # m, thickness of a two-sided plane's sheet
_FLAT = ("halfspace", "plane")
# meshcat's cylinder lies along its frame's y axis; coal's capsules and cylinders along z
_Y_TO_Z = np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])


class _Shape:
    """An obstacle to draw: ``kind`` and its numbers (m) in its own frame, ``pose`` (4×4,
    world). ``"sphere"``: ``size`` the radius; ``"box"``: the side lengths (3,);
    ``"capsule"`` / ``"cylinder"``: ``(radius, length)`` along the frame's z; ``"ellipsoid"``:
    the radii (3,); ``"halfspace"`` / ``"plane"``: ``pose``'s z is the unit normal (toward
    the free side for a half-space), its origin a point of the plane, ``size`` the side of
    the square patch drawn (m, ``None``: sized to the scene)."""

    __slots__ = ("kind", "size", "pose")

    def __init__(self, kind: str, size: Any, pose: np.ndarray) -> None:
        self.kind, self.size, self.pose = kind, size, pose


def _frame_with_z(z: np.ndarray) -> np.ndarray:
    """A rotation (3×3) whose third column is the unit vector ``z``."""
    x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _plane(normal: Any, offset: Any, size: Any, what: str, kind: str) -> _Shape:
    """The plane ``normal · x = offset`` (m): for a half-space the solid side is
    ``normal · x ≤ offset`` (coal's convention), the normal points to the free side."""
    try:
        n = np.asarray(normal, dtype=float).reshape(-1)
        d = float(offset)
    except (TypeError, ValueError):
        raise ValueError(
            f"{what}: normal must be 3 numbers and offset a number (m), got {normal!r}, {offset!r}"
        ) from None
    norm = float(np.linalg.norm(n)) if n.shape == (3,) else 0.0
    if n.shape != (3,) or not np.isfinite(norm) or norm == 0.0 or not np.isfinite(d):
        raise ValueError(
            f"{what}: normal must be a finite non-zero 3-vector and offset finite (m), got "
            f"normal={normal!r}, offset={offset!r}"
        )
    z = n / norm
    T = np.eye(4)
    T[:3, :3] = _frame_with_z(z)
    T[:3, 3] = (d / norm) * z
    if size is not None:
        side = float(size)
        if not (np.isfinite(side) and side > 0):
            raise ValueError(f"{what}: size must be a positive side length (m), got {size!r}")
        size = side
    return _Shape(kind, size, T)


def _coal_shape(obs: Obstacle, what: str) -> _Shape:
    """A :class:`qpcoord.Obstacle` drawn from its coal geometry and pose."""
    g, T = obs.geometry(), np.array(obs.pose, dtype=float)
    if isinstance(g, (coal.Halfspace, coal.Plane)):
        kind = "halfspace" if isinstance(g, coal.Halfspace) else "plane"
        R, p = T[:3, :3], T[:3, 3]
        n = R @ np.array(g.n, dtype=float)  # coal keeps n unit
        return _plane(n, float(g.d) + float(n @ p), None, what, kind)
    if isinstance(g, coal.Sphere):
        return _Shape("sphere", float(g.radius), T)
    if isinstance(g, coal.Box):
        return _Shape("box", 2.0 * np.array(g.halfSide, dtype=float), T)
    if isinstance(g, (coal.Capsule, coal.Cylinder)):
        kind = "capsule" if isinstance(g, coal.Capsule) else "cylinder"
        return _Shape(kind, (float(g.radius), 2.0 * float(g.halfLength)), T)
    if isinstance(g, coal.Ellipsoid):
        return _Shape("ellipsoid", np.array(g.radii, dtype=float), T)
    raise ValueError(
        f"{what}: a {type(g).__name__} cannot be drawn (drawn: coal Sphere, Box, Capsule, "
        "Cylinder, Ellipsoid, Halfspace, Plane)"
    )


def _obstacles(obstacles: Any) -> list[_Shape]:
    """The obstacles to draw, checked."""
    if obstacles is None:
        return []
    if isinstance(obstacles, (Mapping, Obstacle)) or any(
        hasattr(obstacles, a) for a in ("centre", "normal")
    ):
        obstacles = [obstacles]
    out: list[_Shape] = []
    for k, obs in enumerate(obstacles):
        what = f"obstacles[{k}]"
        if isinstance(obs, Obstacle):
            shape = _coal_shape(obs, what)
            if shape.kind == "sphere" and not shape.size > 0:
                raise ValueError(f"{what}: radius must be positive (m), got {shape.size!r}")
            out.append(shape)
            continue
        normal = _field(obs, ("normal",))
        if normal is not None:
            offset = _field(obs, ("offset",))
            if offset is None:
                raise ValueError(f"{what}: a half-space needs normal and offset, got {obs!r}")
            out.append(_plane(normal, offset, _field(obs, ("size",)), what, "halfspace"))
            continue
        centre = _field(obs, ("centre", "center"))
        radius = _field(obs, ("radius",))
        half = _field(obs, ("half_extents",))
        if centre is None or (radius is None) == (half is None):
            raise ValueError(
                f"{what} must be a sphere (centre, radius), a box (centre, half_extents, "
                "optional rotation), a half-space (normal, offset, optional size) or a "
                f"qc.Obstacle, as an object with those attributes or a dict; got {obs!r}"
            )
        c = np.asarray(centre, dtype=float).reshape(-1)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise ValueError(f"{what}: centre must be 3 finite coordinates (m), got {centre!r}")
        T = np.eye(4)
        T[:3, 3] = c
        if radius is not None:
            r = float(radius)
            if not (np.isfinite(r) and r > 0):
                raise ValueError(f"{what}: radius must be positive and finite (m), got {radius!r}")
            out.append(_Shape("sphere", r, T))
            continue
        h = np.asarray(half, dtype=float).reshape(-1)
        if h.shape != (3,) or not np.all(np.isfinite(h)) or np.any(h <= 0):
            raise ValueError(
                f"{what}: half_extents must be 3 positive finite lengths (m), got {half!r}"
            )
        rot = _field(obs, ("rotation",))
        if rot is not None:
            R = np.asarray(rot, dtype=float)
            if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-6):
                raise ValueError(f"{what}: rotation must be a 3×3 rotation matrix")
            T[:3, :3] = R
        out.append(_Shape("box", 2.0 * h, T))
    return out


def _plane_patch(shape: _Shape, centre: Any, extent: float) -> tuple[np.ndarray, np.ndarray]:
    """Where a half-space or plane is drawn: ``(pose, side_lengths)`` of the box (m).

    The patch is a square of side ``shape.size`` (default ``max(1, 2 · extent)`` m) centred
    at the projection of ``centre`` (m, world: the middle of the scene) on the plane, with
    ``extent`` (m) the size of the scene. A half-space is a slab of
    :data:`PLANE_THICKNESS` whose top face lies on the plane, on the solid side; a plane a
    thin sheet centred on it. The pose's z axis is the plane's normal.
    """
    T = shape.pose.copy()
    z, o = T[:3, 2], T[:3, 3]
    c = np.asarray(centre, dtype=float)
    p = c - float((c - o) @ z) * z
    side = shape.size if shape.size is not None else max(1.0, 2.0 * float(extent))
    thick = PLANE_THICKNESS if shape.kind == "halfspace" else _SHEET
    T[:3, 3] = p - 0.5 * thick * z if shape.kind == "halfspace" else p
    return T, np.array([side, side, thick])


# ---------------------------------------------------------------------- the call
def animate(
    robot: Robot,
    trajectory: Any,
    path: str | PathLike,
    targets: Any = None,
    obstacles: Any = None,
    fps: float | None = None,
    *,
    dt: float | None = None,
    t: Any = None,
    max_frames: int = DEFAULT_MAX_FRAMES,
    loop: bool = True,
    visual_model: pin.GeometryModel | None = None,
    annotations: Any = None,
) -> Path:
    """Write one self-contained HTML animation of ``robot`` moving along ``trajectory``.

    The file embeds the viewer (three.js), the robot's visual meshes, the targets, the
    obstacles and the animation: it opens offline in any browser, with no server. The file
    is written atomically (a temporary file in the same folder, then renamed): ``path``
    never holds a half-written page, and on any error nothing is written there.

    Parameters
    ----------
    robot : qpcoord.Robot
        A robot read from a URDF (``qc.robots.load``, ``Robot.from_urdf``): its visual
        meshes are read with ``package_dirs``. Locked joints (the Panda's fingers, Talos's
        upper body) are drawn at their locked configuration. A robot without a URDF needs
        ``visual_model``. A visual geometry meshcat cannot draw (an unknown mesh format) is
        left out; when none can be drawn, ``ValueError``.
    trajectory : qpcoord.Trajectory or array_like, shape (N, nq)
        Configurations in the robot's coordinates (rad, m), one per row. A
        :class:`~qpcoord.Trajectory` brings its times ``.t`` (s); an array needs ``dt`` or
        ``t``. One configuration (shape ``(nq,)``) draws a still.
    path : str or Path
        The HTML file to write (its folder must exist). Returned.
    targets : optional
        Drawn still, in green: 3-D points (m) as spheres of 2 cm, 4×4 poses (or
        ``pinocchio.SE3``) as a sphere and a 10 cm axis triad (x red, y green, z blue).
        One target, a list, or an array of shape (K, 3) / (K, 4, 4).
    obstacles : optional
        Drawn still, in half-transparent red. One obstacle or a list; each is

        - a :class:`qpcoord.Obstacle` -- ``qc.Sphere``, ``qc.Box``, ``qc.Capsule``, or
          ``qc.Obstacle(coal geometry, pose)`` with a coal ``Sphere``, ``Box``, ``Capsule``,
          ``Cylinder``, ``Ellipsoid``, ``Halfspace`` or ``Plane``: the very objects given to
          :class:`~qpcoord.CollisionAvoidance`;
        - a sphere: ``centre`` (3,) and ``radius`` (m);
        - a box: ``centre``, ``half_extents`` (3,) (m) and an optional 3×3 ``rotation`` (box
          to world);
        - a half-space: ``normal`` (3,) and ``offset`` (m), the solid side being
          ``normal · x ≤ offset`` (coal's ``Halfspace``; the normal points to the free side),
          and an optional ``size`` (m);

        given as an object with those attributes or a dict with those keys (``center`` is
        accepted for ``centre``). A half-space is drawn as a square slab of
        :data:`PLANE_THICKNESS` (1 cm) whose top face lies on the plane, centred at the
        projection of the scene's middle on it, of side ``size`` (default: twice the
        scene's extent, at least 1 m); a coal ``Plane`` (two-sided) as a 2 mm sheet.
    fps : float, optional
        Frames kept per second of trajectory time (default :data:`DEFAULT_FPS`, 30). The
        page plays in real time; the browser interpolates between frames.
    dt : float, optional
        Sample time (s) of an array ``trajectory``.
    t : array_like, shape (N,), optional
        Sample times (s) of an array ``trajectory`` (increasing).
    max_frames : int
        At most this many frames are kept (default 600): the page grows by ~0.14 kB per
        frame and visual geometry (Panda: 600 frames add 0.8 MB to 15 MB of meshes and
        viewer).
    loop : bool
        Replay the animation for ever (default) or play it once.
    visual_model : pinocchio.GeometryModel, optional
        Visual geometry to draw instead of the robot's URDF visuals (on ``robot.model``).
    annotations : optional
        What each frame shows beyond the robot, one item per configuration of
        ``trajectory``: :func:`annotate`'s result (pair distances and the IK's active rows),
        or a list of dicts (or objects) with optional keys ``text`` (str, shown in a box at
        the bottom left while the frame is on), ``segments`` (``(p1, p2)`` or ``(p1, p2,
        state)``: two 3-D points, m; ``state`` ``"clear"`` blue, ``"near"`` orange (the
        default), ``"inside"`` magenta) and ``joints`` (joint names, each marked by a
        translucent yellow ball of 6 cm around its origin). Shown at the kept frames (see
        ``fps``); objects switch at each frame's time, the segments' ends move smoothly.
        With :func:`annotate`'s notes a kept frame's text adds what the skipped
        configurations before it showed and it does not (:func:`between`).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ValueError
        Configurations of the wrong size or not finite (``trajectory``), missing or bad
        times (``dt``, ``t``), a robot without visual geometry (``robot``), a folder that
        does not exist or is not writable, or a directory (``path``), a bad target or
        obstacle (``targets[k]``, ``obstacles[k]``), a bad ``fps`` or ``max_frames``,
        annotations of another length than ``trajectory`` or with a bad segment, state or
        joint name (``annotations[k]``).
    ImportError
        meshcat is not installed (``pip install "qpcoord[viz]"``).

    Notes
    -----
    Size: the Panda's page is 15 MB (meshes and viewer) plus 1.5 kB per frame (600 frames:
    15.9 MB, 5.5 MB gzipped); Talos's 11.6 MB plus 7.5 kB per frame (600 frames: 16 MB).
    Write time 0.5–3 s (see the module docstring). Opening it takes a browser 2–4 s.
    """
    if not isinstance(robot, Robot):
        raise ValueError(f"robot must be a qpcoord.Robot, got {type(robot).__name__}")
    out = _output_path(path)
    fps = DEFAULT_FPS if fps is None else fps
    if not (isinstance(fps, (int, float)) and np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive number of frames per second, got {fps!r}")
    if not (isinstance(max_frames, (int, np.integer)) and max_frames >= 2):
        raise ValueError(f"max_frames must be an integer ≥ 2, got {max_frames!r}")
    times, q = _samples(robot, trajectory, dt, t)
    target_poses = _targets(targets)
    obstacle_shapes = _obstacles(obstacles)
    frame_notes = _notes(annotations, robot, len(times))
    geom = _visual_model(robot, visual_model)
    meshcat, mg, Animation, umsgpack = _meshcat()
    from pinocchio.visualize import MeshcatVisualizer

    recorder = _Recorder(umsgpack)
    root = meshcat.Visualizer(window=recorder)
    viz = MeshcatVisualizer(robot.model, None, geom)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        viz.initViewer(viewer=root)
        viz.loadViewerModel(rootNodeName="robot")
    skipped = [str(w.message).splitlines()[0] for w in caught]
    if skipped and len(skipped) >= geom.ngeoms:
        raise NoVisualGeometry(
            f"robot {robot.name!r}: none of its visual geometries could be drawn ({skipped[0]})"
        )

    # still objects: targets (green) and obstacles (red)
    green = mg.MeshLambertMaterial(color=_TARGET_COLOUR)
    for k, (is_pose, T) in enumerate(target_poses):
        node = root["targets"][f"target_{k}"]
        node["point"].set_object(mg.Sphere(_TARGET_RADIUS), green)
        if is_pose:
            node["axes"].set_object(mg.triad(_TARGET_AXIS))
        node.set_transform(T)
    red = mg.MeshLambertMaterial(color=_OBSTACLE_COLOUR, opacity=0.5, transparent=True)
    solids = [(k, o) for k, o in enumerate(obstacle_shapes) if o.kind not in _FLAT]
    for k, shape in solids:
        _draw_solid(root["obstacles"][f"obstacle_{k}"], shape, red, mg)

    # the robot: still at the first configuration, then one animation frame per kept sample
    q_pin = q if robot.coordinate_map is None else q @ robot.coordinate_map.T
    keep = _frames(times, float(fps), int(max_frames))
    points = [T[:3, 3] for _, T in target_poses] + [o.pose[:3, 3] for _, o in solids]
    viz.display(q_pin[keep[0]])
    points.extend(np.array(M.translation) for M in viz.visual_data.oMg)
    joints = [np.array([M.translation for M in viz.data.oMi])]  # joint origins (m), per frame
    anim = Animation(default_framerate=float(fps)) if len(keep) > 1 else None
    if anim is not None:
        joints = []
        for k in keep:
            viz.viewer = anim.at_frame(root, float(times[k] * fps))
            viz.display(q_pin[k])
            points.extend(np.array(M.translation) for M in viz.visual_data.oMg)
            joints.append(np.array([M.translation for M in viz.data.oMi]))
        viz.viewer = root
    overlay = ""
    if frame_notes is not None:
        kept = [frame_notes[k] for k in keep]
        frames = [float(times[k] * fps) for k in keep]
        _draw_notes(root, anim, kept, frames, joints, mg)
        texts = [n[0] for n in kept]
        if all(isinstance(a, FrameNote) for a in annotations):
            # the samples a page skips (fps) must not hide an edge: each kept frame's text
            # adds what the samples since the previous kept frame showed and it does not
            for i in range(1, len(keep)):
                extra = between(annotations, int(keep[i - 1]), int(keep[i]))
                texts[i] = f"{texts[i]}\n{extra}" if extra else texts[i]
        overlay = _overlay_script([float(times[k]) for k in keep], texts)
    if anim is not None:
        root.set_animation(anim, play=True, repetitions=2**31 - 1 if loop else 1)
    cloud = np.array(points)
    lo, hi = cloud.min(axis=0), cloud.max(axis=0)
    sheet = mg.MeshLambertMaterial(color=_OBSTACLE_COLOUR, opacity=0.3, transparent=True)
    for k, shape in enumerate(obstacle_shapes):
        if shape.kind in _FLAT:
            T, sides = _plane_patch(shape, 0.5 * (lo + hi), float(np.max(hi - lo)))
            node = root["obstacles"][f"obstacle_{k}"]
            node.set_object(mg.Box(list(sides)), sheet)
            node.set_transform(T)
    aim = _frame_camera(root, cloud)

    _write_atomically(out, recorder.html(aim + overlay))
    return out


def _draw_solid(node: Any, shape: _Shape, material: Any, mg: Any) -> None:
    """A sphere, box, ellipsoid, cylinder or capsule (a cylinder and two balls) at its pose."""
    if shape.kind == "sphere":
        node.set_object(mg.Sphere(shape.size), material)
    elif shape.kind == "box":
        node.set_object(mg.Box(list(shape.size)), material)
    elif shape.kind == "ellipsoid":
        node.set_object(mg.Ellipsoid(list(shape.size)), material)
    else:
        radius, length = shape.size
        node["body"].set_object(mg.Cylinder(length, radius), material)
        node["body"].set_transform(_Y_TO_Z)
        if shape.kind == "capsule":
            for end, sign in (("top", 1.0), ("bottom", -1.0)):
                T = np.eye(4)
                T[2, 3] = sign * 0.5 * length
                node[end].set_object(mg.Sphere(radius), material)
                node[end].set_transform(T)
    node.set_transform(shape.pose)


# ---------------------------------------------------------------------- annotations
_SEGMENT_COLOURS = {"clear": 0x4477AA, "near": 0xFF9900, "inside": 0xE0119D}
_SEGMENT_RADIUS = 0.005  # m, a witness segment's thickness
_WITNESS_RADIUS = 0.01  # m, its end points
_JOINT_COLOUR = 0xFFD700  # a joint at a limit: a yellow ball around its origin
_JOINT_RADIUS = 0.06  # m
#: the overlay's element id in the page
OVERLAY_ID = "qpcoord-notes"

_Note = tuple[str, list[tuple[np.ndarray, np.ndarray, str]], list[int]]


def _notes(annotations: Any, robot: Robot, n: int) -> list[_Note] | None:
    """Each sample's ``(text, segments (p1, p2, state), joint ids)``, checked."""
    if annotations is None:
        return None
    if isinstance(annotations, (str, bytes, Mapping)) or not hasattr(annotations, "__len__"):
        raise ValueError(
            "annotations must be qc.viz.annotate(...) or a list of per-frame dicts (text, "
            f"segments, joints), got {type(annotations).__name__}"
        )
    if len(annotations) != n:
        raise ValueError(
            f"annotations: {len(annotations)} frames for a trajectory of {n} configurations"
        )
    model = robot.model
    out: list[_Note] = []
    for k, item in enumerate(annotations):
        what = f"annotations[{k}]"
        text = _field(item, ("text",))
        text = "" if text is None else text
        if not isinstance(text, str):
            raise ValueError(f"{what}: text must be a string, got {type(text).__name__}")
        segments = []
        for s, seg in enumerate(_field(item, ("segments",)) or ()):
            seg = tuple(seg)
            state = seg[2] if len(seg) == 3 else "near"
            try:
                p = np.array(seg[:2], dtype=float)
            except (TypeError, ValueError):
                p = None
            if len(seg) not in (2, 3) or p is None or p.shape != (2, 3):
                raise ValueError(
                    f"{what}: segments[{s}] must be (p1, p2[, state]), two 3-D points (m)"
                )
            if not np.all(np.isfinite(p)):
                raise ValueError(f"{what}: segments[{s}] must be finite (m)")
            if state not in _SEGMENT_COLOURS:
                raise ValueError(
                    f"{what}: segments[{s}] state must be one of {', '.join(_SEGMENT_COLOURS)}, "
                    f"got {state!r}"
                )
            segments.append((p[0], p[1], state))
        ids = []
        for name in _field(item, ("joints",)) or ():
            j = model.getJointId(str(name)) if isinstance(name, str) else model.njoints
            if not 0 < j < model.njoints:
                raise ValueError(f"{what}: joints: {name!r} is not a joint of {robot.name!r}")
            ids.append(int(j))
        out.append((text, segments, ids))
    return out


def _segment_pose(p1: np.ndarray, p2: np.ndarray) -> tuple[np.ndarray, list[float]]:
    """Pose and scale of meshcat's unit cylinder (along its y axis) spanning ``p1 → p2``."""
    d = p2 - p1
    length = float(np.linalg.norm(d))
    T = np.eye(4)
    if length > 1e-9:
        R = _frame_with_z(d / length)  # columns x, y, z with z along d
        T[:3, :3] = R[:, [1, 2, 0]]  # y along d (a cyclic permutation: still a rotation)
    T[:3, 3] = 0.5 * (p1 + p2)
    return T, [1.0, max(length, 1e-6), 1.0]


def _draw_notes(
    root: Any, anim: Any, notes: list[_Note], frames: list[float], joints: list, mg: Any
) -> None:
    """Witness segments (coloured by state) and joint markers: their still state at the
    first frame, then one key per frame (``anim``; booleans switch at the keys)."""
    group = root["annotations"]
    slots = max((len(n[1]) for n in notes), default=0)
    for s in range(slots):
        for state, colour in _SEGMENT_COLOURS.items():
            group[f"pair_{s}"][state].set_object(
                mg.Cylinder(1.0, _SEGMENT_RADIUS), mg.MeshLambertMaterial(color=colour)
            )
        for end in ("p1", "p2"):
            group[f"pair_{s}_{end}"].set_object(
                mg.Sphere(_WITNESS_RADIUS), mg.MeshLambertMaterial(color=0x222222)
            )
    marked = sorted({j for n in notes for j in n[2]})
    ball = mg.MeshLambertMaterial(color=_JOINT_COLOUR, opacity=0.6, transparent=True)
    for j in marked:
        group["joints"][f"joint_{j}"].set_object(mg.Sphere(_JOINT_RADIUS), ball)

    def at(viewer: Any, path: tuple[str, ...]) -> Any:
        for name in ("annotations", *path):
            viewer = viewer[name]
        return viewer

    def show(path: tuple[str, ...], i: int, key: str, value: Any, jstype: str) -> None:
        if i == 0:
            at(root, path).set_property(key, value)
        if anim is not None:
            at(anim.at_frame(root, frames[i]), path).set_property(key, jstype, value)

    def place(path: tuple[str, ...], i: int, T: np.ndarray) -> None:
        if i == 0:
            at(root, path).set_transform(T)
        if anim is not None:
            at(anim.at_frame(root, frames[i]), path).set_transform(T)

    def move(path: tuple[str, ...], i: int, p: np.ndarray) -> None:
        """A ball's centre: a position track alone (its rotation never changes)."""
        if i == 0:
            E = np.eye(4)
            E[:3, 3] = p
            at(root, path).set_transform(E)
        if anim is not None:
            at(anim.at_frame(root, frames[i]), path).set_property("position", "vector3", list(p))

    for i, (_, segments, ids) in enumerate(notes):
        for s in range(slots):
            on = s < len(segments)
            p1, p2, state = segments[s] if on else (np.zeros(3), np.zeros(3), "")
            T, scale = _segment_pose(p1, p2)
            place((f"pair_{s}",), i, T)
            show((f"pair_{s}",), i, "scale", scale, "vector3")
            for st in _SEGMENT_COLOURS:
                show((f"pair_{s}", st), i, "visible", on and st == state, "boolean")
            for end, p in (("p1", p1), ("p2", p2)):
                move((f"pair_{s}_{end}",), i, p)
                show((f"pair_{s}_{end}",), i, "visible", on, "boolean")
        for j in marked:
            move(("joints", f"joint_{j}"), i, joints[i][j])
            show(("joints", f"joint_{j}"), i, "visible", j in ids, "boolean")


def _overlay_script(times: list[float], texts: list[str]) -> str:
    """JavaScript that shows, in a box over the view, the text of the frame the animation
    is at (the last key at or before its time, as the switches of the drawn objects)."""
    data = json.dumps({"t": times, "text": texts}, ensure_ascii=True).replace("<", "\\u003c")
    return (
        "\n(function () {\n"
        f"  const notes = {data};\n"
        '  const box = document.createElement("pre");\n'
        f'  box.id = "{OVERLAY_ID}";\n'
        '  box.style.cssText = "position: fixed; bottom: 0; left: 0; margin: 6px; '
        "padding: 4px 6px; "
        "font: 11px monospace; background: rgba(255, 255, 255, 0.85); color: #111; "
        'pointer-events: none; max-width: 96vw; max-height: 45vh; overflow: hidden; z-index: 10";\n'
        "  document.body.appendChild(box);\n"
        "  let shown = -1;\n"
        "  function frame() {\n"
        "    const actions = viewer.animator.actions;\n"
        "    const now = actions.length ? actions[0].time : 0;\n"
        "    let lo = 0, hi = notes.t.length - 1;\n"
        "    while (lo < hi) {\n"
        "      const mid = (lo + hi + 1) >> 1;\n"
        "      if (notes.t[mid] <= now + 1e-6) lo = mid; else hi = mid - 1;\n"
        "    }\n"
        "    if (lo !== shown) { box.textContent = notes.text[lo]; shown = lo; }\n"
        "    requestAnimationFrame(frame);\n"
        "  }\n"
        "  frame();\n"
        "})();\n"
    )


def _frame_camera(root: Any, points: np.ndarray) -> str:
    """Aim meshcat's orbiting camera at the centre of ``points`` (m), from a distance that
    shows them all (meshcat's default looks at the origin from 3 m). Returns the line of
    JavaScript that moves the orbit's centre (meshcat 0.3 has no command for it)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = 0.5 * (lo + hi)
    extent = float(np.max(hi - lo)) + 0.4  # link origins only: leave room for the meshes
    direction = np.array([1.0, 0.6, 0.45])  # front right, above (world, z up)
    eye = centre + max(1.0, 1.1 * extent) * direction / np.linalg.norm(direction)

    def three(v: np.ndarray) -> list[float]:  # the camera's axes are three.js's (y up)
        return [float(v[0]), float(v[2]), float(-v[1])]

    root["/Cameras/default/rotated/<object>"].set_property("position", three(eye))
    x, y, z = three(centre)
    return f"viewer.controls.target.set({x!r}, {y!r}, {z!r}); viewer.controls.update();"


def _write_atomically(path: Path, text: str) -> None:
    folder = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    except OSError as exc:
        raise ValueError(f"path: cannot write in {str(folder)!r}: {exc}") from None
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        try:
            mode = path.stat().st_mode & 0o777
        except FileNotFoundError:
            mode = 0o644
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise ValueError(f"path: cannot write {str(path)!r}: {exc}") from None
        raise
