"""The native engine's ``Settings``: what a user may tune in ``Hierarchy.settings``.

The defaults are the Python engine's tolerances (the two engines solve the same problem);
the iteration cap and the time limit end an active set with the Python engine's errors.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.native_engine import assert_same, native_solver, needs_native
from support.stacks import hard_random_stack

import qpcoord as qc
from qpcoord.core.methods.hierarchical import VIOLATION_TOL
from qpcoord.core.polish import KKT_TOL


@needs_native
def test_defaults_are_the_python_engines_tolerances():
    _, h = native_solver(hard_random_stack(0, n=10, levels=2))
    s = h._solver.settings
    assert s.kkt_tol == KKT_TOL
    assert s.violation_tol == VIOLATION_TOL
    assert s.max_iter_factor == 6
    assert s.time_limit == math.inf


@needs_native
def test_iteration_cap_ends_the_active_set():
    """A cap below what a cold solve takes: 'did not converge' (naming the stage); restored,
    the next call (cold: the failed one dropped the stored sets) solves as before."""
    stack = hard_random_stack(0)
    P, h = native_solver(stack)
    x0, _, info = h.solve(P, warm=False)
    # the cap is max_iter_factor (rows + columns) + 10: 0 leaves 10 iterations per stage
    assert max(info["active_set_iterations"]) > 10
    h._solver.settings.max_iter_factor = 0
    with pytest.raises(qc.SolverError, match="did not converge"):
        h.solve(P, warm=False)
    h._solver.settings.max_iter_factor = 6
    x1, _, _ = h.solve(P)
    np.testing.assert_array_equal(x0, x1)


@needs_native
def test_time_limit_setting_and_the_calls_limit():
    """settings.time_limit bounds every call (the smaller of it and the call's time_left
    applies): an expired limit is the Python engine's time-limit error."""
    stack = hard_random_stack(1)
    P, h = native_solver(stack)
    h._solver.settings.time_limit = 0.0
    with pytest.raises(qc.SolverError, match="time limit reached"):
        h.solve(P, warm=False, time_left=10.0)
    h._solver.settings.time_limit = math.inf
    with pytest.raises(qc.SolverError, match="time limit reached"):
        h.solve(P, warm=False, time_left=0.0)
    h.solve(P, warm=False, time_left=10.0)


@needs_native
def test_time_limit_gives_the_python_engines_error():
    """An expired deadline ends the native active set with the Python engine's message."""
    s = hard_random_stack(0)
    with pytest.raises(qc.SolverError, match=r"time limit of 1e-09 s reached.*native engine"):
        s.solve(engine="native", time_limit=1e-9)
    sn = s.solve(engine="native", time_limit=math.inf)  # not poisoned: a cold solve
    assert_same(s.solve(engine="python"), sn)
