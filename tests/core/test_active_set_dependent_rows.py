"""The primal active-set continuation (:func:`qpcoord.core.polish.active_set_ls`) on a
working set whose rows are dependent to rounding: a direction along which the rows move by
~1e-14 of a step is free, not a constraint."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from qpcoord.core.linalg import svd
from qpcoord.core.polish import KKT_FEAS_TOL, KKT_TOL, active_set_ls, kkt_residual

_STARTS = (
    Path(__file__).resolve().parents[1]
    / "data"
    / "regressions"
    / "humanoid_min_norm_step_starts.npz"
)


@pytest.mark.parametrize("form", ["rows", "box"])
def test_rows_dependent_to_rounding_do_not_stop_the_continuation(form):
    """The LexLS humanoid's minimum-norm step ``min ½‖z + p‖², lo ≤ G z ≤ hi`` (8 free
    directions; ``rows``: the published form, 20 rows; ``box``: its simple bounds as a box,
    26 rows), started where the Python engine's minimum-norm step starts the continuation
    (``rows``: from piqp's QP point, ``box``: from HiGHS's, each pulled back into the rows:
    to ``z = 0``). The data: ``G``, ``lo``, ``hi``, ``p``, that ``start`` and the ``optimum``
    (CVXPY/Clarabel at 1e-12; the continuation now ends 1.1e-10 from it). At the start 11
    rows are met whose normals have rank 7 plus a singular value of 3e-14: counted as rank
    8, they left no free direction, and multipliers of 1e12 on them passed the sign test:
    ``converged`` at the start itself, 0.22 (``rows``) and 17.8 (``box``) from the
    optimum."""
    d = np.load(_STARTS)
    G, lo, hi, p, start, optimum = (
        d[f"{form}_{k}"] for k in ("G", "lo", "hi", "p", "start", "optimum")
    )
    Q = np.eye(p.size)
    # the contract: a feasible start; the injected point is its degenerate vertex
    assert kkt_residual(Q, -p, G, lo, hi, start)[1] == 0.0
    # its rows met to the activity tolerance (rows of unit norm; start = 0, bounds ~1e-14)
    nr = np.linalg.norm(G, axis=1)
    gs = G @ start / nr
    met = np.minimum(gs - lo / nr, hi / nr - gs) <= KKT_FEAS_TOL
    s = svd(G[met] / nr[met, None], full=False)[1]
    assert met.sum() > p.size and s[-1] < 1e-12 * s[0], s
    assert np.linalg.norm(start - optimum) > 0.2

    y, converged = active_set_ls(Q, -p, G, lo, hi, start)

    assert converged
    # the library's certificate, with the rows' gap (the check the step itself gets)
    st, infeas = kkt_residual(Q, -p, G, lo, hi, y, gap=True)
    assert st <= KKT_TOL and infeas <= KKT_FEAS_TOL, (st, infeas)
    # the objective is 1-strongly convex (Q = I): a feasible point whose objective is within
    # Δ of the optimum's lies within √(2Δ) of it. Δ: the gap the certificate admits, about
    # KKT_TOL·‖z + p‖·(‖p‖ + ‖z‖) (kkt_residual's docstring) — 0.013 here, from the
    # problem's scale (‖p‖ = 281) alone; the defect stopped 0.22 and 17.8 away
    gap = KKT_TOL * np.linalg.norm(optimum + p) * (np.linalg.norm(p) + np.linalg.norm(optimum))
    assert np.linalg.norm(y - optimum) <= np.sqrt(2.0 * gap)
