"""The native engine's screen of the dependence test.

A level's moving inequality rows are tested for directions dependent on the frozen rows to
within the movable tolerance by a column-pivoted QR of their projections scaled by their own
norms (``drop_dependent_directions``). The screen first tries a Cholesky of their shifted
Gram matrix; when it succeeds, every pivot of that QR is provably above the tolerance, so
the QR would change nothing and is skipped. The tests solve rows whose projections have
singular values on both sides of the threshold (the screen must refuse the near-dependent
ones, the QR must then drop), the published humanoid (screened) and the extreme Talos states
whose rows are dependent to rounding (not screened, dropped), against the Python engine's
level values, and check which path was taken (``Stats.gram_screens``,
``Stats.dependent_drops``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support.dumps import spec_from_npz as _spec_from_npz
from test_native import LEVEL_TOL, native_solver, needs_native, published_stack

import qpcoord as qc

_DATA = Path(__file__).resolve().parents[1] / "data"


def _same(stack: qc.Stack, warm: bool = False, compare: bool = True) -> tuple[int, int]:
    """Solve ``stack`` natively and (``compare``) with the Python engine: the same level
    values (``LEVEL_TOL`` relative). Returns (levels screened, levels whose rows lost
    dependent directions)."""
    P, h = native_solver(stack)
    _, rn, _ = h.solve(P, warm=warm)
    if compare:
        ref = stack.solve(engine="python").level_residuals
        assert np.all(np.abs(rn - ref) <= LEVEL_TOL * np.maximum(1.0, ref)), (rn, ref)
    stats = h.counters
    return stats.gram_screens, stats.dependent_drops


def _near_dependent(seed: int, m: int, log_sigma: float, zeros: int) -> qc.Stack:
    """n = 8; level 0 freezes x[0:3]; level 1: m inequality rows [R | S], R (m x 3) of norm
    ~1 in the frozen span and S (m x 5) = U diag(sigma) V^T their free parts, the smallest
    ``zeros`` singular values 0 and the next one 10**log_sigma (m > 5: more rows than free
    directions); every row violated after level 0; level 2: x = 0 (x unique)."""
    rng = np.random.default_rng(seed)
    n, f = 8, 3
    k = min(m, n - f)
    sig = np.logspace(-1, log_sigma, k)
    sig[k - min(zeros, k - 1) :] = 0.0
    U, _ = np.linalg.qr(rng.standard_normal((m, k)))
    V, _ = np.linalg.qr(rng.standard_normal((n - f, k)))
    S = (U * sig) @ V.T
    R = rng.standard_normal((m, f))
    C = np.hstack([R, S])
    b0 = rng.standard_normal(f)
    upper = R @ b0 - 0.5 - rng.random(m)
    A0 = np.hstack([np.eye(f), np.zeros((f, n - f))])
    return qc.Stack(
        [qc.Equality(A0, b0), qc.Inequality(C, upper=upper), qc.Equality(np.eye(n), np.zeros(n))],
        bounds=qc.Bounds(-1e3 * np.ones(n), 1e3 * np.ones(n)),
    )


@needs_native
@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    m=st.integers(2, 8),
    log_sigma=st.floats(-16.0, -2.0),
    zeros=st.integers(0, 2),
)
def test_screen_is_bit_for_bit_across_the_threshold(seed, m, log_sigma, zeros):
    _same(_near_dependent(seed, m, log_sigma, zeros))


@needs_native
def test_screen_takes_both_paths():
    # well separated rows are screened (no QR), rows dependent to 1e-13 are not (the QR drops
    # their dependent direction): both on one generator, both for m <= 5 and m > 5
    for m in (4, 7):
        screened, dropped = _same(_near_dependent(3, m, -3.0, 0))
        assert (screened, dropped) == (1, 0), (m, screened, dropped)
        screened, dropped = _same(_near_dependent(3, m, -13.0, 0))
        assert (screened, dropped) == (0, 1), (m, screened, dropped)


@needs_native
def test_published_humanoid_is_screened():
    # 72 moving rows in 88 free directions at one level per step: screened at every step
    stack, move = published_stack("lexls_test01_humanoid")
    P, h = native_solver(stack)
    for step in range(6):
        move(step)
        _, rn, _ = h.solve(P, warm=step > 0)
        ref = stack.solve(engine="python").level_residuals
        assert np.all(np.abs(rn - ref) <= LEVEL_TOL * np.maximum(1.0, ref)), step
        assert h.counters.gram_screens >= 1, step


@needs_native
@pytest.mark.parametrize(
    "path", sorted(_DATA.glob("talos_extreme_feet_*.npz")), ids=lambda p: p.stem
)
def test_rows_dependent_to_rounding_are_not_screened(path):
    # the support polygon's 6 projections have rank 2 plus singular values ~1e-13
    # (test_hierarchy_regressions, which also checks the engines' answers there against
    # each other): the screen refuses, the QR drops
    screened, dropped = _same(qc.Stack(**_spec_from_npz(path)), compare=False)
    assert dropped >= 1
