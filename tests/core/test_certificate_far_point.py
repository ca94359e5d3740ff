"""The Python engine's certificate against a point far out in a level's optimal set: a
certified point that is not the level's minimum-norm point by far is replaced by that point
or reported (status "inaccurate"), never frozen and returned as "optimal"."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import null_space
from support.dumps import DATA, spec_from_npz

import qpcoord as qc
import qpcoord.core.methods.hierarchical as hierarchical

_PARALLEL_EDGES = DATA / "talos_polygon_parallel_edges.npz"

#: Level 3 (joint-velocity damping, ``x`` unique) at the lexicographic optimum.
_LEVEL_3 = 0.47818442
#: How far the injected point lies from the certified one: 100 times beyond ``FAR_RATIO``
#: (1e3 times ``max(1, ‖x‖, ‖z_qp‖)``, here 1e3), and near enough that the level's rows and
#: objective at it are exact to ``eps·1e5·‖[Q; G]‖`` ~ 1e-11, 100 times inside the
#: certificate's tolerances (1e-9): the point is certified on every rounding path.
_DISTANCE = 1e5


def _stack() -> qc.Stack:
    return qc.Stack(**spec_from_npz(_PARALLEL_EDGES))


def _inject_far_point(monkeypatch, near) -> list:
    """Level 2 (the CoM, below the support polygon) certifies a point ``_DISTANCE`` out in its
    optimal set instead of its own point: ``z + t·d`` with ``d`` a unit vector in the null
    space of the level's objective and rows ``[Q; G]`` (16 of its 26 directions), so its
    value and every row are those of the certified point. The exact refinement once produced
    such a point on this stack (two support-polygon edges parallel to 4e-10 both made tight:
    a step of 1.4e7, certified, level 3 frozen at 7.1e6), on one rounding path only; here it
    is given. ``near`` stands in for :meth:`_Certifier.near`; returns the list that receives
    level 2's ``(kept z, ok, z_qp, x)``."""
    run = hierarchical._Certifier.run
    level_2, kept = [], []

    def run_far(self, candidates, H, f, Dy, where):
        z, ok, kkt = run(self, candidates, H, f, Dy, where)
        if where != "level 2":
            return z, ok, kkt
        assert ok and self.mv == 0  # no slacks: y = z
        d = null_space(np.vstack((self.Q, self.G)))[:, 0]
        z_far, ok, kkt = run(self, [z + _DISTANCE * d], H, f, Dy, where)
        # the premise: the certificate accepts the far point (any point of the optimal set)
        assert ok and np.linalg.norm(z_far) > 0.5 * _DISTANCE, (ok, kkt)
        level_2.append(self)
        return z_far, ok, kkt

    def near_spy(self, z, z_qp, x):
        z_kept, ok = near(self, z, z_qp, x)
        if level_2 and self is level_2[-1]:
            kept.append((z_kept, ok, z_qp, x))
        return z_kept, ok

    monkeypatch.setattr(hierarchical._Certifier, "run", run_far)
    monkeypatch.setattr(hierarchical._Certifier, "near", near_spy)
    return kept


@pytest.mark.parametrize("solver", ["daqp", "quadprog"])
def test_far_point_of_the_optimal_set_is_replaced_or_flagged(monkeypatch, solver):
    """The injected point is 1e5 times longer than the level's QP point and than the
    minimum-norm point of the level's optimal set (0.478), beyond ``FAR_RATIO`` (1e3). The
    minimum-norm point has the far point's value in exact arithmetic; whether it counts as no
    worse is decided at rounding (the far point's value is exact to ~1e-11 only), so two
    outcomes are right: replaced (level 3 then at its optimum, 0.478) or reported (status
    "inaccurate" at level 2; ``strict=True``: SolverError). Without the check the far point is
    frozen and the solve says "optimal"; what it then does to the lower levels depends on
    rounding too (their tolerances scale with ``‖x‖``: level 3 ended from 1e-10 relative off
    to 7.1e6 on this stack), so the check is judged by what level 2 keeps."""
    near = hierarchical._Certifier.near
    kept = _inject_far_point(monkeypatch, near)
    sol = _stack().solve(engine="python", solver=solver)
    [(z, ok, z_qp, x)] = kept
    if ok:
        bound = hierarchical.FAR_RATIO * max(1.0, np.linalg.norm(x), np.linalg.norm(z_qp))
        assert np.linalg.norm(z) <= bound
        assert sol.status == "optimal"
        np.testing.assert_allclose(sol.level_residuals[3], _LEVEL_3, rtol=1e-7)
    else:
        assert sol.status == "inaccurate"
        assert sol.info["inaccurate"]["level"] == 2
        with pytest.raises(qc.SolverError, match="level 2"):
            _stack().solve(engine="python", solver=solver, strict=True)


@pytest.mark.parametrize("solver", ["daqp", "quadprog"])
def test_without_the_check_the_far_point_is_frozen_as_optimal(monkeypatch, solver):
    kept = _inject_far_point(monkeypatch, lambda self, z, z_qp, x: (z, True))
    sol = _stack().solve(engine="python", solver=solver)
    [(z, ok, _z_qp, _x)] = kept
    assert ok and np.linalg.norm(z) > 0.5 * _DISTANCE
    assert sol.status == "optimal"


@pytest.mark.parametrize("solver", ["daqp", "quadprog"])
def test_the_fixed_refinement_passes_the_check(solver):
    sol = _stack().solve(engine="python", solver=solver)
    assert sol.status == "optimal"
    np.testing.assert_allclose(sol.level_residuals[3], _LEVEL_3, rtol=1e-7)
