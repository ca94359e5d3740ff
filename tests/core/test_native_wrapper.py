"""The Python around the native calls (``Stack.solve``, strict hierarchy and weighted QP):
the tasks' numbers reach the solver, and the ``Solution``, its ``info`` and the errors are the
Python engine's.

- The refresh copies every task's numbers each call (a value written into a task's array
  behind its back, ``test_hygiene``'s NaN, must reach the native check): after every kind of
  change the stacked arrays equal those of a stack compiled afresh, and the native solve
  (strict hierarchy and weighted QP) equals a fresh Python solve; the arrays stay the same
  objects from call to call.
- The refresh, the solve, the copies and the info dict are one native call
  (``Hierarchy.step``, ``src/native/refresh.hpp``); a task whose data is not float64 of its
  shape (another dtype, byte order, a broadcast, unaligned data) takes the Python refresh
  (``CompiledStack.refresh_stacked``), with the same stacked arrays and solution; strided
  arrays and ndarray subclasses are copied natively.
- ``NativeHierarchy._info``: every call's dict equals the one recomputed from ``stats`` /
  ``detail`` by the rules of the Python engine, and its lists are new objects each call.
- Bad numbers found at solve time (a NaN, a wrong-sided infinity, a bad warm start) are
  named as the Python engine names them; a stack in a cycle through its native solver is
  collected.
"""

from __future__ import annotations

import numpy as np
import pytest
from support.arrays import force_write as _force_write
from support.native_engine import needs_native
from support.native_info import info_reference
from support.stacks import clipped_stack, hard_random_stack
from support.weighted import assert_same_weighted

import qpcoord as qc
from qpcoord.core.polish import KKT_TOL

#: An array put in a task as it is: ``object.__setattr__`` bypasses the rebinding rule
#: (``task.A = J`` is ``update(A=J)``, which validates and copies to float64 C order), as
#: library code may; the native copy must still read (or hand over) what it finds there
_as_is = object.__setattr__


STACKED = ("Aeq", "beq", "C", "clo", "chi", "csw", "lbs", "ubs")


def _tasks(seed: int, n: int = 7):
    rng = np.random.default_rng(seed)
    pos = qc.Equality(rng.standard_normal((3, n)), rng.standard_normal(3), name="pos")
    wpos = qc.Equality(
        rng.standard_normal((2, n)), rng.standard_normal(2), weight=[2.0, 0.5], name="wpos"
    )
    lim = qc.Inequality(rng.standard_normal((3, n)), -0.3, 0.4, name="lim")
    post = qc.Equality(np.eye(n), rng.standard_normal(n), name="posture")
    hard = qc.Inequality(rng.standard_normal((1, n)), -2.0, 2.0, name="hard")
    box = qc.Bounds(-np.ones(n), np.ones(n))
    return rng, (pos, wpos, lim, post, hard), box


def _build(tasks, box) -> qc.Stack:
    pos, wpos, lim, post, hard = tasks
    return qc.Stack([[pos, wpos], lim, post], bounds=box, constraints=[hard])


def _changes(rng, tasks, n: int = 7):
    """Every way a task's matrix, weights or right-hand side changes, one per step."""
    pos, wpos, lim, post, hard = tasks
    return [
        lambda: pos.update(b=rng.standard_normal(3)),  # right-hand side only
        lambda: pos.update(A=rng.standard_normal((3, n))),  # a new A (new array, version)
        lambda: wpos.update(weight=[0.3, 4.0]),  # weights only: √w·A changes
        lambda: wpos._assign(A=rng.standard_normal((2, n))),  # in place, version counted
        lambda: lim.update(C=rng.standard_normal((3, n))),
        lambda: lim.update(weight=[1.0, 3.0, 0.2]),  # the violation weights sw
        lambda: lim._assign(-0.2, 0.1, C=rng.standard_normal((3, n))),  # in place
        lambda: lim._assign(-0.5, 0.5),  # limits only
        lambda: post.update(b=rng.standard_normal(n), weight=np.linspace(0.5, 2.0, n)),
        lambda: hard.update(C=rng.standard_normal((1, n)), lower=-1.5),
        lambda: None,  # nothing changed: nothing copied, the same numbers
    ]


@needs_native
@pytest.mark.parametrize("seed", [0, 1])
def test_stacked_arrays_follow_every_kind_of_change(seed):
    """After each change the stacked arrays are a fresh compile's, and the warm native solve
    equals a fresh stack's Python solve (level values 1e-9 relative, x)."""
    rng, tasks, box = _tasks(seed)
    s = _build(tasks, box)
    s.solve(engine="native")
    for change in _changes(rng, tasks) * 2:
        change()
        got = s.solve(engine="native")
        P = s._compiled
        fresh = _build(tasks, box)._compiled
        fresh.refresh_stacked()
        for name in STACKED:
            np.testing.assert_array_equal(getattr(P, name), getattr(fresh, name), err_msg=name)
        ref = _build(tasks, box).solve(engine="python")
        rp, rn = ref.level_residuals, got.level_residuals
        assert np.all(np.abs(rn - rp) <= 1e-9 * np.maximum(1.0, rp)), (rp, rn)
        np.testing.assert_allclose(got.x, ref.x, atol=1e-7)


@needs_native
def test_engines_alternating_keep_the_stacked_arrays_current():
    """A Python solve (which refreshes the levels' own views) between native solves, with
    matrix changes in between: the native solve still sees every number."""
    rng, tasks, box = _tasks(3)
    s = _build(tasks, box)
    for k, change in enumerate(_changes(rng, tasks)):
        change()
        got = s.solve(engine=("python", "native")[k % 2])
        ref = _build(tasks, box).solve(engine="python")
        np.testing.assert_allclose(got.level_residuals, ref.level_residuals, rtol=1e-9, atol=1e-12)


@needs_native
def test_a_matrix_replaced_behind_the_stacks_back_is_still_read():
    """A matrix put in place bypassing ``update`` (no new ``matrix_version``) is still read
    (same shape) or named (another shape); ``task.A = ...`` itself is an update (checked
    at once)."""
    t = qc.Equality(np.eye(3), [1.0, 2.0, 3.0], name="reach")
    s = qc.Stack([t], bounds=qc.Bounds(-5.0, 5.0))
    np.testing.assert_allclose(s.solve(engine="native").x, [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match=r"Equality 'reach': update changes A's shape"):
        t.A = np.ones((2, 3))
    _as_is(t, "A", 2.0 * np.eye(3))  # same shape, same matrix_version
    np.testing.assert_allclose(s.solve(engine="native").x, [0.5, 1.0, 1.5])
    _as_is(t, "A", np.ones((2, 3)))
    with pytest.raises(ValueError, match=r"Equality 'reach': A changed shape from \(3, 3\)"):
        s.solve(engine="native")


@needs_native
def test_info_equals_its_definition_on_moving_and_unchanged_steps():
    """Moving targets (stages that change what they do) and unchanged re-solves: each info
    is the one recomputed from the arrays, in new lists."""
    rng = np.random.default_rng(7)
    n = 12
    A = rng.standard_normal((4, n))
    pos = qc.Equality(A, rng.standard_normal(4))
    lim = qc.Inequality(rng.standard_normal((5, n)), -0.2, 0.2)
    post = qc.Equality(np.eye(n), np.zeros(n))
    s = qc.Stack([pos, lim, post], bounds=qc.Bounds(-0.3 * np.ones(n), 0.3 * np.ones(n)))
    seen = []
    for step in range(24):
        if step % 4 < 2:  # then twice the same stack (the second: the kept counts)
            pos.update(b=2.0 * np.sin(0.7 * step + np.arange(4)))
        sol = s.solve(engine="native")  # its info built by the native step (Hierarchy.info)
        nh = s._native
        assert sol.info == info_reference(nh.stats, nh.detail, 3, nh.counters)
        for old in seen:
            assert sol.info["active_set_iterations"] is not old["active_set_iterations"]
            assert sol.info["closed_form_levels"] is not old["closed_form_levels"]
            assert sol.info["stats"] is not old["stats"]  # each call's own counters
        sol.info["active_set_iterations"].append(-1)  # a caller's edit stays its own
        sol.info["closed_form_levels"].append(-1)
        seen.append(sol.info)
    assert len({tuple(i["active_set_iterations"][:-1]) for i in seen}) > 1  # and it moved


@needs_native
def test_the_solution_fields():
    """Stack.solve's Solution (built positionally): types and values of every field."""
    s = qc.Stack([qc.Equality(np.eye(3), [0.1, 2.0, 0.3])], bounds=qc.Bounds(-1.0, 1.0))
    sol = s.solve(engine="native")
    assert isinstance(sol, qc.Solution)
    np.testing.assert_allclose(sol.x, [0.1, 1.0, 0.3], atol=1e-12)
    assert sol.status == "optimal" and sol.solver == "native" and sol.method == "hierarchical"
    np.testing.assert_allclose(sol.level_residuals, [1.0], rtol=1e-12)
    assert type(sol.solve_time) is float and np.isfinite(sol.solve_time)  # s; not timed here
    assert sol.info["engine"] == "native" and sol.info["uncertified"] == []
    # the returned arrays are the caller's: the next solve does not write into them
    x = sol.x.copy()
    s.solve(engine="native")
    sol.x[0] = 7.0
    assert s.solve(engine="native").x[0] == pytest.approx(x[0])


class _Sub(np.ndarray):
    """An ndarray subclass (read through the buffer protocol by the native refresh)."""


def _misaligned(values) -> np.ndarray:
    """A float64 array whose data is not 8-byte aligned (a view into a byte buffer)."""
    raw = np.frombuffer(bytearray(8 * len(values) + 1), dtype=np.uint8)[1:]
    out = raw.view(np.float64)
    out[:] = values
    assert not out.flags.aligned
    return out


def _assert_like_fresh(s: qc.Stack, tasks, box) -> None:
    """The stacked arrays of ``s`` after its last native solve are a fresh compile's (Python
    refresh), and the solve equals a fresh stack's Python solve."""
    P = s._compiled
    fresh = _build(tasks, box)._compiled
    fresh.refresh_stacked()
    for name in STACKED:
        np.testing.assert_array_equal(getattr(P, name), getattr(fresh, name), err_msg=name)


@needs_native
def test_one_native_step_refreshes_without_the_python_refresh(monkeypatch):
    """Plain tasks (float64 arrays of their shapes, also strided, transposed or an ndarray
    subclass; weighted rows; a moved box) are refreshed by the native step alone: the
    Python refresh is never called, and the stacked arrays are a fresh compile's."""
    rng, tasks, box = _tasks(5)
    pos, wpos, lim, post, hard = tasks
    s = _build(tasks, box)
    s.solve(engine="native")
    assert s._native._solver.fast_arrays  # numpy arrays read from their heads
    calls = []
    P = s._compiled
    real = P.refresh_stacked
    monkeypatch.setattr(P, "refresh_stacked", lambda: calls.append(1) or real())
    n = 7
    big = rng.standard_normal((6, 2 * n))
    steps = [
        lambda: pos.update(b=rng.standard_normal(3)),
        lambda: _as_is(pos, "A", big[::2, ::2]),  # strided (a view of the caller's)
        lambda: _as_is(wpos, "A", np.asfortranarray(rng.standard_normal((2, n)))),
        lambda: _as_is(lim, "C", rng.standard_normal((3, n)).view(_Sub)),  # buffer protocol
        lambda: setattr(lim, "lower", big[0, :6:2] - 5.0),  # a strided vector
        lambda: wpos.update(weight=[3.0, 0.25]),
        lambda: box.update(lower=-0.5 * np.ones(n)),  # a new box version
        lambda: None,
    ]
    for change in steps * 2:
        change()
        got = s.solve(engine="native")
        _assert_like_fresh(s, tasks, box)
        ref = _build(tasks, box).solve(engine="python")
        rp, rn = ref.level_residuals, got.level_residuals
        assert np.all(np.abs(rn - rp) <= 1e-9 * np.maximum(1.0, rp)), (rp, rn)
    assert calls == []


@needs_native
@pytest.mark.parametrize(
    "change",
    [
        lambda t: setattr(t[0], "b", np.array([1, -2, 3])),  # int64: converted by numpy
        lambda t: _as_is(t[0], "A", t[0].A.astype(">f8")),  # another byte order
        lambda t: setattr(t[2], "upper", np.array([0.4])),  # broadcast to the rows
        lambda t: _as_is(t[2], "C", t[2].C.astype(np.float32)),
        lambda t: setattr(t[1], "sqrt_weight", np.array([1.5, 0.5], dtype=">f8")),
        lambda t: setattr(t[0], "b", _misaligned([0.5, -1.0, 2.0])),
    ],
)
def test_data_the_native_step_does_not_copy_take_the_python_refresh(change, monkeypatch):
    """Another dtype, byte order, a broadcast or unaligned data: the native step hands the
    refresh to ``refresh_stacked`` (which converts or broadcasts as numpy does), with the
    same stacked arrays and solution; with the tasks' own arrays back, the native step
    copies them again."""
    rng, tasks, box = _tasks(6)
    s = _build(tasks, box)
    s.solve(engine="native")
    calls = []
    P = s._compiled
    real = P.refresh_stacked
    monkeypatch.setattr(P, "refresh_stacked", lambda: calls.append(1) or real())
    saved = [dict(vars(t)) for t in tasks]
    change(tasks)
    got = s.solve(engine="native")
    assert calls == [1]
    _assert_like_fresh(s, tasks, box)
    ref = _build(tasks, box).solve(engine="python")
    np.testing.assert_allclose(got.level_residuals, ref.level_residuals, rtol=1e-9, atol=1e-12)
    for t, attrs in zip(tasks, saved, strict=True):
        vars(t).update(attrs)
    s.solve(engine="native")
    assert calls == [1]
    _assert_like_fresh(s, tasks, box)


@needs_native
def test_a_shape_change_in_place_and_a_nan_behind_a_view_are_still_caught():
    """A task's array reshaped in place (same memory, another shape) is named as before;
    a NaN written into a task array's base reaches the native check (``test_hygiene``)."""
    t = qc.Equality(np.eye(4)[:2], [1.0, 2.0], name="reach")
    s = qc.Stack([t], bounds=qc.Bounds(-5.0, 5.0))
    s.solve(engine="native")
    A = np.array(t.A)
    _as_is(t, "A", A)
    A.shape = (4, 2)  # the same object, another shape
    with pytest.raises(ValueError, match=r"Equality 'reach': A changed shape from \(2, 4\)"):
        s.solve(engine="native")
    _as_is(t, "A", np.eye(4)[:2].copy())
    s.solve(engine="native")
    t.b.base[1] = np.nan
    with pytest.raises(ValueError, match="reach"):
        s.solve(engine="native")


@needs_native
def test_the_native_info_equals_the_python_info_when_uncertified():
    """The ``uncertified`` entry (a level value moved after its freeze): the native dict's
    tuple and the Python one agree, for the detail the native call wrote."""
    s = qc.Stack([qc.Equality(np.eye(3), [0.1, 2.0, 0.3])], bounds=qc.Bounds(-1.0, 1.0))
    s.solve(engine="native")
    nh = s._native
    nh.detail[5] = 10 * KKT_TOL  # as a call would write it: level 0 moved by 10 x KKT_TOL
    nh.detail[6] = 0
    info = nh._solver.info(KKT_TOL)
    assert info == info_reference(nh.stats, nh.detail, 1, nh.counters)
    assert info["uncertified"] == [(0, 10 * KKT_TOL)]


@needs_native
def test_a_stack_in_a_cycle_through_its_native_solver_is_collected():
    """The native solver holds the stack's tasks: a task referring back to the stack makes a
    cycle through it, which the garbage collector must see through (``tp_traverse``)."""
    import gc
    import weakref

    t = qc.Equality(np.eye(3), [1.0, 2.0, 3.0], name="reach")
    s = qc.Stack([t], bounds=qc.Bounds(-5.0, 5.0))
    s.solve(engine="native")
    t.owner = s  # the cycle: stack -> solver -> task -> stack
    alive = weakref.ref(s)
    del s, t
    gc.collect()
    assert alive() is None


@needs_native
def test_the_info_stats_pickle_and_name_the_counters_taken():
    """``info["stats"]`` (the call's counters) survives pickling equal and its repr names the
    non-zero counters: an unchanged re-solve takes the caches."""
    import pickle

    s = qc.Stack([qc.Equality(np.eye(3), [0.1, 2.0, 0.3])], bounds=qc.Bounds(-1.0, 1.0))
    for _ in range(2):  # (the caches are allocated at the second call, used from the third)
        s.solve(engine="native")
    stats = s.solve(engine="native").info["stats"]
    assert pickle.loads(pickle.dumps(stats)) == stats
    assert stats.trial_memo_hits > 0 and "trial_memo_hits=" in repr(stats)
    assert "downdates" not in repr(stats) and stats.downdates == 0


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
    assert_same_weighted(fresh, fresh.solve(method="weighted", engine="python"), got)


@needs_native
@pytest.mark.parametrize("seed", [0, 1])
def test_the_weighted_solve_refreshes_natively_after_every_kind_of_change(seed, monkeypatch):
    """Every kind of change above (right-hand sides, new and in-place
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
    """The weighted solver holds the stack's tasks too: its ``tp_traverse`` lets the garbage
    collector see through a cycle."""
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


@needs_native
@pytest.mark.parametrize("engine", ["python", "native"])
def test_nan_in_a_task_names_it(engine):
    t = qc.Inequality(np.eye(2), lower=[0.0, 0.0], name="fence")
    s = qc.Stack([t, qc.Equality(np.eye(2), [1.0, 1.0])], bounds=qc.Bounds(-2.0, 2.0))
    s.solve(engine=engine)
    _force_write(t.C, (0, 0), np.nan)  # reached the array without update()
    with pytest.raises(ValueError, match=r"Inequality 'fence': C contains nan.*found at solve"):
        s.solve(engine=engine)


@needs_native
def test_bad_warm_start_is_rejected():
    with pytest.raises(ValueError, match="warm_start"):
        clipped_stack().solve(engine="native", warm_start=[1.0])


@needs_native
@pytest.mark.parametrize("engine", ["python", "native"])
def test_wrong_sided_infinity_in_the_bounds_is_named(engine):
    s = qc.Stack([qc.Equality(np.eye(2), [1.0, 1.0])], bounds=qc.Bounds(-2.0, 2.0))
    s.solve(engine=engine)
    _force_write(s._compiled.lb, (0,), np.inf)  # reached the array without a setter
    with pytest.raises(ValueError, match="found at solve time"):
        s.solve(engine=engine)


@needs_native
def test_repeated_calls_reuse_the_buffers():
    """The per-step path writes the tasks' numbers straight into the compiled stack's stacked
    arrays, which the native solver is bound to: the same objects every step, and every
    level's buffers are views of them (no copy between refresh and the native call)."""
    s = hard_random_stack(2)
    s.solve(engine="native")
    nh, P = s._native, s._compiled
    arrays = (P.Aeq, P.beq, P.C, P.clo, P.chi, P.csw, nh.x, nh.res, nh.stats, nh.detail)
    ids = [id(a) for a in arrays]
    for _ in range(5):
        s.solve(engine="native")
    assert s._native is nh
    assert [id(a) for a in arrays] == ids
    for L in P.levels:
        assert np.shares_memory(L.C, P.C) and np.shares_memory(L.lo, P.clo)


@needs_native
def test_engines_alternate_on_one_stack():
    """A Python solve lets a level read its task's arrays in place; the next native solve
    must still see every number (the stacked arrays are rewritten, the views restored),
    with weighted rows and a bounds update in between."""
    rng = np.random.default_rng(5)
    A = rng.standard_normal((3, 6))
    pos = qc.Equality(A, rng.standard_normal(3))
    post = qc.Equality(np.eye(6), rng.standard_normal(6), weight=np.linspace(0.5, 2.0, 6))
    lim = qc.Inequality(rng.standard_normal((2, 6)), -0.2, 0.3)
    box = qc.Bounds(-0.8 * np.ones(6), 0.8 * np.ones(6))
    s = qc.Stack([pos, [post, lim]], bounds=box)
    for step in range(6):
        pos.update(b=np.sin(0.3 * step + np.arange(3)))
        if step == 3:
            box.update(lower=-0.5 * np.ones(6))
        engine = ("python", "native")[step % 2]
        got = s.solve(engine=engine)
        fresh = qc.Stack([pos, [post, lim]], bounds=box).solve(engine="python")
        np.testing.assert_allclose(
            got.level_residuals, fresh.level_residuals, rtol=1e-9, atol=1e-12
        )
        assert (got.x >= -0.8 - 1e-12).all() and (got.x <= 0.8 + 1e-12).all()
        if step >= 3:
            assert (got.x >= -0.5 - 1e-12).all()
