"""Bad input and unsolvable problems: every error names the offending task or argument and
says what is wrong; a misbehaving backend raises SolverError, never a returned x."""

from __future__ import annotations

import re

import numpy as np
import pytest

import qpcoord as qc
import qpcoord.core.backends as backends
import qpcoord.core.elimination as reduced
from qpcoord.core.backends import FAILED, INFEASIBLE, OK, QPResult

SOLVERS = qc.available_solvers()
Equality, Inequality, Bounds = qc.Equality, qc.Inequality, qc.Bounds


def eye_level(n=2, name="goal"):
    return Equality(np.eye(n), np.zeros(n), name=name)


# ---------------------------------------------------------------------------------------
# Shapes
# ---------------------------------------------------------------------------------------


def test_b_rows_must_match_A_rows():
    with pytest.raises(
        ValueError, match=r"Equality 'reach': b must have 2 entries, got shape \(3,\)"
    ):
        Equality(np.ones((2, 3)), [1.0, 2.0, 3.0], name="reach")


def test_inequality_bounds_rows_must_match_C_rows():
    with pytest.raises(ValueError, match=r"Inequality 'lim': upper must have 2 entries"):
        Inequality(np.ones((2, 3)), lower=0.0, upper=[1.0, 2.0, 3.0], name="lim")


def test_weight_must_have_one_entry_per_row():
    with pytest.raises(
        ValueError, match=r"Equality 'w': weight must have 2 entries, got shape \(3,\)"
    ):
        Equality(np.ones((2, 3)), 0.0, weight=[1.0, 2.0, 3.0], name="w")
    with pytest.raises(ValueError, match=r"Inequality 'w': weight must have 1 entries"):
        Inequality([[1.0, 2.0]], upper=1.0, weight=[1.0, 1.0], name="w")


def test_matrix_must_be_two_dimensional_with_columns():
    with pytest.raises(ValueError, match=r"Equality 't': A must be 2-D .*got shape \(2, 2, 2\)"):
        Equality(np.ones((2, 2, 2)), 0.0, name="t")
    with pytest.raises(ValueError, match=r"Inequality 't': C has no columns"):
        Inequality(np.ones((2, 0)), upper=0.0, name="t")
    with pytest.raises(ValueError, match=r"Equality 't': A is not a numeric array"):
        Equality("abc", 0.0, name="t")
    with pytest.raises(ValueError, match=r"Equality 't': b is not numeric"):
        Equality([[1.0, 2.0]], "x", name="t")


def test_tasks_across_levels_must_have_the_same_number_of_columns():
    with pytest.raises(
        ValueError,
        match=r"level 1, Equality 'b': has 4 columns but level 0, Equality 'a' has 3",
    ):
        qc.Stack(
            [Equality(np.ones((1, 3)), 0.0, name="a"), Equality(np.ones((1, 4)), 0.0, name="b")]
        )


def test_tasks_within_a_level_must_have_the_same_number_of_columns():
    with pytest.raises(ValueError, match=r"level 0, Inequality 'b': has 4 columns .* has 3"):
        qc.Stack(
            [
                [
                    Equality(np.ones((1, 3)), 0.0, name="a"),
                    Inequality(np.ones((1, 4)), upper=0.0, name="b"),
                ]
            ]
        )


def test_constraints_and_levels_must_have_the_same_number_of_columns():
    with pytest.raises(
        ValueError,
        match=r"level 0, Equality 'a': has 3 columns but constraints, Inequality 'c' has 2",
    ):
        qc.Stack(
            [Equality(np.ones((1, 3)), 0.0, name="a")],
            constraints=[Inequality(np.ones((1, 2)), 0.0, name="c")],
        )


def test_bounds_length_must_match_the_number_of_variables():
    with pytest.raises(
        ValueError, match=r"Bounds 'vel': has 2 entries but the tasks have 3 columns"
    ):
        qc.Stack([eye_level(3)], bounds=Bounds([-1.0, -1.0], [1.0, 1.0], name="vel"))
    with pytest.raises(ValueError, match=r"Bounds 'vel': lower must have 3 entries"):
        Bounds([-1.0, -1.0], [1.0, 1.0, 1.0], name="vel")


# ---------------------------------------------------------------------------------------
# Non-finite numbers (inf only as -inf lower / +inf upper)
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_matrix_entries(bad):
    with pytest.raises(
        ValueError, match=r"Equality 't': A contains a non-finite value .* at row 0, column 1"
    ):
        Equality([[1.0, bad]], 0.0, name="t")
    with pytest.raises(
        ValueError, match=r"Inequality 't': C contains a non-finite value .* at row 1, column 0"
    ):
        Inequality([[1.0, 2.0], [bad, 0.0]], upper=0.0, name="t")


def test_nan_in_vectors():
    with pytest.raises(ValueError, match=r"Equality 't': b contains NaN at index 1"):
        Equality(np.eye(2), [0.0, np.nan], name="t")
    with pytest.raises(ValueError, match=r"Inequality 't': lower contains NaN at index 0"):
        Inequality([[1.0, 2.0]], lower=np.nan, name="t")
    with pytest.raises(ValueError, match=r"Inequality 't': upper contains NaN at index 0"):
        Inequality([[1.0, 2.0]], upper=[np.nan], name="t")
    with pytest.raises(ValueError, match=r"Bounds 'vel': lower contains NaN at index 1"):
        Bounds([0.0, np.nan], [1.0, 1.0], name="vel")
    with pytest.raises(ValueError, match=r"Bounds 'vel': upper contains NaN"):
        qc.Stack([eye_level(2)], bounds=Bounds(-1.0, np.nan, name="vel"))
    with pytest.raises(ValueError, match=r"Equality 't': weight contains NaN at index 1"):
        Equality(np.eye(2), 0.0, weight=[1.0, np.nan], name="t")


@pytest.mark.parametrize("bad", [np.inf, -np.inf])
def test_infinite_target_is_rejected(bad):
    with pytest.raises(
        ValueError, match=r"Equality 't': b has the non-allowed value .*inf.* at index 0"
    ):
        Equality([[1.0, 2.0]], bad, name="t")


def test_infinite_bounds_only_on_the_open_side():
    with pytest.raises(ValueError, match=r"Inequality 't': lower has the non-allowed value .*inf"):
        Inequality([[1.0, 2.0]], lower=np.inf, name="t")
    with pytest.raises(ValueError, match=r"Inequality 't': upper has the non-allowed value .*-inf"):
        Inequality([[1.0, 2.0]], upper=-np.inf, name="t")
    with pytest.raises(
        ValueError, match=r"Bounds 'vel': lower has the non-allowed value .*inf.* at index 0"
    ):
        Bounds([np.inf, 0.0], [1.0, 1.0], name="vel")
    with pytest.raises(
        ValueError, match=r"Bounds 'vel': upper has the non-allowed value .*-inf.* at index 1"
    ):
        Bounds([0.0, 0.0], [1.0, -np.inf], name="vel")
    # the allowed sides are fine
    Inequality([[1.0, 2.0]], lower=-np.inf, upper=np.inf, name="t")
    Bounds([-np.inf, 0.0], [1.0, np.inf])


def test_infinite_weight_is_rejected():
    with pytest.raises(
        ValueError, match=r"Equality 't': weight has the non-allowed value .*inf.* at index 1"
    ):
        Equality(np.eye(2), 0.0, weight=[1.0, np.inf], name="t")


# ---------------------------------------------------------------------------------------
# lower > upper, weights, missing sides
# ---------------------------------------------------------------------------------------


def test_inequality_lower_above_upper():
    with pytest.raises(
        ValueError, match=r"Inequality 't': lower > upper at row 1 \(.*2\.0.* > .*1\.0.*\)"
    ):
        Inequality([[1.0, 2.0], [1.0, 1.0]], lower=[0.0, 2.0], upper=[1.0, 1.0], name="t")


def test_bounds_lower_above_upper():
    with pytest.raises(ValueError, match=r"Bounds 'vel': lower > upper at index 1"):
        Bounds([0.0, 2.0], [1.0, 1.0], name="vel")
    # scalars are checked once the stack knows n
    with pytest.raises(ValueError, match=r"Bounds 'vel': lower > upper at index 0"):
        qc.Stack([eye_level(2)], bounds=Bounds(2.0, 1.0, name="vel"))


@pytest.mark.parametrize("w", [0.0, -1.0, [1.0, 0.0], [1.0, -2.0]])
def test_weight_must_be_positive(w):
    with pytest.raises(ValueError, match=r"Equality 't': weight must be > 0, got .* at row \d"):
        Equality(np.eye(2), 0.0, weight=w, name="t")
    with pytest.raises(ValueError, match=r"Inequality 't': weight must be > 0"):
        Inequality(np.eye(2), upper=0.0, weight=w, name="t")


def test_inequality_needs_a_side():
    with pytest.raises(ValueError, match=r"Inequality 't': give lower, upper or both"):
        Inequality(np.eye(2), name="t")


# ---------------------------------------------------------------------------------------
# Solver, method, stack structure, options
# ---------------------------------------------------------------------------------------


def test_unknown_solver_name():
    with pytest.raises(ValueError, match=r"unknown or uninstalled solver 'foo'; installed: .*daqp"):
        qc.solve_stack([eye_level()], solver="foo")
    with pytest.raises(ValueError, match=r"solver must be a string, got 3"):
        qc.Stack([eye_level()]).solve(solver=3)


def test_unknown_method():
    with pytest.raises(
        ValueError, match=r"unknown method 'bogus'; choose one of hierarchical, nullspace, weighted"
    ):
        qc.solve_stack([eye_level()], method="bogus")


def test_empty_stack():
    with pytest.raises(ValueError, match=r"empty stack"):
        qc.Stack([])
    with pytest.raises(ValueError, match=r"levels must be a list of tasks"):
        qc.Stack(None)


def test_empty_level():
    with pytest.raises(ValueError, match=r"level 0 is empty"):
        qc.Stack([[]])
    with pytest.raises(ValueError, match=r"level 1 is empty"):
        qc.Stack([eye_level(), []])


def test_bounds_passed_as_a_level():
    with pytest.raises(
        ValueError,
        match=r"level 1, task 0: Bounds are always hard; pass them as Stack\(..., bounds=...\)",
    ):
        qc.Stack([eye_level(), Bounds(-1.0, 1.0)])
    with pytest.raises(ValueError, match=r"level 0, task 1: Bounds are always hard"):
        qc.Stack([[eye_level(), Bounds(-1.0, 1.0)]])
    with pytest.raises(ValueError, match=r"constraints, task 0: Bounds are always hard"):
        qc.Stack([eye_level()], constraints=[Bounds(-1.0, 1.0)])


def test_other_objects_as_tasks_or_bounds():
    with pytest.raises(
        ValueError, match=r"level 0, task 0: expected an Equality or Inequality, got ndarray"
    ):
        qc.Stack([np.eye(2)])
    with pytest.raises(ValueError, match=r"level 0: expected a task or a list of tasks, got int"):
        qc.Stack([3])
    with pytest.raises(ValueError, match=r"bounds must be a qpcoord.Bounds, got tuple"):
        qc.Stack([eye_level()], bounds=(-1.0, 1.0))


@pytest.mark.parametrize(
    "option, value, message",
    [
        ("regularization", 0.0, r"regularization must be > 0, got 0"),
        ("regularization", -1e-9, r"regularization must be > 0"),
        ("damping", -1.0, r"damping must be >= 0, got -1"),
        ("damping", np.inf, r"damping must be a finite number"),
        ("weight_ratio", np.nan, r"weight_ratio must be a finite number, got nan"),
        ("weight_ratio", "big", r"weight_ratio must be a finite number, got 'big'"),
    ],
)
def test_bad_stack_options(option, value, message):
    with pytest.raises(ValueError, match=message):
        qc.Stack([eye_level()], **{option: value})


def test_nullspace_rejects_inequalities_and_bounds():
    with pytest.raises(
        ValueError,
        match=r"method='nullspace' handles equality tasks only, but level 1 has Inequality 'lim'; "
        r"use method='hierarchical'",
    ):
        qc.solve_stack(
            [eye_level(), Inequality([[1.0, 0.0]], upper=1.0, name="lim")], method="nullspace"
        )
    with pytest.raises(ValueError, match=r"but the stack has Bounds 'vel'"):
        qc.solve_stack([eye_level()], bounds=Bounds(-1.0, 1.0, name="vel"), method="nullspace")
    with pytest.raises(ValueError, match=r"but constraints has Inequality 'wall'"):
        qc.solve_stack(
            [eye_level()],
            constraints=[Inequality([[1.0, 0.0]], upper=1.0, name="wall")],
            method="nullspace",
        )


# ---------------------------------------------------------------------------------------
# update and warm start
# ---------------------------------------------------------------------------------------


def test_update_cannot_change_shape():
    t = Equality(np.ones((2, 3)), 0.0, name="reach")
    with pytest.raises(
        ValueError, match=r"Equality 'reach': update changes A's shape \(2, 3\) to \(3, 3\)"
    ):
        t.update(A=np.ones((3, 3)))
    with pytest.raises(ValueError, match=r"Equality 'reach': b must have 2 entries"):
        t.update(b=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match=r"Equality 'reach': weight must have 2 entries"):
        t.update(weight=[1.0, 2.0, 3.0])
    c = Inequality(np.ones((2, 3)), upper=0.0, name="lim")
    with pytest.raises(
        ValueError, match=r"Inequality 'lim': update changes C's shape \(2, 3\) to \(2, 4\)"
    ):
        c.update(C=np.ones((2, 4)))
    with pytest.raises(ValueError, match=r"Inequality 'lim': lower must have 2 entries"):
        c.update(lower=[0.0, 0.0, 0.0])
    bounds = Bounds([-1.0, -1.0], [1.0, 1.0], name="vel")
    with pytest.raises(ValueError, match=r"Bounds 'vel': upper must have 2 entries"):
        bounds.update(upper=[1.0, 1.0, 1.0])


def test_update_validates_numbers():
    t = Equality(np.eye(2), 0.0, name="reach")
    with pytest.raises(ValueError, match=r"Equality 'reach': A contains a non-finite value"):
        t.update(A=[[np.nan, 0.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match=r"Equality 'reach': weight must be > 0"):
        t.update(weight=0.0)
    c = Inequality(np.eye(2), lower=0.0, upper=1.0, name="lim")
    with pytest.raises(ValueError, match=r"Inequality 'lim': lower > upper at row 0"):
        c.update(lower=[2.0, 0.0])


def test_shape_changed_behind_the_stacks_back():
    t = Equality(np.ones((2, 3)), 0.0, name="reach")
    stack = qc.Stack([t])
    with pytest.raises(ValueError, match=r"Equality 'reach': update changes A's shape"):
        t.A = np.ones((3, 3))  # an assignment is an update: checked at once
    object.__setattr__(t, "A", np.ones((3, 3)))  # bypasses update(), as library code may
    with pytest.raises(
        ValueError, match=r"Equality 'reach': A changed shape from \(2, 3\) to \(3, 3\)"
    ):
        stack.solve()


@pytest.mark.parametrize(
    "warm, message",
    [
        (np.zeros(2), r"warm_start must be a finite array of 3 values, got shape \(2,\)"),
        (np.zeros(4), r"warm_start must be a finite array of 3 values, got shape \(4,\)"),
        ([np.nan, 0.0, 0.0], r"warm_start must be a finite array of 3 values"),
        ([np.inf, 0.0, 0.0], r"warm_start must be a finite array of 3 values"),
        ("abc", r"warm_start must be a Solution or an array, got 'abc'"),
    ],
)
@pytest.mark.parametrize("method", ["hierarchical", "weighted", "nullspace"])
def test_bad_warm_start(warm, message, method):
    stack = qc.Stack([Equality(np.eye(3), 1.0, name="goal")])
    with pytest.raises(ValueError, match=message):
        stack.solve(warm_start=warm, method=method)


def test_warm_start_from_a_solution_of_another_size():
    small = qc.solve_stack([Equality(np.eye(2), 1.0)])
    with pytest.raises(
        ValueError, match=r"warm_start must be a finite array of 3 values, got shape \(2,\)"
    ):
        qc.Stack([Equality(np.eye(3), 1.0)]).solve(warm_start=small)


# ---------------------------------------------------------------------------------------
# InfeasibleError: the hard part has no solution
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["hierarchical", "weighted", "nullspace"])
def test_inconsistent_hard_equalities(method):
    with pytest.raises(
        qc.InfeasibleError,
        match=r"hard equality constraints are inconsistent \(Equality 'c1', Equality 'c2'\)",
    ):
        qc.solve_stack(
            [eye_level()],
            constraints=[
                Equality([[1.0, 0.0]], 1.0, name="c1"),
                Equality([[2.0, 0.0]], 1.0, name="c2"),
            ],
            method=method,
        )


def test_hard_equalities_that_fix_x_outside_the_bounds():
    with pytest.raises(
        qc.InfeasibleError,
        match=r"constraints: the hard equalities fix x completely and it violates",
    ):
        qc.solve_stack(
            [eye_level()], constraints=[Equality(np.eye(2), 5.0, name="pin")], bounds=Bounds(-1, 1)
        )


_HARD_CONFLICTS = {
    "equality_vs_bounds": lambda: dict(
        constraints=[Equality([[1.0, 1.0]], 5.0, name="sum")], bounds=Bounds(-1.0, 1.0)
    ),
    "inequality_vs_bounds": lambda: dict(
        constraints=[Inequality([[1.0, 1.0]], lower=5.0, name="reach")], bounds=Bounds(-1.0, 1.0)
    ),
    "inequalities": lambda: dict(
        constraints=[
            Inequality([[1.0, 1.0]], lower=5.0, name="c1"),
            Inequality([[1.0, 1.0]], upper=-5.0, name="c2"),
        ]
    ),
}


@pytest.mark.parametrize("method", ["hierarchical", "weighted"])
@pytest.mark.parametrize("case", list(_HARD_CONFLICTS))
@pytest.mark.parametrize("solver", SOLVERS)
def test_hard_constraints_conflicting_with_bounds_or_each_other(solver, case, method):
    kw = _HARD_CONFLICTS[case]()
    with pytest.raises(
        qc.InfeasibleError, match=r"constraints: bounds and hard constraints .*inconsistent"
    ):
        qc.solve_stack([eye_level()], solver=solver, method=method, **kw)


_TIMED_SCRIPT = """
import sys, time, numpy as np, qpcoord as qc
Equality, Inequality, Bounds = qc.Equality, qc.Inequality, qc.Bounds
cases = [
    lambda: dict(constraints=[Equality([[1.0, 1.0]], 5.0)], bounds=Bounds(-1.0, 1.0)),
    lambda: dict(constraints=[Inequality([[1.0, 1.0]], lower=5.0)], bounds=Bounds(-1.0, 1.0)),
    lambda: dict(constraints=[Inequality([[1.0, 1.0]], lower=5.0),
                              Inequality([[1.0, 1.0]], upper=-5.0)]),
]
for solver in qc.available_solvers():
    for i, case in enumerate(cases):
        t = time.perf_counter()
        try:
            qc.solve_stack([Equality(np.eye(2), [0.0, 0.0])], solver=solver, **case())
            out = "returned"
        except qc.InfeasibleError:
            out = "infeasible"
        print(solver, i, out, f"{time.perf_counter() - t:.3f}", flush=True)
"""


def test_infeasible_hard_part_is_reported_without_hanging():
    """Every backend reports three 2-variable infeasible hard parts as InfeasibleError
    (proxqp once took 50-260 s to give up). Run in a subprocess with a generous hang guard:
    a backend stuck in compiled code cannot be interrupted otherwise. The per-case times are
    printed for information, never asserted (shared, noisy machines)."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    limit = 60.0 + 10.0 * len(SOLVERS)  # hang guard, ~100× the normal run
    try:
        out = subprocess.run(
            [sys.executable, "-c", _TIMED_SCRIPT],
            capture_output=True,
            text=True,
            timeout=limit,
            env=env,
        ).stdout
    except subprocess.TimeoutExpired as exc:
        done = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        pytest.fail(f"no answer within {limit} s; finished so far:\n{done}")
    rows = [line.split() for line in out.splitlines()]
    assert len(rows) == 3 * len(SOLVERS), out
    for solver, case, result, _seconds in rows:
        assert result == "infeasible", f"{solver} case {case}: {result}"


def test_soft_levels_never_raise_infeasible():
    """Contradicting *soft* tasks are a hierarchy's normal business."""
    sol = qc.solve_stack(
        [
            Inequality([[1.0, 0.0]], lower=5.0, name="a"),
            Inequality([[1.0, 0.0]], upper=-5.0, name="b"),
        ],
        bounds=Bounds(-1.0, 1.0),
    )
    np.testing.assert_allclose(sol.x[0], 1.0, atol=1e-6)


# ---------------------------------------------------------------------------------------
# SolverError: a backend that misbehaves must never yield a returned x
# ---------------------------------------------------------------------------------------
#
# `reduced.py` calls `solve_dense_qp` through its own module namespace (`from .backends
# import solve_dense_qp`), so that is where it is patched; patching the `_DIRECT["daqp"]`
# entry instead exercises solve_dense_qp's own guard as well.


def _result(y, code, message, exact=False):
    # QPResult gained an ``exact`` flag (active-set backends at tight tolerances)
    if "exact" in getattr(QPResult, "__dataclass_fields__", {}):
        return QPResult(y, code, message, exact)
    return QPResult(y, code, message)


def _far_outside(solver, H, f, G, lo, hi, lb=None, ub=None, y0=None):
    """Status OK, claims to be exact (as daqp/quadprog do), point far below every bound."""
    return _result(np.full(H.shape[0], -100.0), OK, "fake: solved", exact=True)


def _far_outside_inexact(solver, H, f, G, lo, hi, lb=None, ub=None, y0=None):
    """Same point from a backend whose answers qpcoord refines (interior point / ADMM)."""
    return _result(np.full(H.shape[0], -100.0), OK, "fake: solved", exact=False)


def _nan(solver, H, f, G, lo, hi, lb=None, ub=None, y0=None):
    return _result(np.full(H.shape[0], np.nan), OK, "fake: solved")


def _failed(solver, H, f, G, lo, hi, lb=None, ub=None, y0=None):
    return _result(None, FAILED, "fake: exploded")


def _infeasible(solver, H, f, G, lo, hi, lb=None, ub=None, y0=None):
    return _result(None, INFEASIBLE, "fake: infeasible")


FAKES = {
    "nan": _nan,
    "failed": _failed,
    "infeasible": _infeasible,
    "far_outside": _far_outside,
    "far_outside_inexact": _far_outside_inexact,
}


@pytest.fixture(params=["reduced", "direct"])
def patch_backend(request, monkeypatch):
    """Install a fake QP backend for 'daqp', at ``reduced.solve_dense_qp`` (where the stack
    methods call it) or in ``backends._DIRECT`` (behind solve_dense_qp's own checks)."""

    def install(fake):
        if request.param == "reduced":
            monkeypatch.setattr(reduced, "solve_dense_qp", fake)
        else:
            monkeypatch.setitem(
                backends._DIRECT,
                "daqp",
                lambda H, f, G, lo, hi, lb, ub, y0: fake("daqp", H, f, G, lo, hi, lb, ub, y0),
            )

    install.where = request.param
    return install


def _stacks():
    """Stacks whose level 0 needs a QP (its closed form violates bounds or hard rows)."""
    return {
        "bounds": lambda: qc.Stack(
            [Equality(np.eye(2), [5.0, 5.0], name="goal")], bounds=Bounds(-1.0, 1.0)
        ),
        "hard_inequality": lambda: qc.Stack(
            [Equality(np.eye(2), [5.0, 5.0], name="goal")],
            constraints=[Inequality([[1.0, 1.0]], lower=-1.0, upper=1.0, name="wall")],
        ),
        "soft_inequality": lambda: qc.Stack(
            [
                Inequality([[1.0, 1.0]], lower=1.5, name="lim"),
                Equality(np.eye(2), [5.0, -5.0], name="goal"),
            ],
            bounds=Bounds(-1.0, 1.0),
        ),
    }


@pytest.mark.parametrize("method", ["hierarchical", "weighted"])
@pytest.mark.parametrize("stack_name", ["bounds", "hard_inequality", "soft_inequality"])
@pytest.mark.parametrize("fake_name", list(FAKES))
def test_misbehaving_backend_raises_solver_error(fake_name, stack_name, method, patch_backend):
    """Never a returned x: not clipped into the bounds, not 'refined' onto a wrong active
    set, not passed on as NaN."""
    patch_backend(FAKES[fake_name])
    stack = _stacks()[stack_name]()
    stack._work.fallback = False  # as Stack(..., fallback=False)
    with pytest.raises(qc.SolverError, match=r"daqp") as info:
        stack.solve(solver="daqp", method=method)
    text = str(info.value)
    expected = {
        "nan": r"non-finite",
        "failed": r"failed: fake: exploded",
        "infeasible": r"failed: fake: infeasible",  # a soft level is never infeasible
        "far_outside": r"outside the bounds|violat|breaks an inequality",
        "far_outside_inexact": r"outside the bounds|violat|breaks an inequality",
    }[fake_name]
    assert re.search(expected, text), text
    if fake_name in ("failed", "infeasible"):
        assert re.search(r"level 0|weighted QP", text), text  # says where it happened


@pytest.mark.parametrize("method", ["hierarchical", "weighted"])
@pytest.mark.parametrize("fake_name", ["failed", "infeasible"])
def test_failing_backend_falls_back_and_says_so(fake_name, method, monkeypatch):
    """A level QP is feasible by construction: a backend that fails on it is replaced by
    the next fallback backend, and the Solution records it."""
    monkeypatch.setitem(
        backends._DIRECT,
        "daqp",
        lambda H, f, G, lo, hi, lb, ub, y0: FAKES[fake_name]("daqp", H, f, G, lo, hi, lb, ub, y0),
    )
    stack = _stacks()["bounds"]()
    sol = stack.solve(solver="daqp", method=method)
    np.testing.assert_allclose(sol.x, [1.0, 1.0], atol=1e-9)
    assert sol.info["fallbacks"] and "quadprog" in sol.info["fallbacks"][0]


def test_fallback_option_is_validated():
    with pytest.raises(ValueError, match="fallback"):
        qc.Stack([Equality(np.eye(2), [0.0, 0.0])], fallback="yes")


def _hard_stack(fallback: bool = True):
    return qc.Stack(
        [Equality(np.eye(2), [5.0, 5.0], name="goal")],
        constraints=[Inequality([[1.0, 1.0]], lower=1.0, name="wall")],  # x = 0 violates it
        bounds=Bounds(-1.0, 1.0),
        fallback=fallback,
    )


@pytest.mark.parametrize("fake_name", ["failed", "nan", "far_outside", "infeasible"])
def test_misbehaving_backend_in_the_hard_phase(fake_name, patch_backend, request):
    """The hard phase (finding a point that satisfies bounds and hard rows) needs a QP here;
    the hard part *is* feasible (x = (0.5, 0.5)), so a bad backend answer is a SolverError
    without fallback -- an "infeasible" too: an LP shows the hard part consistent."""
    patch_backend(FAKES[fake_name])
    with pytest.raises(qc.SolverError, match=r"constraints: .*daqp") as info:
        _hard_stack(fallback=False).solve(solver="daqp")
    if fake_name == "infeasible":
        assert "LP feasibility test shows are consistent" in str(info.value)


@pytest.mark.parametrize("fake_name", ["failed", "infeasible"])
def test_hard_phase_falls_back(fake_name, monkeypatch):
    """With the fallback on, a consistent hard part the backend fails on (or calls
    infeasible) is solved by the next backend, and the Solution says so."""
    monkeypatch.setitem(
        backends._DIRECT,
        "daqp",
        lambda H, f, G, lo, hi, lb, ub, y0: FAKES[fake_name]("daqp", H, f, G, lo, hi, lb, ub, y0),
    )
    sol = _hard_stack().solve(solver="daqp")
    np.testing.assert_allclose(sol.x, [1.0, 1.0], atol=1e-9)
    assert "constraints: quadprog" in sol.info["fallbacks"]


def test_infeasible_code_in_the_hard_phase_is_infeasible_error(patch_backend):
    """An "infeasible" from the backend on an inconsistent hard part, confirmed by the LP."""
    patch_backend(_infeasible)
    stack = qc.Stack(
        [Equality(np.eye(2), [5.0, 5.0], name="goal")],
        constraints=[Inequality([[1.0, 1.0]], lower=3.0, name="wall")],  # box: x1 + x2 ≤ 2
        bounds=Bounds(-1.0, 1.0),
    )
    with pytest.raises(
        qc.InfeasibleError,
        match=r"constraints: bounds and hard constraints are inconsistent \(.*fake: infeasible; "
        r"confirmed by an LP",
    ):
        stack.solve(solver="daqp")


def test_stack_still_works_after_a_backend_failure(monkeypatch):
    """A SolverError leaves the Stack usable (its workspace is reset on the next solve)."""
    stack = qc.Stack([Equality(np.eye(2), [5.0, 5.0], name="goal")], bounds=Bounds(-1.0, 1.0))
    with monkeypatch.context() as m:
        m.setattr(reduced, "solve_dense_qp", _failed)
        with pytest.raises(qc.SolverError):
            stack.solve(solver="daqp")
    np.testing.assert_allclose(stack.solve(solver="daqp").x, [1.0, 1.0], atol=1e-6)
