"""The native engine's pivoted QRs by matrix-vector product and rank-one update (issue 24).

``Hierarchy.gemv_qr`` (default on) applies each Householder reflector of the solve's pivoted
QRs (closed forms, freezes, working sets, least-squares steps) to a trailing block of at
least 48 x 8 by one matrix-vector product and one rank-one update instead of a dot and an
axpy per column: the same arithmetic summed in another order. Each test runs it beside the
old loop (switch off) on moving data and checks both against the Python engine (level values
1e-9 relative, x where it is unique), and that the new path was taken.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from hlsp import load

import qpcoord as qc
from qpcoord.core import native

needs_native = pytest.mark.skipif(
    not native.available(),
    reason=f"the native engine (qpcoord._native) is not built: {native._load_error}",
)


def _published(stem: str, box: bool = False):
    """(stack, move(step)) of a published problem, moved as hierarchy_published.py does."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    import hierarchy_published as hp

    prob = load(stem, simple_as_bounds=box)
    return qc.Stack(prob.levels, bounds=prob.bounds), hp._mover(prob.levels)


def _run(stem: str, box: bool, steps: int, unique: bool) -> tuple[int, int]:
    """Solve `steps` moved steps with gemv_qr on and off; returns the reflectors each applied
    by the product (on, off)."""
    from qpcoord.core.native import NativeHierarchy

    stack, move = _published(stem, box)
    P = stack._compiled
    new = NativeHierarchy(P, stack.damping)
    old = NativeHierarchy(P, stack.damping)
    old._solver.gemv_qr = False
    assert new._solver.gemv_qr
    on = off = 0
    for step in range(steps):
        move(step)
        xn, rn, _ = new.solve(P)
        on += new._solver.gemv_steps
        xo, ro, _ = old.solve(P)
        off += old._solver.gemv_steps
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
    _, r, _ = h.solve(P)
    assert h._solver.gemv_qr and h._solver.gemv_steps == 0
    sp = stack.solve(engine="python")
    np.testing.assert_allclose(r, sp.level_residuals, rtol=1e-9, atol=1e-10)
