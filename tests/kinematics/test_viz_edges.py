"""qc.viz at the edges: half-spaces and planes drawn where they are, coal obstacles drawn as
the shapes CollisionAvoidance sees, and per-frame annotations (pair distances, witness
segments, active constraints) that match the IK's own rows."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc

pytest.importorskip("meshcat", reason="qpcoord.viz needs meshcat (the viz extra)")
coal = pytest.importorskip("coal")

from qpcoord.kinematics import viz  # noqa: E402


@pytest.fixture(scope="module")
def panda() -> qc.Robot:
    return qc.robots.load("panda")


def _recorded(monkeypatch) -> list[dict]:
    """Every meshcat command the next animate() sends, lowered."""
    sent: list[dict] = []
    original = viz._Recorder.send

    def spy(self, command):
        sent.append(command.lower())
        original(self, command)

    monkeypatch.setattr(viz._Recorder, "send", spy)
    return sent


def _matrix(cmd: dict) -> np.ndarray:
    return np.array(cmd["matrix"], dtype=float).reshape(4, 4).T  # three.js: column-major


# ---------------------------------------------------------------------- planes
@pytest.mark.parametrize(
    "normal, offset",
    [((0.0, 0.0, 1.0), 0.2), ((0.0, -2.0, 0.0), -0.7), ((1.0, 1.0, 1.0), 0.3)],
)
def test_a_half_space_patch_lies_on_its_plane_on_the_solid_side(normal, offset):
    (shape,) = viz._obstacles([{"normal": normal, "offset": offset}])
    centre = np.array([0.3, -0.1, 0.4])
    T, sides = viz._plane_patch(shape, centre, extent=0.8)
    n = np.array(normal) / np.linalg.norm(normal)
    d = offset / np.linalg.norm(normal)
    R, c = T[:3, :3], T[:3, 3]
    # a rotation whose z axis is the outward normal; tolerances: one rounding of unit vectors
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-12) and np.linalg.det(R) > 0
    assert np.allclose(R[:, 2], n, atol=1e-12)
    assert sides == pytest.approx([1.6, 1.6, viz.PLANE_THICKNESS])  # 2 × extent
    top = c + 0.5 * viz.PLANE_THICKNESS * n  # centre of the slab's top face
    assert n @ top == pytest.approx(d, abs=1e-12)  # on the plane
    assert n @ c < d  # the slab is on the solid side (n·x ≤ d)
    # the top face's centre is the scene centre's foot on the plane
    assert np.allclose(top, centre - (n @ centre - d) * n, atol=1e-12)


def test_a_patch_has_at_least_one_metre_and_the_size_asked(panda):
    (small,) = viz._obstacles({"normal": (0, 0, 1), "offset": 0.0})
    assert viz._plane_patch(small, np.zeros(3), 0.1)[1][0] == 1.0
    (sized,) = viz._obstacles({"normal": (0, 0, 1), "offset": 0.0, "size": 0.4})
    assert viz._plane_patch(sized, np.zeros(3), 3.0)[1][0] == 0.4


def test_coal_half_space_and_plane_obstacles_with_a_pose():
    """A qc.Obstacle holding a coal.Halfspace / coal.Plane (what CollisionAvoidance takes):
    the drawn plane is the geometry's plane moved by the obstacle's pose."""
    pose = np.eye(4)
    pose[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # 90° about z
    pose[:3, 3] = (0.0, 0.5, 0.0)
    wall = qc.Obstacle(coal.Halfspace(np.array([1.0, 0.0, 0.0]), 0.1), pose, name="wall")
    sheet = qc.Obstacle(coal.Plane(np.array([0.0, 0.0, 1.0]), 0.3), name="sheet")
    a, b = viz._obstacles([wall, sheet])
    assert a.kind == "halfspace" and b.kind == "plane"
    # world normal R·(1,0,0) = (0,1,0); offset 0.1 + n·t = 0.6: the wall is y ≤ 0.6
    assert np.allclose(a.pose[:3, 2], [0.0, 1.0, 0.0]) and a.pose[1, 3] == pytest.approx(0.6)
    T, sides = viz._plane_patch(b, np.array([1.0, 2.0, 3.0]), 0.5)
    assert np.allclose(T[:3, 3], [1.0, 2.0, 0.3]) and sides[2] < viz.PLANE_THICKNESS  # centred


def test_the_page_draws_the_patch_and_coal_shapes(panda, tmp_path, monkeypatch):
    sent = _recorded(monkeypatch)
    obstacles = [
        qc.Obstacle(coal.Halfspace(np.array([0.0, 0.0, 1.0]), 0.05), name="table"),
        qc.Capsule((0.5, 0.0, 0.3), (0.5, 0.2, 0.5), 0.05),  # not a ball: it has a radius
        qc.Obstacle(coal.Cylinder(0.05, 0.3), name="post"),
        {"centre": (0.4, -0.3, 0.4), "radius": 0.1},
    ]
    viz.animate(
        panda, panda.reference_configuration("default"), tmp_path / "p.html", obstacles=obstacles
    )
    objects = {c["path"]: c for c in sent if c["type"] == "set_object"}
    transforms = {c["path"]: _matrix(c) for c in sent if c["type"] == "set_transform"}
    table = "/meshcat/obstacles/obstacle_0"
    geom = objects[table]["object"]["geometries"][0]
    assert geom["type"] == "BoxGeometry" and geom["depth"] == pytest.approx(viz.PLANE_THICKNESS)
    assert transforms[table][2, 3] == pytest.approx(0.05 - viz.PLANE_THICKNESS / 2)
    capsule = "/meshcat/obstacles/obstacle_1"
    assert {f"{capsule}/body", f"{capsule}/top", f"{capsule}/bottom"} <= set(objects)
    axis = transforms[capsule][:3, :3] @ transforms[f"{capsule}/body"][:3, 1]  # meshcat: y
    assert np.allclose(axis, np.array([0.0, 0.2, 0.2]) / np.sqrt(0.08), atol=1e-9)
    assert objects[f"{capsule}/body"]["object"]["geometries"][0]["height"] == pytest.approx(
        np.sqrt(0.08)
    )
    assert "/meshcat/obstacles/obstacle_2/bottom" not in objects  # a cylinder has no caps
    assert objects["/meshcat/obstacles/obstacle_3"]["object"]["geometries"][0]["type"] == (
        "SphereGeometry"
    )


@pytest.mark.parametrize(
    "obstacle, match",
    [
        ({"normal": (0, 0, 0), "offset": 0.1}, r"obstacles\[0\]: normal must be a finite non"),
        ({"normal": (0, 0, 1)}, r"obstacles\[0\]: a half-space needs normal and offset"),
        ({"normal": (0, 0, 1), "offset": np.nan}, r"obstacles\[0\]: normal .* offset finite"),
        ({"normal": (0, 1), "offset": 0.0}, r"obstacles\[0\]: normal"),
        ({"normal": (0, 0, 1), "offset": 0.0, "size": -1}, r"obstacles\[0\]: size"),
        (qc.Obstacle(coal.Cone(0.1, 0.2)), r"obstacles\[0\]: a Cone cannot be drawn"),
    ],
)
def test_bad_planes_name_the_obstacle(panda, tmp_path, obstacle, match):
    with pytest.raises(ValueError, match=match):
        viz.animate(
            panda,
            panda.reference_configuration("default"),
            tmp_path / "x.html",
            obstacles=[obstacle],
        )
    assert not (tmp_path / "x.html").exists()
