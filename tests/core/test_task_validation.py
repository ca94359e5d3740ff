"""Every rejected task argument gets its exact message (the one-shot path is
cheap without weakening a check; these pin the messages the validation gives, argument by
argument, at construction and at ``update``)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import qpcoord as qc
from qpcoord import Bounds as B
from qpcoord import Equality as E
from qpcoord import Inequality as I  # noqa: E741
from qpcoord import Stack

nan, inf = np.nan, np.inf
MAG = (
    " is outside the magnitudes a QP can square (1e-150 … 1e+150, or exactly 0): rescale the units"
)


def A_with(v, r=1, c=2):
    """The 3 × 3 identity with entry (r, c) replaced by ``v``."""
    A = np.eye(3)
    A[r, c] = v
    return A


CASES = [
    # Equality A
    (
        "eq A nan",
        lambda: E(A_with(nan), np.zeros(3), name="t"),
        ValueError,
        "Equality 't': A contains a non-finite value np.float64(nan) at row 1, column 2",
    ),
    (
        "eq A inf",
        lambda: E(A_with(inf), np.zeros(3), name="t"),
        ValueError,
        "Equality 't': A contains a non-finite value np.float64(inf) at row 1, column 2",
    ),
    (
        "eq A -inf",
        lambda: E(A_with(-inf), np.zeros(3), name="t"),
        ValueError,
        "Equality 't': A contains a non-finite value np.float64(-inf) at row 1, column 2",
    ),
    (
        "eq A huge",
        lambda: E(A_with(1e200), np.zeros(3), name="t"),
        ValueError,
        "Equality 't': A[1, 2] = np.float64(1e+200)" + MAG,
    ),
    (
        "eq A tiny",
        lambda: E(A_with(-1e-200), np.zeros(3), name="t"),
        ValueError,
        "Equality 't': A[1, 2] = np.float64(-1e-200)" + MAG,
    ),
    (
        "eq A list nan",
        lambda: E([[1.0, 2.0], [nan, 0.0]], 0.0, name="t"),
        ValueError,
        "Equality 't': A contains a non-finite value np.float64(nan) at row 1, column 0",
    ),
    (
        "eq A complex",
        lambda: E(np.eye(3) + 0j, np.zeros(3), name="t"),
        TypeError,
        "Equality 't': A is complex; tasks take real numbers",
    ),
    (
        "eq A strings",
        lambda: E([["a", "b"]], 0.0, name="t"),
        ValueError,
        "Equality 't': A is not a numeric array (could not convert string to float: 'a')",
    ),
    (
        "eq A 3d",
        lambda: E(np.zeros((2, 2, 2)), 0.0, name="t"),
        ValueError,
        "Equality 't': A must be 2-D (rows × variables), got shape (2, 2, 2)",
    ),
    (
        "eq A no rows",
        lambda: E(np.zeros((0, 3)), np.zeros(0), name="t"),
        ValueError,
        "Equality 't': A has no rows (shape (0, 3)); a task needs at least one row "
        "(leave an empty task out of the stack)",
    ),
    (
        "eq A no cols",
        lambda: E(np.zeros((2, 0)), np.zeros(2), name="t"),
        ValueError,
        "Equality 't': A has no columns (shape (2, 0))",
    ),
    (
        "eq A object",
        lambda: E(object(), 0.0, name="t"),
        ValueError,
        "Equality 't': A is not a numeric array "
        "(float() argument must be a string or a real number, not 'object')",
    ),
    (
        "eq b nan",
        lambda: E(np.eye(3), [0.0, 0.0, nan], name="t"),
        ValueError,
        "Equality 't': b contains NaN at index 2",
    ),
    (
        "eq b inf",
        lambda: E(np.eye(3), [0.0, inf, 0.0], name="t"),
        ValueError,
        "Equality 't': b has the non-allowed value np.float64(inf) at index 1",
    ),
    (
        "eq b -inf scalar",
        lambda: E(np.eye(3), -inf, name="t"),
        ValueError,
        "Equality 't': b has the non-allowed value np.float64(-inf) at index 0",
    ),
    (
        "eq b shape",
        lambda: E(np.eye(3), np.zeros(4), name="t"),
        ValueError,
        "Equality 't': b must have 3 entries, got shape (4,)",
    ),
    (
        "eq b 2d",
        lambda: E(np.eye(3), np.zeros((3, 2)), name="t"),
        ValueError,
        "Equality 't': b must have 3 entries, got shape (3, 2)",
    ),
    (
        "eq b complex",
        lambda: E(np.eye(3), [0, 1j, 0], name="t"),
        TypeError,
        "Equality 't': b is complex; tasks take real numbers",
    ),
    (
        "eq b str",
        lambda: E(np.eye(3), "x", name="t"),
        ValueError,
        "Equality 't': b is not numeric (could not convert string to float: 'x')",
    ),
    (
        "eq w nan",
        lambda: E(np.eye(3), 0.0, weight=nan, name="t"),
        ValueError,
        "Equality 't': weight contains NaN at index 0",
    ),
    (
        "eq w nan vec",
        lambda: E(np.eye(3), 0.0, weight=[1.0, 1.0, nan], name="t"),
        ValueError,
        "Equality 't': weight contains NaN at index 2",
    ),
    (
        "eq w inf",
        lambda: E(np.eye(3), 0.0, weight=inf, name="t"),
        ValueError,
        "Equality 't': weight has the non-allowed value np.float64(inf) at index 0",
    ),
    (
        "eq w zero",
        lambda: E(np.eye(3), 0.0, weight=0.0, name="t"),
        ValueError,
        "Equality 't': weight must be > 0, got np.float64(0.0) at row 0",
    ),
    (
        "eq w neg int",
        lambda: E(np.eye(3), 0.0, weight=-1, name="t"),
        ValueError,
        "Equality 't': weight must be > 0, got np.float64(-1.0) at row 0",
    ),
    (
        "eq w neg vec",
        lambda: E(np.eye(3), 0.0, weight=[1.0, -2.0, 1.0], name="t"),
        ValueError,
        "Equality 't': weight must be > 0, got np.float64(-2.0) at row 1",
    ),
    (
        "eq w shape",
        lambda: E(np.eye(3), 0.0, weight=[1.0, 1.0], name="t"),
        ValueError,
        "Equality 't': weight must have 3 entries, got shape (2,)",
    ),
    (
        "eq w complex",
        lambda: E(np.eye(3), 0.0, weight=1j, name="t"),
        TypeError,
        "Equality 't': weight is complex; tasks take real numbers",
    ),
    (
        "eq w bool",
        lambda: E(np.eye(3), 0.0, weight=False, name="t"),
        ValueError,
        "Equality 't': weight must be > 0, got np.float64(0.0) at row 0",
    ),
    # Inequality
    (
        "in C nan",
        lambda: I(A_with(nan), upper=0.0, name="t"),
        ValueError,
        "Inequality 't': C contains a non-finite value np.float64(nan) at row 1, column 2",
    ),
    (
        "in C inf",
        lambda: I(A_with(inf), upper=0.0, name="t"),
        ValueError,
        "Inequality 't': C contains a non-finite value np.float64(inf) at row 1, column 2",
    ),
    (
        "in C huge",
        lambda: I(A_with(1e151), upper=0.0, name="t"),
        ValueError,
        "Inequality 't': C[1, 2] = np.float64(1e+151)" + MAG,
    ),
    (
        "in C tiny",
        lambda: I(A_with(1e-151), upper=0.0, name="t"),
        ValueError,
        "Inequality 't': C[1, 2] = np.float64(1e-151)" + MAG,
    ),
    (
        "in C complex",
        lambda: I(np.eye(2) + 1j, upper=0.0, name="t"),
        TypeError,
        "Inequality 't': C is complex; tasks take real numbers",
    ),
    (
        "in none",
        lambda: I(np.eye(2), name="t"),
        ValueError,
        "Inequality 't': give lower, upper or both",
    ),
    (
        "in lo nan",
        lambda: I(np.eye(3), lower=[0.0, nan, 0.0], name="t"),
        ValueError,
        "Inequality 't': lower contains NaN at index 1",
    ),
    (
        "in lo inf",
        lambda: I(np.eye(3), lower=[0.0, 0.0, inf], name="t"),
        ValueError,
        "Inequality 't': lower has the non-allowed value np.float64(inf) at index 2",
    ),
    (
        "in hi nan",
        lambda: I(np.eye(3), upper=nan, name="t"),
        ValueError,
        "Inequality 't': upper contains NaN at index 0",
    ),
    (
        "in hi -inf",
        lambda: I(np.eye(3), upper=[-inf, 0.0, 0.0], name="t"),
        ValueError,
        "Inequality 't': upper has the non-allowed value np.float64(-inf) at index 0",
    ),
    (
        "in lo>hi",
        lambda: I(np.eye(3), lower=[0.0, 2.0, 0.0], upper=1.0, name="t"),
        ValueError,
        "Inequality 't': lower > upper at row 1 (np.float64(2.0) > np.float64(1.0))",
    ),
    (
        "in lo shape",
        lambda: I(np.eye(3), lower=[0.0, 2.0], name="t"),
        ValueError,
        "Inequality 't': lower must have 3 entries, got shape (2,)",
    ),
    (
        "in hi complex",
        lambda: I(np.eye(3), upper=[0.0, 2.0j, 0], name="t"),
        TypeError,
        "Inequality 't': upper is complex; tasks take real numbers",
    ),
    (
        "in w nan",
        lambda: I(np.eye(3), upper=1.0, weight=[1.0, nan, 1.0], name="t"),
        ValueError,
        "Inequality 't': weight contains NaN at index 1",
    ),
    (
        "in w zero",
        lambda: I(np.eye(3), upper=1.0, weight=0, name="t"),
        ValueError,
        "Inequality 't': weight must be > 0, got np.float64(0.0) at row 0",
    ),
    (
        "in w inf",
        lambda: I(np.eye(3), upper=1.0, weight=inf, name="t"),
        ValueError,
        "Inequality 't': weight has the non-allowed value np.float64(inf) at index 0",
    ),
    # Bounds
    (
        "bd lo nan",
        lambda: B([0.0, nan], [1.0, 1.0], name="vel"),
        ValueError,
        "Bounds 'vel': lower contains NaN at index 1",
    ),
    (
        "bd hi nan",
        lambda: B([0.0, 0.0], [1.0, nan], name="vel"),
        ValueError,
        "Bounds 'vel': upper contains NaN at index 1",
    ),
    (
        "bd lo inf",
        lambda: B([inf, 0.0], [1.0, 1.0], name="vel"),
        ValueError,
        "Bounds 'vel': lower has the non-allowed value np.float64(inf) at index 0",
    ),
    (
        "bd hi -inf",
        lambda: B([0.0, 0.0], [1.0, -inf], name="vel"),
        ValueError,
        "Bounds 'vel': upper has the non-allowed value np.float64(-inf) at index 1",
    ),
    (
        "bd lo>hi",
        lambda: B([0.0, 2.0], [1.0, 1.0], name="vel"),
        ValueError,
        "Bounds 'vel': lower > upper at index 1 (np.float64(2.0) > np.float64(1.0))",
    ),
    (
        "bd shapes",
        lambda: B([0.0, 2.0], [1.0, 1.0, 1.0], name="vel"),
        ValueError,
        "Bounds 'vel': lower must have 3 entries, got shape (2,)",
    ),
    (
        "bd complex",
        lambda: B([0.0, 1j], 1.0, name="vel"),
        TypeError,
        "Bounds 'vel': lower is complex; tasks take real numbers",
    ),
    (
        "bd str",
        lambda: B("a", 1.0, name="vel"),
        ValueError,
        "Bounds 'vel': lower is not numeric (could not convert string to float: 'a')",
    ),
    (
        "bd scalar nan",
        lambda: B(nan, 1.0, name="vel"),
        ValueError,
        "Bounds 'vel': lower contains NaN at index 0",
    ),
    (
        "bd scalar inf",
        lambda: B(inf, 1.0, name="vel"),
        ValueError,
        "Bounds 'vel': lower has the non-allowed value np.float64(inf) at index 0",
    ),
    (
        "bd scalar lo>hi",
        lambda: B(2.0, 1.0, name="vel"),
        ValueError,
        "Bounds 'vel': lower > upper at index 0 (np.float64(2.0) > np.float64(1.0))",
    ),
    # updates
    (
        "eq upd A nan",
        lambda: E(np.eye(3), 0.0, name="t").update(A=A_with(nan)),
        ValueError,
        "Equality 't': A contains a non-finite value np.float64(nan) at row 1, column 2",
    ),
    (
        "eq upd A shape",
        lambda: E(np.eye(3), 0.0, name="t").update(A=np.eye(2)),
        ValueError,
        "Equality 't': update changes A's shape (3, 3) to (2, 2)",
    ),
    (
        "eq upd A tiny",
        lambda: E(np.eye(3), 0.0, name="t").update(A=A_with(1e-300)),
        ValueError,
        "Equality 't': A[1, 2] = np.float64(1e-300)" + MAG,
    ),
    (
        "eq upd b inf",
        lambda: E(np.eye(3), 0.0, name="t").update(b=[inf, 0.0, 0.0]),
        ValueError,
        "Equality 't': b has the non-allowed value np.float64(inf) at index 0",
    ),
    (
        "eq upd w neg",
        lambda: E(np.eye(3), 0.0, name="t").update(weight=-1.0),
        ValueError,
        "Equality 't': weight must be > 0, got np.float64(-1.0) at row 0",
    ),
    (
        "in upd C nan",
        lambda: I(np.eye(3), upper=0.0, name="t").update(C=A_with(nan)),
        ValueError,
        "Inequality 't': C contains a non-finite value np.float64(nan) at row 1, column 2",
    ),
    (
        "in upd lo nan",
        lambda: I(np.eye(3), upper=0.0, name="t").update(lower=nan),
        ValueError,
        "Inequality 't': lower contains NaN at index 0",
    ),
    (
        "in upd lo>hi",
        lambda: I(np.eye(3), upper=0.0, name="t").update(lower=1.0),
        ValueError,
        "Inequality 't': lower > upper at row 0 (np.float64(1.0) > np.float64(0.0))",
    ),
    (
        "in upd w nan",
        lambda: I(np.eye(3), upper=0.0, name="t").update(weight=nan),
        ValueError,
        "Inequality 't': weight contains NaN at index 0",
    ),
    (
        "bd upd hi nan",
        lambda: B(np.zeros(2), np.ones(2), name="vel").update(upper=[1.0, nan]),
        ValueError,
        "Bounds 'vel': upper contains NaN at index 1",
    ),
    (
        "bd upd shape",
        lambda: B(np.zeros(2), np.ones(2), name="vel").update(upper=[1.0, 1.0, 1.0]),
        ValueError,
        "Bounds 'vel': upper must have 2 entries, got shape (3,)",
    ),
    (
        "bd upd scalar lo>hi",
        lambda: B(0.0, 1.0, name="vel").update(lower=3.0),
        ValueError,
        "Bounds 'vel': lower > upper at index 0 (np.float64(3.0) > np.float64(1.0))",
    ),
    # limits whose rows satisfy lower <= upper but hold a wrong-sided infinity on both
    # sides, or NaN beside an allowed infinity: the hot path's order test alone would
    # pass the first kind, so its infinity reductions must name them
    (
        "bd lo=hi=+inf",
        lambda: B([inf, 0.0], [inf, 1.0], name="vel"),
        ValueError,
        "Bounds 'vel': lower has the non-allowed value np.float64(inf) at index 0",
    ),
    (
        "bd lo=hi=-inf",
        lambda: B([0.0, -inf], [1.0, -inf], name="vel"),
        ValueError,
        "Bounds 'vel': upper has the non-allowed value np.float64(-inf) at index 1",
    ),
    (
        "bd scalar lo=hi=+inf",
        lambda: B(inf, inf, name="vel"),
        ValueError,
        "Bounds 'vel': lower has the non-allowed value np.float64(inf) at index 0",
    ),
    (
        "bd lo nan, hi +inf",
        lambda: B([nan, 0.0], inf, name="vel"),
        ValueError,
        "Bounds 'vel': lower contains NaN at index 0",
    ),
    (
        "bd upd lo=hi=+inf",
        lambda: B([0.0, 0.0], [1.0, 1.0], name="vel").update(lower=[0.0, inf], upper=[1.0, inf]),
        ValueError,
        "Bounds 'vel': lower has the non-allowed value np.float64(inf) at index 1",
    ),
    (
        "in lo=hi=+inf",
        lambda: I(np.eye(3), lower=[0.0, inf, 0.0], upper=[1.0, inf, 1.0], name="t"),
        ValueError,
        "Inequality 't': lower has the non-allowed value np.float64(inf) at index 1",
    ),
    (
        "in lo=hi=-inf",
        lambda: I(np.eye(3), lower=-inf, upper=[0.0, 0.0, -inf], name="t"),
        ValueError,
        "Inequality 't': upper has the non-allowed value np.float64(-inf) at index 2",
    ),
    (
        "in upd lo=hi=-inf",
        lambda: I(np.eye(3), lower=0.0, upper=1.0, name="t").update(
            lower=[-inf, 0.0, 0.0], upper=[-inf, 1.0, 1.0]
        ),
        ValueError,
        "Inequality 't': upper has the non-allowed value np.float64(-inf) at index 0",
    ),
    (
        "in upd lo>hi",
        lambda: I(np.eye(3), lower=0.0, upper=1.0, name="t").update(
            lower=[0.0, 2.0, 0.0], upper=1.0
        ),
        ValueError,
        "Inequality 't': lower > upper at row 1 (np.float64(2.0) > np.float64(1.0))",
    ),
    # two bad limits: lower's problem is named first, as each side is checked in turn
    (
        "in lo nan, hi complex",
        lambda: I(np.eye(3), lower=[nan, 0.0, 0.0], upper=[1j, 0.0, 0.0], name="t"),
        ValueError,
        "Inequality 't': lower contains NaN at index 0",
    ),
    (
        "in lo nan, hi shape",
        lambda: I(np.eye(3), lower=[nan, 0.0, 0.0], upper=[1.0, 1.0], name="t"),
        ValueError,
        "Inequality 't': lower contains NaN at index 0",
    ),
    (
        "eq b nan scalar",
        lambda: E(np.eye(3), nan, name="t"),
        ValueError,
        "Equality 't': b contains NaN at index 0",
    ),
]


@pytest.mark.parametrize("case, build, error, message", CASES, ids=[c[0] for c in CASES])
def test_rejected_argument_is_named_exactly(case, build, error, message):
    with pytest.raises(error) as info:
        build()
    assert type(info.value) is error
    assert str(info.value) == message


def test_accepted_inputs_keep_their_derived_flags():
    """What a task derives from accepted numbers (the fast validation path keeps it)."""
    eye = E(np.eye(3, dtype=int), [1, 2, 3])
    assert eye.is_identity and eye.unit_weight and eye.A.dtype == float
    np.testing.assert_array_equal(eye.sqrt_weight, np.ones(3))
    assert not E(2.0 * np.eye(3), 0.0).is_identity
    assert not E(np.eye(3)[[1, 0, 2]], 0.0).is_identity  # a permutation
    off = np.eye(3)
    off[0, 1] = 1e-3
    assert not E(off, 0.0).is_identity
    assert not E(np.ones((3, 3)), 0.0).is_identity
    assert not E(np.eye(3)[:2], 0.0).is_identity  # not square
    w = E(np.ones((2, 3)), np.array([[1.0], [2.0]]), weight=[4.0, 9.0])
    assert not w.unit_weight
    np.testing.assert_array_equal(w.sqrt_weight, [2.0, 3.0])
    np.testing.assert_array_equal(w.b, [1.0, 2.0])
    assert E([1.0, 2.0], 3, weight=True).unit_weight  # a 1-D A is one row; True is 1.0
    src = np.arange(6.0).reshape(2, 3)
    t = I(src, lower=0.0, upper=[1.0, inf], weight=2.0)
    src[0, 0] = 99.0  # the task does not alias the caller's array
    assert t.C[0, 0] == 0.0
    for arr in (t.C, t.lower, t.upper, t.weight, t.sqrt_weight):
        assert not arr.flags.writeable
    np.testing.assert_array_equal(t.lower, [0.0, 0.0])
    np.testing.assert_array_equal(t.sqrt_weight, np.sqrt([2.0, 2.0]))
    b = B(np.array([-1, -2]), 3)
    np.testing.assert_array_equal(b.upper, [3.0, 3.0])
    assert b.n == 2 and b.lower.dtype == float and not b.lower.flags.writeable
    s = B(-1.0, None)
    assert s.n is None
    lo, hi = s.resolve(3)
    np.testing.assert_array_equal(lo, -np.ones(3))
    assert np.all(hi == inf)


def test_the_arrays_behind_the_views_stay_writable_for_the_library():
    """1-D ``A``, column ``b``, Fortran-ordered and strided input: each task array is a
    read-only view of a C-contiguous array of the same shape (the library's ``_assign``
    writes through it)."""
    t = E([1.0, 2.0], np.array([[1.0]]))
    t._assign(A=np.array([[3.0, 4.0]]), b=np.array([2.0]))
    np.testing.assert_array_equal(t.A, [[3.0, 4.0]])
    np.testing.assert_array_equal(t.b, [2.0])
    f = E(np.asfortranarray(np.arange(6.0).reshape(2, 3)), np.zeros((1, 2)))
    g = I(np.arange(12.0).reshape(3, 4)[:, ::2], lower=np.zeros((3, 1)), upper=inf)
    for task in (t, f, g):
        for arr in vars(task).values():
            if isinstance(arr, np.ndarray):
                assert arr.flags.c_contiguous and not arr.flags.writeable
                assert arr.base.shape == arr.shape and arr.base.flags.writeable
    g._assign(np.ones(3), np.full(3, 2.0), C=np.ones((3, 2)))
    np.testing.assert_array_equal(g.lower, np.ones(3))


def _eye(n, name=""):
    return E(np.eye(n), 0.0, name=name)


def _box(n, name=""):
    return I(np.eye(n), upper=1.0, name=name)


_COLS = ": all tasks must act on the same variable"
STRUCTURE_CASES = [
    (
        "column error before a bad task",
        lambda: Stack([[_eye(3), "x"], _eye(4, "b")]),
        "level 1, Equality 'b': has 4 columns but level 0, Equality (unnamed) has 3" + _COLS,
    ),
    (
        "column error in constraints before a bad level task",
        lambda: Stack([[B(0.0, 1.0)], _eye(3)], constraints=[_box(2, "c")]),
        "level 1, Equality (unnamed): has 3 columns but constraints, Inequality 'c' has 2" + _COLS,
    ),
    (
        "bad level task before bad constraint",
        lambda: Stack([_eye(3), [_eye(3), 5]], constraints=[B()]),
        "level 1, task 1: expected an Equality or Inequality, got int",
    ),
    (
        "first bad task of a level",
        lambda: Stack([[_eye(3), None, B()]]),
        "level 0, task 1: expected an Equality or Inequality, got NoneType",
    ),
    (
        "bounds in a level",
        lambda: Stack([[_eye(3)], [_eye(3), B()]]),
        "level 1, task 1: Bounds are always hard; pass them as Stack(..., bounds=...)",
    ),
    (
        "bad constraint",
        lambda: Stack([_eye(3)], constraints=[_box(3), np.eye(3)]),
        "constraints, task 1: expected an Equality or Inequality, got ndarray",
    ),
    (
        "bounds type",
        lambda: Stack([_eye(3)], bounds=(0, 1)),
        "bounds must be a qpcoord.Bounds, got tuple",
    ),
    (
        "bounds type after task errors",
        lambda: Stack([[_eye(3), 1]], bounds=(0, 1)),
        "level 0, task 1: expected an Equality or Inequality, got int",
    ),
    (
        "bounds length",
        lambda: Stack([_eye(3)], bounds=B(np.zeros(2), np.ones(2), name="v")),
        "Bounds 'v': has 2 entries but the tasks have 3 columns",
    ),
    ("empty", lambda: Stack([]), "empty stack: give at least one level with one task"),
    (
        "level not iterable",
        lambda: Stack([3]),
        "level 0: expected a task or a list of tasks, got int",
    ),
    (
        "levels not iterable",
        lambda: Stack(3),
        "levels must be a list of tasks or task lists, got 3",
    ),
    (
        "empty level",
        lambda: Stack([_eye(2), []]),
        "level 1 is empty: give it at least one task or remove it",
    ),
    (
        "within level columns",
        lambda: Stack([[_box(3, "a"), _eye(2, "b")]]),
        "level 0, Equality 'b': has 2 columns but level 0, Inequality 'a' has 3" + _COLS,
    ),
]


@pytest.mark.parametrize(
    "case, build, message", STRUCTURE_CASES, ids=[c[0] for c in STRUCTURE_CASES]
)
def test_rejected_structure_is_named_exactly(case, build, message):
    """Which error a stack with several problems reports first (the structure pass)."""
    with pytest.raises(ValueError) as info:
        build()
    assert str(info.value) == message


def test_a_stack_of_constraints_only_and_mixed_levels_compiles():
    s = Stack([], constraints=_eye(2))
    assert s.n == 2 and s.num_levels == 0
    s = Stack([[_box(3, "a"), _eye(3, "b")], _eye(3, "c")], constraints=[_box(3, "h")])
    assert [[t.name for t in lev] for lev in s.levels] == [["b", "a"], ["c"]]
    P = s._compiled
    assert (P.hard.m_eq, P.hard.m_in) == (0, 3)
    assert [(L.m_eq, L.m_in) for L in P.levels] == [(3, 3), (3, 0)]
    assert P.Aeq.shape == (6, 3) and P.C.shape == (6, 3)
    assert np.shares_memory(P.levels[0].C, P.C) and np.shares_memory(P.levels[1].Ae, P.Aeq)


def test_compiled_rows_name_each_task_once_at_its_first_row():
    """The bookkeeping the native engine's refresh reads (``set_tasks``): every task once,
    constraints first, then the levels in order, each with its row count and first row in
    the stacked arrays; the per-block views and the copies agree with it."""
    h1, h2 = _eye(3, "h1"), _box(3, "h2")
    a, b, c = _eye(3, "a"), _box(3, "b"), _box(3, "c")
    d = E(np.ones((2, 3)), 0.0, name="d")
    s = Stack([[a, b, c], d], constraints=[h1, h2])
    P = s._compiled
    eq_tasks, eq_rows, eq_first, in_tasks, in_rows, in_first = P._task_rows
    assert [t.name for t in eq_tasks] == ["h1", "a", "d"]
    assert (eq_rows, eq_first) == ([3, 3, 2], [0, 3, 6])
    assert [t.name for t in in_tasks] == ["h2", "b", "c"]
    assert (in_rows, in_first) == ([3, 3, 3], [0, 3, 6])
    assert [op[0] for op in P._eq_ops] == eq_tasks and [op[0] for op in P._in_ops] == in_tasks
    for op, first, rows in zip(P._in_ops, in_first, in_rows, strict=True):
        assert op[2].shape == (rows, 3) and np.shares_memory(op[2], P.C[first : first + rows])
    assert P.levels[0].C.shape == (6, 3) and P.levels[1].C.shape == (0, 3)
    assert not P.equalities_only
    assert Stack([a, d], bounds=B(-1.0, 1.0)).compiled.equalities_only
    assert not Stack([a], constraints=[h1]).compiled.equalities_only
    assert not Stack([a], constraints=[h2]).compiled.equalities_only
    assert not Stack([a, b]).compiled.equalities_only


# ---------------------------------------------------------------------------------------
# finiteness checks are exact and silent: large finite numbers are not "non-finite"


@pytest.mark.parametrize(
    "a, expected",
    [
        (np.full(3, 1e308), True),  # a sum would overflow to inf
        (np.array([np.inf, -np.inf]), False),  # a sum would be NaN
        (np.array([1.0, np.nan]), False),
        (np.zeros((0, 3)), True),
        (np.eye(3), True),
    ],
)
def test_all_finite_is_exact(a, expected):
    from qpcoord.core.linalg import all_finite

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert all_finite(a) is expected


def test_large_finite_targets_are_accepted_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        t = qc.Equality(np.eye(3), [1e308, -1e308, 1e308], name="big")
        t._assign(b=np.array([1e308, 1e308, -1e308]))  # the trusted per-step path too
        i = qc.Inequality(np.eye(2), [-1e308, -1e308], [1e308, 1e308])
        i.update(lower=[-1e308, 0.0], upper=[1e308, 1e308])
    assert t.b[0] == 1e308
