"""The rows a level inherits from the levels above: their dependence on the frozen rows and
their norms, with the Python engine's answers.

A level's moving inequality rows are tested for directions dependent on the frozen rows to
within the movable tolerance by a column-pivoted QR of their projections scaled by their own
norms; a Cholesky of their shifted Gram matrix screens that test first (when it succeeds,
every pivot of the QR is provably above the tolerance): the same decisions bit for bit on
both sides of the threshold. An inherited row's norm is computed once per call, on first use.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support.dumps import spec_from_npz as _spec_from_npz
from support.native_engine import LEVEL_TOL, X_TOL, native_solver, needs_native
from support.published import published_stack

import qpcoord as qc
from qpcoord.core import native
from qpcoord.core.methods.hierarchical import _drop_dependent
from qpcoord.core.native import NativeHierarchy

_DATA = Path(__file__).resolve().parents[1] / "data"


def _screened_and_dropped(
    stack: qc.Stack, warm: bool = False, compare: bool = True
) -> tuple[int, int]:
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


def _box_kkt_residual(stack: qc.Stack, x: np.ndarray) -> tuple[float, np.ndarray, float]:
    """The level-1 stationarity of ``x`` on the stack of ``_near_dependent(641, 8, -14, 0)``
    (every level-1 row violated, x[0:3] frozen by level 0), with the level's rows as the rank
    rule poses them (``_drop_dependent``: the directions dependent to 1e-9 removed), against
    the box rows active at ``x``: ``(‖g + Aλ‖ / ‖g‖, λ, error bound)``, ``g`` the gradient of
    the level's value in x[3:], ``λ ≥ 0`` the box multipliers (least squares)."""
    ineq = stack.levels[1][0]
    C, up = ineq.C, ineq.upper
    D, _ = _drop_dependent(C[:, 3:], np.linalg.norm(C, axis=1))
    res = C[:, :3] @ x[:3] + D @ x[3:] - up
    assert (res > 0).all()  # the level's value is its rows' least squares
    g = 2.0 * D.T @ res
    act = np.flatnonzero(np.abs(x[3:]) >= 1e3 * (1.0 - 1e-12))
    A = np.eye(5)[:, act] * np.sign(x[3:][act])
    lam = np.linalg.lstsq(A, -g, rcond=None)[0] if act.size else np.zeros(0)
    rel = float(np.linalg.norm(g + A @ lam) / np.linalg.norm(g))
    # g is ~4e-9 (the gain along the 3e-8 direction), formed from residuals O(1) whose
    # rounding is ~eps·(‖C‖_F‖x‖ + ‖up‖): its error relative to ‖g‖, times 10
    err = (
        10.0
        * np.finfo(float).eps
        * np.linalg.norm(D)
        * (np.linalg.norm(C) * np.linalg.norm(x) + np.linalg.norm(up))
    )
    return rel, lam, float(err / np.linalg.norm(g))


@pytest.mark.parametrize("engine", ["native", "python"])
def test_a_near_dependent_inequality_level_reaches_the_box(engine):
    """Seed 641 of the generator (found by the hypothesis search below): the level-1 rows
    have singular values 0.1 … 3e-8 above the rank rule's 1e-9 and 1.8e-11, 1e-14 under it.
    Every row stays violated; along the 3e-8 direction the level's value falls by ~5e-7 of
    itself across the whole box, with gradients ~3e-9, under the KKT tolerance: the Python
    engine's regularised QP point stopped at |x| = 499 (level 2 = 530, every backend) where
    the level's optimum is on the box (level 2 = 1937, the native engine). Both finish such
    a level exactly (its moving rows' last pivot under ILL_CONDITIONED): x is stationary
    for the level's rows against the active box rows, with non-negative multipliers."""
    if engine == "native" and not native.available():
        pytest.skip("native engine not built")
    stack = _near_dependent(641, 8, -14.0, 0)
    sol = stack.solve(engine=engine)
    assert sol.status == "optimal"
    rel, lam, err = _box_kkt_residual(stack, sol.x)
    assert lam.size >= 1 and (lam > 0).all(), lam
    assert rel <= err, (rel, err)


@needs_native
def test_the_engines_agree_on_the_near_dependent_inequality_level():
    stack = _near_dependent(641, 8, -14.0, 0)
    native_levels = stack.solve(engine="native").level_residuals
    for solver in ("daqp", "quadprog"):
        python_levels = stack.solve(engine="python", solver=solver).level_residuals
        # the level values (sums of squares of O(1)-O(1e3) entries) agree to the rounding of
        # the level's optimum on the box, ~1e-9 of them (the x ~1e3 the box lets the rows' ~3e-8
        # direction reach)
        np.testing.assert_allclose(native_levels, python_levels, rtol=1e-9, atol=1e-12)


@needs_native
@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    m=st.integers(2, 8),
    log_sigma=st.floats(-16.0, -2.0),
    zeros=st.integers(0, 2),
)
def test_screen_is_bit_for_bit_across_the_threshold(seed, m, log_sigma, zeros):
    _screened_and_dropped(_near_dependent(seed, m, log_sigma, zeros))


@needs_native
@pytest.mark.xfail(
    strict=True,
    reason="open defect: the engines use a level-1 direction the rank rule drops "
    "(singular value 1e-12 of the free rows, under 1e-9) differently: the Python engine's "
    "level 1 is 3.8e-10 lower, its level 2 1806 against the native engine's 1463",
)
def test_both_engines_use_a_dropped_direction_alike():
    """A hypothesis example of the search above (seed 5467080, eight rows, the smallest
    singular value of their free part 1e-12): both engines answer "optimal" with level 1
    equal to 3.8e-10 of itself, within the rank rule's tolerance, and level 2 a quarter
    apart. The Python engine's level-1 QP keeps the dropped direction's linear term (its
    regularisation the only curvature) and walks it to the box; the native active set keeps
    it in the level's objective and the freeze drops it. One rule for both is needed."""
    _screened_and_dropped(_near_dependent(5467080, 8, -12.0, 0))


@needs_native
def test_the_screen_decides_both_ways():
    # well separated rows (singular values 0.1 ... 0.01: every pivot proven above the
    # ill-conditioning threshold 1e-3) are screened (no QR); rows with a singular value 1e-3
    # are not screened and keep every direction (the QR runs: the level is finished exactly);
    # rows dependent to 1e-13 are not screened and the QR drops their dependent direction:
    # all on one generator, for m <= 5 and m > 5
    for m in (4, 7):
        screened, dropped = _screened_and_dropped(_near_dependent(3, m, -2.0, 0))
        assert (screened, dropped) == (1, 0), (m, screened, dropped)
        screened, dropped = _screened_and_dropped(_near_dependent(3, m, -3.0, 0))
        assert (screened, dropped) == (0, 0), (m, screened, dropped)
        screened, dropped = _screened_and_dropped(_near_dependent(3, m, -13.0, 0))
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
    screened, dropped = _screened_and_dropped(qc.Stack(**_spec_from_npz(path)), compare=False)
    assert dropped >= 1


def _run(stack: qc.Stack, move, steps: int) -> tuple[int, int]:
    """Solve ``stack`` warm at ``steps`` moved steps with one native solver; every step equal
    to the Python engine (level values ``LEVEL_TOL`` relative, x ``X_TOL``). Returns (warm
    hits summed over the steps after the first, stages per solve)."""
    P = stack._compiled
    nat = NativeHierarchy(P, stack.damping)
    hits = 0
    stages = 0
    for step in range(steps):
        move(step)
        x, r, info = nat.solve(P, warm=step > 0)
        sp = stack.solve(engine="python")
        ref = sp.level_residuals
        assert np.all(np.abs(r - ref) <= LEVEL_TOL * np.maximum(1.0, ref)), (step, r, ref)
        scale = max(1.0, float(np.max(np.abs(sp.x))))
        assert np.max(np.abs(x - sp.x)) <= X_TOL * scale, (step, np.max(np.abs(x - sp.x)))
        if step > 0:
            hits += int(info["warm_start_hits"])
        stages = len(ref)
    return hits, stages


@needs_native
def test_soth_sot_inherited_rows_warm():
    # level 0: 30 joint limits (27-28 stay active and are inherited), then 3/3/6/6 equality
    # rows: every level adds the 30 inherited rows with their kept norms
    stack, move = published_stack("soth_sot")
    steps = 12
    hits, levels = _run(stack, move, steps)
    # the driver on 50 moved steps: 5.98 of 6 stages hit per solve
    assert hits >= (steps - 1) * levels, (hits, steps, levels)


@needs_native
def test_bounds_only_warm():
    # 9 variables, bounds only (no inherited row), a 3-row then a 9-row equality level
    # pushing several bounds active
    rng = np.random.default_rng(7)
    A1 = rng.standard_normal((3, 9))
    A2 = rng.standard_normal((9, 9))
    b1 = 3.0 * rng.standard_normal(3)
    b2 = 3.0 * rng.standard_normal(9)
    t1, t2 = qc.Equality(A1, b1.copy()), qc.Equality(A2, b2.copy())
    stack = qc.Stack([t1, t2], bounds=qc.Bounds(-0.5, 0.5))

    def move(step: int) -> None:
        t1.update(b=b1 + 1e-3 * np.sin(0.1 * step + np.arange(3)))
        t2.update(b=b2 + 1e-3 * np.sin(0.1 * step + np.arange(9)))

    hits, levels = _run(stack, move, 10)
    assert hits > 0


@needs_native
def test_inherited_rows_with_infinite_sides_and_zero_rows():
    # inherited rows skipped by inherit (both sides infinite) and a zero row (its norm 0:
    # its projection never binds); the kept norms must match the Python engine on every
    # moved step
    rng = np.random.default_rng(11)
    n = 24
    C = rng.standard_normal((20, n))
    C[3] = 0.0
    lo = -0.2 * np.ones(20)
    hi = 0.2 * np.ones(20)
    lo[5], hi[5] = -np.inf, np.inf
    lo[8] = -np.inf
    ineq = qc.Inequality(C, lo, hi)
    A1 = rng.standard_normal((4, n))
    A2 = rng.standard_normal((6, n))
    b1 = 4.0 * rng.standard_normal(4)
    b2 = 4.0 * rng.standard_normal(6)
    t1, t2 = qc.Equality(A1, b1.copy()), qc.Equality(A2, b2.copy())
    stack = qc.Stack([ineq, t1, t2])

    def move(step: int) -> None:
        t1.update(b=b1 + 1e-2 * np.sin(0.3 * step + np.arange(4)))
        t2.update(b=b2 + 1e-2 * np.sin(0.3 * step + np.arange(6)))

    hits, levels = _run(stack, move, 10)
    assert hits > 0
