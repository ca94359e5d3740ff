"""The weighted method's limit: its regularisation against the lowest level's weight.

``method="weighted"`` adds ``ε‖x‖²`` (``ε = regularization·max(1, max diag H)``) where the
levels leave ``H = Σₖ weight_ratioᵏ AₖᵀAₖ`` singular. That term is one more (lowest) level
pulling ``x`` to 0; a level ``k`` of unit curvature that it competes with keeps the relative
residual ``ε / (ε + weight_ratioᵏ)`` of a task it could meet exactly. With the defaults
(``regularization = 1e-9``, ``weight_ratio = 1e-3``) a fourth level (weight 1e-9) is met only
halfway. Documented in docs/stack.md ("weighted") and docs/solvers.md ("Accuracy").
"""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc
from qpcoord.core import native

ENGINES = ["python"] + (["native"] if native.available() else [])
#: the stack's regularisation (the default)
EPS = 1e-9


def _tasks(seed: int, n: int = 10, rows=(3, 3, 2, 1)) -> list[qc.Equality]:
    """Four satisfiable equality levels of orthonormal rows in the first ``n - 1``
    coordinates; the last coordinate is in no task (``H`` exactly singular: the
    regularisation is always added, ``max diag H ≤ 1`` so ``ε`` is the regularisation)."""
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.normal(size=(n - 1, n - 1)))
    out, i = [], 0
    for m in rows:
        A = np.zeros((m, n))
        A[:, : n - 1] = Q[:, i : i + m].T
        out.append(qc.Equality(A, rng.normal(size=m)))
        i += m
    return out


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("ratio", [1e-1, 1e-2, 1e-3, 1e-4])
def test_the_lowest_level_keeps_eps_over_eps_plus_its_weight(engine, ratio):
    for seed in range(3):
        tasks = _tasks(seed)
        sol = qc.Stack(tasks, weight_ratio=ratio, regularization=EPS).solve(
            method="weighted", engine=engine
        )
        low = tasks[-1]
        rel = np.linalg.norm(low.A @ sol.x - low.b) / np.linalg.norm(low.b)
        lowest = ratio ** (len(tasks) - 1)
        np.testing.assert_allclose(rel, EPS / (EPS + lowest), rtol=1e-4)
        # the level above, weighted ratio² (1e3 x the lowest), keeps ~ε / ratio²
        mid = tasks[-2]
        rel2 = np.linalg.norm(mid.A @ sol.x - mid.b) / np.linalg.norm(mid.b)
        assert rel2 <= 2.0 * EPS / ratio**2
        assert sol.x[-1] == 0.0  # the free coordinate: regularised to its minimum norm
