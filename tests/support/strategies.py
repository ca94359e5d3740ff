"""hypothesis strategies of random stacks shared by the engines' agreement tests."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

import qpcoord as qc


@st.composite
def stacks(draw):
    """Random stacks: n ≤ 8, 1–4 levels of equality and inequality rows (duplicated rows for
    rank deficiency, conflicting targets), optional bounds around 0, optional hard
    equalities (consistent) and hard inequalities (met by a known point inside the box)."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    n = draw(st.integers(2, 8))
    levels = []
    for _ in range(draw(st.integers(1, 4))):
        tasks = []
        me = draw(st.integers(0, 4))
        mi = draw(st.integers(0 if me else 1, 3))
        if me:
            A = rng.standard_normal((me, n))
            if me > 1 and draw(st.booleans()):
                A[-1] = A[0]  # duplicated row (a conflict if the targets differ)
            w = rng.uniform(0.1, 10.0, me) if draw(st.booleans()) else 1.0
            tasks.append(qc.Equality(A, 2.0 * rng.standard_normal(me), weight=w))
        if mi:
            C = rng.standard_normal((mi, n))
            lo = rng.uniform(-2.0, 1.0, mi)
            hi = lo + rng.uniform(0.0, 2.0, mi)
            lo[rng.random(mi) < 0.3] = -np.inf
            tasks.append(qc.Inequality(C, lo, hi, weight=rng.uniform(0.5, 4.0, mi)))
        levels.append(tasks)
    bounds = None
    x0 = rng.uniform(-0.5, 0.5, n)
    if draw(st.booleans()):
        bounds = qc.Bounds(-rng.uniform(0.6, 2.0, n), rng.uniform(0.6, 2.0, n))
    constraints = []
    if draw(st.booleans()):
        A = rng.standard_normal((draw(st.integers(1, max(1, n - 2))), n))
        constraints.append(qc.Equality(A, A @ x0))
    if draw(st.booleans()):
        C = rng.standard_normal((2, n))
        constraints.append(qc.Inequality(C, C @ x0 - 0.2, C @ x0 + rng.uniform(0.0, 0.5, 2)))
    return dict(levels=levels, bounds=bounds, constraints=constraints or None)
