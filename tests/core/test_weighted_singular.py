"""The weighted method's "H singular → add ε‖x‖²" decision.

``H = WᵀW`` with ``W`` the levels' equality rows in the hard equalities' null space, row-scaled
by ``√(weight_ratioᵏ)``. The decision is a rank decision on ``W`` itself (the ``R`` of its
Householder QR, ``methods/weighted.py`` ``_SINGULAR``), the same in both engines; before, it was
a test on the Cholesky pivots of the formed ``H``, whose rounding (~√ε_machine·‖W‖) sat a factor
~7 under the threshold: 1–6 of 50 exactly singular ``H`` passed as regular, no ``ε`` was added
and ``x`` got an arbitrary component (up to 10) along the directions no level fixes. With ``ε``,
the unconstrained optimum is the least-squares solution of ``[W; √ε I]`` (not ``H⁻¹f``: forming
``H`` cost 2e-7 in ``x``), so both engines give the ε-regularised answer to ~1e-13.
"""

from __future__ import annotations

import subprocess

import numpy as np
import pytest
import scipy.linalg
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.native_engine import WEIGHTED_BUILT, needs_native

import qpcoord as qc

#: the native engine where its weighted QP is built (a failure instead under
#: ``QPCOORD_REQUIRE_NATIVE=1``: :mod:`support.native_engine`)
ENGINES = ["python"] + (["native"] if WEIGHTED_BUILT else [])
RATIOS = [1e-1, 1e-2, 1e-3, 1e-4]


def _reference(spec: dict, ratio: float, eps: float | None) -> np.ndarray:
    """``argmin Σₖ ratioᵏ‖√wₖ(Aₖx − bₖ)‖² + ε‖x‖²`` subject to the hard equalities, by an
    SVD-based least-squares solve (``gelsd``) in the hard equalities' null space (not the
    engines' QR); ``eps=None``: without ``ε`` (a regular ``H``)."""
    n = spec["n"]
    if spec["hard"] is not None:
        Ah, bh = spec["hard"]
        xh = np.linalg.lstsq(Ah, bh, rcond=None)[0]
        Z = scipy.linalg.null_space(Ah)
    else:
        xh, Z = np.zeros(n), np.eye(n)
    rows, rhs = [], []
    for k, (A, b, w) in enumerate(spec["levels"]):
        s = np.sqrt(ratio**k * w)[:, None]
        rows.append(s * (A @ Z))
        rhs.append(s[:, 0] * (b - A @ xh))
    if eps is not None:
        rows.append(np.sqrt(eps) * np.eye(Z.shape[1]))
        rhs.append(-np.sqrt(eps) * (Z.T @ xh))
    z = scipy.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), lapack_driver="gelsd")[0]
    return xh + Z @ z


def _stack(spec: dict, ratio: float) -> qc.Stack:
    levels = [qc.Equality(A, b, weight=w) for A, b, w in spec["levels"]]
    hard = None if spec["hard"] is None else [qc.Equality(*spec["hard"])]
    return qc.Stack(levels, constraints=hard, weight_ratio=ratio)


def _weighted_rows(spec: dict, ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """``W`` (rows ``√(ratioᵏ wₖ)·Aₖ``, x-space) and ``c`` (``√(ratioᵏ wₖ)·bₖ``)."""
    g = [np.sqrt(ratio**k * w) for k, (_A, _b, w) in enumerate(spec["levels"])]
    W = np.vstack([gk[:, None] * A for gk, (A, _b, _w) in zip(g, spec["levels"], strict=True)])
    c = np.concatenate([gk * b for gk, (_A, b, _w) in zip(g, spec["levels"], strict=True)])
    return W, c


def _eps(spec: dict, ratio: float, reg: float = 1e-9) -> float:
    """``ε = regularization·max(1, max diag Σₖ ratioᵏ AₖᵀWₖAₖ)`` (the x-space Hessian)."""
    d = sum(
        ratio**k * np.einsum("ij,i,ij->j", A, w, A) for k, (A, _b, w) in enumerate(spec["levels"])
    )
    return reg * max(1.0, float(np.max(d)))


@st.composite
def singular_stacks(draw):
    """Equality levels whose rows all lie in a random ``d``-dimensional subspace of Rⁿ (random
    coordinates: ``H`` is singular exactly, not at rounding), optional hard equalities leaving
    more than ``d`` free directions, weights 0.1–10."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    n = draw(st.integers(3, 9))
    d = draw(st.integers(1, n - 1))
    h = draw(st.integers(0, n - d - 1))
    P = np.linalg.qr(rng.standard_normal((n, n)))[0][:, :d].T  # d orthonormal rows
    consistent = draw(st.booleans())  # every level satisfiable (b = A x₀)
    x0 = rng.uniform(-1.0, 1.0, n)
    levels = []
    for _ in range(draw(st.integers(1, 4))):
        m = draw(st.integers(1, 5))
        A = rng.standard_normal((m, d)) @ P
        w = rng.uniform(0.1, 10.0, m) if draw(st.booleans()) else np.ones(m)
        levels.append((A, A @ x0 if consistent else 2.0 * rng.standard_normal(m), w))
    hard = None
    if h:
        Ah = rng.standard_normal((h, n))
        hard = (Ah, Ah @ rng.uniform(-1.0, 1.0, n))
    return dict(n=n, levels=levels, hard=hard)


@st.composite
def regular_stacks(draw):
    """Up to 3 equality levels whose rows together span Rⁿ (the last one has ``n`` rows), well
    conditioned: ``H`` is regular at any of :data:`RATIOS`."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    n = draw(st.integers(2, 8))
    levels = []
    for _ in range(draw(st.integers(1, 3))):
        m = draw(st.integers(1, 4))
        levels.append((rng.standard_normal((m, n)), 2.0 * rng.standard_normal(m), np.ones(m)))
    Q = np.linalg.qr(rng.standard_normal((n, n)))[0]
    levels.append((Q * rng.uniform(0.5, 2.0, n), rng.standard_normal(n), np.ones(n)))
    return dict(n=n, levels=levels, hard=None)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(spec=singular_stacks(), ratio=st.sampled_from(RATIOS))
def test_exactly_singular_h_gets_the_eps_regularised_answer_on_both_engines(spec, ratio):
    """``x`` is the ε-regularised answer on both engines, to 1e-9 of ``|x|∞`` plus the
    problem's own sensitivity: along ``H``'s null space ``ε z = −Wᵀ(W z − c)``, so a rounding
    of ``W`` (``ε_machine·‖W‖``, any backward-stable solver) moves ``z`` by
    ``ε_machine·‖W‖·‖W z − c‖ / ε`` -- 0 when every level is met (measured 1e-13), up to
    ~1e-7 with conflicting targets (residual ~4, ``ε`` 2e-9: 1e-8 measured between the two
    engines' QRs)."""
    eps = _eps(spec, ratio)
    ref = _reference(spec, ratio, eps)
    W = np.vstack(
        [np.sqrt(ratio**k * w)[:, None] * A for k, (A, _b, w) in enumerate(spec["levels"])]
    )
    c = np.concatenate([np.sqrt(ratio**k * w) * b for k, (_A, b, w) in enumerate(spec["levels"])])
    sens = np.finfo(float).eps * np.linalg.norm(W, 2) * np.linalg.norm(W @ ref - c) / eps
    tol = 1e-9 * max(1.0, float(np.max(np.abs(ref)))) + 10.0 * sens
    xs = {}
    for engine in ENGINES:
        sol = _stack(spec, ratio).solve(method="weighted", engine=engine)
        assert sol.info["regularized"], engine
        assert np.max(np.abs(sol.x - ref)) <= tol, (engine, sol.x, ref, sens)
        xs[engine] = sol.x
    if len(xs) == 2:
        assert np.max(np.abs(xs["python"] - xs["native"])) <= tol


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(spec=regular_stacks(), ratio=st.sampled_from(RATIOS))
def test_regular_h_is_solved_exactly_without_eps(spec, ratio):
    """No ``ε``: the exact weighted least squares, as before (``H⁻¹f`` from ``H``'s Cholesky:
    to 1e-9 plus the rounding of the formed ``H`` amplified by its condition number)."""
    ref = _reference(spec, ratio, None)
    W = np.vstack(
        [np.sqrt(ratio**k * w)[:, None] * A for k, (A, _b, w) in enumerate(spec["levels"])]
    )
    kappa = np.linalg.cond(W) ** 2
    tol = max(1.0, float(np.max(np.abs(ref)))) * (1e-9 + 10.0 * kappa * np.finfo(float).eps)
    for engine in ENGINES:
        sol = _stack(spec, ratio).solve(method="weighted", engine=engine)
        assert not sol.info["regularized"], engine
        assert np.max(np.abs(sol.x - ref)) <= tol, (engine, sol.x, ref, kappa)


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("ratio", [1e-1, 10**-1.5, 1e-2, 10**-2.5, 1e-3, 1e-4])
def test_no_free_component_when_h_is_singular_in_random_coordinates(engine, ratio):
    """The stack of docs/stack.md's table: four levels of orthonormal rows (3 + 3 + 2 + 1 in
    R¹⁰, satisfiable) in random coordinates, so that the one direction no level sees is not a
    coordinate axis. Before: 1–5 of these 50 stacks passed as regular per ratio, with a
    component up to 10 along that direction; now all are regularised and it is ~1e-14."""
    for seed in range(50):
        rng = np.random.default_rng(seed)
        n = 10
        Q = np.linalg.qr(rng.normal(size=(n - 1, n - 1)))[0]
        R = np.linalg.qr(rng.normal(size=(n, n)))[0]
        tasks, i = [], 0
        for m in (3, 3, 2, 1):
            A = np.zeros((m, n))
            A[:, : n - 1] = Q[:, i : i + m].T
            tasks.append(qc.Equality(A @ R.T, rng.normal(size=m)))
            i += m
        sol = qc.Stack(tasks, weight_ratio=ratio).solve(method="weighted", engine=engine)
        assert sol.info["regularized"], seed
        assert abs(float(R[:, -1] @ sol.x)) <= 1e-10, seed


def test_python_engine_reports_the_regularisation():
    sing = qc.Stack([qc.Equality([[1.0, 1.0]], [2.0])]).solve(method="weighted", engine="python")
    assert sing.info["regularized"]
    np.testing.assert_allclose(sing.x, [1.0, 1.0], atol=1e-8)
    full = qc.Stack([qc.Equality(np.eye(2), [2.0, -1.0])]).solve(method="weighted", engine="python")
    assert not full.info["regularized"]
    np.testing.assert_allclose(full.x, [2.0, -1.0], rtol=0, atol=1e-15)


@pytest.mark.engine_independent
@needs_native
def test_no_allocation_on_the_regularised_path(weighted_driver):
    """``weighted_driver.cpp ... singular``: the levels' rows in half the coordinates, so ``ε``
    is added every call (the QR of ``[W; √ε I]`` at each refactor, its least-squares solve at
    each call): 0 heap allocations over 2 000 solves, factor kept or rebuilt."""
    exe = str(weighted_driver)
    out = subprocess.run([exe, "12", "singular"], check=True, capture_output=True, text=True)
    lines = out.stdout.strip().splitlines()
    assert len(lines) == 2, out.stdout
    assert all("regularised/solve 1.00" in line for line in lines), out.stdout
    assert all(line.endswith("allocations after the first 0") for line in lines), out.stdout
