"""The native engine's compression of a tall level whose full QR ends on an exactly zero
block.

A tall level's least squares runs on the r rows of M's full pivoted QR (R and Qm^T e: an
orthogonal transform, the rest of Qm^T e constant) also when that QR stopped at a pivot
column exactly zero, the trailing block being exactly zero (its rows of R are zero: the same
objective up to a constant): the humanoid box form's level 3, 97 rows, rank 54 of 62, runs
on 62 rows, not 97 (``Stats.zero_tail_compressions``).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_native import native_solver, published_stack

from qpcoord.core import native

needs_native = pytest.mark.skipif(
    not native.available(),
    reason=f"the native engine (qpcoord._native) is not built: {native._load_error}",
)


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
