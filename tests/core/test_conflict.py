"""InfeasibleError.conflict: the hard rows that cannot hold together, named, with their
violations at the least-violation point -- the same on both engines."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import qpcoord as qc
import qpcoord.core.conflict as conflict_mod
from qpcoord.core.conflict import ConflictRow

Equality, Inequality, Bounds = qc.Equality, qc.Inequality, qc.Bounds
ENGINES = ["python", "native"] if qc.core.native.available() else ["python"]
#: Values found by HiGHS's LP (feasibility tolerances 1e-10) on rows of unit scale: 1e-8
#: leaves two orders of magnitude for its rounding.
LP_TOL = 1e-8


def goal(n=3):
    return Equality(np.eye(n), np.zeros(n), name="goal")


def infeasible(engine, method="hierarchical", n=3, **kw) -> qc.InfeasibleError:
    with pytest.raises(qc.InfeasibleError) as info:
        qc.solve_stack([goal(n)], engine=engine, method=method, **kw)
    return info.value


def names(conflict):
    return [(r.task, r.row, r.kind) for r in conflict]


def e(i, n=3):
    return np.eye(n)[[i]]


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("method", ["hierarchical", "weighted"])
def test_two_hard_bands_that_cannot_both_hold(engine, method):
    err = infeasible(
        engine,
        method,
        constraints=[
            Inequality(e(0), lower=1.0, upper=3.0, name="band a"),
            Inequality(e(0), lower=-2.0, upper=0.0, name="band b"),
        ],
        bounds=Bounds(-5.0, 5.0),
    )
    assert names(err.conflict) == [("band a", 0, "lower"), ("band b", 0, "upper")]
    # min over x0 of the larger of (1 − x0, x0 − 0): x0 = 0.5, each missed by 0.5
    for row, bound in zip(err.conflict, (1.0, 0.0), strict=True):
        assert row.bound == bound
        assert row.value == pytest.approx(0.5, abs=LP_TOL)
        assert row.violation == pytest.approx(0.5, abs=LP_TOL)
        assert not row.is_bound and row.joint == ""
    assert "'band a' row 0: ≥ 1 missed by 0.5" in str(err)
    assert "'band b' row 0: ≤ 0 missed by 0.5" in str(err)


@pytest.mark.parametrize("engine", ENGINES)
def test_hard_equality_against_the_bounds_names_the_variables(engine):
    err = infeasible(
        engine,
        n=2,
        constraints=[Equality([[1.0, 1.0]], 5.0, name="sum")],
        bounds=Bounds(-1.0, 1.0, name="box"),
    )
    assert names(err.conflict) == [
        ("sum", 0, "equality"),
        ("box", 0, "upper bound"),
        ("box", 1, "upper bound"),
    ]
    # relative rule: 5 − (x0 + x1) = 5 t and x_i − 1 = t at the least-violation point, so
    # x_i = 1 + t, 5 − 2 − 2t = 5t: t = 3/7
    t = 3.0 / 7.0
    assert [r.violation for r in err.conflict] == pytest.approx([5 * t, t, t], abs=LP_TOL)
    assert err.conflict[1].is_bound
    assert "'box' x[0]: ≤ 1 missed by 0.429" in str(err)


@pytest.mark.parametrize("engine", ENGINES)
def test_the_conflict_leaves_out_an_innocent_row(engine):
    """Three hard rows, two in conflict: the third (on the same variable, met at the
    least-violation point) is not named."""
    err = infeasible(
        engine,
        constraints=[
            Inequality(e(0), lower=1.0, name="a"),
            Inequality(e(0) + e(1), upper=3.0, name="innocent"),
            Inequality(e(0), upper=0.0, name="b"),
        ],
    )
    assert names(err.conflict) == [("a", 0, "lower"), ("b", 0, "upper")]
    assert "innocent" not in str(err)


@pytest.mark.parametrize("engine", ENGINES)
def test_the_conflict_is_irreducible(engine, monkeypatch):
    """Every multiplier counted (the certificate's support not used), the deletion filter
    alone must drop the rows not needed: a second conflicting row on the same side, an
    innocent row and every bound; what is left is infeasible and each of its proper subsets
    feasible."""
    monkeypatch.setattr(conflict_mod, "_SUPPORT_TOL", -1.0)
    rows = [
        Inequality(e(0), lower=1.0, name="a"),
        Inequality(e(0) + e(1), upper=3.0, name="innocent"),
        Inequality(e(0), upper=0.0, name="b"),
        Inequality(e(0), upper=-1.0, name="c"),
    ]
    err = infeasible(engine, constraints=rows, bounds=Bounds(-5.0, 5.0))
    got = names(err.conflict)
    assert len(got) == 2 and got[0] == ("a", 0, "lower") and got[1][0] in ("b", "c")
    kept = [t for t in rows if t.name in {r.task for r in err.conflict}]
    for drop in kept:
        qc.solve_stack([goal()], constraints=[t for t in kept if t is not drop], engine=engine)


@pytest.mark.parametrize("engine", ENGINES)
def test_three_rows_that_conflict_together(engine):
    """x0 ≥ 1, x1 ≥ 1, x0 + x1 ≤ 0: no two conflict, the three do; all are named."""
    err = infeasible(
        engine,
        constraints=[
            Inequality(e(0), lower=1.0, name="a"),
            Inequality(e(1), lower=1.0, name="b"),
            Inequality(e(0) + e(1), upper=0.0, name="sum"),
        ],
    )
    assert names(err.conflict) == [("a", 0, "lower"), ("b", 0, "lower"), ("sum", 0, "upper")]
    # x0 = x1 = 1 − t, 2 − 2t = t: t = 2/3
    assert [r.violation for r in err.conflict] == pytest.approx([2 / 3] * 3, abs=LP_TOL)


@pytest.mark.parametrize("engine", ENGINES)
def test_inconsistent_hard_equalities_are_the_conflict(engine):
    """The equalities alone have no common point: the bounds are not named, even though
    they conflict with the equalities too, and the rows are named within their tasks."""
    err = infeasible(
        engine,
        n=2,
        constraints=[
            Equality([[1.0, 0.0], [0.0, 1.0]], [0.0, 1.0], name="pins"),
            Equality([[2.0, 0.0]], 1.0, name="c2"),
        ],
        bounds=Bounds(-0.1, 0.1),
    )
    assert "hard equality constraints are inconsistent" in str(err)
    assert names(err.conflict) == [("pins", 0, "equality"), ("c2", 0, "equality")]


@pytest.mark.parametrize("engine", ENGINES)
def test_unnamed_tasks_are_named_by_their_label(engine):
    err = infeasible(engine, constraints=[Inequality(e(0), lower=1.0), Inequality(e(0), upper=0.0)])
    assert [r.task for r in err.conflict] == ["Inequality (unnamed)"] * 2


def test_engines_name_the_same_conflict_on_a_random_stack():
    """A random infeasible hard part (6 variables, 10 inequality rows and a box): both
    engines name the same rows with the same violations."""
    if len(ENGINES) < 2:
        pytest.skip("the native engine is not built")
    rng = np.random.default_rng(7)
    C = rng.standard_normal((10, 6))
    x0 = rng.standard_normal(6)
    lower = C @ x0 + 0.5  # rows 0..4 ask for more than rows 5..9 allow along -C
    C[5:] = -C[:5] + 0.1 * rng.standard_normal((5, 6))
    lower[5:] = -(C[:5] @ x0) + 0.2
    cons = [Inequality(C[i : i + 1], lower=lower[i], name=f"r{i}") for i in range(10)]
    got = [
        infeasible(eng, n=6, constraints=cons, bounds=Bounds(-3.0, 3.0)).conflict for eng in ENGINES
    ]
    assert got[0] and names(got[0]) == names(got[1])
    # the LP is the same on the same numbers: only HiGHS's rounding differs (none here)
    np.testing.assert_allclose(
        [r.violation for r in got[0]], [r.violation for r in got[1]], rtol=0, atol=LP_TOL
    )


def test_conflict_survives_pickling():
    err = infeasible(
        "python", constraints=[Inequality(e(0), lower=1.0, name="a"), Inequality(e(0), upper=0.0)]
    )
    back = pickle.loads(pickle.dumps(err))
    assert back.conflict == err.conflict and str(back) == str(err)
    assert isinstance(back.conflict[0], ConflictRow)


def test_an_error_built_outside_a_stack_has_no_conflict():
    assert qc.InfeasibleError("no").conflict == ()


@pytest.mark.parametrize("engine", ENGINES)
def test_bad_input_still_gets_its_own_error(engine):
    """Bad numbers are ValueErrors naming the task, before any conflict search."""
    with pytest.raises(ValueError, match=r"Inequality 'a': lower > upper at row 0"):
        Inequality(e(0), lower=1.0, upper=0.0, name="a")
    with pytest.raises(ValueError, match=r"Equality 'c': b contains NaN at index 0"):
        Equality(e(0), [np.nan], name="c")
    with pytest.raises(ValueError, match=r"bounds"):
        qc.solve_stack([goal()], bounds=Bounds([0.0, 0.0, 1.0], [1.0, 1.0, 0.0]), engine=engine)
    stack = qc.Stack([goal()], constraints=[Inequality(e(0), lower=1.0, name="a")])
    with pytest.raises(ValueError, match="unknown method"):
        stack.solve(method="fastest", engine=engine)


@pytest.mark.parametrize("engine", ENGINES)
def test_out_of_time_the_rows_kept_still_conflict(engine, monkeypatch):
    """The filter's LPs see no time left: it stops at once and names every row of the
    (forced, whole-set) support -- not irreducible, still in conflict, never empty."""
    monkeypatch.setattr(conflict_mod, "_SUPPORT_TOL", -1.0)
    monkeypatch.setattr(conflict_mod, "time_left", lambda: 0.0)
    rows = [
        Inequality(e(0), lower=1.0, name="a"),
        Inequality(e(1), upper=3.0, name="innocent"),
        Inequality(e(0), upper=0.0, name="b"),
    ]
    err = infeasible(engine, constraints=rows)
    assert names(err.conflict) == [
        ("a", 0, "lower"),
        ("innocent", 0, "upper"),
        ("b", 0, "upper"),
    ]
    # x0 = 0.5 misses a and b by 0.5 (t = 0.5); the innocent row, not needed, is missed by
    # at most t·max(1, |3|) wherever the LP put x1
    a, innocent, b = err.conflict
    assert [a.violation, b.violation] == pytest.approx([0.5, 0.5], abs=LP_TOL)
    assert 0.0 <= innocent.violation <= 1.5 + LP_TOL


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("failure", ["raises", "finds none"])
def test_a_failed_search_never_hides_the_infeasibility(engine, failure, monkeypatch):
    """The search raising, or finding the rows consistent (an engine and the LP disagreeing
    at the tolerance's edge), leaves the engine's InfeasibleError, saying so."""

    def broken(*args, **kwargs):
        if failure == "raises":
            raise ValueError("injected")
        return ()

    monkeypatch.setattr(conflict_mod, "find_conflict", broken)
    err = infeasible(engine, constraints=[Inequality(e(0), lower=1.0), Inequality(e(0), upper=0.0)])
    assert err.conflict == ()
    assert "bounds and hard constraints are inconsistent" in str(err)
    said = "(injected)" if failure == "raises" else "(the elastic LP finds them consistent"
    assert f"the rows in conflict could not be isolated {said}" in str(err)
