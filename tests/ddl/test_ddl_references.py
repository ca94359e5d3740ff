"""Atmospheric OPD synthesis, steps and ramps (qpcoord.ddl.references)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

import qpcoord.ddl as ddl
from qpcoord.ddl.references import Layer, fig619_steps, opd_psd, ramp_reference

# B = 100 m, D = 1.8 m, v = 10 m/s: regimes change at 0.2 v/B = 0.02 Hz and 0.3 v/D ≈ 1.7 Hz.
# The asymptotic slopes hold for L0 = ∞ (a 25 m outer scale flattens the PSD below ≈ v/L0).


def _slope(f, p, lo, hi, nbins=6):
    """Log-log slope of the power averaged in log-spaced bins over [lo, hi].

    Averaging in bins wider than the baseline's sin² period (v/B = 0.1 Hz) removes the
    interference notches, which would bias a fit on raw log values.
    """
    edges = np.logspace(np.log10(lo), np.log10(hi), nbins + 1)
    fc, pc = [], []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        sel = (f >= a) & (f < b)
        assert np.count_nonzero(sel) >= 3
        fc.append(np.sqrt(a * b))
        pc.append(p[sel].mean())
    return np.polyfit(np.log(fc), np.log(pc), 1)[0]


def test_analytic_psd_regimes():
    f = np.logspace(-5, 2, 400_000)
    s = opd_psd(f, L0=np.inf)
    assert _slope(f, s, 3e-5, 2e-3) == pytest.approx(-2 / 3, abs=0.1)
    # mid band: sin² oscillates — fit its envelope average over many periods
    assert _slope(f, s, 0.15, 1.0) == pytest.approx(-8 / 3, abs=0.25)
    assert _slope(f, s, 8.0, 60.0) == pytest.approx(-17 / 3, abs=0.3)


@pytest.mark.parametrize(
    ("fs", "duration", "band", "slope", "L0"),
    [
        (0.2, 200000.0, (3e-4, 4e-3), -2 / 3, np.inf),
        (20.0, 2000.0, (0.15, 0.9), -8 / 3, np.inf),
        (250.0, 300.0, (10.0, 60.0), -17 / 3, np.inf),
    ],
)
def test_generated_psd_slopes_match_regimes(fs, duration, band, slope, L0):
    x = ddl.kolmogorov_opd(duration, fs, seed=5, L0=L0)
    f, p = signal.welch(x, fs=fs, nperseg=len(x) // 8)
    measured = _slope(f, p, *band, nbins=4)
    analytic = _slope(f[1:], opd_psd(f[1:], L0=L0), *band, nbins=4)
    assert measured == pytest.approx(slope, abs=0.35)
    assert measured == pytest.approx(analytic, abs=0.25)
    sel = (f >= band[0]) & (f <= band[1])
    ratio = p[sel].mean() / opd_psd(f[sel], L0=L0).mean()
    assert 0.7 < ratio < 1.4  # level too, not only the slope


def test_rms_matches_integrated_psd():
    rms = [ddl.kolmogorov_opd(20.0, 1000.0, seed=s).std() for s in range(8)]
    fw = np.logspace(np.log10(1000.0 / (4 * 20000)), np.log10(500.0), 4000)
    expected = np.sqrt(np.trapezoid(opd_psd(fw), fw))
    assert 0.5 * expected < np.mean(rms) < 1.5 * expected
    # the Paranal figure of the notes: ≈ 2.5 µm rms at B = 100 m, L0 = 25 m (whole spectrum)
    fall = np.logspace(-6, 3, 20000)
    assert np.sqrt(np.trapezoid(opd_psd(fall), fall)) == pytest.approx(2.5e-6, rel=0.15)


def test_deterministic_per_seed():
    a = ddl.kolmogorov_opd(1.0, 8000.0, seed=3, preset="paranal_250hz")
    b = ddl.kolmogorov_opd(1.0, 8000.0, seed=3, preset="paranal_250hz")
    c = ddl.kolmogorov_opd(1.0, 8000.0, seed=4, preset="paranal_250hz")
    assert a.shape == (8000,)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_250hz_preset_content():
    x = ddl.kolmogorov_opd(10.0, 8000.0, seed=1, preset="paranal_250hz")
    f, p = signal.welch(x, fs=8000.0, nperseg=16000)

    def band_rms(lo, hi):
        sel = (f >= lo) & (f < hi)
        return np.sqrt(np.trapezoid(p[sel], f[sel]))

    assert 1e-8 < band_rms(50, 250) < 1e-6  # "small amplitudes above 50 Hz"
    assert band_rms(260, 4000) < 1e-3 * band_rms(50, 250)  # band-limited at 250 Hz
    plain = ddl.kolmogorov_opd(10.0, 8000.0, seed=1)
    fp, pp = signal.welch(plain, fs=8000.0, nperseg=16000)
    sel = (fp >= 50) & (fp < 250)
    assert np.sqrt(np.trapezoid(pp[sel], fp[sel])) < 1e-9  # one frozen layer: ~nothing


def test_steps_and_ramps():
    steps = fig619_steps(1.0, 1000.0)
    assert steps["centre"][0] == -2.5e-3 and steps["centre"][-1] == 2.5e-3
    assert steps["extremity"][0] == pytest.approx(27.5e-3)
    assert steps["extremity"][-1] == pytest.approx(32.5e-3)
    r = ramp_reference(1.0, 1000.0, 0.0, 1e-3, t0=0.1, rate=2e-3)
    assert r[100] == 0.0 and r[-1] == pytest.approx(1e-3)
    assert np.max(np.diff(r)) == pytest.approx(2e-6)


def test_bad_input():
    with pytest.raises(ValueError, match="duration"):
        ddl.kolmogorov_opd(-1.0, 8000.0)
    with pytest.raises(ValueError, match="preset"):
        ddl.kolmogorov_opd(1.0, 8000.0, preset="mauna_kea")
    with pytest.raises(ValueError, match="unknown"):
        ddl.kolmogorov_opd(1.0, 8000.0, wind=3.0)
    with pytest.raises(ValueError, match="r0"):
        opd_psd([1.0], r0=0.0)
    with pytest.raises(ValueError, match="Layer.weight"):
        Layer(10.0, 2.0)
    with pytest.raises(ValueError, match="rate"):
        ramp_reference(1.0, 100.0, 0.0, 1.0, rate=-1.0)
