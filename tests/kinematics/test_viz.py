"""qc.viz.animate: one self-contained HTML animation (meshcat's static page), written
atomically, silent, with no process left; a headless Chromium opens it offline and shows
the robot."""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from support.browser import need_browser, offline_viewer, pixels

import qpcoord as qc

pytest.importorskip("meshcat", reason="qpcoord.viz needs meshcat (the viz extra)")

from qpcoord.kinematics import viz  # noqa: E402


@pytest.fixture(scope="module")
def panda() -> qc.Robot:
    return qc.robots.load("panda")


def _swing(robot: qc.Robot, n: int = 31) -> np.ndarray:
    """A swing of every joint around the SRDF's default posture (rad), shape (n, nq)."""
    q0 = robot.reference_configuration("default")
    s = np.sin(np.linspace(0.0, 2.0 * np.pi, n))[:, None]
    return np.clip(q0 + 0.6 * s, robot.lower, robot.upper)


def _children() -> set[int]:
    """Processes whose parent is this one (Linux /proc)."""
    me, out = os.getpid(), set()
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == me:
                out.add(int(d.name))
    return out


# ---------------------------------------------------------------------- the file
def test_writes_one_self_contained_page(panda, tmp_path, capfd):
    before = _children() if Path("/proc").is_dir() else set()
    out = viz.animate(
        panda,
        _swing(panda),
        tmp_path / "panda.html",
        dt=0.05,
        targets=[[0.5, 0.2, 0.5], np.eye(4)],
        obstacles=[{"centre": (0.4, -0.3, 0.4), "radius": 0.1}],
    )
    assert out == tmp_path / "panda.html"
    html = out.read_text(encoding="utf-8")
    assert html.startswith("<!DOCTYPE html>")
    # everything inlined: no external script, stylesheet or image
    assert "<script src" not in html and "<link" not in html and "<img" not in html
    assert "MeshCat.Viewer" in html
    # Panda's meshes (11 visual geometries, the locked fingers included) are in the page
    assert 14e6 < out.stat().st_size < 20e6
    assert sorted(p.name for p in tmp_path.iterdir()) == ["panda.html"]  # no temp file left
    assert oct(out.stat().st_mode & 0o777) == oct(0o644)
    captured = capfd.readouterr()
    assert captured.out == "" and captured.err == ""  # the library prints nothing
    if before or Path("/proc").is_dir():
        assert _children() <= before  # no server process started or left


def test_the_page_is_meshcats_static_export_format(panda, tmp_path):
    """The in-process recorder gives the page meshcat's server would (same tree walk):
    the still objects, the robot's nodes, the camera and one animation command."""
    rec: list = []
    original = viz._Recorder.send

    def spy(self, command):
        rec.append(command.lower())
        original(self, command)

    viz._Recorder.send = spy
    try:
        viz.animate(panda, _swing(panda, 5), tmp_path / "a.html", dt=0.1, obstacles=[])
    finally:
        viz._Recorder.send = original
    kinds = [c["type"] for c in rec]
    assert kinds.count("set_animation") == 1
    paths = {c["path"] for c in rec if c["type"] == "set_object"}
    assert "/meshcat/robot/visuals/panda_leftfinger_0" in paths  # locked joint drawn
    anim = next(c for c in rec if c["type"] == "set_animation")
    assert {a["path"] for a in anim["animations"]} >= {"/meshcat/robot/visuals/panda_link7_0"}
    keys = anim["animations"][0]["clip"]["tracks"][0]["keys"]
    assert [k["time"] for k in keys] == pytest.approx([0.0, 3.0, 6.0, 9.0, 12.0])  # 30 fps


def test_the_recorder_writes_the_page_meshcats_server_writes(panda, tmp_path):
    """Guard on meshcat's internals: every command also goes to a real meshcat server
    (subprocess), whose static export must equal the recorder's page (whitespace aside)."""
    import contextlib

    import meshcat

    with contextlib.redirect_stdout(io.StringIO()):
        window = meshcat.Visualizer().window  # starts meshcat's server and prints its URL
    recorders = []

    class Both(viz._Recorder):
        def __init__(self, *args):
            super().__init__(*args)
            recorders.append(self)

        def send(self, command):
            super().send(command)
            window.send(command)

    try:
        original, viz._Recorder = viz._Recorder, Both
        try:
            viz.animate(
                panda,
                _swing(panda, 4),
                tmp_path / "a.html",
                dt=0.1,
                targets=[np.eye(4)],
                obstacles=[{"centre": (0.5, 0, 0.2), "half_extents": (0.1, 0.1, 0.1)}],
            )
        finally:
            viz._Recorder = original
        theirs = window.get_scene()
    finally:
        window.zmq_socket.close(linger=0)  # else zmq waits for it when the interpreter exits
        window.server_proc.kill()
        window.server_proc.wait(timeout=10)

    def lines(page: str) -> list[str]:
        return [line.strip() for line in page.splitlines() if line.strip()]

    assert lines(recorders[0].html()) == lines(theirs)


def test_frames_are_subsampled_to_fps_and_max_frames():
    fine = np.arange(1001) * 0.001  # 1 s at 1 kHz
    keep = viz._frames(fine, 30.0, 600)
    assert len(keep) == 31 and keep[0] == 0 and keep[-1] == 1000
    assert np.allclose(np.diff(fine[keep]), 1 / 30, atol=1e-3)
    assert len(viz._frames(np.arange(100_001) * 0.001, 30.0, 600)) == 600  # 100 s: capped
    coarse = np.arange(11) * 0.1  # 10 Hz: every sample kept, none invented
    assert list(viz._frames(coarse, 30.0, 600)) == list(range(11))
    assert list(viz._frames(np.zeros(1), 30.0, 600)) == [0]


def test_a_trajectory_object_and_a_still(panda, tmp_path):
    q = _swing(panda, 4)
    traj = qc.Trajectory(
        t=np.array([0.0, 0.1, 0.2, 0.4]),
        q=q,
        qdot=np.zeros((4, panda.nv)),
        y=np.zeros((4, 3)),
        y_ref=np.zeros((4, 3)),
    )
    assert viz.animate(panda, traj, tmp_path / "t.html").is_file()
    still = viz.animate(panda, q[0], tmp_path / "still.html")  # one configuration, no dt
    assert still.is_file()


def test_overwrite_keeps_the_file_mode(panda, tmp_path):
    target = tmp_path / "page.html"
    target.write_text("old")
    target.chmod(0o600)
    viz.animate(panda, _swing(panda, 3), target, dt=0.1)
    assert target.stat().st_mode & 0o777 == 0o600
    assert target.read_text(encoding="utf-8").startswith("<!DOCTYPE html>")


# ---------------------------------------------------------------------- bad input, atomicity
def test_failure_leaves_nothing_at_path(panda, tmp_path, monkeypatch):
    target = tmp_path / "page.html"
    target.write_text("previous run")

    def broken(self, *args):
        raise RuntimeError("disk full")

    monkeypatch.setattr(viz._Recorder, "html", broken)
    with pytest.raises(RuntimeError, match="disk full"):
        viz.animate(panda, _swing(panda, 3), target, dt=0.1)
    assert target.read_text() == "previous run"  # untouched
    assert [p.name for p in tmp_path.iterdir()] == ["page.html"]  # no temp file
    fresh = tmp_path / "new.html"
    with pytest.raises(RuntimeError):
        viz.animate(panda, _swing(panda, 3), fresh, dt=0.1)
    assert not fresh.exists()


def test_a_write_error_is_a_value_error_naming_path(panda, tmp_path, monkeypatch):
    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(viz.os, "replace", full)
    with pytest.raises(ValueError, match="path"):
        viz.animate(panda, _swing(panda, 3), tmp_path / "p.html", dt=0.1)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"trajectory": np.zeros((5, 3))}, "trajectory"),
        ({"trajectory": np.full((5, 7), np.nan)}, r"trajectory\[0\]"),
        ({"trajectory": np.zeros((5, 7)), "dt": None}, "dt"),
        ({"dt": -0.1}, "dt"),
        ({"t": [0.0, 0.2, 0.1, 0.3, 0.4], "dt": None}, "t: sample times must increase"),
        ({"path": "/nonexistent-folder/x.html"}, "path"),
        ({"targets": [[1.0, 2.0]]}, "targets"),
        ({"targets": [np.diag([2.0, 1.0, 1.0, 1.0])]}, r"targets\[0\]"),
        ({"obstacles": [{"centre": (0, 0, 0), "radius": -0.1}]}, r"obstacles\[0\]: radius"),
        ({"obstacles": [{"centre": (np.nan, 0, 0), "radius": 0.1}]}, r"obstacles\[0\]: centre"),
        ({"obstacles": [{"centre": (0, 0, 0), "half_extents": (0.1, 0, 0.1)}]}, "half_extents"),
        ({"obstacles": [object()]}, r"obstacles\[0\]"),
        ({"fps": 0}, "fps"),
        ({"max_frames": 1}, "max_frames"),
    ],
)
def test_bad_input_names_the_argument(panda, tmp_path, kwargs, match):
    args = {"trajectory": _swing(panda, 5), "path": tmp_path / "x.html", "dt": 0.1}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        viz.animate(panda, **args)
    assert not (tmp_path / "x.html").exists()


def test_path_must_be_writable(panda, tmp_path):
    with pytest.raises(ValueError, match="path .* is a directory"):
        viz.animate(panda, _swing(panda, 3), tmp_path, dt=0.1)
    locked = tmp_path / "ro"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if os.access(locked, os.W_OK):  # root ignores the mode
            pytest.skip("running as root: a read-only folder is writable")
        with pytest.raises(ValueError, match="path: folder .* is not writable"):
            viz.animate(panda, _swing(panda, 3), locked / "x.html", dt=0.1)
    finally:
        locked.chmod(0o700)


def test_a_robot_without_visual_geometry(tmp_path):
    arm = qc.robots.load("planar_3r")  # URDF with no <visual>
    with pytest.raises(ValueError, match="robot 'planar_3r' has no visual geometry"):
        viz.animate(arm, np.zeros((3, 3)), tmp_path / "x.html", dt=0.1)
    bare = qc.Robot(arm.model)  # not read from a URDF at all
    with pytest.raises(ValueError, match="visual_model"):
        viz.animate(bare, np.zeros(3), tmp_path / "x.html")
    assert list(tmp_path.iterdir()) == []


def test_duck_typed_obstacles_and_own_visual_model(tmp_path):
    """qc.Sphere / qc.Box are duck-typed (centre, radius / half_extents, rotation); a robot
    without meshes can bring its own visual model (here: a ball on each link, on a robot
    with a coordinate map: absolute joint angles)."""
    import coal

    arm = qc.robots.load("planar_3r")
    geom = pin.GeometryModel()
    for j in range(1, arm.model.njoints):
        obj = pin.GeometryObject(f"ball{j}", j, pin.SE3.Identity(), coal.Sphere(0.1))
        obj.meshColor = np.array([0.2, 0.2, 0.8, 1.0])
        geom.addGeometryObject(obj)

    class Ball:
        centre, radius = np.array([1.0, 1.0, 0.0]), 0.2

    class Brick:
        centre, half_extents, rotation = (0.0, 2.0, 0.0), (0.3, 0.1, 0.1), np.eye(3)

    out = viz.animate(
        arm,
        np.linspace([0, 0, 0], [1, 2, 3], 20),
        tmp_path / "arm.html",
        dt=0.05,
        obstacles=[Ball(), Brick()],
        targets=np.array([[1.0, 1.0, 0.0], [2.0, 0.0, 0.0]]),
        visual_model=geom,
    )
    assert out.stat().st_size > 0.8e6  # three.js alone is 0.85 MB


# ---------------------------------------------------------------------- in a browser
def test_the_page_renders_the_robot_offline_in_headless_chromium(panda, tmp_path):
    """Open the written file in headless Chromium (software WebGL), with the network off,
    and look at it: a canvas, a robot in it (pixels that vanish when the robot is hidden),
    the red obstacle and the green target, a pose that changes along the animation, and no
    request but the file itself and its inlined data: URLs."""
    page_path = viz.animate(
        panda,
        _swing(panda, 41),
        tmp_path / "panda.html",
        dt=0.05,
        targets=[[0.45, 0.35, 0.6]],
        obstacles=[{"centre": (0.5, -0.35, 0.4), "radius": 0.12}],
        loop=False,
    )

    with offline_viewer(page_path) as (page, requests):
        assert page.evaluate("document.querySelectorAll('canvas').length") >= 1
        duration = page.evaluate("viewer.animator.duration")
        assert duration == pytest.approx(2.0)
        page.wait_for_timeout(2500)  # a few seconds of animation: the meshes are in
        page.evaluate("viewer.animator.pause(); viewer.animator.seek(0)")
        page.wait_for_timeout(300)
        start = pixels(page)
        page.evaluate(f"viewer.animator.seek({duration / 4})")
        page.wait_for_timeout(300)
        quarter = pixels(page)
        page.evaluate(
            "viewer.scene_tree.find(['meshcat', 'robot']).set_property('visible', false);"
            "viewer.set_dirty()"
        )
        page.wait_for_timeout(300)
        hidden = pixels(page)

    assert start.std() > 5.0  # not a blank page
    robot = np.abs(quarter - hidden).sum(axis=2) > 30
    share = robot.mean()
    assert 0.01 < share < 0.6, f"robot covers {share:.1%} of the view"
    rows, cols = np.nonzero(robot)
    h, w = robot.shape
    assert h * 0.1 < rows.mean() < h * 0.9 and w * 0.1 < cols.mean() < w * 0.9  # in view
    moved = (np.abs(start - quarter).sum(axis=2) > 30).mean()
    assert moved > 0.002, "the robot does not move along the animation"
    r, g, b = hidden[..., 0], hidden[..., 1], hidden[..., 2]
    assert ((r > g + 60) & (r > b + 60)).sum() > 200  # the red obstacle
    assert ((g > r + 40) & (g > b + 20)).sum() > 20  # the green target
    schemes = {u.split(":", 1)[0] for u in requests}
    assert schemes <= {"file", "data", "blob"}, f"network requests: {requests[:5]}"


def test_no_browser_skips_with_a_reason_or_fails_where_ci_promised_one(monkeypatch):
    monkeypatch.delenv("QPCOORD_REQUIRE_BROWSER", raising=False)
    with pytest.raises(pytest.skip.Exception, match="no Chromium"):
        need_browser("no Chromium browser found")
    monkeypatch.setenv("QPCOORD_REQUIRE_BROWSER", "1")
    with pytest.raises(pytest.fail.Exception, match="QPCOORD_REQUIRE_BROWSER is set"):
        need_browser("no Chromium browser found")
