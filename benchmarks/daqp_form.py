"""DAQP's hierarchical form of a qpcoord stack, shared by ``hierarchy_bench.py`` and
``hierarchy_published.py`` (a helper module: it runs nothing)."""

from __future__ import annotations

import numpy as np

import qpcoord as qc


def daqp_problem(levels, bounds, n):
    """DAQP's hierarchical form: bounds hard (first n simple bounds), one block per level."""
    A, bu, bl, breaks = [], [bounds.upper * np.ones(n)], [bounds.lower * np.ones(n)], [n]
    count = n
    for lev in levels:
        lev = lev if isinstance(lev, list) else [lev]
        for t in lev:
            if isinstance(t, qc.Equality):
                A.append(t.A)
                bu.append(t.b)
                bl.append(t.b)
                count += t.A.shape[0]
            else:
                A.append(t.C)
                bu.append(np.minimum(t.upper, 1e30))
                bl.append(np.maximum(t.lower, -1e30))
                count += t.C.shape[0]
        breaks.append(count)
    return (
        np.vstack(A),
        np.concatenate(bu),
        np.concatenate(bl),
        np.zeros(count, dtype=np.int32),
        np.array(breaks, dtype=np.int32),
    )
