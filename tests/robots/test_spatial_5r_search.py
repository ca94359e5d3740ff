"""The general 5R geometry of the search (issue 18, finding 5) against qpcoord's arm."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc
from qpcoord.robots import spatial_5r_search as S

Q_START = np.array([0.2315, 0.3544, 1.0815, 1.9971, 4.4705])  # spatial_5r docstring


def qpcoord_arm_params() -> np.ndarray:
    """qpcoord's arm in the search's parameters: column along z, yaw about z, then four
    pitch joints about y with links along x."""
    h = np.pi / 2
    p = np.zeros(S.N_PARAMS)
    p[0:2] = (0.0, 0.0)  # u0 = z
    for i in range(1, 6):
        p[2 * i : 2 * i + 2] = (h, 0.0)  # links along x
    p[12:14] = (0.0, 0.0)  # a1 = z
    for i in range(1, 5):
        p[12 + 2 * i : 14 + 2 * i] = (h, h)  # a2..a5 = y
    return p


def test_forward_matches_the_urdf_arm():
    arm = qc.robots.load("spatial_5r")
    rng = np.random.default_rng(0)
    p = qpcoord_arm_params()
    for _ in range(5):
        q = rng.uniform(-3, 3, 5)
        y, J = S.forward(p, q)
        np.testing.assert_allclose(y, arm.position(q), atol=1e-12)
        np.testing.assert_allclose(J, arm.jacobian(q), atol=1e-12)


def test_thm42_hypothesis_on_qpcoord_arm():
    # the docstring of spatial_5r: σ_min([J; ω₄; ω₅]) ≥ 0.18 and the motion closes
    s42, sj, err, closure = S.thm42_hypothesis(qpcoord_arm_params(), q0=Q_START, steps=200)
    assert 0.15 < s42 < 0.3
    assert sj >= 0.25
    assert err < 1e-3
    assert closure < 1e-6


def test_search_is_seeded_and_checks_input():
    a = S.search(starts=1, seed=3)
    b = S.search(starts=1, seed=3)
    np.testing.assert_array_equal(a[0].params, b[0].params)
    with pytest.raises(ValueError, match="starts"):
        S.search(starts=0)
    with pytest.raises(ValueError, match="params"):
        S.forward(np.zeros(3), np.zeros(5))
