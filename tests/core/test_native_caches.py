"""The native engine's caches of a re-solve whose matrices did not change.

The freeze cache: a level's freeze -- the change of the null-space basis Z, of the
free dimension r and of the carried projection of the inherited rows -- is a function of Z
and of that projection on entry, of the level's rows and of the freeze's kind, rank and
violated rows; none of them depends on the targets or on the bounds' values. A re-solve whose
matrices did not change (targets, bounds moved: the benchmarks' re-solves, an LTI
coordinator) restores the stored outputs of the level's last freeze instead of applying its
reflectors to Z again.

The trial cache: a stage's warm trial factorises its stored working set's rows
(pivoted QR of G_w^T), the objective's null-space columns (Q Qf) and K = Q N; each stage
keeps its own factorisations, and a trial whose working rows and objective are bit for bit
the last trial's of the stage, nothing having updated them since (it hit), uses them as
they are.

The closed-form cache: a level whose rows and Z on entry are bit for bit its last
call's keeps M = A Z (each stage holds its own) and the factorisations of its closed form
(the pivoted QR of M and the RZ of its [R11 R12], or M's SVD; each stage keeps its own):
only the solves with the new targets run.

The bound-rows cache: a stage whose Z on entry is bit for bit its last
call's copies its bound rows (Z's rows scaled to unit norm) as one block from that call's;
only their bounds, which move with x and the box, are computed.

The tests compare a solver using its caches against a twin that makes the same calls with
every cache dropped before each (``Hierarchy.invalidate_caches``: it computes every
factorisation and freeze, from the same stored working sets), bit for bit (x's and the level
values' bits, the info dicts), along sequences in which each level's matrix stays, changes, or
comes back to an earlier value (a cache keyed on too little would restore a stale
factorisation there), and check that the caches are used where the matrices repeat and not
where they change.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from support.native_engine import native_solver, needs_native
from support.published import benchmark_module, published_stack

import qpcoord as qc


def _bits(v: np.ndarray) -> np.ndarray:
    """The float64 entries' bits (0.0 and -0.0 differ)."""
    return np.ascontiguousarray(v, dtype=np.float64).view(np.uint64)


#: The caches' hit counters (``Stats``): freezes, trials, closed forms, bound rows.
HITS = ("freeze_memo_hits", "trial_memo_hits", "closed_form_memo_hits", "bound_rows_memo_hits")


def _memo_pair(stack: qc.Stack):
    """``(P, new, plain)``: two native solvers of ``stack``; ``_same_step`` drops ``plain``'s
    caches before each of its calls."""
    P, new = native_solver(stack)
    _, plain = native_solver(stack)
    return P, new, plain


def _hits(h) -> tuple[int, int, int, int]:
    stats = h.counters
    return tuple(getattr(stats, k) for k in HITS)


def _same_step(P, new, plain, warm: bool = True) -> tuple[int, int, int, int]:
    """One solve by each (``plain`` with its caches dropped first: everything computed): x,
    level values and info bit for bit the same; returns ``new``'s hits (:data:`HITS`)."""
    xn, rn, infon = new.solve(P, warm=warm)
    plain._solver.invalidate_caches()
    xp, rp, infop = plain.solve(P, warm=warm)
    np.testing.assert_array_equal(_bits(xn), _bits(xp))
    np.testing.assert_array_equal(_bits(rn), _bits(rp))
    hits = _hits(new)
    assert _hits(plain) == (0, 0, 0, 0)
    assert {**infon, "stats": None} == {**infop, "stats": None}  # (stats: the cache hits)
    return hits


def _random_stack(seed: int):
    """A stack of n = 6..12 variables, 3..5 levels mixing equality levels (some rank-
    deficient, some wide) and inequality levels that bind, a box half of the time; returns
    (stack, tasks, matrices): each task's original matrix, and a second one to switch to."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(6, 13))
    tasks, mats = [], []
    for _ in range(int(rng.integers(3, 6))):
        m = int(rng.integers(1, n))
        rank = int(rng.integers(1, m + 1))
        A = rng.standard_normal((m, rank)) @ rng.standard_normal((rank, n))
        A2 = A + 0.1 * rng.standard_normal((m, n))
        if rng.random() < 0.5:
            tasks.append(qc.Equality(A, rng.standard_normal(m)))
        else:
            tasks.append(qc.Inequality(A, upper=-rng.random(m)))
        mats.append((A, A2))
    box = rng.random() < 0.5
    bounds = qc.Bounds(-np.ones(n), np.ones(n)) if box else None
    return qc.Stack(tasks, bounds=bounds), tasks, mats, rng


def _move(task, rng, A=None) -> None:
    """New targets (and matrix ``A`` if given) for an Equality or an Inequality."""
    if isinstance(task, qc.Equality):
        task.update(A=A, b=task.b + 0.3 * rng.standard_normal(task.b.shape[0]))
    else:
        m = task.C.shape[0]
        task.update(C=A, upper=-rng.random(m))


@needs_native
@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_memos_equal_the_factorisations_computed_along_changing_matrices(seed):
    """Each step moves every target and, per level, keeps the matrix, switches to the other
    one or back (then the stored freeze of the first matrices may be restored: correct only
    if the cache's key holds every input): the solver with its caches equals the one that
    computes everything, bit for bit, each step, warm or cold."""
    stack, tasks, mats, rng = _random_stack(seed)
    P, new, plain = _memo_pair(stack)
    current = [0] * len(tasks)
    for _step in range(10):
        for i, task in enumerate(tasks):
            if rng.random() < 0.3:
                current[i] = 1 - current[i]
                _move(task, rng, mats[i][current[i]])
            else:
                _move(task, rng)
        _same_step(P, new, plain, warm=bool(rng.random() < 0.8))


@needs_native
def test_memo_restores_every_freeze_of_a_re_solve_and_none_of_a_changed_stack():
    """A 30-variable chain of 3 / 3 / 6 / 6 equality rows under a binding box (the
    benchmarks' chain30): once the memo is warm (two solves per level), every freeze of a
    re-solve with moved targets is restored, bit for bit what the freezes give; a step whose
    first level's matrix changed restores none (Z differs below it)."""
    rng = np.random.default_rng(3)
    n = 30
    rows = []
    for m, upto in ((3, n), (3, 20), (6, 15), (6, n)):
        J = np.zeros((m, n))
        J[:, :upto] = rng.standard_normal((m, upto))
        rows.append(J / np.linalg.norm(J, axis=1, keepdims=True))
    tasks = [qc.Equality(J, rng.uniform(-0.5, 0.5, J.shape[0])) for J in rows]
    stack = qc.Stack(tasks, bounds=qc.Bounds(-0.5 * np.ones(n), 0.5 * np.ones(n)))
    P, new, plain = _memo_pair(stack)
    base = [t.b.copy() for t in tasks]
    hits = []
    for step in range(12):
        for t, b0 in zip(tasks, base, strict=True):
            t.update(b=b0 + 0.2 * np.sin(0.05 * step + np.arange(b0.shape[0])))
        hits.append(_same_step(P, new, plain))
    assert plain.counters.wide_freezes > 0  # the binding levels' freezes
    freezes = [h[0] for h in hits]
    assert freezes[-1] > 0 and freezes[-1] == freezes[-2]  # every freeze of the re-solve
    assert sum(h[1] for h in hits[4:]) > 0  # warm trials reused
    assert hits[-1][2] == 4  # every level's closed form
    assert hits[-1][3] > 0  # the bound rows of the stages that ran an active set
    tasks[0].update(A=rows[0] + 1e-3 * rng.standard_normal(rows[0].shape))
    assert _same_step(P, new, plain) == (0, 0, 0, 0)


@needs_native
@pytest.mark.parametrize("unit", [False, True], ids=["rows", "unit rows"])
def test_memo_on_the_moving_published_humanoid(unit):
    """The LexLS humanoid moved as hierarchy_published's re-solve table (targets only): bit
    for bit the freezes' results, and restored freezes from the third step on."""
    st_, move = published_stack("lexls_test01_humanoid", False, unit)
    P, new, plain = _memo_pair(st_)
    hits = []
    for step in range(5):
        move(step)
        hits.append(_same_step(P, new, plain))
    assert hits[-1][0] > 0 and hits[-1][2] > 0


@needs_native
def test_soth_re_solve_reuses_every_trial():
    """The published soth problem re-solved with moved targets (hierarchy_bench's soth_sot:
    30 joint-limit rows, then 3 / 3 / 6 / 6 equality rows): every stage's stored working set
    hits, and once warm every trial's factorisations are reused and every freeze restored,
    bit for bit what computing them gives."""
    bench = benchmark_module("hierarchy_bench")
    scen = bench._scenario(bench.soth_sot, np.random.default_rng(0))
    P, new, plain = _memo_pair(scen["stack"])
    hits = []
    for step in range(14):  # the freezes' memo is warm after two calls per level
        scen["move"](step)
        hits.append(_same_step(P, new, plain))
    levels = new._solver.num_levels
    # every freeze, every stage's trial (levels, minimum norm), the equality levels' closed
    # forms (level 0 has no equality row)
    # (no box: no bound rows)
    assert hits[-1] == (levels, levels + 1, levels - 1, 0)


@needs_native
def test_counters_are_exposed_and_per_call():
    """The hit counters are 0 before any solve, count a re-solve's hits, and are a copy (a
    later call does not change an earlier call's)."""
    stack = qc.Stack([qc.Equality(np.eye(3)[:2], np.ones(2)), qc.Equality(np.eye(3), np.zeros(3))])
    P, h = native_solver(stack)
    assert _hits(h) == (0, 0, 0, 0)
    first = []
    for _ in range(4):
        h.solve(P)
        first.append(h.counters)
    assert h.counters.closed_form_memo_hits == _hits(h)[2] > 0
    assert first[0].closed_form_memo_hits == 0


@needs_native
def test_bound_rows_memo_follows_the_box_and_its_open_sides():
    """chain30's stack (hierarchy_bench) with the box moved every step, a variable's bounds
    both open on some steps (its row is skipped: the rows are no block, nothing is copied)
    and one side open on others: bit for bit the rows projected and scaled at each call, the
    rows copied wherever Z repeats and every variable has a finite side."""
    bench = benchmark_module("hierarchy_bench")
    scen = bench._scenario(bench.chain30, np.random.default_rng(0))
    stack, bounds = scen["stack"], scen["daqp"][1]
    P, new, plain = _memo_pair(stack)
    n = 30
    copied = []
    for step in range(16):
        scen["move"](step)
        lo = -0.5 - 0.05 * np.sin(0.3 * step + np.arange(n))
        hi = 0.5 + 0.05 * np.cos(0.2 * step + np.arange(n))
        if step % 4 == 1:
            lo[7], hi[7] = -np.inf, np.inf  # both sides open: no row for x_7
        elif step % 4 == 3:
            hi[3] = np.inf  # one side open: the row stays
        bounds.update(lower=lo, upper=hi)
        hits = _same_step(P, new, plain)
        copied.append(hits[3])
        if step % 4 == 1:
            assert hits[3] == 0
    assert sum(copied[2:]) > 0
