"""The general 5R geometry of the search against qpcoord's arm."""

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


def test_forward_batch_matches_forward():
    rng = np.random.default_rng(1)
    P = rng.uniform(0.0, 3.0, (4, S.N_PARAMS))
    Q = rng.uniform(-3.0, 3.0, (4, 5))
    y, J = S.forward_batch(P, Q)
    for k in range(4):
        y1, J1 = S.forward(P[k], Q[k])
        np.testing.assert_allclose(y[k], y1, atol=1e-13)
        np.testing.assert_allclose(J[k], J1, atol=1e-13)
    with pytest.raises(ValueError, match="params"):
        S.forward_batch(np.zeros((2, 3)), np.zeros((2, 5)))
    with pytest.raises(ValueError, match="q must"):
        S.forward_batch(P, np.zeros((3, 5)))


def test_pinv_sections_is_the_simulate_pseudo_inverse_run():
    """The batched J⁺ runner is qc.simulate with PseudoInverse (same RK4, same feedback):
    on qpcoord's arm, two periods from the IK-corrected start agree to round-off, for each
    copy of the arm in the batch."""
    arm = qc.robots.load("spatial_5r")
    path = qc.paths.LissajousSphere()
    traj = qc.simulate(
        arm, qc.schemes.PseudoInverse(arm, gain=1.0), path, Q_START, 2 * path.period,
        path.period / 100,
    )  # fmt: skip
    run = S.pinv_sections(
        np.stack([qpcoord_arm_params()] * 2), traj.info["q_start"], periods=2, steps=100
    )
    sec = qc.analysis.poincare_section(traj, path.period)
    assert run.sections.shape == (3, 2, 5)
    for k in range(2):
        np.testing.assert_allclose(run.sections[:, k], sec, atol=1e-12)
    assert run.max_tracking_m == pytest.approx([traj.max_error] * 2, rel=1e-9)
    assert np.all(run.min_sigma_J > 0.2)
    with pytest.raises(ValueError, match="periods"):
        S.pinv_sections(qpcoord_arm_params(), periods=0)
    with pytest.raises(ValueError, match="gain"):
        S.pinv_sections(qpcoord_arm_params(), gain=-1.0)
