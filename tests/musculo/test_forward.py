"""Appendix A forward model (Fig A.3): activation dynamics and the arm under muscle forces."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc
from qpcoord import musculo
from qpcoord.musculo.forward import acceleration, simulate


@pytest.fixture(scope="module")
def model():
    return qc.robots.load("shoulder")


def test_acceleration_inverts_the_inverse_dynamics(model):
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(model.lower * 0.5, model.upper * 0.5)
        qd, qdd = rng.normal(size=3), rng.normal(size=3)
        Q = model.generalised_forces(q, qd, qdd)
        d = musculo.distribute(model, q, Q)
        assert d.feasible
        np.testing.assert_allclose(acceleration(model, q, qd, d.forces), qdd, atol=1e-8)


def test_hanging_arm_at_rest_stays(model):
    t = np.array([0.0, 0.05])
    run = simulate(model, t, np.zeros((2, model.n_muscles)), np.zeros(3), np.zeros(3), dt=1e-3)
    assert not run.left_range
    assert run.t[-1] == pytest.approx(0.05)
    np.testing.assert_allclose(run.q, 0.0, atol=1e-12)


def test_activation_follows_a_step_with_tau(model):
    # s steps 0 -> 0.01 at 1 ms and is held: a lags it by the first-order law (held s per step)
    t = np.array([0.0, 1e-3, 0.02])
    s = np.zeros((3, model.n_muscles))
    s[1:] = 0.01
    tau = 2e-3
    run = simulate(model, t, s, np.zeros(3), np.zeros(3), dt=1e-3, tau=tau)
    np.testing.assert_allclose(run.a[1], 0.0)  # the first step holds s(0) = 0
    expected = 0.01 * (1.0 - np.exp(-1e-3 / tau))
    np.testing.assert_allclose(run.a[2], expected, rtol=1e-12)
    assert np.all(np.abs(run.a[-1] - 0.01) <= 0.01 * np.exp(-18e-3 / tau) * 1.0001)


def test_open_loop_follows_the_static_optimum_at_first(model):
    # the computed excitations of a slow motion reproduce it closely over its first 0.1 s
    t = np.linspace(0.0, 0.2, 41)
    qs = np.column_stack([-0.3 * (t / 0.2) ** 3, 0.0 * t, 0.0 * t])
    qds = np.gradient(qs, t, axis=0)
    qdds = np.gradient(qds, t, axis=0)
    share = musculo.MuscleSharing(model)
    s = np.array(
        [
            share.solve(qs[k], model.generalised_forces(qs[k], qds[k], qdds[k])).activations
            for k in range(len(t))
        ]
    )
    run = simulate(model, t, np.clip(s, 0, 1), qs[0], qds[0], dt=5e-4)
    k = np.searchsorted(run.t, 0.1)
    ref = np.interp(run.t[k], t, qs[:, 0])
    assert abs(run.q[k, 0] - ref) < 2e-3


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"times": [0.0, 0.0]}, "times"),
        ({"excitations": np.full((2, 11), 1.5)}, "excitations"),
        ({"dt": 0.0}, "dt"),
        ({"tau": -1.0}, "tau"),
        ({"q0": [0.0, 0.0, 3.0]}, "psi"),
    ],
)
def test_bad_input(model, kw, match):
    args = dict(times=[0.0, 0.1], excitations=np.zeros((2, 11)), q0=np.zeros(3), qd0=np.zeros(3))
    args.update(kw)
    with pytest.raises(ValueError, match=match):
        simulate(model, **args)
