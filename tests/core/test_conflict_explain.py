"""Solution.explain(): per level and task, the residual and the inequality rows active or
violated -- what gave way when a soft level could not be met."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import qpcoord as qc

Equality, Inequality, Bounds = qc.Equality, qc.Inequality, qc.Bounds
ENGINES = ["python", "native"] if qc.core.native.available() else ["python"]
#: x is exact to rounding on both engines (active-set solutions on unit-scale rows).
TOL = 1e-9


def unmet_stack() -> qc.Stack:
    """Level 0 asks x0 + x1 ≥ 3 and x0 = x1 inside the box [-1, 1]²: the band cannot be met
    (the box caps x0 + x1 at 2), the equality can. Level 1 asks x = (0, 0.5); a hard row
    keeps x0 − x1 ≤ 0.5 (inactive: x0 = x1)."""
    return qc.Stack(
        [
            [
                Equality([[1.0, -1.0]], 0.0, name="same"),
                Inequality(
                    [[1.0, 1.0], [1.0, 0.0]],
                    lower=[3.0, -5.0],
                    upper=[np.inf, 5.0],
                    name="reach band",
                ),
            ],  # fmt: skip
            Equality(np.eye(2), [0.0, 0.5], name="posture"),
        ],
        bounds=Bounds(-1.0, 1.0, name="box"),
        constraints=[Inequality([[1.0, -1.0]], upper=0.5, name="keep")],
    )


@pytest.mark.parametrize("engine", ENGINES)
def test_explain_names_what_gave_way(engine):
    sol = unmet_stack().solve(engine=engine)
    np.testing.assert_allclose(sol.x, [1.0, 1.0], atol=TOL)
    ex = sol.explain()
    assert [L.met for L in ex.levels] == [False, False]
    assert ex.unmet == ex.levels
    same, band = ex.levels[0].tasks
    assert same.task == "Equality 'same'" and same.met and same.rows == ()
    assert band.task == "Inequality 'reach band'" and not band.met
    # row 0 (x0 + x1 ≥ 3) missed by 1 at x = (1, 1); row 1 (|x0| ≤ 5) inside, not listed
    (row,) = band.rows
    assert (row.row, row.side, row.bound) == (0, "lower", 3.0) and row.violated
    assert row.value == pytest.approx(2.0, abs=TOL)
    assert row.violation == pytest.approx(1.0, abs=TOL)
    assert band.residual == pytest.approx(1.0, abs=TOL)
    assert ex.levels[0].value == pytest.approx(sol.level_residuals[0])
    # the posture gives way too: ‖(1, 1) − (0, 0.5)‖
    (posture,) = ex.levels[1].tasks
    assert posture.residual == pytest.approx(np.hypot(1.0, 0.5), abs=TOL)
    # what held it back: both upper bounds active; the hard row is not at its bound
    assert [(r.row, r.side, r.violated) for r in ex.bounds.rows] == [
        (0, "upper", False),
        (1, "upper", False),
    ]
    (keep,) = ex.constraints
    assert keep.met and keep.rows == ()
    text = str(ex)
    assert "level 0: value 1 (not met)" in text
    assert "Inequality 'reach band': residual 1 (not met)" in text
    assert "row 0 (≥ 3) violated by 1" in text
    assert "Bounds 'box'" in text and "row 1 (≤ 1) active" in text


@pytest.mark.parametrize("engine", ENGINES)
def test_a_met_level_lists_its_active_rows(engine):
    """A band met at its face is active, not violated; the level is met."""
    stack = qc.Stack(
        [
            Inequality([[1.0, 0.0]], upper=0.25, name="wall"),
            Equality(np.eye(2), [1.0, 0.0], name="goal"),
        ]
    )
    ex = stack.solve(engine=engine).explain()
    (wall,) = ex.levels[0].tasks
    assert ex.levels[0].met and wall.met and wall.residual == 0.0
    assert [(r.row, r.side, r.violated) for r in wall.rows] == [(0, "upper", False)]
    assert not ex.levels[1].met and ex.unmet == (ex.levels[1],)
    assert ex.bounds is None and ex.constraints == ()


def test_both_engines_explain_alike():
    if len(ENGINES) < 2:
        pytest.skip("the native engine is not built")
    a, b = (unmet_stack().solve(engine=e).explain() for e in ENGINES)
    assert str(a) == str(b)


def test_explain_without_a_stack_says_so():
    sol = unmet_stack().solve(engine="python")
    back = pickle.loads(pickle.dumps(sol))
    np.testing.assert_array_equal(back.x, sol.x)
    with pytest.raises(ValueError, match="no stack to explain"):
        back.explain()


def test_explain_of_an_ik_step_names_the_tasks():
    """The IK's solution explains itself on both engines (the native step's Solution gets
    the IK's stack): a posture level under the speed limits."""
    panda = qc.robots.load("panda")
    q = panda.neutral()
    target = q + 10.0  # 10 rad away at gain 1/s: 10 rad/s asked, the speed limits cap it
    for engine in ENGINES:
        ik = qc.IK(panda, [qc.PostureTask(panda, target, name="far posture")], dt=0.01,
                   limits=[qc.VelocityLimits(panda)], engine=engine)  # fmt: skip
        v, sol = ik.step(q)
        ex = sol.explain()
        (posture,) = ex.levels[0].tasks
        assert posture.task == "Equality 'far posture'" and not posture.met
        assert [r.row for r in ex.bounds.rows] == list(range(panda.nv))
        assert all(r.side == "upper" and not r.violated for r in ex.bounds.rows)
