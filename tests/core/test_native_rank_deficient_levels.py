"""Rank-deficient and ill-conditioned levels: their closed forms and freezes equal the
Python engine.

A level's closed form comes from a (rank-revealing) QR of its projected equalities, or from
the damped SVD when their smallest singular value is not certainly above the damping
threshold. A tall rank-deficient level whose closed form came from the pivoted QR
``M P = Qm [R11 R12; 0 R22]`` (``R22`` below the rank tolerance, dropped) is frozen onto
``null([R11 R12] P^T)``, a basis from the RZ factorisation the closed form already made; the
minimum-norm solutions of trapezoidal systems (``M``, and the projected objective ``K`` of an
active set, whose QR is reused while the working set's QR does not change) come from that RZ
too; a tall level whose full QR ends on an exactly zero block runs on the ``R`` rows only.
Every test solves with the Python engine too (level values ``LEVEL_TOL`` relative, x where
unique) and checks that the path under test was taken (its ``Stats`` counter).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.native_engine import (
    LEVEL_TOL,
    X_TOL,
    assert_same,
    native_solver,
    needs_native,
    path_check,
)
from support.published import published_stack
from support.stacks import hard_random_stack, inequality_shifts

import qpcoord as qc
from qpcoord.core import native


@needs_native
@pytest.mark.parametrize("cond", [1e2, 1e5, 1e6, 3e6, 2e7, math.inf])
def test_closed_forms_by_qr_and_by_svd_agree_with_python(cond):
    """A level's closed form comes from a QR of its projected equalities when their smallest
    singular value is certainly above the damping threshold (4x), else from the damped SVD:
    well-conditioned (QR), just above the threshold (SVD, undamped), below it (SVD, damped:
    s = 5e-8 < 1e-7 s_ref) and exactly rank-deficient levels all give the Python engine's
    answer, with the box inactive and active. (Far below the threshold, s ~ 1e-8..1e-12, the
    next level's value differs between the engines: a known discrepancy, not covered
    here.)"""
    rng = np.random.default_rng(int(cond) % 97 if math.isfinite(cond) else 7)
    n = 7
    U, _ = np.linalg.qr(rng.standard_normal((4, 4)))
    V, _ = np.linalg.qr(rng.standard_normal((n, n)))
    s = np.array([1.0, 0.5, 1.0 / cond if math.isfinite(cond) else 0.0, 0.2])
    A = (U * s) @ V[:, :4].T  # 4 x 7, singular values s
    wide = qc.Equality(A, rng.standard_normal(4))
    tall = qc.Equality(rng.standard_normal((9, n)), rng.standard_normal(9))
    for box in (10.0, 0.3):
        st = qc.Stack([wide, tall], bounds=qc.Bounds(-box, box))
        assert_same(st.solve(engine="python"), st.solve(engine="native"))


def _rank_deficient_stack(rng, box: float) -> tuple[qc.Stack, list[qc.Equality]]:
    """Levels whose projected equalities are exactly rank-deficient: a tall level (9 rows of
    rank 3 on 8 variables), a wide one (3 rows of rank 2: one row a combination of the
    others), a conflicting inequality level, a tall level of rank 2 again; the box on top."""
    n = 8
    tall = qc.Equality(
        rng.standard_normal((9, 3)) @ rng.standard_normal((3, n)), rng.standard_normal(9)
    )
    W = rng.standard_normal((2, n))
    wide = qc.Equality(np.vstack([W, W[0] - 2.0 * W[1]]), rng.standard_normal(3))
    C = rng.standard_normal((4, n))
    ineq = qc.Inequality(C, rng.uniform(0.5, 1.0, 4), np.full(4, np.inf))
    low = qc.Equality(
        rng.standard_normal((6, 2)) @ rng.standard_normal((2, n)), rng.standard_normal(6)
    )
    st = qc.Stack([tall, wide, ineq, low], bounds=qc.Bounds(-box, box))
    return st, [tall, wide, low]


@needs_native
@pytest.mark.parametrize("box", [10.0, 0.4], ids=["box-inactive", "box-active"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rank_deficient_closed_form_by_qr_equals_the_svd(seed, box):
    """A rank-deficient level's closed form comes from the rank-revealing QR of its projected
    equalities (no SVD) when the QR shows a clear gap: tall and wide levels, accepted closed
    forms and closed forms followed by an active set (the freeze from the QR's row space),
    warm over moving right-hand sides. Every step equals the Python engine (level values
    1e-9 relative, x to 1e-7), and the QR path was taken for the tall and the wide level."""
    from qpcoord.core.native import NativeHierarchy

    rng = np.random.default_rng(seed)
    st, eqs = _rank_deficient_stack(rng, box)
    P = st._compiled
    by_qr = NativeHierarchy(P, st.damping)
    targets = [t.b.copy() for t in eqs]
    qr_forms = 0
    for step in range(6):
        for j, (t, b0) in enumerate(zip(eqs, targets, strict=True)):
            t.update(b=b0 + 0.2 * np.sin(0.8 * step + j + np.arange(b0.size)))
        xq, rq, _ = by_qr.solve(P)
        qr_forms += by_qr.counters.qr_closed_forms
        sp = st.solve(engine="python")
        np.testing.assert_allclose(rq, sp.level_residuals, rtol=1e-9, atol=1e-10)
        scale = max(1.0, float(np.max(np.abs(sp.x))))
        assert np.max(np.abs(xq - sp.x)) <= X_TOL * scale
    # the tall and the wide level at every step (the last level may have no freedom left)
    assert qr_forms >= 6 * 2


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compressed_and_wide_least_squares_equal_python(seed):
    """Conflicting inequality levels on few equality rows (a wide projected objective: its
    step from one QR of K^T) and a last level of many rank-deficient equality rows beside
    inequality rows (a tall level factorised by the QR: its least squares on the compressed
    objective R), warm over moving bounds and targets: every step equals the Python engine
    (level values 1e-9 relative, x to 1e-7)."""
    from qpcoord.core.native import NativeHierarchy

    rng = np.random.default_rng(seed)
    n = 40
    st = hard_random_stack(seed, n=n, levels=1)
    C = rng.standard_normal((10, n))
    tall = qc.Equality(
        rng.standard_normal((40, 12)) @ rng.standard_normal((12, n)), rng.standard_normal(40)
    )
    last = qc.Inequality(C, rng.uniform(0.5, 1.0, 10), np.full(10, np.inf))
    st = qc.Stack([*st.levels, [tall, last]], bounds=qc.Bounds(-np.ones(n), np.ones(n)))
    P = st._compiled
    new = NativeHierarchy(P, st.damping)
    move = inequality_shifts(st)
    b0 = tall.b.copy()
    for step in range(8):
        move(step)
        tall.update(b=b0 + 0.1 * np.sin(0.5 * step + np.arange(40)))
        xn, rn, info = new.solve(P)
        assert new.counters.qr_closed_forms == 2  # the wide first and the tall last level
        # the last level's least squares ran (later steps: warm trials on the same problem)
        assert step > 0 or info["active_set_iterations"][-1] > 0
        sp = st.solve(engine="python")
        np.testing.assert_allclose(rn, sp.level_residuals, rtol=1e-9, atol=1e-10)
        scale = max(1.0, float(np.max(np.abs(sp.x))))
        assert np.max(np.abs(xn - sp.x)) <= X_TOL * scale


def _equality_under_bounds(seed: int, rank: int, cond: float):
    """A 30 x 20 equality level of the given rank (singular values 1 .. cond) under a
    unit-row inequality level and tight bounds: its closed form leaves the box, so its least
    squares runs the active set on the bound rows (no slack: the K path), warm from step to
    step as its target moves. Returns (stack, move(step))."""
    rng = np.random.default_rng(seed)
    n = 20
    U, _ = np.linalg.qr(rng.standard_normal((30, rank)))
    V, _ = np.linalg.qr(rng.standard_normal((n, rank)))
    A = U @ np.diag(np.logspace(0, np.log10(cond), rank)) @ V.T
    C = rng.standard_normal((6, n))
    C /= np.linalg.norm(C, axis=1)[:, None]
    ineq = qc.Inequality(C, rng.uniform(-0.2, 0.1, 6), np.full(6, np.inf))
    b0 = 2.0 * rng.standard_normal(30)
    eq = qc.Equality(A, b0)
    last = qc.Equality(rng.standard_normal((4, n)), rng.standard_normal(4))
    st = qc.Stack([ineq, eq, last], bounds=qc.Bounds(-0.3 * np.ones(n), 0.3 * np.ones(n)))
    d = rng.standard_normal(30)

    def move(step: int) -> None:
        eq.update(b=b0 + 0.05 * np.sin(0.5 * step) * d)

    return st, move


def _tall_rank_deficient(seed: int):
    """Tall equality levels of low rank (30 x 24 of rank 9, 20 x 24 of rank 6), then a
    full-rank 5 x 24 one; the two first levels' targets move. Returns (stack, move(step))."""
    rng = np.random.default_rng(seed)
    n = 24
    A1 = rng.standard_normal((30, 9)) @ rng.standard_normal((9, n))
    A2 = rng.standard_normal((20, 6)) @ rng.standard_normal((6, n))
    A3 = rng.standard_normal((5, n))
    b1, b2, b3 = (rng.standard_normal(m) for m in (30, 20, 5))
    t1, t2, t3 = qc.Equality(A1, b1), qc.Equality(A2, b2), qc.Equality(A3, b3)

    def move(step: int) -> None:
        t1.update(b=b1 + 0.3 * step * rng.standard_normal(30))
        t2.update(b=b2 + 0.3 * np.cos(step) * rng.standard_normal(20))

    return qc.Stack([t1, t2, t3]), move


def _path_count(st: qc.Stack, move, steps: int, counter: str, unique: bool) -> int:
    """The total of the native ``Stats`` field ``counter`` over ``steps`` solves of ``st``,
    each after ``move(step)`` and checked against the Python engine (level values, and x if
    ``unique``: :func:`support.native_engine.path_check`)."""
    P, h = native_solver(st)
    total = 0
    for step in range(steps):
        move(step)
        total += path_check(st, P, h, counter, unique)[0]
    return total


@needs_native
@pytest.mark.parametrize(
    ("seed", "rank", "cond", "unique"),
    [(0, 20, 1e-1, True), (1, 12, 1e-1, True), (2, 20, 1e-6, False), (4, 9, 1e-6, False)],
    ids=["full rank", "rank-deficient K", "ill-conditioned", "ill-conditioned, rank 9"],
)
def test_equality_level_on_the_bounds(seed, rank, cond, unique):
    """An equality level held by the bounds, moving: full-rank and rank-deficient K (the
    minimum-norm step through the QR of [R11 R12]^T, also reused), well- and
    ill-conditioned (sigma_min / sigma_max = 1e-6: the exact finish, started from the warm
    trial's K): equal to the Python engine at every step, x
    compared where the problem is well conditioned."""
    st, move = _equality_under_bounds(seed, rank, cond)
    assert _path_count(st, move, 8, "k_qr_reuses", unique) > 0


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rank_deficient_tall_levels_closed_form_and_freeze(seed):
    """Tall equality levels of low rank (30 x 24 of rank 9, 20 x 24 of rank 6) with their
    closed forms feasible: the minimum-norm step and the row space frozen come from the RZ;
    the last level and the minimum-norm stage then see the same null space. x is unique:
    equal to the Python engine's, over changing targets."""
    st, move = _tall_rank_deficient(seed)
    # both rank-deficient levels at every step
    assert _path_count(st, move, 4, "rz_factors", True) >= 8


@needs_native
@pytest.mark.parametrize(
    ("seed", "rank", "cond", "unique"),
    [(1, 12, 1e-1, True), (4, 9, 1e-6, False)],
    ids=["rank-deficient K", "ill-conditioned, rank 9"],
)
def test_rank_deficient_k_by_rz(seed, rank, cond, unique):
    """An equality level held by the bounds (its active set's K rank-deficient): the
    minimum-norm step by the RZ equals the Python engine's."""
    st, move = _equality_under_bounds(seed, rank, cond)
    assert _path_count(st, move, 8, "rz_factors", unique) > 0


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rank_deficient_tall_closed_forms(seed):
    """Tall equality levels of low rank (30 x 24 of rank 9, 20 x 24 of rank 6) whose closed
    forms are accepted, then a full-rank level: both rank-deficient levels frozen by the null
    space (N from the RZ); x is unique and equals the Python engine's over changing
    targets."""
    st, move = _tall_rank_deficient(seed)
    # both rank-deficient levels at every step
    assert _path_count(st, move, 4, "null_space_freezes", True) == 8


@needs_native
@pytest.mark.parametrize(
    ("seed", "rank", "cond", "unique", "taken"),
    [(1, 12, 1e-1, True, True), (4, 9, 1e-6, False, True), (5, 15, 1e-9, False, False)],
    ids=["rank 12", "ill-conditioned, rank 9", "very ill-conditioned, rank 15"],
)
def test_rank_deficient_level_held_by_the_bounds(seed, rank, cond, unique, taken):
    """A 30 x 20 equality level of low rank held by the bounds (its active set ends with
    no violated row: the null-space freeze after a least squares), moving, ill-conditioned
    up to sigma_min / sigma_max = 1e-9 (there damped: the SVD's closed form and the general
    freeze): equal to the Python engine."""
    st, move = _equality_under_bounds(seed, rank, cond)
    assert (_path_count(st, move, 6, "null_space_freezes", unique) > 0) == taken


@needs_native
@pytest.mark.parametrize("gap", [1e-15, 1e-14, 1e-13, 1e-12, 1e-10])
def test_rank_near_the_tolerance(gap):
    """A 30 x 20 level of rank 8 plus one direction of relative size ``gap``, around the
    rank tolerance (30 eps |A|_F, about 1.3e-14 here): below it the QR drops the direction
    and the null-space freeze keeps it free; above it the direction is under the damping
    threshold (1e-7): the SVD's damped closed form, and the general freeze (1e-14: at the
    tolerance, either). Always the Python engine's level values, over changing targets."""
    rng = np.random.default_rng(3)
    n = 20
    U, _ = np.linalg.qr(rng.standard_normal((30, 9)))
    V, _ = np.linalg.qr(rng.standard_normal((n, 9)))
    s = np.r_[np.logspace(0, -1, 8), gap]
    A = U @ np.diag(s) @ V.T
    b0 = rng.standard_normal(30)
    eq = qc.Equality(A, b0)
    last = qc.Equality(rng.standard_normal((4, n)), rng.standard_normal(4))
    st = qc.Stack([eq, last])

    def move(step: int) -> None:
        eq.update(b=b0 + 0.1 * np.sin(step + np.arange(30)))

    total = _path_count(st, move, 4, "null_space_freezes", False)
    if gap < 1e-14:
        assert total == 4
    elif gap > 1e-14:
        assert total == 0


@needs_native
def test_violated_rows_beside_a_rank_deficient_level_take_the_general_freeze():
    """A level with a rank-deficient tall equality part and an inequality row it cannot
    meet (violated at its optimum): the freeze must hold that row too, so the general freeze
    runs, not the null space of the closed form's QR; the Python engine's level values."""
    rng = np.random.default_rng(9)
    n = 12
    A = rng.standard_normal((16, 5)) @ rng.standard_normal((5, n))
    c = rng.standard_normal(n)
    c /= np.linalg.norm(c)
    cons = [qc.Inequality(c[None, :], [-0.1], [0.1])]
    lev = [qc.Equality(A, rng.standard_normal(16)), qc.Inequality(c[None, :], [5.0], [np.inf])]
    st = qc.Stack(
        [lev, qc.Equality(rng.standard_normal((3, n)), rng.standard_normal(3))], constraints=cons
    )
    P, h = native_solver(st)
    _, rn, _ = h.solve(P)
    assert h.counters.null_space_freezes == 0
    sp = st.solve(engine="python")
    assert np.all(np.abs(rn - sp.level_residuals) <= LEVEL_TOL * np.maximum(1.0, rn))


@needs_native
@pytest.mark.parametrize("seed", [0, 1])
def test_rank_deficient_wide_level_under_inherited_rows(seed):
    """A wide level of rank 4 in 6 rows (its M^T's QR stops at rank 4) under an inherited
    inequality level that its closed form leaves: the wide freeze drops rank columns only,
    then two more levels; equal to the Python engine (x unique)."""
    rng = np.random.default_rng(seed)
    n = 16
    C = rng.standard_normal((10, n))
    C /= np.linalg.norm(C, axis=1)[:, None]
    lo0 = rng.uniform(-0.3, -0.05, 10)
    ineq = qc.Inequality(C, lo0, np.full(10, np.inf))
    A = rng.standard_normal((6, 4)) @ rng.standard_normal((4, n))
    b0 = 4.0 * rng.standard_normal(6)
    wide = qc.Equality(A, b0)
    mid = qc.Equality(rng.standard_normal((5, n)), rng.standard_normal(5))
    last = qc.Equality(np.eye(n), np.zeros(n))
    st = qc.Stack([ineq, wide, mid, last], bounds=qc.Bounds(-np.ones(n), np.ones(n)))

    def move(step: int) -> None:
        ineq.update(lower=lo0 + 0.1 * np.sin(0.8 * step + np.arange(10)))
        wide.update(b=b0 + 0.5 * np.cos(step + np.arange(6)))

    assert _path_count(st, move, 5, "wide_freezes", True) >= 1


@needs_native
def test_rank_deficient_tall_level_is_not_full_rank():
    """A tall level of rank 5 < r held by the bounds: freedom is left, the full-rank
    shortcut is not taken (the null-space freeze is); the Python engine's level values."""
    rng = np.random.default_rng(4)
    n = 10
    A = rng.standard_normal((14, 5)) @ rng.standard_normal((5, n))
    eq = qc.Equality(A, 3.0 * rng.standard_normal(14))
    last = qc.Equality(np.eye(n), rng.standard_normal(n))
    st = qc.Stack([eq, last], bounds=qc.Bounds(-0.2 * np.ones(n), 0.2 * np.ones(n)))
    P, h = native_solver(st)
    _, rn, _ = h.solve(P)
    # only the last level (full rank in what the first leaves) may take it
    assert h.counters.full_rank_freezes <= 1
    sp = st.solve(engine="python")
    assert np.all(np.abs(rn - sp.level_residuals) <= LEVEL_TOL * np.maximum(1.0, rn))


@needs_native
def test_humanoid_compresses_its_zero_tail_level(monkeypatch):
    """The humanoid box form's last tall level (97 rows, rank 54 of 62): its full pivoted QR
    ends on an exactly zero block; compressed to its R rows, the level values are the Python
    engine's.

    Run on the baseline build: the x86-64-v3 build (FMA) rounds the QR otherwise and none of
    the humanoid's forms ends on an exactly zero block there (its tail is rounding, not zero:
    no compression, the uncompressed path, which the other tests cover)."""
    monkeypatch.setattr(native, "_module", native.import_variant("baseline"))
    stack, move = published_stack("lexls_test01_humanoid", True, False)
    P, h = native_solver(stack)
    compressed = 0
    for step in range(4):
        move(step)
        h._solver.invalidate_caches()  # (the closed form is computed: its QR is what counts)
        _, r, _ = h.solve(P)
        compressed += h.counters.zero_tail_compressions
        sp = stack.solve(engine="python")
        np.testing.assert_allclose(r, sp.level_residuals, rtol=1e-9, atol=1e-10)
    assert compressed >= 3
