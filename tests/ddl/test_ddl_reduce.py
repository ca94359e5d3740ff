"""Balanced truncation of a stable discrete law: the error bound, the full order, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from qpcoord.ddl.reduce import balanced_truncation, hankel_singular_values


def _system(n: int = 12, seed: int = 3):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    a = q @ np.diag(rng.uniform(0.3, 0.97, n)) @ q.T  # stable, spectral radius 0.97
    b = rng.standard_normal((n, 1))
    c = rng.standard_normal((2, n))
    d = rng.standard_normal((2, 1))
    return a, b, c, d, 1e-4


def _response(ss, z):
    a, b, c, d, _ = ss
    n = a.shape[0]
    return np.array([c @ np.linalg.solve(zi * np.eye(n) - a, b) + d for zi in z])


def test_truncation_error_within_twice_the_discarded_hankel_values():
    ss = _system()
    z = np.exp(1j * np.linspace(0.0, np.pi, 2000))
    g = _response(ss, z)
    for order in (2, 5, 8, 10):
        red, hsv = balanced_truncation(ss, order)
        err = max(np.linalg.norm(gi - ri, 2) for gi, ri in zip(g, _response(red, z), strict=True))
        # the H∞ bound 2 Σ_{i>r} σ_i; the grid's maximum is at most the supremum
        assert err <= 2.0 * hsv[order:].sum() * (1 + 1e-9)
        assert red[0].shape == (order, order)


def test_channel_units_change_what_is_kept():
    ss = _system()
    h1 = hankel_singular_values(ss)
    h2 = hankel_singular_values(ss, 1.0, [1.0, 1e-3])  # second output in small units
    assert h2[0] > 10.0 * h1[0]


def test_bad_systems_are_named():
    a, b, c, d, ts = _system()
    with pytest.raises(ValueError, match="must be stable"):
        balanced_truncation((1.01 * np.eye(3), b[:3], c[:, :3], d, ts), 1)
    with pytest.raises(ValueError, match="order must be an integer in 1..12"):
        balanced_truncation((a, b, c, d, ts), 0)
    with pytest.raises(ValueError, match="A must be square"):
        balanced_truncation((a[:, :5], b, c, d, ts), 1)
    with pytest.raises(ValueError, match="B is not finite"):
        balanced_truncation((a, np.full_like(b, np.nan), c, d, ts), 1)
