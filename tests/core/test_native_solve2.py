"""The native engine's pivoted QRs by matrix-vector product and rank-one update, and the
compression of a tall level whose full QR ends on an exactly zero block (issue 24).

``Hierarchy.gemv_qr`` (default off: fewer instructions, no wall-time gain) applies each
Householder reflector of the solve's pivoted QRs (closed forms, freezes, working sets,
least-squares steps) to a trailing block of at least 48 x 8 by one matrix-vector product and
one rank-one update instead of a dot and an axpy per column: the same arithmetic summed in
another order. Each test runs it beside the old loop (switch off) on moving data and checks
both against the Python engine (level values 1e-9 relative, x where it is unique), and that
the new path was taken.

``Hierarchy.compress_zero_tail`` (default on): a tall level's least squares runs on the r
rows of M's full pivoted QR also when that QR stopped at a pivot column exactly zero, the
trailing block being exactly zero (its rows of R are zero: the same objective up to a
constant); before, such a level (the humanoid box form's level 3, 97 rows, rank 54 of 62)
ran on M's 97 rows.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_native import published_stack

import qpcoord as qc
from qpcoord.core import native

needs_native = pytest.mark.skipif(
    not native.available(),
    reason=f"the native engine (qpcoord._native) is not built: {native._load_error}",
)


def _run(
    stem: str,
    box: bool,
    steps: int,
    unique: bool,
    switch: str = "gemv_qr",
    unit: bool = False,
    gemv: bool = True,
    wy: bool = True,
) -> tuple[int, int]:
    """Solve `steps` moved steps with `switch` on and off; returns its path's counter summed
    over the steps (on, off): reflectors applied by the product (gemv_qr) or levels
    compressed (compress_zero_tail). wy: both solvers' wy_right (Z's changes in the WY form)."""
    from qpcoord.core.native import NativeHierarchy

    counter = {"gemv_qr": "gemv_steps", "compress_zero_tail": "zero_tail_compressions"}[switch]
    stack, move = published_stack(stem, box, unit)
    P = stack._compiled
    new = NativeHierarchy(P, stack.damping)
    old = NativeHierarchy(P, stack.damping)
    new._solver.wy_right = old._solver.wy_right = wy
    if switch == "gemv_qr":
        assert not new._solver.gemv_qr  # off by default: no wall-time gain
        new._solver.gemv_qr = True
    else:
        new._solver.gemv_qr = old._solver.gemv_qr = gemv
        assert getattr(new._solver, switch)
    setattr(old._solver, switch, False)
    on = off = 0
    for step in range(steps):
        move(step)
        xn, rn, _ = new.solve(P)
        on += getattr(new._solver, counter)
        xo, ro, _ = old.solve(P)
        off += getattr(old._solver, counter)
        sp = stack.solve(engine="python")
        for r in (rn, ro):
            np.testing.assert_allclose(r, sp.level_residuals, rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(rn, ro, rtol=1e-9, atol=1e-10)
        if unique:
            scale = max(1.0, float(np.max(np.abs(sp.x))))
            assert np.max(np.abs(xn - sp.x)) <= 1e-7 * scale
            assert np.max(np.abs(xn - xo)) <= 1e-7 * scale
    return on, off


@needs_native
@pytest.mark.parametrize("box", [False, True], ids=["rows", "box form"])
def test_humanoid_gemv_qr_equals_the_loop_and_python(box):
    """The LexLS humanoid (88 variables, 5 levels; its box form: level 3's 97 x 62 M): the
    large QRs take the product path, the level values are the loop's and the Python
    engine's (x is the ill-conditioned minimum-norm point: not compared)."""
    on, off = _run("lexls_test01_humanoid", box, 4, unique=False)
    assert off == 0
    assert on > 0


@needs_native
@pytest.mark.parametrize(
    ("box", "unit", "gemv"),
    [(True, False, False), (False, True, True)],
    ids=["box form, loop QR", "unit rows, gemv QR"],
)
def test_humanoid_compresses_its_zero_tail_level(monkeypatch, box, unit, gemv):
    """The humanoid's last tall level (97 rows, rank 52-54 of 60-62): in these two variants
    its full pivoted QR ends on an exactly zero block (which one does depends on the
    rounding of the QR); compressed to its R rows, the level values are those of the
    uncompressed least squares and the Python engine's.

    Run on the baseline build: the x86-64-v3 build (FMA) rounds the QR otherwise and none of
    the humanoid's eight forms ends on an exactly zero block there (its tail is rounding, not
    zero: no compression, the uncompressed path, which the other tests cover). Z's changes
    by the reflector loop (wy_right off), as when these variants were chosen: the WY form
    rounds Z otherwise, and other variants then end on the exactly zero block."""
    monkeypatch.setattr(native, "_module", native.import_variant("baseline"))
    on, off = _run(
        "lexls_test01_humanoid",
        box,
        4,
        unique=False,
        switch="compress_zero_tail",
        unit=unit,
        gemv=gemv,
        wy=False,
    )
    assert off == 0
    assert on >= 3


@needs_native
def test_soth_keeps_the_loop_and_equals_python():
    """soth_sot (30 variables): its QRs (30 x 28 and smaller) are below the product path's
    48 rows (the per-column loop is faster there), so both switches give the same path and
    the same answer as the Python engine."""
    on, off = _run("soth_sot", False, 6, unique=True)
    assert on == off == 0


@needs_native
def test_small_problems_keep_the_loop():
    """Below 48 rows the per-column loop is kept (its overhead is lower): a 9-variable stack
    applies no reflector by the product, and still equals the Python engine."""
    from qpcoord.core.native import NativeHierarchy

    rng = np.random.default_rng(3)
    n = 9
    levels = [
        qc.Equality(rng.standard_normal((3, n)), rng.standard_normal(3)),
        qc.Inequality(rng.standard_normal((4, n)), np.full(4, -np.inf), rng.standard_normal(4)),
        qc.Equality(rng.standard_normal((5, n)), rng.standard_normal(5)),
    ]
    stack = qc.Stack(levels, bounds=qc.Bounds(-np.ones(n), np.ones(n)))
    P = stack._compiled
    h = NativeHierarchy(P, stack.damping)
    h._solver.gemv_qr = True
    _, r, _ = h.solve(P)
    assert h._solver.gemv_steps == 0
    sp = stack.solve(engine="python")
    np.testing.assert_allclose(r, sp.level_residuals, rtol=1e-9, atol=1e-10)
