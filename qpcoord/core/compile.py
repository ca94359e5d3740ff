"""Compiled form of a stack: per-level stacked arrays, refreshed in place every solve.

:class:`~qpcoord.Stack` validates the structure once (number of variables, rows per task)
and keeps one :class:`CompiledStack`. Each solve copies the tasks' current numbers into
the preallocated buffers (no re-stacking, no re-validation of the structure), which is the
"structure cache" of the per-step hot path.

The buffers of all blocks (hard constraints first, then the levels) are views of one
contiguous array per kind (``CompiledStack.Aeq``, ``beq``, ``C``, ``lo``, ``hi``, ``sw``,
``lb``, ``ub``), laid out as the native engine reads them: :meth:`CompiledStack.refresh_stacked`
writes the tasks' numbers straight into them (one loop over tasks), and the native call
reads them without a copy.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import InitVar, dataclass, field

import numpy as np

from .elimination import FEAS_TOL
from .linalg import all_finite
from .tasks import Bounds, Equality, Inequality, _bad_box, _full, find_bad_value
from .tolerance import widen

__all__ = ["CompiledLevel", "CompiledStack", "compile_stack"]


@dataclass
class CompiledLevel:
    """Stacked rows of one priority level (or of the hard constraints).

    ``Ae x ≈ be`` are the equality rows already multiplied by ``√weight``; ``lo ≤ C x ≤ hi``
    are the inequality rows with ``sw`` = ``√weight`` of each row's violation.
    """

    eqs: list[Equality]
    ineqs: list[Inequality]
    n: int
    Ae: np.ndarray = field(init=False)
    be: np.ndarray = field(init=False)
    C: np.ndarray = field(init=False)
    lo: np.ndarray = field(init=False)
    hi: np.ndarray = field(init=False)
    sw: np.ndarray = field(init=False)

    #: allocate the level's own buffers (``False``: :class:`CompiledStack` gives it views of
    #: its stacked arrays right after, see :meth:`_use`)
    buffers: InitVar[bool] = True

    def __post_init__(self, buffers: bool) -> None:
        eqs, ineqs = self.eqs, self.ineqs
        # one task per kind is the common level: no list of row counts to sum
        if len(eqs) == 1:
            shape = eqs[0].A.shape
            self._eq_shapes = [shape]
            #: number of equality rows
            self.m_eq = shape[0]
        else:
            self._eq_shapes = [t.A.shape for t in eqs]
            self.m_eq = sum([s[0] for s in self._eq_shapes])
        if ineqs:
            self._in_shapes = [t.C.shape for t in ineqs]
            #: number of inequality rows
            self.m_in = sum([s[0] for s in self._in_shapes])
        else:
            self._in_shapes = []
            self.m_in = 0
        #: the level is exactly ``x = be`` (one unit-weight identity task, no inequalities)
        self.identity = False
        if buffers:
            me, mi, n = self.m_eq, self.m_in, self.n
            self._use(
                np.zeros((me, n)), np.zeros(me),
                np.zeros((mi, n)), np.zeros(mi), np.zeros(mi), np.ones(mi),
            )  # fmt: skip

    def _use(self, Ae, be, C, lo, hi, sw) -> None:
        """Make the given arrays the level's buffers (``lo``/``hi`` widened by ``FEAS_TOL``
        for the closed-form feasibility test are ``low``/``hiw``, the same until a refresh)."""
        self.Ae = self._Ae_buf = Ae
        self.be = self._be_buf = be
        self.C = C
        self.low = self.lo = lo
        self.hiw = self.hi = hi
        self.sw = sw

    def refresh(self) -> None:
        """Copy the tasks' current numbers into the buffers (checks shapes did not change).

        A level made of one unit-weight equality reads that task's arrays directly; they
        are only read, never written, by the solve methods.
        """
        eqs: Sequence[Equality] = self.eqs
        if len(eqs) == 1 and eqs[0].unit_weight:
            # one unit-weight task: read its arrays in place (no copy on the hot path)
            t = eqs[0]
            if t.A.shape != self._eq_shapes[0]:
                raise ValueError(
                    f"{t.label}: A changed shape from {self._eq_shapes[0]} to {t.A.shape}"
                )
            self.Ae, self.be = t.A, t.b
            self.identity = t.is_identity and not self.ineqs
            eqs = ()
        elif eqs:
            self.Ae, self.be = self._Ae_buf, self._be_buf
            self.identity = False
        i = 0
        for t, shape in zip(eqs, self._eq_shapes, strict=False):
            if t.A.shape != shape:
                raise ValueError(f"{t.label}: A changed shape from {shape} to {t.A.shape}")
            m = shape[0]
            if t.unit_weight:
                self.Ae[i : i + m] = t.A
                self.be[i : i + m] = t.b
            else:
                sw = t.sqrt_weight
                np.multiply(t.A, sw[:, None], out=self.Ae[i : i + m])
                np.multiply(t.b, sw, out=self.be[i : i + m])
            i += m
        i = 0
        for u, shape in zip(self.ineqs, self._in_shapes, strict=True):
            if u.C.shape != shape:
                raise ValueError(f"{u.label}: C changed shape from {shape} to {u.C.shape}")
            m = shape[0]
            self.C[i : i + m] = u.C
            self.lo[i : i + m] = u.lower
            self.hi[i : i + m] = u.upper
            self.sw[i : i + m] = u.sqrt_weight
            i += m
        if self.ineqs:
            self.low, self.hiw = widen(self.lo, self.hi, FEAS_TOL)

    def check_finite(self) -> None:
        """``ValueError`` naming the task and argument if a number is NaN or a wrong-sided
        infinity (a solve-time check: tasks validate what they are given, this catches
        what reached their arrays another way). Three reductions per kind of row."""
        bad = False
        if self.m_eq and not (all_finite(self.Ae) and all_finite(self.be)):
            bad = True
        if self.m_in and (not all_finite(self.C) or _bad_box(self.lo, self.hi)):
            bad = True
        if bad:
            tasks: list[Equality | Inequality] = [*self.eqs, *self.ineqs]
            for t in tasks:
                problem = find_bad_value(t)
                if problem is not None:
                    raise ValueError(f"{problem} (found at solve time)")

    def residual(self, x: np.ndarray) -> float:
        """Norm of the weighted equality residual and inequality violation at ``x``."""
        total = 0.0
        if self.m_eq:
            r = self.Ae @ x - self.be
            total += float(r @ r)
        if self.m_in:
            cx = self.C @ x
            v = self.sw * (cx - np.clip(cx, self.lo, self.hi))
            total += float(v @ v)
        return float(np.sqrt(total))


@dataclass
class CompiledStack:
    """All levels, hard constraints and bounds of a stack, as arrays."""

    n: int
    levels: list[CompiledLevel]
    hard: CompiledLevel
    bounds: Bounds | None
    lb: np.ndarray | None = None
    ub: np.ndarray | None = None
    _bounds_version: int = -1

    @property
    def equalities_only(self) -> bool:
        """No hard constraints and no inequality rows in any level (bounds allowed)."""
        return self._equalities_only

    def __post_init__(self) -> None:
        self._stack_buffers()  # and _equalities_only

    @property
    def capacity(self) -> int:
        """Most inequality rows a solve can inherit."""
        return self.hard.m_in + sum(L.m_in for L in self.levels)

    def check_finite(self) -> None:
        """``ValueError`` naming the task (or the bounds) and the argument if a NaN or a
        wrong-sided infinity is in the data about to be solved."""
        for L in self.levels:
            L.check_finite()
        self.hard.check_finite()
        b = self.bounds
        if (
            b is not None
            and self.lb is not None
            and self.ub is not None
            and _bad_box(self.lb, self.ub)
        ):
            problem = find_bad_value(b)
            raise ValueError(f"{problem or b.label + ': bounds contain NaN'} (found at solve time)")

    def refresh(self) -> None:
        """Re-read every task's numbers (the per-step update of the Python engine: a level
        of one unit-weight equality reads its task's arrays in place, see
        :meth:`CompiledLevel.refresh`)."""
        for L in self.levels:
            L.refresh()
        self.hard.refresh()
        self._aliased = True
        self._refresh_bounds()

    def _refresh_bounds(self) -> None:
        b = self.bounds
        if b is not None and b.version != self._bounds_version:
            self.lb, self.ub = b.resolve(self.n)
            self._bounds_version = b.version

    def _stack_buffers(self) -> None:
        """One contiguous array per kind; every block's buffers become views of it (a block
        without rows of a kind gets the shared empty view of that kind)."""
        blocks = [self.hard, *self.levels]
        n = self.n
        me = mi = 0
        for B in blocks:
            me += B.m_eq
            mi += B.m_in
        self._equalities_only = not (self.hard.m_eq or mi)
        Aeq = self.Aeq = np.zeros((me, n))
        beq = self.beq = np.zeros(me)
        C = self.C = np.zeros((mi, n))
        clo = self.clo = np.zeros(mi)
        chi = self.chi = np.zeros(mi)
        csw = self.csw = _full(mi, 1.0)
        #: the box as the native engine reads it (±inf without bounds)
        self.lbs = _full(n, -np.inf)
        self.ubs = _full(n, np.inf)
        # each copy a refresh makes, per kind: (task, shape, its rows of the stacked arrays)
        # and, for the native engine's own refresh (NativeHierarchy: Hierarchy.set_tasks),
        # the same as tasks, row counts and first rows
        eq_ops: list[tuple] = []  # (task, shape, A rows, b rows)
        in_ops: list[tuple] = []  # (task, shape, C rows, lo, hi, sw)
        eq_tasks: list[Equality] = []
        eq_rows: list[int] = []
        eq_first: list[int] = []
        in_tasks: list[Inequality] = []
        in_rows: list[int] = []
        in_first: list[int] = []
        no_eq = (Aeq[:0], beq[:0])
        no_in = (C[:0], clo[:0], chi[:0], csw[:0]) if mi else (C, clo, chi, csw)
        i = j = 0
        for B in blocks:
            i1, j1 = i + B.m_eq, j + B.m_in
            eq = (Aeq[i:i1], beq[i:i1]) if i1 > i else no_eq
            ineq = (C[j:j1], clo[j:j1], chi[j:j1], csw[j:j1]) if j1 > j else no_in
            B._use(*eq, *ineq)
            if len(B.eqs) == 1:  # one task: its rows are the block's
                t, shape = B.eqs[0], B._eq_shapes[0]
                eq_ops.append((t, shape, *eq))
                eq_tasks.append(t)
                eq_rows.append(shape[0])
                eq_first.append(i)
            else:
                for t, shape in zip(B.eqs, B._eq_shapes, strict=True):
                    m = i + shape[0]
                    eq_ops.append((t, shape, Aeq[i:m], beq[i:m]))
                    eq_tasks.append(t)
                    eq_rows.append(shape[0])
                    eq_first.append(i)
                    i = m
            if len(B.ineqs) == 1:
                u, shape = B.ineqs[0], B._in_shapes[0]
                in_ops.append((u, shape, *ineq))
                in_tasks.append(u)
                in_rows.append(shape[0])
                in_first.append(j)
            elif B.ineqs:
                for u, shape in zip(B.ineqs, B._in_shapes, strict=True):
                    m = j + shape[0]
                    in_ops.append((u, shape, C[j:m], clo[j:m], chi[j:m], csw[j:m]))
                    in_tasks.append(u)
                    in_rows.append(shape[0])
                    in_first.append(j)
                    j = m
            i, j = i1, j1
        self._eq_ops = eq_ops
        self._in_ops = in_ops
        self._task_rows = (eq_tasks, eq_rows, eq_first, in_tasks, in_rows, in_first)
        self._aliased = False

    def refresh_stacked(self) -> None:
        """Write every task's current numbers into the stacked arrays (the native engine's
        per-step update): one loop over the tasks, no per-level pass, no copy afterwards.

        Checks that no task's matrix changed shape (``ValueError`` naming it); the numbers
        themselves are checked by the native call (finite, no wrong-sided infinity). The
        native strict hierarchy does these copies in its own call (``Hierarchy.step``,
        ``src/native/refresh.hpp``, from ``_task_rows``) and comes here only for data it does
        not copy (not float64 of the task's shape, or levels aliasing their tasks' arrays).
        """
        for t, shape, A, b in self._eq_ops:
            tA = t.A
            if tA.shape != shape:
                raise ValueError(f"{t.label}: A changed shape from {shape} to {tA.shape}")
            if t.unit_weight:
                A[...] = tA
                b[...] = t.b
            else:
                sw = t.sqrt_weight
                np.multiply(tA, sw[:, None], out=A)
                np.multiply(t.b, sw, out=b)
        for t, shape, C, lo, hi, sw in self._in_ops:
            tC = t.C
            if tC.shape != shape:
                raise ValueError(f"{t.label}: C changed shape from {shape} to {tC.shape}")
            C[...] = tC
            lo[...] = t.lower
            hi[...] = t.upper
            sw[...] = t.sqrt_weight
        if self._aliased:  # a Python-engine refresh pointed levels at their tasks' arrays
            for B in (self.hard, *self.levels):
                B.Ae, B.be = B._Ae_buf, B._be_buf
                B.identity = False
                B.low, B.hiw = B.lo, B.hi
            self._aliased = False
        self._refresh_bounds()
        if self.lb is not None:  # every step: the box as resolved (it may view the bounds')
            self.lbs[...] = self.lb
            self.ubs[...] = self.ub


def _not_a_task(t, where: str, j: int) -> str:
    """The message for an object that is not an Equality or Inequality in a level."""
    if isinstance(t, Bounds):
        return f"{where}, task {j}: Bounds are always hard; pass them as Stack(..., bounds=...)"
    return f"{where}, task {j}: expected an Equality or Inequality, got {type(t).__name__}"


def _where(k: int) -> str:
    """The name of block ``k`` in messages (block 0: the hard constraints)."""
    return "constraints" if k == 0 else f"level {k - 1}"


def compile_stack(levels, bounds, constraints) -> CompiledStack:
    """Validate a stack's structure and build its buffers.

    Parameters
    ----------
    levels : sequence
        ``levels[0]`` is the highest priority; each item is a task or a list of tasks.
    bounds : Bounds or None
    constraints : sequence of tasks or None
        Hard constraints (must hold exactly).

    Raises
    ------
    ValueError
        Empty stack, empty level, mixed numbers of variables, unknown task types.
    """
    if isinstance(levels, (Equality, Inequality)):
        levels = [levels]
    try:
        levels = list(levels)
    except TypeError:
        raise ValueError(f"levels must be a list of tasks or task lists, got {levels!r}") from None
    hard_tasks = [] if constraints is None else constraints
    if isinstance(hard_tasks, (Equality, Inequality)):
        hard_tasks = [hard_tasks]
    hard_tasks = list(hard_tasks)
    if not levels and not hard_tasks:
        raise ValueError("empty stack: give at least one level with one task")
    norm_levels = []
    for k, lev in enumerate(levels):
        if lev.__class__ is list:  # the common level: a list, or one task
            tasks = lev[:]
        elif isinstance(lev, (Equality, Inequality, Bounds)):
            tasks = [lev]
        else:
            try:
                tasks = list(lev)
            except TypeError:
                raise ValueError(
                    f"level {k}: expected a task or a list of tasks, got {type(lev).__name__}"
                ) from None
        if not tasks:
            raise ValueError(f"level {k} is empty: give it at least one task or remove it")
        norm_levels.append(tasks)
    # one pass over the tasks (constraints first): every task must have the same number of
    # columns (reported first, in this order), and only Equality / Inequality may be in a
    # level or the constraints (the first other object of the levels is reported, else of
    # the constraints)
    n = None
    first: tuple = ()  # (block, task) of the first task: named only in a message
    bad_task: list[str | None] = [None, None]  # levels, constraints
    blocks = []
    for k, tasks in enumerate([hard_tasks, *norm_levels]):
        eqs, ineqs = [], []
        for j, t in enumerate(tasks):
            cls = t.__class__
            if cls is Equality or (cls is not Inequality and isinstance(t, Equality)):
                eqs.append(t)
                cols = t.A.shape[1]
            elif isinstance(t, Inequality):
                ineqs.append(t)
                cols = t.C.shape[1]
            else:
                if bad_task[k == 0] is None:
                    bad_task[k == 0] = _not_a_task(t, _where(k), j)
                continue
            if n is None:
                n, first = cols, (k, t)
            elif cols != n:
                raise ValueError(
                    f"{_where(k)}, {t.label}: has {cols} columns but {_where(first[0])}, "
                    f"{first[1].label} has {n}: all tasks must act on the same variable"
                )
        blocks.append((eqs, ineqs))
    if bad_task[0] or bad_task[1]:
        raise ValueError(bad_task[0] or bad_task[1])
    if bounds is not None and not isinstance(bounds, Bounds):
        raise ValueError(f"bounds must be a qpcoord.Bounds, got {type(bounds).__name__}")
    if n is None:
        raise ValueError("empty stack: no task found")
    if bounds is not None:
        bounds.resolve(n)  # ValueError now if the length does not match
    out = CompiledStack(
        n=n,
        levels=[CompiledLevel(e, i, n, False) for e, i in blocks[1:]],
        hard=CompiledLevel(*blocks[0], n, False),
        bounds=bounds,
    )
    return out
