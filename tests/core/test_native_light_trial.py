"""The native engine's warm trial of a level without inequality rows on its stored set's rows
alone: the inherited rows and bounds the set leaves out are checked at the trial's point, so
the trial decides as the one on the whole level problem.

A level of equalities below inherited inequality rows (the IK levels below a support
polygon) keeps one inherited row in its working set; its warm trial builds only that row
and the objective. A point on that row alone that crosses a bound must miss (the whole
problem's trial sees the bound row): x is then the active set's, the Python engine's.
"""

from __future__ import annotations

import numpy as np
import pytest
from support.native_engine import X_TOL, needs_native

import qpcoord as qc


def _solver(stack: qc.Stack):
    from qpcoord.core.native import NativeHierarchy

    return NativeHierarchy(stack._compiled, stack.damping)


def _python_x(stack: qc.Stack) -> np.ndarray:
    return stack.solve(engine="python").x


def _assert_python(stack: qc.Stack, x: np.ndarray) -> None:
    ref = _python_x(stack)
    # the optimum is unique (the last level has full rank) and |x| <= 2 (the box): the
    # engines agree to their shared tolerance on x, relative to max(1, |x|)
    assert np.max(np.abs(x - ref)) <= X_TOL * max(1.0, float(np.max(np.abs(ref))))


@needs_native
def test_a_bound_the_stored_row_alone_crosses_makes_the_trial_miss():
    """x0 + x1 <= 1 inherited from level 0; level 1 pulls x to t in the box |x| <= 2. From
    t = (1, 1, 0, 0) the set is that row; at t = (3.2, -1.4, 0, 0) the point on it alone is
    (2.8, -1.8, 0, 0), outside the box: the optimum is (2, -1.4, 0, 0), the row inactive.
    A nearby target first: the stored row's trial hits there."""
    n = 4
    half = qc.Inequality(np.array([[1.0, 1.0, 0.0, 0.0]]), np.array([-np.inf]), np.ones(1))
    pull = qc.Equality(np.eye(n), np.array([1.0, 1.0, 0.0, 0.0]))
    stack = qc.Stack([half, pull], bounds=qc.Bounds(-2.0 * np.ones(n), 2.0 * np.ones(n)))
    new = _solver(stack)
    x, _, _ = new.solve(stack._compiled)
    np.testing.assert_allclose(x, [0.5, 0.5, 0.0, 0.0], rtol=0, atol=1e-12)

    pull.update(b=np.array([1.1, 0.95, 0.1, -0.2]))
    x, _, info = new.solve(stack._compiled)
    assert info["warm_start_hits"] >= 1  # level 1: its stored row, tried alone
    assert info["active_set_iterations"][1] == 0
    _assert_python(stack, x)

    pull.update(b=np.array([3.2, -1.4, 0.0, 0.0]))
    x, _, info = new.solve(stack._compiled)
    np.testing.assert_allclose(x, [2.0, -1.4, 0.0, 0.0], rtol=0, atol=1e-12)
    assert info["active_set_iterations"][1] > 0  # not a hit: the active set moved
    _assert_python(stack, x)


def _polygon_like_stack(seed: int, n: int = 10):
    """Six inequality rows of rank 2 (a point in a polygon: rows c_i^T J x, J 2 x n) as
    level 0, a 3-row equality task, a posture task below, a box that binds at times."""
    rng = np.random.default_rng(seed)
    J = rng.standard_normal((2, n))
    angles = np.linspace(0.0, 2.0 * np.pi, 6, endpoint=False)
    normals = np.column_stack([np.cos(angles), np.sin(angles)])
    poly = qc.Inequality(normals @ J, np.full(6, -np.inf), np.full(6, 0.3))
    hand = qc.Equality(rng.standard_normal((3, n)), np.zeros(3))
    posture = qc.Equality(np.eye(n), np.zeros(n))
    box = qc.Bounds(-0.8 * np.ones(n), 0.8 * np.ones(n))
    return qc.Stack([poly, hand, posture], bounds=box), hand, posture, rng


@needs_native
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_levels_below_polygon_rows_match_python_over_moving_targets(seed):
    """The rank-2 polygon rows inherited by two equality levels whose targets move: every
    warm answer is the Python engine's and a fresh solver's (cold), and the levels below the
    polygon hit their stored sets on some calls."""
    stack, hand, posture, rng = _polygon_like_stack(seed)
    new = _solver(stack)
    b_hand = 2.0 * rng.standard_normal(3)
    b_post = 0.5 * rng.standard_normal(posture.b.shape[0])
    hits_below = 0
    for step in range(40):
        hand.update(b=b_hand * np.cos(0.15 * step) + 0.3 * np.sin(0.5 * step))
        posture.update(b=b_post * np.sin(0.1 * step))
        x, _, info = new.solve(stack._compiled)
        _assert_python(stack, x)
        xc, _, _ = _solver(stack).solve(stack._compiled)
        assert np.max(np.abs(x - xc)) <= X_TOL * max(1.0, float(np.max(np.abs(xc))))
        if 0 in info["closed_form_levels"]:  # then every hit is a level's below it
            hits_below += info["warm_start_hits"]
    assert hits_below >= 10
