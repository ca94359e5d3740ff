"""The Python engine's certificate against a point far out in a level's optimal set (robust,
issue 24): session 12's bug, reproduced by reverting its fix, is flagged, not returned as
"optimal"."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import qpcoord as qc
import qpcoord.core.methods.hierarchical as hierarchical
from qpcoord.core.linalg import numerical_rank

_PARALLEL_EDGES = Path(__file__).resolve().parents[1] / "data" / "talos_polygon_parallel_edges.npz"


def _stack() -> qc.Stack:
    from test_hierarchy_regressions import _spec_from_npz

    return qc.Stack(**_spec_from_npz(_PARALLEL_EDGES))


def _revert_refine_fix(monkeypatch):
    """``_refine_at`` as before 575fb47: every active row independent at rounding."""
    monkeypatch.setattr(hierarchical, "active_rank", lambda s, shape, tol: numerical_rank(s, shape))


@pytest.mark.parametrize("solver", ["daqp", "quadprog"])
def test_far_point_of_the_optimal_set_is_flagged(monkeypatch, solver):
    """Without the fix the refinement of level 2 (the CoM) makes two support-polygon edges
    parallel to 4e-10 exactly tight: a step of 1.4e7, certified (the level's KKT residual
    5.6e-10; in the data's exact arithmetic the wedge's tip is even 3e-9 better), and
    level 3 froze at 7.1e6 instead of 0.478 with status "optimal". The kept point is 2.8e7
    times longer than the level's QP point and than the minimum-norm point of the level's
    optimal set (0.478), beyond ``FAR_RATIO`` (1e3); no replacement is certified and no
    worse, so the level is reported: status "inaccurate" (``strict=True``: SolverError)."""
    _revert_refine_fix(monkeypatch)
    sol = _stack().solve(engine="python", solver=solver)
    assert sol.status == "inaccurate"
    assert sol.info["inaccurate"]["level"] == 2
    with pytest.raises(qc.SolverError, match="level 2"):
        _stack().solve(engine="python", solver=solver, strict=True)
    # the check is what flags it: without it the same point says "optimal"
    monkeypatch.setattr(hierarchical._Certifier, "near", lambda self, z, z_qp, x: (z, True))
    silent = _stack().solve(engine="python", solver=solver)
    assert silent.status == "optimal" and silent.level_residuals[3] > 1e6


@pytest.mark.parametrize("solver", ["daqp", "quadprog"])
def test_the_fixed_refinement_passes_the_check(solver):
    sol = _stack().solve(engine="python", solver=solver)
    assert sol.status == "optimal"
    np.testing.assert_allclose(sol.level_residuals[3], 0.47818442, rtol=1e-7)
