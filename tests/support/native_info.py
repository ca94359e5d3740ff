"""The native engine's ``Solution.info`` by its definition, from the solver's arrays: the
reference the C++ ``Hierarchy.info`` (``Stack.solve`` and the IK step) is tested against."""

from __future__ import annotations

import numpy as np

from qpcoord.core.polish import KKT_TOL


def info_reference(stats: np.ndarray, detail: np.ndarray, levels: int, counters) -> dict:
    """The info dict by its definition (the Python engine's counts), from the arrays, and the
    solver's counters (its ``Stats``: ``NativeHierarchy.counters``)."""
    its = [int(v) for v in stats[:, 0]]
    stages = range(stats.shape[0])
    dev = float(detail[5])
    return {
        "engine": "native",
        "hard_iterations": its[0],
        "active_set_iterations": its[1:-1],
        "min_norm_iterations": its[-1],
        "warm_start_hits": int(np.count_nonzero(stats[:, 1])),
        "warm_start_seeded": int(detail[7]),
        "closed_form_levels": [k - 1 for k in stages if stats[k, 2] and 1 <= k <= levels],
        "qp_calls": sum(1 for k in stages if stats[k, 0] or stats[k, 1]),
        "uncertified": [(int(detail[6]), dev)] if dev > KKT_TOL else [],
        "stats": counters,
    }
