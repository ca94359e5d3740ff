"""The appendix A shoulder model: data, kinematics (XZY angles, Eq. A.2, A.10), muscle paths
and moment arms (A.16–A.19), rigid-arm dynamics (A.1–A.6), contact force, bad input."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import qpcoord as qc
from qpcoord.robots import shoulder

DATA_MD = Path(__file__).resolve().parents[3] / "shared" / "data" / "shoulder-muscles.md"


@pytest.fixture(scope="module")
def model():
    return qc.robots.load("shoulder")


def _posture(u, model):
    """Map u ∈ [0, 1]³ into the model range (rad)."""
    return model.lower + np.asarray(u) * (model.upper - model.lower)


unit3 = st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3)


# ---------------------------------------------------------------- data
def test_load_gives_the_documented_model(model):
    assert "shoulder" in qc.robots.names()
    assert model.n_muscles == 11 and len(model.names) == 11
    assert model.moment_arms(np.zeros(3)).shape == (3, 11)
    assert np.allclose(model.pcsa * 4e5, model.f_max)  # Eq. A.14, 40 N/cm²
    assert model.inertia_transverse == pytest.approx(0.18 + 3.67 * 0.249**2)


@pytest.mark.skipif(not DATA_MD.is_file(), reason="shared/data/shoulder-muscles.md not present")
def test_json_matches_the_cited_data_table(model):
    rows = [
        line
        for line in DATA_MD.read_text().splitlines()
        if line.startswith("| ") and re.search(r"\| \d+ \|", line)
    ]
    assert len(rows) == 11
    for j, line in enumerate(rows):
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert cells[0] == model.names[j]
        assert float(cells[2]) == model.f_max[j]
        nums = [float(v.replace("−", "-")) for v in ", ".join(cells[3:5]).split(",")]
        assert np.array_equal(nums[:3], model.origins[j])
        assert np.array_equal(nums[3:], model.insertions[j])


def test_package_data_is_the_json_file():
    path = qc.robots.description_path("shoulder_muscles.json")
    assert len(json.loads(path.read_text())["muscles"]) == 11


# ---------------------------------------------------------------- kinematics
def _omega_fd(q, qd, h=1e-6):
    """World angular velocity from R(q ± h q̇) (central differences): vee(Ṙ Rᵀ)."""
    Rd = (shoulder.rotation(q + h * qd) - shoulder.rotation(q - h * qd)) / (2 * h)
    S = Rd @ shoulder.rotation(q).T
    return np.array([S[2, 1], S[0, 2], S[1, 0]])


@settings(max_examples=25, deadline=None)
@given(unit3, st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3))
def test_axes_are_the_partials_of_omega_and_match_eq_A2(model, u, qd):
    q, qd = _posture(u, model), np.asarray(qd)
    w = _omega_fd(q, qd)
    P = model.axes(q)
    assert np.allclose(P.T @ qd, w, atol=1e-8)  # Eq. A.10: e_i = ∂ω/∂q̇_i
    # Eq. A.2: body-frame components
    th, ph, ps = q
    td, pd, sd = qd
    a2 = np.array(
        [
            td * np.cos(ps) * np.cos(ph) - pd * np.sin(ps),
            -td * np.sin(ph) + sd,
            td * np.sin(ps) * np.cos(ph) + np.cos(ps) * pd,
        ]
    )
    assert np.allclose(shoulder.rotation(q).T @ w, a2, atol=1e-8)


def test_sign_conventions_of_the_angles():
    down = np.array([0.0, -1.0, 0.0])
    # θ < 0 takes the hanging arm laterally (+Z): abduction
    assert (shoulder.rotation([-0.3, 0, 0]) @ down)[2] > 0.1
    # ϕ > 0 takes it anteriorly (+X): flexion
    assert (shoulder.rotation([0, 0.3, 0]) @ down)[0] > 0.1
    # ψ > 0 turns the anterior side medially (−Z): internal rotation
    assert (shoulder.rotation([0, 0, 0.3]) @ np.array([1.0, 0, 0]))[2] < -0.1


# ---------------------------------------------------------------- muscle paths
def _lengths_fd(model, q, h=1e-6):
    """−∂ℓ/∂q by central differences (m), shape (3, 11)."""
    out = np.empty((3, model.n_muscles))
    for i in range(3):
        e = np.zeros(3)
        e[i] = h
        out[i] = -(model.lengths(q + e) - model.lengths(q - e)) / (2 * h)
    return out


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(0.01, 0.99), min_size=3, max_size=3))
def test_moment_arms_equal_minus_length_gradient(model, u):
    """Eq. A.19 (W = P B, B = [r × d]) against the tendon-excursion moment arms."""
    q = _posture(u, model)
    assert np.allclose(model.moment_arms(q), _lengths_fd(model, q), atol=2e-7)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(0.01, 0.99), min_size=3, max_size=3))
def test_straight_model_moment_arms_equal_minus_length_gradient(u):
    m = shoulder.build(wrap=False)
    q = _posture(u, m)
    assert np.allclose(m.moment_arms(q), _lengths_fd(m, q), atol=2e-7)


@pytest.mark.parametrize("lines", ["elements", "lumped"])
@settings(max_examples=40, deadline=None)
@given(u=unit3)
def test_wrap_engages_exactly_when_the_straight_line_cuts_the_sphere(lines, u):
    model = shoulder.build(lines=lines)
    q = _posture(u, model)
    p = model.line_paths(q)
    straight = shoulder.build(wrap=False, lines=lines).line_paths(q)
    for j in range(model.n_lines):
        o, i, r = model.line_origins[j], p.insertions[j], model.line_wrap_radii[j]
        d = i - o
        t = np.clip(-(o @ d) / (d @ d), 0.0, 1.0)
        cuts = r > 0 and np.linalg.norm(o + t * d) < r
        assert p.wrapped[j] == cuts
        if cuts:
            assert p.lengths[j] > straight.lengths[j]
            # the free segment at the origin is tangent to the sphere
            assert np.linalg.norm(np.cross(o, p.directions[j])) == pytest.approx(r, rel=1e-12)
        else:
            assert p.lengths[j] == pytest.approx(straight.lengths[j], rel=1e-14)


def test_moment_arms_are_continuous_when_a_wrap_engages(model):
    """The wrapped length is C¹, so W has no jump where a wrap engages: the change of W
    over a step there is no larger than elsewhere, and shrinks with the step (measured, 8
    engagements/releases: ≤ 2.4e-4 m per 0.2° step there, 3.2e-4 m elsewhere; a tenth of the
    step gives ≤ 0.100 of the change)."""

    def jumps(thetas):
        Ws = np.array([model.moment_arms([th, 0.3, 0.2]) for th in thetas])
        wrapped = np.array([model.paths([th, 0.3, 0.2]).wrapped for th in thetas])
        at = (np.diff(wrapped.astype(int), axis=0) != 0).any(axis=1)
        step = np.abs(np.diff(Ws, axis=0)).max(axis=(1, 2))
        return at, step

    coarse = np.radians(np.linspace(-100.0, 30.0, 651))  # 0.2° steps
    at, step = jumps(coarse)
    assert at.sum() >= 4  # wraps engage and release along this sweep
    assert step[at].max() <= 1.5 * step[~at].max()
    for k in np.flatnonzero(at):  # 0.02° steps across each engagement
        fine_at, fine_step = jumps(np.linspace(coarse[k], coarse[k + 1], 11))
        assert fine_at.any() and fine_step[fine_at].max() <= 0.15 * step[k]


def test_moment_arm_signs_at_neutral_match_the_data_note(model):
    """Data note: subscapularis internal rotation (+13.7 mm, straight), infraspinatus and
    teres minor external rotation (−10.7, −12.9 mm), supraspinatus abduction (11.7 mm),
    teres major and latissimus adduct and extend; the wrap increases the arms of the
    muscles whose straight line crosses the head."""
    idx = {n: k for k, n in enumerate(model.names)}
    Ws = shoulder.build(wrap=False, lines="lumped").moment_arms(np.zeros(3)) * 1e3  # mm
    W = shoulder.build(lines="lumped").moment_arms(np.zeros(3)) * 1e3
    assert Ws[2, idx["subscapularis"]] == pytest.approx(13.7, abs=0.3)
    assert Ws[2, idx["infraspinatus"]] == pytest.approx(-10.7, abs=0.3)
    assert Ws[2, idx["teres minor"]] == pytest.approx(-12.9, abs=0.3)
    assert -Ws[0, idx["supraspinatus"]] == pytest.approx(11.7, abs=0.3)  # abduction: θ < 0
    for name in ("teres major", "latissimus dorsi"):
        assert W[0, idx[name]] > 0 and W[1, idx[name]] < 0  # adduct (θ+), extend (ϕ−)
    for name in ("supraspinatus", "deltoideus medial"):
        assert -W[0, idx[name]] > -Ws[0, idx[name]] > 0  # wrapped abduction arm is larger
    for name in ("subscapularis", "infraspinatus"):
        assert abs(W[2, idx[name]]) > abs(Ws[2, idx[name]])


def test_moment_arm_matrix_has_rank_3_over_the_range(model):
    grid = [np.linspace(lo, hi, 7) for lo, hi in zip(model.lower, model.upper, strict=True)]
    worst = min(
        np.linalg.svd(model.moment_arms([a, b, c]), compute_uv=False)[-1]
        for a in grid[0]
        for b in grid[1]
        for c in grid[2]
    )
    assert worst > 5e-3  # m; measured 8.3e-3 m (θ = −100°, ϕ = 80°, ψ = −90°) on this 7³ grid


# ---------------------------------------------------------------- dynamics
def _lagrangian_Q(model, q, qd, qdd, h=1e-5):
    """Eq. A.6 by finite differences of L = T − V (A.3–A.5)."""

    def L(q_, qd_):
        return model.kinetic_energy(q_, qd_) - model.potential_energy(q_)

    def dL_dqd(q_, qd_):
        g = np.empty(3)
        for i in range(3):
            e = np.zeros(3)
            e[i] = h
            g[i] = (L(q_, qd_ + e) - L(q_, qd_ - e)) / (2 * h)
        return g

    # d/dt ∂L/∂q̇ along (q̇, q̈)
    ddt = (dL_dqd(q + h * qd, qd + h * qdd) - dL_dqd(q - h * qd, qd - h * qdd)) / (2 * h)
    dLdq = np.empty(3)
    for i in range(3):
        e = np.zeros(3)
        e[i] = h
        dLdq[i] = (L(q + e, qd) - L(q - e, qd)) / (2 * h)
    return ddt - dLdq


@settings(max_examples=25, deadline=None)
@given(
    st.lists(st.floats(0.05, 0.95), min_size=3, max_size=3),
    st.lists(st.floats(-3.0, 3.0), min_size=6, max_size=6),
)
def test_generalised_forces_equal_the_lagrangian(model, u, rates):
    q = _posture(u, model)
    qd, qdd = np.asarray(rates[:3]), 3.0 * np.asarray(rates[3:])
    Q = model.generalised_forces(q, qd, qdd)
    assert np.allclose(Q, _lagrangian_Q(model, q, qd, qdd), atol=1e-5)


def test_power_balance_along_a_motion(model):
    """Q·q̇ = d(T + V)/dt along a smooth motion (the work of the muscles)."""
    t = np.linspace(0.0, 1.0, 2001)
    qs = np.stack([-1.2 * np.sin(t) ** 2, 0.6 * t**2, 0.4 * np.sin(3 * t)], axis=1)
    qds = np.stack([-1.2 * np.sin(2 * t), 1.2 * t, 1.2 * np.cos(3 * t)], axis=1)
    qdds = np.stack([-2.4 * np.cos(2 * t), 1.2 + 0 * t, -3.6 * np.sin(3 * t)], axis=1)
    E = np.array(
        [
            model.kinetic_energy(q, v) + model.potential_energy(q)
            for q, v in zip(qs, qds, strict=True)
        ]
    )
    P = np.array(
        [model.generalised_forces(q, v, a) @ v for q, v, a in zip(qs, qds, qdds, strict=True)]
    )
    dE = np.gradient(E, t)
    assert np.max(np.abs(dE - P)[1:-1]) < 1e-4 * np.max(np.abs(P))


def test_static_gravity_and_point_load(model):
    mgl = model.mass * model.gravity * model.com_distance
    q = np.radians([-90.0, 0.0, 0.0])  # 90° abduction
    z = np.zeros(3)
    assert np.allclose(model.generalised_forces(q, z, z), [-mgl, 0.0, 0.0], atol=1e-12)
    # gravity moment projected on the axes is −∂V/∂q
    rc = shoulder.rotation(q) @ np.array([0.0, -model.com_distance, 0.0])
    Mg = np.cross(rc, [0.0, -model.mass * model.gravity, 0.0])
    q2 = np.radians([-40.0, 25.0, 30.0])
    rc2 = shoulder.rotation(q2) @ np.array([0.0, -model.com_distance, 0.0])
    Mg2 = np.cross(rc2, [0.0, -model.mass * model.gravity, 0.0])
    assert np.allclose(model.axes(q) @ Mg, -model.gravity_forces(q))
    assert np.allclose(model.axes(q2) @ Mg2, -model.gravity_forces(q2))
    M = model.point_load_moment(q, 2.0, 0.6)
    Q = model.generalised_forces(q, z, z, external_moment=M)
    assert Q[0] == pytest.approx(-mgl - 2.0 * 9.81 * 0.6)


def test_contact_force(model):
    z = np.zeros(3)
    F0 = np.zeros(model.n_muscles)
    # hanging arm, no muscle force: the arm hangs from the glenoid
    assert np.allclose(model.contact_force(z, z, z, F0), [0.0, -model.mass * 9.81, 0.0])
    # Newton: muscle forces add along their lines of action at the origin side
    q = np.radians([-60.0, 20.0, 10.0])
    F = np.linspace(10.0, 110.0, model.n_muscles)
    d = model.paths(q).directions
    expected = d.T @ F + model.mass * (np.array([0.0, -9.81, 0.0]))
    assert np.allclose(model.contact_force(q, z, z, F), expected)
    # a rotation about the long axis alone does not accelerate the centre of mass
    assert np.allclose(model.com_acceleration(z, [0.0, 0.0, 3.0], [0.0, 0.0, 5.0]), 0.0)


# ---------------------------------------------------------------- bad input
def test_posture_outside_the_range_is_named(model):
    with pytest.raises(ValueError, match=r"q\[0\] \(theta\) = -2\.5 rad"):
        model.moment_arms([-2.5, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"phi"):
        model.generalised_forces([0.0, np.pi / 2, 0.0], np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="non-finite"):
        model.moment_arms([np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="qd"):
        model.generalised_forces(np.zeros(3), [0.0, np.inf, 0.0], np.zeros(3))
    with pytest.raises(ValueError, match="shape"):
        model.moment_arms([0.0, 0.0])


def test_bad_model_data_is_named():
    f = [1063.0, 1739.0, -505.0, 463.0, 1432.0, 497.0, 608.0, 621.0, 1431.0, 562.0, 1188.0]
    with pytest.raises(ValueError, match=r"f_max of 'deltoideus anterior' must be > 0 N, got -505"):
        shoulder.build(f_max=f)
    with pytest.raises(ValueError, match="unknown shoulder option"):
        qc.robots.load("shoulder", bogus=1)
    with pytest.raises(ValueError, match="arm must be"):
        shoulder.build(arm="leg")
    radii = np.full(11, 0.2)
    with pytest.raises(ValueError, match="inside its wrap sphere"):
        shoulder.build(wrap_radii=radii)
    with pytest.raises(ValueError, match="gimbal"):
        shoulder.build(upper=[0.5, np.pi / 2, 1.0])
    with pytest.raises(ValueError, match="mass"):
        shoulder.build(mass=-1.0)


# ---------------------------------------------------------------- DAS3 element lines
ELEMENTS = json.loads(qc.robots.description_path("shoulder_elements.json").read_text())["muscles"]


def test_elements_sum_to_the_lumped_table():
    """The element file and the lumped table are the same DAS3 data: F_max sums, and the
    force-weighted element points are the lumped points to the table's 1 mm rounding."""
    lumped = shoulder.build(lines="lumped")
    assert list(ELEMENTS) == list(lumped.names)
    for j, name in enumerate(lumped.names):
        f = np.array([e["f_max"] for e in ELEMENTS[name]])
        assert f.sum() == pytest.approx(lumped.f_max[j], abs=1e-9)
        for key, ref in (("origin", lumped.origins[j]), ("insertion", lumped.insertions[j])):
            mean = f @ np.array([e[key] for e in ELEMENTS[name]]) / f.sum()
            assert np.abs(mean - ref).max() <= 0.5e-3 + 1e-6, (name, key)


def _one_muscle_per_element(wrap: bool = True):
    """A model with every DAS3 element as its own muscle, and the muscle → element shares."""
    table = shoulder._load_table()
    radii = table["wrap_spheres"]
    names, f, o, i, r, owner = [], [], [], [], [], []
    for j, m in enumerate(table["muscles"]):
        for e in ELEMENTS[m["name"]]:
            names.append(e["das"])
            f.append(e["f_max"])
            o.append(e["origin"])
            i.append(e["insertion"])
            r.append(radii[m["wrap"]] if (wrap and m["wrap"]) else 0.0)
            owner.append(j)
    seg = table["arm"]
    model = shoulder.ShoulderModel(
        names,
        f,
        o,
        i,
        r,
        mass=seg["mass"],
        com_distance=seg["com_distance"],
        inertia_transverse_com=seg["inertia_transverse_com"],
        inertia_longitudinal_com=seg["inertia_longitudinal_com"],
    )
    f, owner = np.array(f), np.array(owner)
    share = np.zeros((11, len(f)))
    for e, j in enumerate(owner):
        share[j, e] = f[e] / f[owner == j].sum()
    return model, share


@pytest.mark.parametrize("wrap", [True, False])
def test_element_muscle_arm_is_the_force_weighted_mean_of_its_elements(wrap):
    """lines="elements": each muscle's moment arm is its elements' arms weighted by their
    share of F_max, at every posture (not only at neutral, where the lumped line is fitted)."""
    model = shoulder.build(wrap=wrap)
    assert model.lines == "elements" and model.n_lines == 60
    per_element, share = _one_muscle_per_element(wrap)
    np.testing.assert_allclose(model.line_share, share, atol=1e-15)
    rng = np.random.default_rng(4)
    for _ in range(10):
        q = _posture(rng.uniform(0, 1, 3), model)
        np.testing.assert_allclose(
            model.moment_arms(q), per_element.moment_arms(q) @ share.T, atol=1e-15
        )
        # the muscles' net force on the humerus is the elements' force
        F = rng.uniform(0, 1, 11) * model.f_max
        np.testing.assert_allclose(
            model.paths(q).directions.T @ F,
            per_element.paths(q).directions.T @ (share.T @ F),
            atol=1e-12,
        )


def test_middle_deltoid_abducts_with_its_elements_arm_at_neutral():
    """The lumped middle deltoid has 6.9 mm of abduction arm at q = 0,
    its seven DAS3 elements 11.4 mm force-weighted (the model now uses the elements)."""
    j = shoulder.build().names.index("deltoideus medial")
    assert -shoulder.build(lines="lumped").moment_arms(np.zeros(3))[0, j] == pytest.approx(
        6.9e-3, abs=0.05e-3
    )
    assert -shoulder.build().moment_arms(np.zeros(3))[0, j] == pytest.approx(11.4e-3, abs=0.05e-3)


def test_lines_option_is_checked():
    with pytest.raises(ValueError, match="lines must be"):
        shoulder.build(lines="tendons")
    with pytest.raises(ValueError, match="elements must have one entry per muscle"):
        shoulder.build(elements=[None])
    bad = [None] * 11
    bad[0] = {"f_max": [-1.0], "origins": [[0.0, 0.1, 0.0]], "insertions": [[0.0, -0.1, 0.0]]}
    with pytest.raises(ValueError, match="f_max must be positive"):
        shoulder.build(elements=bad)


@pytest.mark.skipif(
    not Path(__import__("os").environ.get("QPCOORD_DAS3_OSIM", "/nonexistent")).is_file(),
    reason="set QPCOORD_DAS3_OSIM to DAS3's das4_v4.osim (AbdnBiomechEng/arm-model)",
)
def test_element_file_is_read_from_das3():
    import os

    from qpcoord.robots.shoulder_das3 import read_elements

    assert read_elements(os.environ["QPCOORD_DAS3_OSIM"]) == ELEMENTS
    with pytest.raises(ValueError, match="osim"):
        read_elements("/nonexistent.osim")
