"""Tests of the reference paths (:mod:`qpcoord.kinematics.paths`): geometry, derivatives against
finite
differences, periodicity, arc length, vectorised evaluation and parameter checks."""

from __future__ import annotations

import numpy as np
import pytest

from qpcoord import paths

#: Central-difference step (s) and the agreement required (relative to max(1, |value|)).
FD_STEP = 1e-5
FD_TOL = 1e-6
#: Two evaluations of one closed form (vectorised and scalar, a rotation built two ways, a
#: formula against its exact value) differ by the rounding of each elementary function
#: (numpy's sin and cos: within an ulp or two) and of each product and sum over terms no
#: larger than the value's scale: ``ROUNDING`` ulps of ``max(1, scale)``. A path has a handful
#: of such operations in a chain; 16 covers them with room (measured: at most 1 ulp).
ROUNDING = 16 * np.finfo(float).eps


def rounding(*values) -> float:
    """The absolute agreement of two evaluations of values of these magnitudes."""
    return ROUNDING * max(1.0, *(float(np.max(np.abs(v), initial=0.0)) for v in values))


PATHS = {
    "lissajous-default": paths.LissajousSphere,
    "lissajous-custom": lambda: paths.LissajousSphere(
        radius=0.7,
        center=(1.0, 2.0, -0.5),
        omega=1.3,
        amplitude=1.1,
        phase=0.3,
        angles=(0.2, -0.9, 1.4),
    ),
    "circle-default": paths.Circle,
    "circle-custom": lambda: paths.Circle(center=(-0.5, 0.25), radius=1.2, period=2.5, phase=1.0),
}


@pytest.fixture(params=list(PATHS), ids=list(PATHS))
def path(request) -> paths.Path:
    return PATHS[request.param]()


def sample_times(path: paths.Path, rng: np.random.Generator, count: int = 12) -> np.ndarray:
    return np.concatenate([[0.0], rng.uniform(-path.period, 2 * path.period, count)])


def rotation_about(axis: int, angle: float) -> np.ndarray:
    """Independent rotation matrix (right-handed) about coordinate ``axis``."""
    c, s = np.cos(angle), np.sin(angle)
    i, j = [k for k in range(3) if k != axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    if axis == 1:  # y: the (z, x) plane keeps the right-handed orientation
        R[i, j], R[j, i] = s, -s
    return R


# ---------------------------------------------------------------------------------------
# geometry
# ---------------------------------------------------------------------------------------


def test_lissajous_defaults_are_the_thesis_example():
    p = paths.LissajousSphere()
    assert p.radius == 1.5 and p.omega == 0.4 and p.amplitude == 0.6
    assert p.phase == pytest.approx(np.pi / 2, abs=0)
    np.testing.assert_array_equal(p.center, [0.0, -0.5, 0.2])
    np.testing.assert_allclose(p.angles, (np.pi / 4, np.pi / 4, 0.0), rtol=0, atol=0)
    assert p.period == pytest.approx(2 * np.pi / 0.4, rel=1e-15)
    assert p.dim == 3


def test_lissajous_matches_equation_3_3(rng):
    """``Y = Rx(a) Ry(b) Rz(c) r (cos x cos y, cos x sin y, sin x) + centre``."""
    p = paths.LissajousSphere()
    R = rotation_about(0, np.pi / 4) @ rotation_about(1, np.pi / 4) @ rotation_about(2, 0.0)
    for t in sample_times(p, rng, 5):
        xp = 0.6 * np.cos(0.4 * t + np.pi / 2)
        yp = 0.6 * np.cos(0.8 * t + np.pi / 2)
        s = 1.5 * np.array([np.cos(xp) * np.cos(yp), np.cos(xp) * np.sin(yp), np.sin(xp)])
        # |R s| = 1.5 and the centre ~0.5: the terms' scale is 2; the angles 0.4 t, 0.8 t
        # carry eps·|t| each (times slopes below 1), so |t| counts as a scale too
        np.testing.assert_allclose(
            p.position(t), R @ s + np.array([0.0, -0.5, 0.2]), rtol=0, atol=rounding(2.0, t)
        )


def test_rotation_helpers_are_right_handed():
    for axis, fn in enumerate((paths.rotation_x, paths.rotation_y, paths.rotation_z)):
        for angle in (0.3, -1.2, 2.5):
            np.testing.assert_allclose(fn(angle), rotation_about(axis, angle), atol=rounding(1.0))
    # a quarter turn about z takes x to y (cos(π/2) is 6e-17, not 0)
    np.testing.assert_allclose(
        paths.rotation_z(np.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=rounding(1.0)
    )


@pytest.mark.parametrize("name", ["lissajous-default", "lissajous-custom"])
def test_lissajous_lies_on_its_sphere(name, rng):
    p = PATHS[name]()
    points = p.position(sample_times(p, rng, 200))
    distances = np.linalg.norm(points - p.center, axis=1)
    np.testing.assert_allclose(distances, p.radius, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["circle-default", "circle-custom"])
def test_circle_lies_on_its_circle_at_constant_speed(name, rng):
    p = PATHS[name]()
    t = sample_times(p, rng, 200)
    np.testing.assert_allclose(
        np.linalg.norm(p.position(t) - p.center, axis=1), p.radius, rtol=0, atol=1e-12
    )
    speed = 2 * np.pi * p.radius / p.period
    np.testing.assert_allclose(np.linalg.norm(p.velocity(t), axis=1), speed, rtol=1e-13)
    np.testing.assert_allclose(
        np.linalg.norm(p.acceleration(t), axis=1), speed**2 / p.radius, rtol=1e-13
    )


def test_circle_defaults_are_the_thesis_figure():
    c = paths.Circle()
    np.testing.assert_array_equal(c.center, [1.5, 0.0])
    assert c.radius == 0.5 and c.period == np.pi and c.phase == 0.0 and c.dim == 2
    np.testing.assert_allclose(c.position(0.0), [2.0, 0.0], rtol=0, atol=rounding(2.0))
    # counter-clockwise: a quarter period later it is at the top
    np.testing.assert_allclose(c.position(np.pi / 4), [1.5, 0.5], rtol=0, atol=rounding(2.0))


def test_circle_phase_rotates_the_start():
    c = paths.Circle(center=(0.0, 0.0), radius=2.0, phase=np.pi / 2)
    np.testing.assert_allclose(c.position(0.0), [0.0, 2.0], atol=rounding(2.0))


# ---------------------------------------------------------------------------------------
# derivatives, periodicity, length
# ---------------------------------------------------------------------------------------


def assert_close_relative(actual, expected, tol, what):
    err = np.abs(np.asarray(actual) - expected) / np.maximum(1.0, np.abs(expected))
    assert err.max() <= tol, f"{what}: relative error {err.max():.3g}"


def test_velocity_is_the_derivative_of_position(path, rng):
    t = sample_times(path, rng)
    fd = (path.position(t + FD_STEP) - path.position(t - FD_STEP)) / (2 * FD_STEP)
    assert_close_relative(path.velocity(t), fd, FD_TOL, "velocity")


def test_acceleration_is_the_derivative_of_velocity(path, rng):
    t = sample_times(path, rng)
    fd = (path.velocity(t + FD_STEP) - path.velocity(t - FD_STEP)) / (2 * FD_STEP)
    assert_close_relative(path.acceleration(t), fd, FD_TOL, "acceleration")


def test_acceleration_is_the_second_difference_of_position(path, rng):
    h = 1e-4
    t = sample_times(path, rng)
    fd = (path.position(t + h) - 2 * path.position(t) + path.position(t - h)) / h**2
    assert_close_relative(path.acceleration(t), fd, 1e-5, "acceleration")


def test_path_is_periodic(path, rng):
    t = sample_times(path, rng)
    for method in ("position", "velocity", "acceleration"):
        fn = getattr(path, method)
        np.testing.assert_allclose(fn(t + path.period), fn(t), rtol=0, atol=1e-12, err_msg=method)


def test_path_is_not_periodic_with_half_the_period(path):
    """Guards the periodicity test: the period is the smallest one (for these paths)."""
    t = np.linspace(0.0, path.period, 7)
    assert np.abs(path.position(t + path.period / 2) - path.position(t)).max() > 1e-3


def test_position_velocity_returns_both_at_once(path):
    p, v = path.position_velocity(0.8)
    np.testing.assert_array_equal(p, path.position(0.8))
    np.testing.assert_array_equal(v, path.velocity(0.8))


@pytest.mark.parametrize(
    ("center", "radius"), [((1.5, 0.0), 0.5), ((0.0, 0.0), 2.0), ((3.0, -1.0), 0.1)]
)
def test_circle_length_is_its_circumference(center, radius):
    c = paths.Circle(center=center, radius=radius, period=1.7)
    assert c.length() == pytest.approx(2 * np.pi * radius, abs=1e-6)


def test_lissajous_length_matches_a_fine_polyline():
    p = paths.LissajousSphere()
    t = np.linspace(0.0, p.period, 200001)
    polyline = float(np.sum(np.linalg.norm(np.diff(p.position(t), axis=0), axis=1)))
    assert p.length() == pytest.approx(polyline, rel=1e-6)
    assert p.length() > 0.1


# ---------------------------------------------------------------------------------------
# shapes
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["position", "velocity", "acceleration"])
def test_vector_times_give_one_row_per_time(path, method):
    fn = getattr(path, method)
    t = np.linspace(0.0, 3.0, 5)
    out = fn(t)
    assert out.shape == (5, path.dim)
    for k, tk in enumerate(t):
        np.testing.assert_allclose(out[k], fn(float(tk)), rtol=0, atol=rounding(out))
    assert fn(0.5).shape == (path.dim,)
    assert fn([0.5]).shape == (1, path.dim)
    assert fn(np.array([])).shape == (0, path.dim)


# ---------------------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"radius": 0.0}, "radius must be > 0"),
        ({"radius": -1.0}, "radius must be > 0"),
        ({"radius": np.nan}, "radius must be > 0 and finite"),
        ({"radius": "big"}, "radius must be a number"),
        ({"radius": True}, "radius must be a number"),
        ({"center": (0.0, np.nan, 0.0)}, "center must be 3 finite numbers"),
        ({"center": (0.0, 1.0)}, "center must be 3 finite numbers"),
        ({"omega": 0.0}, "omega must be > 0"),
        ({"amplitude": np.inf}, "amplitude must be finite"),
        ({"phase": np.nan}, "phase must be finite"),
        ({"angles": (0.0, np.nan, 0.0)}, "angles must be finite"),
    ],
)
def test_lissajous_bad_parameters(options, message):
    with pytest.raises(ValueError, match=message):
        paths.LissajousSphere(**options)


@pytest.mark.parametrize("angles", [(0.1, 0.2), (0.1, 0.2, 0.3, 0.4)], ids=["two", "four"])
def test_lissajous_wrong_number_of_angles_is_named(angles):
    with pytest.raises(ValueError, match="angles"):
        paths.LissajousSphere(angles=angles)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"radius": 0.0}, "radius must be > 0"),
        ({"radius": -0.5}, "radius must be > 0"),
        ({"center": (np.nan, 0.0)}, "center must be 2 finite numbers"),
        ({"center": (0.0, 0.0, 0.0)}, "center must be 2 finite numbers"),
        ({"period": 0.0}, "period must be > 0"),
        ({"period": np.inf}, "period must be > 0 and finite"),
        ({"phase": np.nan}, "phase must be finite"),
    ],
)
def test_circle_bad_parameters(options, message):
    with pytest.raises(ValueError, match=message):
        paths.Circle(**options)


@pytest.mark.parametrize("method", ["position", "velocity", "acceleration"])
@pytest.mark.parametrize(
    ("t", "message"),
    [
        (np.zeros((2, 3)), "1-D array"),
        ([[0.0], [1.0]], "1-D array"),
        (np.nan, "non-finite"),
        ([0.0, np.inf], "non-finite"),
        ("soon", "soon"),
    ],
    ids=["2-d", "column", "nan", "inf", "text"],
)
def test_bad_times(path, method, t, message):
    with pytest.raises(ValueError, match=message):
        getattr(path, method)(t)


def test_horizontal_circle_starts_at_its_start_point():
    start = np.array([0.3, -0.1, 0.5])
    c = paths.HorizontalCircle(start, radius=0.1, period=2.0)
    np.testing.assert_allclose(c.position(0.0), start, atol=rounding(start))
    # a full period: the angle 2π·t/T is 2π to its rounding, times the radius 0.1
    np.testing.assert_allclose(c.position(2.0), start, atol=rounding(start))
    t = np.linspace(0, 2, 7)
    np.testing.assert_allclose(np.linalg.norm(c.position(t) - c.center, axis=1), 0.1)
    h = 1e-6
    np.testing.assert_allclose(
        c.velocity(0.3), (c.position(0.3 + h) - c.position(0.3 - h)) / 2e-6, atol=1e-8
    )
    with pytest.raises(ValueError, match="start"):
        paths.HorizontalCircle([0, 0], 0.1, 1.0)
    with pytest.raises(ValueError, match="radius"):
        paths.HorizontalCircle(start, -0.1, 1.0)
