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


# ---------------------------------------------------------------------- annotations
DT = 0.01  # s
Q0 = np.array([0.0, -0.4, 0.0, -2.2, 0.0, 1.9, 0.8])  # rad: the hand at (0.45, 0, 0.45) m
TABLE_Z = 0.2  # m
GJK_TOL = 1e-5  # m: see test_annotations_hold_the_distances_and_the_steps_active_rows


def _oracle(sol) -> set[tuple[str, int, str]]:
    """(task, row, side) of the rows Solution.explain() finds active at the step (the
    bounds named "limits")."""
    e = sol.explain()
    tasks = [t for L in e.levels for t in L.tasks] + list(e.constraints)
    out = {(t.task.split("'")[1], r.row, r.side) for t in tasks for r in t.rows}
    if e.bounds is not None:
        out |= {("limits", r.row, r.side) for r in e.bounds.rows}
    return out


@pytest.fixture(scope="module")
def run(panda):
    """The hand pushed under a table band and past a ball, with acceleration limits (their
    box depends on the previous step): configurations, solutions, the active rows each
    step's Solution.explain() found right after the step."""
    ball = qc.Sphere((0.5, 0.12, 0.3), 0.06)
    avoid = qc.CollisionAvoidance(panda, [ball], self_collision=False)
    target = panda.frame_pose(Q0, "panda_hand_tcp")
    target[:3, 3] = (0.5, 0.25, 0.12)
    band = qc.PositionBand(panda, lower=[-np.inf, -np.inf, TABLE_Z], gain=50.0)
    limits = [
        qc.JointLimits(panda),
        qc.VelocityLimits(panda),
        qc.kinematics.tasks.AccelerationLimits(panda, 100.0),
    ]
    hand = qc.FrameTask(panda, "panda_hand_tcp", target, gain=5.0)
    ik = qc.IK(panda, [[band], [hand]], dt=DT, constraints=[avoid], limits=limits)
    qs, sols, truth = [Q0], [], []
    for _ in range(100):
        v, sol = ik.step(qs[-1])
        sols.append(sol)
        truth.append(_oracle(sol))
        qs.append(panda.integrate(qs[-1], v, DT))
    return {
        "ik": ik,
        "avoid": avoid,
        "ball": ball,
        "q": np.array(qs),
        "sols": sols,
        "truth": truth,
        "target": target,
    }


def test_annotations_hold_the_distances_and_the_steps_active_rows(panda, run):
    ik, avoid, q = run["ik"], run["avoid"], run["q"]
    v_before, last_before = ik.v_prev.copy(), ik.last
    notes = viz.annotate(ik, q, run["sols"], collision=avoid)
    assert len(notes) == len(q) and notes.pairs == tuple(avoid.pairs)
    assert np.array_equal(ik.v_prev, v_before) and ik.last is last_before  # state restored
    seen = set()
    for k, note in enumerate(notes):
        assert note.time == pytest.approx(k * DT)
        # the same call at the same configuration. coal's GJK on convex hulls stops on a
        # relative duality gap and starts from its previous result: repeats differ by
        # ~1e-6 m (1.3e-6 m seen with OPENBLAS_CORETYPE=Prescott); GJK_TOL is a tenth of the
        # 0.1 mm the overlay prints
        np.testing.assert_allclose(
            note.distances, avoid.compute_distances(q[k]), rtol=0, atol=GJK_TOL
        )
        d = np.sort(note.distances)
        assert [w.distance for w in note.nearest] == list(d[:3])
        for w in note.nearest:
            # witness points: as far apart as the distance (one GJK result)
            assert np.linalg.norm(w.points[1] - w.points[0]) == pytest.approx(
                abs(w.distance), abs=GJK_TOL
            )
            assert w.pair == avoid.pairs[w.index]
            want = "inside" if w.distance < 0.02 else "near" if w.distance < 0.10 else "clear"
            assert w.state == want
        if k == len(q) - 1:
            assert note.active is None  # no step from the last configuration
            continue
        got = {(r.task if r.level != "limits" else "limits", r.row, r.side) for r in note.active}
        assert got == run["truth"][k], f"frame {k}"
        seen |= {r.level for r in note.active}
        for r in note.active:
            if r.task == avoid.name:
                assert r.name == " – ".join(avoid.pairs[r.row])
            if r.level == "limits":
                assert r.joint == f"panda_joint{r.row + 1}" and r.joint in note.joints
                assert r.task in {"joint limits", "velocity limits", "acceleration limits"}
    # the run reaches every kind of edge: a limit, the band (level 0), a collision row
    assert seen == {"limits", "level 0", "constraints"}
    states = {w.state for note in notes for w in note.nearest}
    assert {"clear", "near"} <= states


def test_the_overlay_text_names_the_frame(run):
    notes = viz.annotate(run["ik"], run["q"], [s.x for s in run["sols"]], collision=run["avoid"])
    k = next(i for i, n in enumerate(notes) if n.active and n.nearest[0].state == "near")
    text = notes[k].text
    assert text.startswith(f"t = {k * DT:.3f} s")
    assert f"{notes[k].nearest[0].distance:+.4f}" in text
    assert all(str(r) in text for r in notes[k].active)
    assert notes[-1].text.endswith(notes[-1].nearest[-1].state)  # no "active:" section


def _annotated_page(panda, run, path, **options):
    """The run annotated and animated with its ball and the table, written at ``path``
    (``options``: more of ``viz.animate``'s): the notes, the page's path and the frames
    kept."""
    notes = viz.annotate(run["ik"], run["q"], run["sols"], collision=run["avoid"])
    out = viz.animate(
        panda,
        run["q"],
        path,
        dt=DT,
        obstacles=[run["ball"], {"normal": (0, 0, 1), "offset": TABLE_Z}],
        annotations=notes,
        **options,
    )
    keep = viz._frames(np.arange(len(run["q"])) * DT, viz.DEFAULT_FPS, viz.DEFAULT_MAX_FRAMES)
    return notes, out, keep


def test_the_page_draws_what_the_notes_say(panda, run, tmp_path, monkeypatch):
    import json
    import re

    sent = _recorded(monkeypatch)
    notes, out, keep = _annotated_page(panda, run, tmp_path / "edges.html")
    anim = next(c for c in sent if c["type"] == "set_animation")
    tracks = {a["path"]: {t["name"]: t for t in a["clip"]["tracks"]} for a in anim["animations"]}
    base = "/meshcat/annotations"
    # the nearest pair's segment: scaled to its length, coloured by its state, per frame
    scale = [key["value"][1] for key in tracks[f"{base}/pair_0"][".scale"]["keys"]]
    assert scale == pytest.approx([abs(notes[k].nearest[0].distance) for k in keep], abs=GJK_TOL)
    for state in ("clear", "near", "inside"):
        keys = tracks[f"{base}/pair_0/{state}"][".visible"]["keys"]
        assert [key["value"] for key in keys] == [notes[k].nearest[0].state == state for k in keep]
    # joints at a limit marked, and only then
    marked = {p.rsplit("_", 1)[1] for p in tracks if p.startswith(f"{base}/joints/")}
    assert marked == {str(panda.model.getJointId(j)) for k in keep for j in notes[k].joints}
    for j in marked:
        name = panda.model.names[int(j)]
        keys = tracks[f"{base}/joints/joint_{j}"][".visible"]["keys"]
        assert [key["value"] for key in keys] == [name in notes[k].joints for k in keep]
    # the overlay: the kept frames' texts, inline, nothing fetched from a network
    html = out.read_text(encoding="utf-8")
    data = json.loads(re.search(r"const notes = (\{.*?\});\n", html).group(1))
    texts = [t.split("\nbetween frames")[0] for t in data["text"]]
    assert texts == [notes[k].text for k in keep]
    for i in range(1, len(keep)):  # what the skipped samples showed is added
        extra = viz.between(notes, int(keep[i - 1]), int(keep[i]))
        assert data["text"][i] == (f"{texts[i]}\n{extra}" if extra else texts[i])
    assert data["t"] == pytest.approx([k * DT for k in keep])
    script = html[html.index("const notes") :]
    assert "http" not in script and "<script src" not in html and "<link" not in html


def test_skipped_samples_do_not_hide_an_edge(run):
    """Shown at 10 fps, a 100 Hz run skips 9 samples in 10: the kept frame's text adds the
    nearest pair and the rows active in between (here: the first steps' acceleration
    limits, gone by frame 10)."""
    notes = viz.annotate(run["ik"], run["q"], run["sols"], collision=run["avoid"])

    def rows(k: int) -> set[tuple[str, str, str]]:
        return {(r.task, r.name, "≥" if r.side == "lower" else "≤") for r in notes[k].active}

    gone = set().union(*(rows(k) for k in range(1, 10))) - rows(10)
    assert gone, "the run's first steps hold a row that frame 10 does not"
    text = viz.between(notes, 0, 10)
    assert text.startswith("between frames (t 0.010–0.090 s, 9 not shown):")
    for task, name, sign in gone:
        steps = sum((task, name, sign) in rows(k) for k in range(1, 10))
        assert f"{task}: {name} {sign} bound ({steps} steps)" in text
    nearest = min((notes[k] for k in range(1, 10)), key=lambda n: n.nearest[0].distance)
    if nearest.nearest[0].distance < notes[10].nearest[0].distance:
        assert f"{nearest.nearest[0].distance:+.4f}" in text
    assert viz.between(notes, 10, 11) == ""  # nothing skipped


def test_a_list_of_frame_dicts_and_a_still(panda, tmp_path, monkeypatch):
    sent = _recorded(monkeypatch)
    frames = [
        {"text": "free"},
        {
            "text": "near",
            "segments": [((0.5, 0, 0.3), (0.5, 0.1, 0.3))],
            "joints": ["panda_joint4"],
        },
        {"segments": [((0.5, 0, 0.3), (0.5, 0.0, 0.3), "inside")]},  # touching: zero length
    ]
    q = np.array([Q0, Q0 + 0.1, Q0 + 0.2])
    viz.animate(panda, q, tmp_path / "d.html", dt=0.1, annotations=frames)
    anim = next(c for c in sent if c["type"] == "set_animation")
    tracks = {a["path"]: {t["name"]: t for t in a["clip"]["tracks"]} for a in anim["animations"]}
    vis = tracks["/meshcat/annotations/pair_0/near"][".visible"]["keys"]
    assert [key["value"] for key in vis] == [False, True, False]
    joint = tracks["/meshcat/annotations/joints/joint_4"][".visible"]["keys"]
    assert [key["value"] for key in joint] == [False, True, False]
    still = viz.animate(panda, Q0, tmp_path / "s.html", annotations=[{"text": "at rest"}])
    assert '"at rest"' in still.read_text(encoding="utf-8")


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"ik": "ik"}, "ik must be a qpcoord.IK"),
        ({"solutions": None, "collision": None}, "give solutions"),
        ({"cut": 5}, r"solutions: 95 given for 101 configurations"),
        ({"bad_solution": 3}, r"solutions\[3\] must be a finite velocity of size nv = 7"),
        ({"collision": "ball"}, "collision must be a qpcoord.CollisionAvoidance"),
        ({"nearest": -1}, "nearest"),
        ({"t": [0.0, 1.0]}, "t must hold 101"),
        ({"trajectory": np.zeros((4, 3))}, "trajectory"),
    ],
)
def test_annotate_names_bad_input(run, kwargs, match):
    args = {
        "ik": run["ik"],
        "trajectory": run["q"],
        "solutions": list(run["sols"]),
        "collision": run["avoid"],
    }
    if "cut" in kwargs:
        args["solutions"] = args["solutions"][: -kwargs.pop("cut")]
    if "bad_solution" in kwargs:
        args["solutions"][kwargs.pop("bad_solution")] = np.zeros(6)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        viz.annotate(args.pop("ik"), args.pop("trajectory"), **args)


def test_annotate_refuses_another_robots_collision_task(run):
    other = qc.robots.load("panda")
    avoid = qc.CollisionAvoidance(other, [qc.Sphere((0.5, 0, 0.3), 0.05)], self_collision=False)
    with pytest.raises(ValueError, match="collision: its robot is not the IK's"):
        viz.annotate(run["ik"], run["q"], collision=avoid)


@pytest.mark.parametrize(
    "annotations, match",
    [
        ("text", "annotations must be"),
        ([{"text": "a"}], r"annotations: 1 frames for a trajectory of 3"),
        ([{}, {"text": 3}, {}], r"annotations\[1\]: text must be a string"),
        ([{}, {}, {"segments": [((0, 0, 0),)]}], r"annotations\[2\]: segments\[0\] must be"),
        ([{}, {}, {"segments": [((0, 0, np.nan), (0, 0, 1))]}], r"segments\[0\] must be finite"),
        ([{"segments": [((0, 0, 0), (0, 0, 1), "red")]}, {}, {}], "state must be one of"),
        ([{"joints": ["elbow"]}, {}, {}], r"annotations\[0\]: joints: 'elbow' is not a joint"),
    ],
)
def test_animate_names_bad_annotations(panda, tmp_path, annotations, match):
    q = np.array([Q0, Q0, Q0])
    with pytest.raises(ValueError, match=match):
        viz.animate(panda, q, tmp_path / "x.html", dt=0.1, annotations=annotations)
    assert not (tmp_path / "x.html").exists()


# ---------------------------------------------------------------------- in a browser
def test_the_annotated_page_shows_each_frame_offline_in_headless_chromium(panda, run, tmp_path):
    """Open the annotated page in headless Chromium (software WebGL, network off): at a
    frame where the nearest pair is within the influence distance the overlay holds that
    frame's text and an orange witness segment is drawn; at the first frame a joint at its
    limit is marked in yellow; nothing but the file and its data: URLs is requested."""
    from support.browser import offline_viewer, pixels

    notes, page_path, keep = _annotated_page(panda, run, tmp_path / "edges.html", loop=False)
    near = next(k for k in keep if notes[k].nearest[0].state == "near")
    assert notes[0].joints, "the run starts at a limit (the acceleration limit from rest)"

    def hide(path: str) -> str:
        return f"viewer.scene_tree.find({path}).set_property('visible', false); viewer.set_dirty()"

    with offline_viewer(page_path) as (page, requests):
        page.wait_for_timeout(2500)  # the meshes are in
        overlay = f"document.getElementById('{viz.OVERLAY_ID}').textContent"
        page.evaluate("viewer.animator.pause(); viewer.animator.seek(0)")
        page.wait_for_timeout(300)
        assert page.evaluate(overlay) == notes[0].text
        # the text box covers a part of a small view: out of the way of the pixels
        page.evaluate(f"document.getElementById('{viz.OVERLAY_ID}').style.opacity = 0")
        start = pixels(page)
        page.evaluate(hide("['meshcat', 'annotations', 'joints']"))
        page.wait_for_timeout(300)
        unmarked = pixels(page)
        page.evaluate(f"viewer.animator.seek({near * DT})")
        page.wait_for_timeout(300)
        previous = int(keep[list(keep).index(near) - 1])
        extra = viz.between(notes, previous, near)
        assert page.evaluate(overlay) == notes[near].text + (f"\n{extra}" if extra else "")
        # the robot and the ball hidden: the segment is not behind them
        page.evaluate(hide("['meshcat', 'robot']") + ";" + hide("['meshcat', 'obstacles']"))
        page.wait_for_timeout(300)
        segment = pixels(page)

    r, g, b = start[..., 0], start[..., 1], start[..., 2]
    yellow = (r > 180) & (g > 150) & (b < 110)
    assert yellow.sum() > (np.abs(start - unmarked).sum(axis=2) > 30).sum() * 0.3 > 20
    r, g, b = segment[..., 0], segment[..., 1], segment[..., 2]
    orange = (r > 200) & (g > 100) & (g < 190) & (b < 80)
    assert orange.sum() > 3, "no orange witness segment"
    schemes = {u.split(":", 1)[0] for u in requests}
    assert schemes <= {"file", "data", "blob"}, f"network requests: {requests[:5]}"
