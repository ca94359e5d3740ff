"""The native engine's freeze of a rank-deficient tall level by the null space of its QR,
and the changes of Z in the compact WY form.

A tall equality level M (me x r) whose closed form came from the pivoted QR of M,
M P = Qm [R11 R12; 0 R22] with R22 below the rank tolerance (dropped), is frozen onto
null([R11 R12] P^T): an orthonormal basis N of null([R11 R12]) comes from the RZ the closed
form already made of [R11 R12], applied to the last r - rank unit vectors, and Z <- Z P N by
one product (the carried projection Cin Z likewise). A level that leaves violated rows takes
the general freeze.

In the x86-64-v3 build (FMA), a change of Z (and of the carried projection Cin Z) by the
reflectors of a QR (a wide level's M^T, a freeze's F^T) of 16 to m / 3 reflectors on at
least 24 rows is applied in the compact WY form (LAPACK's dlarft and dlarfb): Qf = I - V T
V^T, B Qf = B - ((B V) T) V^T by matrix products (the humanoid's wide level 1: 21
reflectors on its 88 x 86 Z and on 72 inherited rows); the baseline build applies one
reflector at a time. Every step here equals the Python engine (level values 1e-9 relative,
x where unique), and the path was taken (``Stats.null_space_freezes``,
``Stats.wy_applications``).
"""

from __future__ import annotations

import numpy as np
import pytest
from support.hlsp import load
from test_native import (
    LEVEL_TOL,
    native_solver,
    needs_native,
    path_check,
    published_module,
    published_stack,
)
from test_native_kqr import _equality_under_bounds

import qpcoord as qc
from qpcoord.core import native


def _check(stack: qc.Stack, P, h, unique_x: bool, counter: str = "null_space_freezes") -> int:
    """The Python engine's level values (x where unique); returns the path's ``counter``."""
    return path_check(stack, P, h, counter, unique_x)[0]


def _fma() -> bool:
    """The loaded extension is the x86-64-v3 build (FMA: the WY form of the changes of Z)."""
    return native.load().ISA == "x86-64-v3"


@needs_native
@pytest.mark.parametrize(
    ("box", "unit"),
    [(False, False), (True, False), (False, True), (True, True)],
    ids=["rows", "box form", "unit rows", "box + unit rows"],
)
def test_moving_humanoid_null_space_freeze_equals_python(box, unit):
    """The LexLS humanoid moved as hierarchy_published's re-solve table: its 97-row level of
    rank 52 in 60 (box form: 54 in 62) is frozen by the null space of its QR at every step;
    level values equal the Python engine's (x: the ill-conditioned
    minimum-norm point, not compared)."""
    st, move = published_stack("lexls_test01_humanoid", box, unit)
    P, h = native_solver(st)
    total = 0
    for step in range(4):
        move(step)
        total += _check(st, P, h, unique_x=False)
    assert total >= 4


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rank_deficient_tall_closed_forms(seed):
    """Tall equality levels of low rank (30 x 24 of rank 9, 20 x 24 of rank 6) whose closed
    forms are accepted, then a full-rank level: both rank-deficient levels frozen by the null
    space (N from the RZ); x is unique and equals the Python engine's over changing
    targets."""
    rng = np.random.default_rng(seed)
    n = 24
    A1 = rng.standard_normal((30, 9)) @ rng.standard_normal((9, n))
    A2 = rng.standard_normal((20, 6)) @ rng.standard_normal((6, n))
    A3 = rng.standard_normal((5, n))
    b1, b2, b3 = (rng.standard_normal(m) for m in (30, 20, 5))
    t1, t2, t3 = qc.Equality(A1, b1), qc.Equality(A2, b2), qc.Equality(A3, b3)
    st = qc.Stack([t1, t2, t3])
    P, h = native_solver(st)
    total = 0
    for step in range(4):
        t1.update(b=b1 + 0.3 * step * rng.standard_normal(30))
        t2.update(b=b2 + 0.3 * np.cos(step) * rng.standard_normal(20))
        total += _check(st, P, h, unique_x=True)
    assert total == 8  # both rank-deficient levels at every step


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
    P, h = native_solver(st)
    total = 0
    for step in range(6):
        move(step)
        total += _check(st, P, h, unique_x=unique)
    assert (total > 0) == taken


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
    P, h = native_solver(st)
    total = 0
    for step in range(4):
        eq.update(b=b0 + 0.1 * np.sin(step + np.arange(30)))
        total += _check(st, P, h, unique_x=False)
    if gap < 1e-14:
        assert total == 4
    elif gap > 1e-14:
        assert total == 0


@needs_native
def test_violated_rows_take_the_general_freeze():
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
@pytest.mark.parametrize(("box", "unit"), [(False, False), (True, False)], ids=["rows", "box form"])
def test_moving_humanoid_wy_equals_python(box, unit):
    """The moving humanoid: its wide level of 21 rows changes Z (and, rows form, the 72
    inherited rows' projection) in the WY form at every step (the FMA build); level values
    equal the Python engine's."""
    st, move = published_stack("lexls_test01_humanoid", box, unit)
    P, h = native_solver(st)
    total = 0
    for step in range(4):
        move(step)
        total += _check(st, P, h, unique_x=False, counter="wy_applications")
    assert (total >= 4) if _fma() else (total == 0)


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("rows", [15, 16, 18, 20], ids=lambda r: f"{r} rows")
def test_wide_levels_under_inherited_rows_by_wy(seed, rows):
    """An inequality level of 30 rows over 64 variables (its rows inherited: the carried
    projection), then wide equality levels of 15-20 rows (16 and more: the WY form on Z and
    on Cin Z in the FMA build; 15: the loop), then a last level: x is unique and equals the
    Python engine's over changing targets."""
    rng = np.random.default_rng(seed)
    n = 64
    C = rng.standard_normal((30, n))
    C /= np.linalg.norm(C, axis=1)[:, None]
    lo0 = rng.uniform(-1.0, -0.2, 30)
    ineq = qc.Inequality(C, lo0, np.full(30, np.inf))
    e1 = qc.Equality(rng.standard_normal((rows, n)), rng.standard_normal(rows))
    e2 = qc.Equality(rng.standard_normal((rows, n)), rng.standard_normal(rows))
    last = qc.Equality(rng.standard_normal((n, n)), rng.standard_normal(n))
    st = qc.Stack([ineq, e1, e2, last], bounds=qc.Bounds(-5 * np.ones(n), 5 * np.ones(n)))
    P, h = native_solver(st)
    b1 = e1.b.copy()
    total = 0
    for step in range(4):
        ineq.update(lower=lo0 + 0.3 * np.sin(0.7 * step + np.arange(30)))
        e1.update(b=b1 + 0.2 * np.cos(step + np.arange(rows)))
        total += _check(st, P, h, unique_x=True, counter="wy_applications")
    assert (total > 0) == (rows >= 16 and _fma())


@needs_native
@pytest.mark.parametrize("variant", ["baseline", "x86-64-v3"])
@pytest.mark.parametrize("counter", ["null_space_freezes", "wy_applications"])
def test_each_build_takes_the_paths(monkeypatch, variant, counter):
    """Each build (baseline, x86-64-v3 where this CPU runs it) on the moving humanoid: the
    null-space freeze is taken by both, the WY form by the x86-64-v3 build only (FMA), and
    the level values equal the Python engine's (the builds round differently)."""
    try:
        mod = native.import_variant(variant)
    except (native.NativeUnavailableError, ValueError):
        pytest.skip(f"no {variant} build on this machine")
    monkeypatch.setattr(native, "_module", mod)
    hp = published_module()
    prob = load("lexls_test01_humanoid")
    st = qc.Stack(prob.levels, bounds=prob.bounds)
    P, h = native_solver(st)
    assert type(h._solver).__module__ == mod.__name__
    move = hp._mover(prob.levels)
    total = 0
    for step in range(3):
        move(step)
        total += _check(st, P, h, unique_x=False, counter=counter)
    if counter == "wy_applications" and variant == "baseline":
        assert total == 0
    else:
        assert total >= 3
