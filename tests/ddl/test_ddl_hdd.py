"""The IEEJ HDD benchmark: loader, plant cases, the benchmark's own evaluation."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from qpcoord.ddl.benchmarks import hdd

_CANDIDATES = [os.environ.get("QPCOORD_HDD_DATA", ""), "/work/shared/data/hdd"]
_CANDIDATES += [str(Path(__file__).resolve().parents[3] / "shared" / "data" / "hdd")]
DATA = next((p for p in _CANDIDATES if p and Path(p, "plant.npz").is_file()), None)
needs_data = pytest.mark.skipif(DATA is None, reason="HDD benchmark data not found")


@pytest.fixture(scope="module")
def bench():
    return hdd.load(DATA)


def test_load_names_what_is_missing(tmp_path):
    with pytest.raises(ValueError, match="is not a directory"):
        hdd.load(tmp_path / "nowhere")
    with pytest.raises(ValueError, match=r"plant\.npz is missing"):
        hdd.load(tmp_path)


@needs_data
def test_cases_scale_frequencies_damping_and_pzt_gain(bench):
    a2, b2, c2 = bench.pzt(2)
    a7, b7, c7 = bench.pzt(7)
    # static gains 1 and 0.95 (case 7: PZT gain ×0.95), modes ×1.06 in frequency (LT)
    g2 = -c2 @ np.linalg.solve(a2, b2)
    g7 = -c7 @ np.linalg.solve(a7, b7)
    assert abs(g2[0, 0]) == pytest.approx(1.0, rel=1e-9)
    assert abs(g7[0, 0]) == pytest.approx(0.95, rel=1e-9)
    w2 = np.sort(np.abs(np.linalg.eigvals(a2)))
    w7 = np.sort(np.abs(np.linalg.eigvals(a7)))
    np.testing.assert_allclose(w7, 1.06 * w2, rtol=1e-9)
    with pytest.raises(ValueError, match="case must be an integer 1..9"):
        bench.vcm(10)


@needs_data
def test_short_window_loop_is_consistent(bench):
    ref = hdd.reference_controller(bench)
    r = hdd.evaluate(bench, ref, 2, t_sim=0.15, t_start=0.1, n_rev=6)
    # the loop (plant lifted over Ts) and the plant filtered at Tsc afterwards agree at the
    # sampling instants: e = −y_c(nTs) + d_RRO, to rounding of the signals that cancel in y_c
    # (the rigid body's open-loop drift, 0.1 µm, against the control's response: both
    # integrated over 1.5e5 steps of a double pole at 1, relative 1e-6 of that drift)
    n = r["e"].size
    y_ts = r["y_c"][:: bench.mr_plant][:n]
    rro = np.resize(bench.rro, n)
    drift = np.max(np.abs(hdd.disturbances(bench, 2, 0.15).y_dist))
    assert np.max(np.abs(y_ts + r["e"] - rro)) < 1e-6 * drift
    assert 10.0 < r["sigma3_pct"] < 17.0 and r["pzt_ok"]


@needs_data
def test_reference_controller_reproduces_the_published_worst_case(bench):
    # case 9 is the published worst (14.54 %, max |y_cp| 14.13 nm), given to 0.01: the
    # evaluation must land within half of that reading step (14.544 % and 14.132 nm here)
    r = hdd.evaluate(bench, hdd.reference_controller(bench), 9)
    assert r["sigma3_pct"] == pytest.approx(hdd.PUBLISHED_SIGMA3[8], abs=0.006)
    assert r["pzt_max"] == pytest.approx(14.13e-9, abs=0.006e-9)


@needs_data
def test_rv_disturbance_matches_its_state_space_recursion(bench):
    # d_f through the RV filter (3 Hz pole: 1 − 2e-5 from 1 at Tsc) against the recursion of
    # its exactly discretised state-space model; the polynomial (lfilter) form was 6 % off
    from scipy import signal

    n = 20000
    num, den = bench.rv_num, bench.rv_den
    num_sp = np.trim_zeros(num - num[0] / den[0] * den, "f")
    a, b, c, _, _ = signal.cont2discrete(signal.tf2ss(num_sp, den), bench.Tsc, method="zoh")
    w = np.random.RandomState(1).rand(n) - 0.5
    x = np.zeros(a.shape[0])
    ref = np.empty(n)
    for k in range(n):
        ref[k] = (c @ x)[0]
        x = a @ x + b[:, 0] * w[k]
    got = hdd._zoh_modes(num_sp, den, w, bench.Tsc)
    # both exact to rounding; their difference is rounding accumulated over n steps of a
    # near-unit pole (relative 1e-9 is 1e6 times the double epsilon, 1e5 below the old error)
    assert np.max(np.abs(got - ref)) < 1e-9 * np.max(np.abs(ref))


@needs_data
def test_fresh_seeds_replace_every_noise(bench):
    base = hdd.disturbances(bench, 2, 0.01)
    fresh = list(range(1001, 1015))
    d_all = hdd.disturbances(bench, 2, 0.01, seeds=fresh)
    d_fan = hdd.disturbances(bench, 2, 0.01, seeds=[1, *fresh[1:]])  # RV kept: seed 1
    d_rv = hdd.disturbances(bench, 2, 0.01, seeds=[1001, *range(2, 15)])  # fan kept
    # the fan modes' part changes with their seeds (the fan modes move the head by ~10 nm;
    # with the evaluation's seeds kept the difference would be exactly 0)
    assert np.max(np.abs(base.y_dist - d_fan.y_dist)) > 1e-9
    np.testing.assert_allclose(d_all.y_dist - d_fan.y_dist, d_rv.y_dist - base.y_dist, atol=1e-20)
    with pytest.raises(ValueError, match="seeds must be 14 integers"):
        hdd.disturbances(bench, 2, 0.01, seeds=[1, 2])


@needs_data
def test_linear_plant_of_the_benchmark(bench):
    lp = hdd.linear_plant(bench, 2)
    m = lp.discrete()
    assert m.n_plant == 32 + 24 + 16 + 10  # VCM, F_mv, PZT, F_mp
    assert lp.fine_stroke == pytest.approx((-50e-9, 50e-9))
    assert len(lp.disturbances) == 14
    with pytest.raises(ValueError, match="controller Ts"):
        hdd.evaluate(
            bench, (np.eye(1), np.ones((1, 1)), np.ones((2, 1)), np.zeros((2, 1)), 1e-4), 2
        )


@needs_data
def test_evaluate_refuses_a_controller_that_does_not_stabilise(bench):
    a, b, c, d, ts = hdd.reference_controller(bench)
    with pytest.raises(ValueError, match="does not stabilise case 2"):
        hdd.evaluate(bench, (a, b, -c, -d, ts), 2, t_sim=0.15, t_start=0.1, n_rev=6)


@needs_data
def test_designed_and_reduced_controller_meet_the_spec_on_fresh_disturbances(bench):
    # the design and its reduction on the nine cases, with noise the evaluation never uses
    # (seeds 1001–1014); 3σ on a 0.1 s window moves by ~0.1 %-points with the seeds, the
    # 0.3 s figure of the worst case (7) is 6.70 %: the bound 7 % is the goal itself
    from qpcoord.ddl import sensitivity
    from qpcoord.ddl.lqg import closed_loop_poles

    law = hdd.design_controller(bench)
    red = hdd.reduced_controller(law)
    assert red[0].shape == (hdd.REDUCED_ORDER, hdd.REDUCED_ORDER)

    class Law:
        def state_space(self):
            return red

    f = np.geomspace(10.0, 0.499 / bench.Ts, 800)
    for case in hdd.CASES:
        plant = hdd.linear_plant(bench, case, disturbance_models=False)
        assert np.max(np.abs(closed_loop_poles(plant, Law()))) < 1.0
        assert np.max(np.abs(sensitivity(plant, Law(), f))) <= 2.0  # 6 dB
    dist = hdd.disturbances(bench, 7, 0.25, seeds=range(1001, 1015))
    r = hdd.evaluate(bench, red, 7, t_sim=0.25, n_rev=12, dist=dist)
    assert r["sigma3_pct"] < 7.0 and r["pzt_max"] < 0.5 * bench.pzt_stroke
