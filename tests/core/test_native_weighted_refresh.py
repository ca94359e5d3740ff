"""The native weighted QP refreshes its stacked arrays natively.

``NativeWeighted.solve`` (``Stack.solve(method="weighted")`` on the native engine) copied the
tasks' numbers with the Python :meth:`CompiledStack.refresh_stacked`; it now uses the native
copy of the strict hierarchy's ``step`` (``src/native/refresh.hpp``, bound by
``Weighted.set_tasks``) and goes to ``refresh_stacked`` only for data that copy does not take
(another dtype or byte order, a broadcast, unaligned data), which converts, broadcasts or
raises naming the task. Checked as ``test_native_wrapper`` checks the strict hierarchy's:
after every kind of change the stacked arrays are a fresh compile's and the solve equals a
fresh stack's Python weighted solve.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_native_weighted import _same
from test_native_wrapper import _assert_like_fresh, _build, _changes, _misaligned, _Sub, _tasks

import qpcoord as qc
from qpcoord.core import native

needs_native = pytest.mark.skipif(
    not native.available(),
    reason=f"the native engine (qpcoord._native) is not built: {native._load_error}",
)


def _solve(s: qc.Stack) -> qc.Solution:
    return s.solve(method="weighted", engine="native")


def _count_python_refresh(s: qc.Stack, monkeypatch) -> list:
    calls: list = []
    P = s._compiled
    real = P.refresh_stacked
    monkeypatch.setattr(P, "refresh_stacked", lambda: calls.append(1) or real())
    return calls


def _assign(t, name: str, value) -> None:
    """A matrix of another layout or dtype put in place as is (``update``, and so
    ``task.A = ...``, would convert it; ``object.__setattr__`` bypasses it, as library code
    may), with the version bump ``update`` makes: the weighted engine refactors on it."""
    object.__setattr__(t, name, value)
    object.__setattr__(t, "matrix_version", t.matrix_version + 1)


def _like_fresh_python(s, tasks, box, got: qc.Solution) -> None:
    _assert_like_fresh(s, tasks, box)
    fresh = _build(tasks, box)
    _same(fresh, fresh.solve(method="weighted", engine="python"), got)


@needs_native
@pytest.mark.parametrize("seed", [0, 1])
def test_the_weighted_solve_refreshes_natively_after_every_kind_of_change(seed, monkeypatch):
    """Every kind of change of test_native_wrapper (right-hand sides, new and in-place
    matrices, weights, limits, the hard rows, nothing), then strided, Fortran-ordered and
    subclassed arrays and a moved box: the Python refresh is never called."""
    rng, tasks, box = _tasks(seed)
    pos, wpos, lim, post, hard = tasks
    s = _build(tasks, box)
    _solve(s)
    assert s._native_weighted._solver.fast_arrays  # numpy arrays read from their heads
    calls = _count_python_refresh(s, monkeypatch)
    n = 7
    big = rng.standard_normal((6, 2 * n))

    more = [
        lambda: _assign(pos, "A", big[::2, ::2]),  # strided (a view of the caller's)
        lambda: _assign(wpos, "A", np.asfortranarray(rng.standard_normal((2, n)))),
        lambda: _assign(lim, "C", rng.standard_normal((3, n)).view(_Sub)),  # buffer protocol
        lambda: setattr(lim, "lower", big[0, :6:2] - 5.0),  # a strided vector
        lambda: box.update(lower=-0.5 * np.ones(n)),  # a new box version
    ]
    for change in _changes(rng, tasks) + more:
        change()
        _like_fresh_python(s, tasks, box, _solve(s))
    assert calls == []


@needs_native
@pytest.mark.parametrize(
    "change",
    [
        lambda t: setattr(t[0], "b", np.array([1, -2, 3])),  # int64: converted by numpy
        lambda t: _assign(t[0], "A", t[0].A.astype(">f8")),  # another byte order (same values)
        lambda t: setattr(t[2], "upper", np.array([0.4])),  # broadcast to the rows
        lambda t: _assign(t[2], "C", t[2].C.astype(np.float32)),  # rounded: a new matrix
        lambda t: setattr(t[0], "b", _misaligned([0.5, -1.0, 2.0])),
    ],
)
def test_data_the_native_copy_does_not_take_goes_to_the_python_refresh(change, monkeypatch):
    """The same answer through ``refresh_stacked``; with the tasks' own arrays back, the
    native copy takes them again."""
    rng, tasks, box = _tasks(6)
    s = _build(tasks, box)
    _solve(s)
    calls = _count_python_refresh(s, monkeypatch)
    saved = [dict(vars(t)) for t in tasks]
    change(tasks)
    _like_fresh_python(s, tasks, box, _solve(s))
    assert calls == [1]
    for t, attrs in zip(tasks, saved, strict=True):
        vars(t).update(attrs)
    _like_fresh_python(s, tasks, box, _solve(s))
    assert calls == [1]


@needs_native
def test_a_shape_change_and_a_nan_behind_a_view_are_caught_by_the_weighted_solve():
    t = qc.Equality(np.eye(4)[:2], [1.0, 2.0], name="reach")
    s = qc.Stack([t, qc.Equality(np.eye(4), np.zeros(4))], bounds=qc.Bounds(-5.0, 5.0))
    _solve(s)
    A = np.array(t.A)
    object.__setattr__(t, "A", A)  # as is (task.A = A would copy it)
    A.shape = (4, 2)  # the same object, another shape
    with pytest.raises(ValueError, match=r"Equality 'reach': A changed shape from \(2, 4\)"):
        _solve(s)
    object.__setattr__(t, "A", np.eye(4)[:2].copy())
    _solve(s)
    t.b.base[1] = np.nan
    with pytest.raises(ValueError, match="reach"):
        _solve(s)


@needs_native
def test_a_stack_in_a_cycle_through_its_native_weighted_solver_is_collected():
    """The weighted solver now holds the stack's tasks too: its ``tp_traverse``."""
    import gc
    import weakref

    t = qc.Equality(np.eye(3), [1.0, 2.0, 3.0], name="reach")
    s = qc.Stack([t], bounds=qc.Bounds(-5.0, 5.0))
    _solve(s)
    assert s._native_weighted is not None
    t.owner = s  # the cycle: stack -> solver -> task -> stack
    alive = weakref.ref(s)
    del s, t
    gc.collect()
    assert alive() is None
