"""Appendix C: Preisach model, its memory (wipe-out), its inverse, identification."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from qpcoord import hysteresis as hy

LV = np.linspace(0.0, 6.0, 7)  # V, a coarse mesh: cells of 1 V


def random_model(seed: int = 0, levels=LV) -> hy.PreisachModel:
    """A model with random positive densities (area in rectangle cells, line on diagonal)."""
    rng = np.random.default_rng(seed)
    n = levels.size - 1
    h = np.diff(levels)
    mu = rng.uniform(0.2, 1.0, (n, n)) * 1e-7  # m/V², rectangle cells (i > j)
    c = rng.uniform(0.5, 1.5, n) * 1e-6  # m/V, diagonal line density
    E = np.zeros((n + 1, n + 1))
    for i in range(1, n + 1):
        for j in range(i - 1, -1, -1):
            # X(l_i, l_j) = X(l_i, l_{j+1}) + X(l_{i−1}, l_j) − X(l_{i−1}, l_{j+1}) + cell mass
            if j == i - 1:
                E[i, j] = c[j] * h[j]
            else:
                E[i, j] = (
                    E[i, j + 1] + E[i - 1, j] - E[i - 1, j + 1] + mu[i - 1, j] * h[i - 1] * h[j]
                )
    return hy.PreisachModel(levels, E, offset=1e-6)


MODEL = random_model()
SUB = 8  # relays per cell edge in the brute-force oracle


def relay_oracle(model: hy.PreisachModel, sub: int = SUB):
    """Relays (Eq. C.1) reproducing ``model`` exactly for inputs on the sub-grid l + k h/sub:
    area relays at sub-cell centres with the cell's density −a11, diagonal relays with the
    diagonal cell's line density."""
    lv = model.levels
    n = lv.size - 1
    al, be, w = [], [], []
    for i in range(n):
        ca = lv[i] + (np.arange(sub) + 0.5) * (lv[i + 1] - lv[i]) / sub
        c = model._a[1, i, i]  # X = c (α − β) on the diagonal cell
        al += ca.tolist()
        be += ca.tolist()
        w += [c * (lv[i + 1] - lv[i]) / sub] * sub
        for j in range(i):
            cb = lv[j] + (np.arange(sub) + 0.5) * (lv[j + 1] - lv[j]) / sub
            A, B = np.meshgrid(ca, cb, indexing="ij")
            dens = -model._a[3, i, j]
            area = (lv[i + 1] - lv[i]) * (lv[j + 1] - lv[j]) / sub**2
            al += A.ravel().tolist()
            be += B.ravel().tolist()
            w += [dens * area] * A.size
    return np.array(al), np.array(be), np.array(w)


def relay_outputs(model, u):
    al, be, w = relay_oracle(model)
    on = np.zeros(al.size, dtype=bool)
    prev = model.u_min
    out = []
    for v in u:
        if v > prev:
            on |= al <= v
        elif v < prev:
            on &= be < v
        prev = v
        out.append(model.offset + w @ on)
    return np.array(out)


grid_values = st.lists(st.integers(0, SUB * (LV.size - 1)), min_size=1, max_size=40).map(
    lambda k: np.array(k, dtype=float) / SUB * (LV[1] - LV[0])
)
voltages = st.lists(
    st.one_of(st.floats(0.0, 6.0), st.sampled_from([0.0, 6.0, 3.0])), min_size=1, max_size=60
).map(np.array)


# ---------------------------------------------------------------------------- Everett


def test_everett_interpolates_nodes_and_is_zero_on_diagonal():
    A, B = np.meshgrid(LV, LV, indexing="ij")
    low = A >= B
    assert np.allclose(MODEL.everett_at(A[low], B[low]), MODEL.everett[low], rtol=0, atol=1e-18)
    v = np.linspace(0, 6, 37)
    assert np.allclose(MODEL.everett_at(v, v), 0.0, atol=1e-18)


def test_everett_is_bilinear_in_a_rectangle_cell():
    # Eq. C.8: along α at fixed β, and along β at fixed α, X is affine inside a cell
    a = np.linspace(4.0, 5.0, 5)
    x = MODEL.everett_at(a, 1.3)
    assert np.allclose(np.diff(x, 2), 0.0, atol=1e-18)
    b = np.linspace(1.0, 2.0, 5)
    assert np.allclose(np.diff(MODEL.everett_at(4.4, b), 2), 0.0, atol=1e-18)


# ---------------------------------------------------------------------------- evaluation


def check_against_relays(u):
    want = relay_outputs(MODEL, u)
    assert np.allclose(MODEL.evaluate(u), want, rtol=0, atol=1e-15)
    stage = hy.PreisachStage(MODEL)
    assert np.allclose([stage.step(v) for v in u], want, rtol=0, atol=1e-15)


@settings(max_examples=40, deadline=None)
@given(grid_values)
def test_matches_brute_force_relays(u):
    """Eqs C.6–C.7 with wipe-out equal the hysteron sum of Eq. C.1 (independent oracle)."""
    check_against_relays(u)


@pytest.mark.parametrize("seed", range(4))
def test_matches_brute_force_relays_on_long_random_walks(seed):
    rng = np.random.default_rng(seed)
    k = np.clip(24 + np.cumsum(rng.integers(-5, 6, 1500)), 0, SUB * (LV.size - 1))
    check_against_relays(k / SUB * (LV[1] - LV[0]))


@settings(max_examples=60, deadline=None)
@given(voltages)
def test_vectorised_run_equals_per_sample_steps(u):
    stage = hy.PreisachStage(MODEL)
    stepped = np.array([stage.step(v) for v in u])
    fresh = hy.PreisachStage(MODEL)
    assert np.allclose(fresh.run(u), stepped, rtol=0, atol=1e-17)
    assert fresh.extrema == stage.extrema
    # continuing from a state: split the signal in two runs
    again = hy.PreisachStage(MODEL)
    k = len(u) // 2
    two = np.r_[again.run(u[:k]), again.run(u[k:])]
    assert np.allclose(two, stepped, rtol=0, atol=1e-17)


@settings(max_examples=60, deadline=None)
@given(voltages)
def test_output_stays_inside_the_major_loop(u):
    x = MODEL.evaluate(u)
    lower = MODEL.offset + MODEL.everett_at(u, np.zeros_like(u))
    upper = MODEL.x_max - MODEL.everett_at(np.full_like(u, 6.0), u)
    assert np.all(x >= lower - 1e-18) and np.all(x <= upper + 1e-18)


@settings(max_examples=60, deadline=None)
@given(voltages, st.floats(0.0, 6.0))
def test_wipe_out(u, v):
    """Only the dominant extrema matter: the state reduces to its stored extrema, and an
    input exceeding every past maximum (or below every past minimum) erases the past."""
    stage = hy.PreisachStage(MODEL)
    x = stage.run(u)[-1]
    reduced = np.r_[stage.extrema[1:], stage.u]
    assert np.isclose(MODEL.evaluate(reduced)[-1], x, rtol=0, atol=1e-17)
    top = max(float(u.max()), v)
    assert np.isclose(
        MODEL.evaluate(np.r_[u, top, v])[-1], MODEL.evaluate([top, v])[-1], atol=1e-17
    )
    assert np.isclose(MODEL.evaluate(np.r_[u, 0.0, v])[-1], MODEL.evaluate([v])[-1], atol=1e-17)


@settings(max_examples=40, deadline=None)
@given(st.floats(3.5, 6.0), st.floats(3.5, 6.0), st.floats(0.5, 1.5), st.floats(1.6, 3.4))
def test_congruency_of_minor_loops(m1, m2, lo, hi):
    """Minor loops between the same extrema are vertical translates (classical Preisach)."""
    loop = np.r_[np.linspace(lo, hi, 9), np.linspace(hi, lo, 9)]
    xa = MODEL.evaluate(np.r_[m1, lo, loop])[2:]
    xb = MODEL.evaluate(np.r_[m2, lo, loop])[2:]
    d = xa - xb
    assert np.allclose(d, d[0], rtol=0, atol=1e-17)


def test_ascending_then_descending_follows_eqs_c6_c7():
    X = MODEL.everett_at
    u = [5.0, 2.0, 4.0, 3.0]
    x = MODEL.evaluate(u)
    off = MODEL.offset
    assert np.isclose(x[0], off + X(5.0, 0.0))
    assert np.isclose(x[1], off + X(5.0, 0.0) - X(5.0, 2.0))  # C.7, N = 1
    s1 = X(5.0, 0.0) - X(5.0, 2.0)
    assert np.isclose(x[2], off + s1 + X(4.0, 2.0))  # C.6
    assert np.isclose(x[3], off + s1 + X(4.0, 2.0) - X(4.0, 3.0))  # C.7, N = 2


# ---------------------------------------------------------------------------- inverse


targets = st.lists(st.floats(0.0, 1.0), min_size=1, max_size=60).map(np.array)


@settings(max_examples=60, deadline=None)
@given(targets)
def test_model_of_inverse_is_identity(f):
    x = MODEL.x_min + f * (MODEL.x_max - MODEL.x_min)
    comp = hy.PreisachCompensator(MODEL)
    u = comp.run(x)
    assert np.all((u >= MODEL.u_min) & (u <= MODEL.u_max))
    stroke = MODEL.x_max - MODEL.x_min
    assert np.allclose(MODEL.evaluate(u), x, rtol=0, atol=1e-12 * stroke)
    stage = hy.PreisachStage(MODEL)
    stage.run(u)
    assert np.allclose(stage.extrema, comp.extrema, rtol=0, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(voltages)
def test_inverse_of_model_is_identity(u):
    x = MODEL.evaluate(u)
    assert np.allclose(hy.PreisachCompensator(MODEL).run(x), u, rtol=0, atol=1e-9)


def test_compensator_ddl_interface_in_volts():
    stage = hy.PreisachStage(MODEL, output="volts")
    comp = hy.PreisachCompensator(MODEL, input="volts")
    rng = np.random.default_rng(3)
    want = np.clip(3.0 + np.cumsum(rng.normal(0, 0.2, 400)), 0.0, 6.0)
    got = np.array([stage.step(comp.step(v)) for v in want])
    assert np.allclose(got, want, rtol=0, atol=1e-9)
    stage.reset()
    comp.reset()
    assert stage.u == 0.0 and comp.x == MODEL.x_min
    # without the compensator, the effective voltage lags (hysteresis) by a visible amount
    assert np.abs(np.array([stage.step(v) for v in want]) - want).max() > 0.05


# ---------------------------------------------------------------------------- identification


def test_identify_recovers_a_preisach_plant_exactly():
    plant = hy.PreisachStage(MODEL)
    model = hy.identify(plant, LV, du=0.05)
    assert np.allclose(model.everett, MODEL.everett, rtol=0, atol=1e-18)
    assert np.isclose(model.offset, MODEL.offset)


def test_forc_program_reads_every_node():
    u, idx = hy.forc_program(LV, du=0.25)
    A, B = np.meshgrid(LV, LV, indexing="ij")
    low = idx >= 0
    assert np.array_equal(low, A >= B)
    assert np.allclose(u[idx[low]], B[low])
    assert np.all(np.abs(np.diff(u)) <= 0.25 + 1e-12)


def test_compensator_beats_linear_command_tenfold_on_mismatched_stack():
    """Acceptance test: a stack that is not a mesh Preisach model (relays off
    the mesh + Bouc–Wen), 1.25 nm metrology; open-loop 1 Hz sine, errors after 1 s."""
    plant = hy.RelayPiezo(n_relays=1500, seed=4)
    model = hy.identify(plant, np.linspace(0, 10, 21), du=0.02, resolution=1.25e-9)
    fs = 2000.0
    t = np.arange(int(2 * fs)) / fs
    ref = 13.5e-6 + 12e-6 * np.sin(2 * np.pi * t - np.pi / 2)
    plant.reset()
    e_lin = plant.run(model.linear_command(ref)) - ref
    plant.reset()
    e_comp = plant.run(hy.PreisachCompensator(model).run(ref)) - ref
    keep = t >= 1.0
    rms_lin = np.sqrt(np.mean(e_lin[keep] ** 2))
    rms_comp = np.sqrt(np.mean(e_comp[keep] ** 2))
    assert rms_lin > 300e-9  # the stack is really hysteretic
    assert rms_comp * 10 < rms_lin


def test_bouc_wen_piezo_is_a_monotone_loop_and_rate_independent():
    p = hy.BoucWenPiezo()
    up = np.linspace(0, 10, 101)
    coarse = p.run(np.r_[up, up[::-1]])
    p.reset()
    fine_u = np.linspace(0, 10, 1001)
    fine = p.run(np.r_[fine_u, fine_u[::-1]])
    assert np.all(np.diff(coarse[:101]) > 0) and np.all(np.diff(coarse[101:]) < 0)
    assert np.allclose(coarse[[50, 100, 151]], fine[[500, 1000, 1501]], rtol=0, atol=1e-15)
    assert coarse[151] - coarse[50] > 1e-6  # a hysteresis loop, µm wide


# ---------------------------------------------------------------------------- bad input


def test_non_monotone_major_loop_is_rejected():
    xf = np.zeros((LV.size, LV.size))
    asc = np.array([0.0, 1.0, 2.0, 1.5, 4.0, 5.0, 6.0]) * 1e-6
    for i in range(LV.size):
        xf[i, : i + 1] = np.linspace(0.0, asc[i], i + 1)
    with pytest.raises(ValueError, match=r"non-monotone major loop.*1\.5e-06"):
        hy.PreisachModel.from_forc(LV, xf)


def test_non_monotone_reversal_curve_is_rejected():
    E = MODEL.everett.copy()
    E[5, 2] = E[5, 3] * 0.5  # X must decrease along β
    with pytest.raises(ValueError, match="non-monotone"):
        hy.PreisachModel(LV, E)


@pytest.mark.parametrize("bad", [np.nan, -0.1, 6.5])
def test_input_outside_range_or_nan_is_named(bad):
    stage = hy.PreisachStage(MODEL)
    with pytest.raises(ValueError, match="NaN" if np.isnan(bad) else repr(bad)):
        stage.step(bad)
    with pytest.raises(ValueError, match="NaN" if np.isnan(bad) else repr(bad)):
        MODEL.evaluate([1.0, bad])
    comp = hy.PreisachCompensator(MODEL)
    with pytest.raises(ValueError, match="target"):
        comp.step(bad * 1e-3)  # metres well outside [x_min, x_max]
    with pytest.raises(ValueError, match="NaN"):
        hy.PreisachCompensator(MODEL, clip=True).step(np.nan)


def test_clip_saturates_instead_of_raising():
    stage = hy.PreisachStage(MODEL, clip=True)
    assert stage.step(9.0) == pytest.approx(MODEL.x_max)
    assert stage.step(-3.0) == pytest.approx(MODEL.x_min)
    comp = hy.PreisachCompensator(MODEL, clip=True)
    assert comp.step(1.0) == pytest.approx(MODEL.u_max)


def test_bad_construction_arguments():
    with pytest.raises(ValueError, match="strictly increasing"):
        hy.PreisachModel([0.0, 2.0, 1.0], np.zeros((3, 3)))
    with pytest.raises(ValueError, match="shape"):
        hy.PreisachModel(LV, np.zeros((3, 3)))
    E = MODEL.everett.copy()
    E[4, 1] = np.nan
    with pytest.raises(ValueError, match=r"everett\[4, 1\]"):
        hy.PreisachModel(LV, E)
    with pytest.raises(ValueError, match="output"):
        hy.PreisachStage(MODEL, output="mm")
    with pytest.raises(ValueError, match="alpha"):
        MODEL.everett_at(1.0, 2.0)
    with pytest.raises(ValueError, match="volts"):
        hy.BoucWenPiezo().step(11.0)


def test_synthetic_stacks_in_volts_for_the_ddl_fine_stage():
    """``output="volts"``: effective voltage, u_max at the top of the major loop; the
    compensator in volts in front of it cuts the error of the bare stack."""
    plant = hy.RelayPiezo(n_relays=800, seed=2, output="volts")
    assert plant.step(10.0) == pytest.approx(10.0)
    assert plant.step(0.0) == pytest.approx(0.0, abs=1e-9)
    model = hy.identify(hy.RelayPiezo(n_relays=800, seed=2), np.linspace(0, 10, 21), du=0.02)
    comp = hy.PreisachCompensator(model, input="volts")
    want = 5.0 + 3.0 * np.sin(np.linspace(0, 4 * np.pi, 800))
    plant.reset()
    bare = plant.run(want) - want
    plant.reset()
    fed = np.array([plant.step(comp.step(v)) for v in want]) - want
    assert np.abs(fed[200:]).max() * 5 < np.abs(bare[200:]).max()


class _Bumpy:
    """A plant whose ascending branch dips at 5 V (not a hysteresis loop)."""

    def reset(self):
        self.u = 0.0

    def step(self, volts):
        self.u = volts
        return 1e-6 * volts - (3e-6 if 4.9 < volts < 5.6 else 0.0)


def test_identify_rejects_a_non_monotone_plant():
    with pytest.raises(ValueError, match="non-monotone major loop"):
        hy.identify(_Bumpy(), np.linspace(0, 10, 11), du=0.1)
    with pytest.raises(ValueError, match="resolution"):
        hy.identify(_Bumpy(), np.linspace(0, 10, 11), resolution=-1.0)
