"""Tests of the robot registry :mod:`qpcoord.robots`: ``load``, the thesis planar arms in
closed form, option checking and the descriptions shipped in a (non-editable) wheel."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

import qpcoord as qc
from qpcoord.robots import planar_chain

REPO_ROOT = Path(__file__).resolve().parents[2]
KNOWN_NAMES = ("planar_3r", "spatial_5r", "planar_nr", "panda", "ur5", "shoulder")


# ---------------------------------------------------------------------------------------
# closed forms of the planar arms (absolute angles)
# ---------------------------------------------------------------------------------------


def planar_position(q: np.ndarray) -> np.ndarray:
    """Unit links, absolute angles: ``(Σ cos qᵢ, Σ sin qᵢ)``."""
    return np.array([np.sum(np.cos(q)), np.sum(np.sin(q))])


def planar_jacobian(q: np.ndarray) -> np.ndarray:
    """Thesis Ex. 4.3 (for n = 3): ``[[-sin q₁, -sin q₂, -sin q₃], [cos q₁, cos q₂, cos q₃]]``."""
    return np.array([-np.sin(q), np.cos(q)])


def planar_hessian(q: np.ndarray) -> np.ndarray:
    """``H[0] = diag(-cos q)``, ``H[1] = diag(-sin q)``."""
    return np.array([np.diag(-np.cos(q)), np.diag(-np.sin(q))])


def test_planar_3r_at_zero_is_stretched_along_x():
    arm = qc.robots.load("planar_3r")
    np.testing.assert_allclose(arm.position([0.0, 0.0, 0.0]), [3.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(
        arm.jacobian([0.0, 0.0, 0.0]), [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]], atol=1e-15
    )


def test_planar_3r_uses_absolute_angles():
    """With all absolute angles π/2 every link points along y (relative angles would curl)."""
    arm = qc.robots.load("planar_3r")
    np.testing.assert_allclose(arm.position(np.full(3, np.pi / 2)), [0.0, 3.0], atol=1e-14)


def test_planar_3r_matches_the_thesis_closed_forms(rng):
    arm = qc.robots.load("planar_3r")
    assert (arm.nq, arm.m) == (3, 2)
    for q in rng.uniform(-np.pi, np.pi, size=(6, 3)):
        np.testing.assert_allclose(arm.position(q), planar_position(q), rtol=0, atol=1e-14)
        np.testing.assert_allclose(arm.jacobian(q), planar_jacobian(q), rtol=0, atol=1e-14)
        np.testing.assert_allclose(arm.hessian(q), planar_hessian(q), rtol=0, atol=1e-14)


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 6])
def test_planar_nr_matches_the_closed_forms(n, rng):
    arm = qc.robots.load("planar_nr", n=n)
    assert (arm.nq, arm.m) == (n, 2)
    assert arm.name == f"planar_{n}r"
    for q in rng.uniform(-np.pi, np.pi, size=(4, n)):
        np.testing.assert_allclose(arm.position(q), planar_position(q), rtol=0, atol=1e-14)
        np.testing.assert_allclose(arm.jacobian(q), planar_jacobian(q), rtol=0, atol=1e-14)
        np.testing.assert_allclose(arm.hessian(q), planar_hessian(q), rtol=0, atol=1e-14)


def test_planar_nr_with_three_links_equals_planar_3r(rng):
    built, shipped = qc.robots.load("planar_nr", n=3), qc.robots.load("planar_3r")
    for q in rng.uniform(-np.pi, np.pi, size=(5, 3)):
        np.testing.assert_allclose(built.position(q), shipped.position(q), rtol=0, atol=1e-14)
        np.testing.assert_allclose(built.jacobian(q), shipped.jacobian(q), rtol=0, atol=1e-14)
        np.testing.assert_allclose(built.hessian(q), shipped.hessian(q), rtol=0, atol=1e-14)


@pytest.mark.parametrize("name", ["planar_3r", "planar_nr"])
def test_planar_arms_are_unlimited(name):
    arm = qc.robots.load(name, **({"n": 4} if name == "planar_nr" else {}))
    assert np.all(arm.lower == -np.inf) and np.all(arm.upper == np.inf)
    assert np.all(arm.velocity_limit == np.inf)


def test_planar_chain_link_length_scales_the_arm():
    arm = qc.Robot(planar_chain(2, length=0.5), "tip", rows=(0, 1))
    np.testing.assert_allclose(arm.position([0.0, 0.0]), [1.0, 0.0], atol=1e-15)
    # relative angles (no coordinate map): second link folded back
    np.testing.assert_allclose(arm.position([0.0, np.pi]), [0.0, 0.0], atol=1e-15)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((0,), "n must be an integer >= 1"),
        ((True,), "n must be an integer"),
        ((2.0,), "n must be an integer"),
        ((2, 0.0), "length must be a positive"),
        ((2, np.nan), "length must be a positive"),
    ],
)
def test_planar_chain_bad_arguments(args, message):
    with pytest.raises(ValueError, match=message):
        planar_chain(*args)


# ---------------------------------------------------------------------------------------
# the external and shipped arms
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "nq", "frame"),
    [("panda", 7, "panda_hand_tcp"), ("ur5", 6, "tool0")],
)
def test_external_arms(name, nq, frame):
    arm = qc.robots.load(name)
    assert (arm.nq, arm.m, arm.frame, arm.name) == (nq, 3, frame, name)
    assert np.all(np.isfinite(arm.lower)) and np.all(np.isfinite(arm.upper))
    assert np.all(arm.lower < arm.upper)
    assert np.all(np.isfinite(arm.velocity_limit)) and np.all(arm.velocity_limit > 0)


def test_panda_fingers_are_locked():
    arm = qc.robots.load("panda")
    names = list(arm.model.names)
    assert "panda_finger_joint1" not in names and "panda_finger_joint2" not in names
    assert [f"panda_joint{i}" for i in range(1, 8)] == names[1:]


def test_spatial_5r_shape():
    arm = qc.robots.load("spatial_5r")
    assert (arm.nq, arm.m, arm.frame) == (5, 3, "tip")
    y = arm.position(np.zeros(5))
    assert y.shape == (3,) and np.all(np.isfinite(y))


def test_names_lists_every_loadable_robot():
    """The thesis robots and the two first arms come first, then example-robot-data's."""
    from qpcoord.robots.external import EXAMPLE_ROBOTS

    names = qc.robots.names()
    assert names[: len(KNOWN_NAMES)] == KNOWN_NAMES
    assert set(names) == set(KNOWN_NAMES) | set(EXAMPLE_ROBOTS)


# ---------------------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------------------


def test_unknown_name_lists_the_known_robots():
    with pytest.raises(ValueError, match="unknown robot 'kuka'") as info:
        qc.robots.load("kuka")
    assert all(name in str(info.value) for name in KNOWN_NAMES)


@pytest.mark.parametrize(
    ("name", "options", "message"),
    [
        ("planar_nr", {}, "takes exactly the option n"),
        ("planar_nr", {"n": 0}, "n must be an integer >= 1, got 0"),
        ("planar_nr", {"n": -2}, "n must be an integer >= 1"),
        ("planar_nr", {"n": True}, "n must be an integer >= 1, got True"),
        ("planar_nr", {"n": 3.0}, "n must be an integer >= 1"),
        ("planar_nr", {"n": "3"}, "n must be an integer >= 1"),
        ("planar_nr", {"n": 3, "length": 2.0}, "takes exactly the option n"),
        ("planar_3r", {"foo": 1}, r"load\('planar_3r'\) takes no options.*foo"),
        ("panda", {"n": 7}, r"load\('panda'\) takes no options"),
        ("ur5", {"foo": 1}, r"load\('ur5'\) takes no options"),
    ],
)
def test_bad_options(name, options, message):
    with pytest.raises(ValueError, match=message):
        qc.robots.load(name, **options)


def test_description_path_of_a_missing_file():
    with pytest.raises(ValueError, match="no robot description file 'atlas.urdf'"):
        qc.robots.description_path("atlas.urdf")


def test_missing_example_robot_data_is_reported(monkeypatch):
    from importlib import metadata

    from qpcoord.robots import external

    def not_installed(name):
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(external.metadata, "distribution", not_installed)
    with pytest.raises(ValueError, match="example-robot-data"):
        qc.robots.load("panda")


def test_missing_file_in_example_robot_data_is_reported():
    from qpcoord.robots.external import example_robot_data_urdf

    with pytest.raises(ValueError, match="has no file 'nothing/here.urdf'"):
        example_robot_data_urdf("nothing/here.urdf")


# ---------------------------------------------------------------------------------------
# non-editable install
# ---------------------------------------------------------------------------------------


def _build_wheel(source: Path, out: Path) -> Path:
    """Build a wheel of ``source`` into ``out``: without build isolation if the venv can,
    else with it (fetches the build requirements)."""
    errors = []
    for extra in (["--no-build-isolation"], []):
        proc = subprocess.run(
            [
                sys.executable,
                "-m",
                "pip",
                "wheel",
                "--no-deps",
                # the baseline build only: the wheel's contents are under test, not the
                # x86-64-v3 variant (which CI's editable install builds); half the compile
                # time, which under load passed the 300 s limit
                "-C",
                "cmake.define.QPCOORD_NATIVE_VARIANTS=OFF",
                *extra,
                "-w",
                str(out),
                str(source),
            ],
            capture_output=True,
            text=True,
            timeout=300,
        )
        wheels = sorted(out.glob("qpcoord-*.whl"))
        if proc.returncode == 0 and wheels:
            return wheels[0]
        errors.append(proc.stdout[-2000:] + proc.stderr[-2000:])
    pytest.fail("could not build a wheel:\n" + "\n----\n".join(errors))


@pytest.mark.engine_independent
def test_wheel_ships_and_loads_the_descriptions(tmp_path):
    # build from a copy so the checkout gets no build/ or egg-info directories
    source = tmp_path / "source"
    shutil.copytree(
        REPO_ROOT,
        source,
        ignore=shutil.ignore_patterns(
            ".git",
            "build",
            "dist",
            "*.egg-info",
            "__pycache__",
            ".pytest_cache",
            ".hypothesis",
            ".ruff_cache",
            "out",
            # virtual environments in the checkout (CI's .venv, benchmarks/.placo-venv):
            # 2.5 GB that would be copied on every run
            ".venv",
            "*-venv",
        ),
    )
    wheel = _build_wheel(source, tmp_path / "wheels")
    with zipfile.ZipFile(wheel) as archive:
        members = archive.namelist()
        assert "qpcoord/robots/descriptions/planar_3r.urdf" in members
        assert "qpcoord/robots/descriptions/__init__.py" in members
        # a machine with a C++ compiler (this one, CI) builds the native engine into the wheel
        if shutil.which("c++") or shutil.which("g++"):
            assert any(m.startswith("qpcoord/_native") for m in members), members
        installed = tmp_path / "installed"
        archive.extractall(installed)

    # an editable install (scikit-build-core) puts a redirecting finder first in
    # sys.meta_path, ahead of PYTHONPATH: drop it so the wheel's copy is the one imported
    script = (
        "import sys; "
        "sys.meta_path[:] = [f for f in sys.meta_path "
        "if type(f).__name__ != 'ScikitBuildRedirectingFinder']; "
        "import qpcoord, qpcoord.robots as r; "
        "print(qpcoord.__file__); "
        "print(r.load('planar_3r').position([0, 0, 0]).tolist())"
    )
    env = {**os.environ, "PYTHONPATH": str(installed)}
    proc = subprocess.run(
        [sys.executable, "-c", script],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    module_file, position = proc.stdout.strip().splitlines()[-2:]
    assert Path(module_file).resolve().is_relative_to(installed.resolve()), module_file
    assert position == "[3.0, 0.0]"
