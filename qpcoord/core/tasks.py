"""Tasks: the building blocks of a :class:`~qpcoord.Stack`.

A task is linear in the decision variable ``x`` (for a velocity-level IK step ``x`` is the
joint velocity in rad/s or the joint displacement in rad; for a force-sharing problem it is
a force in N; the units of ``A``, ``b``, ``C`` and the bounds follow from the user's choice
of ``x``):

- :class:`Equality` -- minimise ``‖diag(√w)(A x − b)‖²``;
- :class:`Inequality` -- ``lower ≤ C x ≤ upper``; at a soft level of a stack the squared
  violation is minimised, as a hard constraint it must hold;
- :class:`Bounds` -- a box ``lower ≤ x ≤ upper`` that always holds.

Every task validates its numbers when built and when updated with ``update(...)``, and
raises :class:`ValueError` naming the task and what is wrong. ``update`` keeps the shape,
so a stack built once can be re-solved every control step with new numbers.

In-place rule. The arrays a task keeps (``A``, ``b``, ``C``, ``lower``, ``upper``, ``weight``
and a :class:`Bounds`' ``lower``/``upper``) are read-only views: ``task.b[0] = 1.0`` raises
numpy's "assignment destination is read-only", and ``task.update(...)`` / ``bounds.update(...)``
is the one way to change them (validated, and counted in ``matrix_version`` / ``version`` so
that every cached solver sees the change). Library code that must write per step without
allocating uses the private, explicit paths: ``Equality._assign``, ``Inequality._assign``
(checked, version-bumping) and ``Bounds._writable()`` followed by ``Bounds._touch()``.

Rebinding rule. Rebinding an attribute a cached factorisation depends on -- ``task.A = J``,
``task.C = ...``, ``task.weight = ...``, ``bounds.lower = ...`` / ``bounds.upper = ...`` -- is
``update(...)`` of that argument: validated (``ValueError`` naming it), copied, and counted in
``matrix_version`` / ``version``, so that the weighted engine, :class:`PersistentQP` and the
compiled stacks never keep numbers the task no longer has. (Rebinding a right-hand side,
``b`` or an inequality's ``lower`` / ``upper``, to an array of the caller's stays allowed: it
is read at every solve and checked there; per-step code uses it to write in place.)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .linalg import all_finite

__all__ = ["Equality", "Inequality", "Bounds", "Task"]


#: ``object.__setattr__``: the tasks' own writes of the guarded attributes (see
#: ``_Task.__setattr__``)
_setattr = object.__setattr__

#: Counts every ``update(...)`` and public attribute write of a task: a compiled step that
#: holds a copy of tasks' weights or binds their arrays (the native IK step) looks at them
#: again only when it moved (one comparison per step).
TASK_WRITES = [0]


def _label(kind: str, name: str) -> str:
    return f"{kind} {name!r}" if name else f"{kind} (unnamed)"


#: Smallest and largest non-zero magnitude accepted in a task matrix: the QPs square the
#: matrices (``AᵀA``), so entries outside would under- or overflow (1e-320 made quadprog
#: fail with an IndexError). Rescale the units of ``x`` or of the task instead.
MATRIX_RANGE = (1e-150, 1e150)


# the reductions of the validation, without ndarray.sum/max/min's Python wrappers
_max, _min = np.maximum.reduce, np.minimum.reduce
#: numpy dtype kinds converted to float without a check: bool, signed, unsigned, float
_REAL_KINDS = ("b", "i", "u", "f")
#: the native float64 dtype: an array of it is copied with ``ndarray.copy`` (a third of
#: ``np.array(..., dtype=float)``'s time on control-step sizes)
_F64 = np.dtype(float)
_INF = math.inf


def _full(rows: int, value: float) -> np.ndarray:
    """``np.full(rows, value)`` without its Python wrapper."""
    arr = np.empty(rows)
    arr.fill(value)
    return arr


def _frozen(arr: np.ndarray) -> np.ndarray:
    """A read-only view of ``arr``, a fresh C-contiguous array of the caller's."""
    view = arr.view()
    view.flags.writeable = False
    return view


def _readonly(arr: np.ndarray) -> np.ndarray:
    """A read-only view of a fresh array (the array itself, its ``base``, stays writable
    for the library's explicit in-place paths)."""
    if not arr.flags.owndata or not arr.flags.c_contiguous:
        arr = np.array(arr, order="C")
    view = arr.view()
    view.flags.writeable = False
    return view


def _w(view: np.ndarray) -> np.ndarray:
    """The writable array behind a task's read-only view (library-internal writes only). An
    attribute rebound to a writable array of the caller's (``task.b = buffer[:m]``, which
    some per-step code does) is returned as it is."""
    if view.flags.writeable:
        return view
    base = view.base
    if base is None or base.shape != view.shape or not base.flags.writeable:
        raise ValueError("internal: a task array with no writable buffer behind it")
    return base


def _numeric(value: ArrayLike, what: str, label: str, noun: str = "numeric") -> np.ndarray:
    """``value`` as a new float array; complex input is a ``TypeError`` and non-numeric input
    a ``ValueError``, both naming ``what`` (numpy would drop an imaginary part)."""
    if type(value) is np.ndarray:
        if value.dtype is _F64:
            return value.copy()  # the common case: no check, one C-ordered copy
        if value.dtype.kind in _REAL_KINDS:
            return np.array(value, dtype=float, order="C")
    try:
        complex_in = np.iscomplexobj(value)
    except (TypeError, ValueError):  # ragged lists: let np.array name the problem
        complex_in = False
    if complex_in:
        raise TypeError(f"{label}: {what} is complex; tasks take real numbers")
    try:
        # a copy: a task never aliases the caller's array
        return np.array(value, dtype=float, order="C")
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{label}: {what} is not {noun} ({exc})") from None


def _matrix(value: ArrayLike, what: str, label: str) -> np.ndarray:
    arr = _numeric(value, what, label, "a numeric array")
    if arr.ndim != 2:
        if arr.ndim == 1:
            arr.shape = (1, arr.shape[0])  # in place: arr stays the owner of its data
        else:
            raise ValueError(
                f"{label}: {what} must be 2-D (rows × variables), got shape {arr.shape}"
            )
    if arr.shape[1] == 0:
        raise ValueError(f"{label}: {what} has no columns (shape {arr.shape})")
    if arr.shape[0] == 0:
        raise ValueError(
            f"{label}: {what} has no rows (shape {arr.shape}); a task needs at least one row "
            "(leave an empty task out of the stack)"
        )
    # two or three reductions on the hot path: the largest magnitude (NaN and ±inf fail
    # ``<=``) and the smallest (non-zero) one; the messages are built only if one fails
    lo_mag, hi_mag = MATRIX_RANGE
    mag = np.abs(arr)
    if _max(mag, None) <= hi_mag and (
        _min(mag, None) >= lo_mag or mag.min(where=mag > 0, initial=np.inf) >= lo_mag
    ):
        return _frozen(arr)  # fresh, C-contiguous, the owner of its data
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(
            f"{label}: {what} contains a non-finite value {arr[tuple(bad)]!r} "
            f"at row {bad[0]}, column {bad[1]}"
        )
    i, j = np.argwhere((mag > hi_mag) | ((mag < lo_mag) & (mag > 0)))[0]
    raise ValueError(
        f"{label}: {what}[{i}, {j}] = {arr[i, j]!r} is outside the magnitudes a QP can "
        f"square ({lo_mag:g} … {hi_mag:g}, or exactly 0): rescale the units"
    )


def _entries(value: ArrayLike, rows: int, what: str, label: str) -> np.ndarray:
    """``value`` as a new float array of ``rows`` entries (scalars broadcast, a row or column
    matrix is flattened); its numbers are not checked (:func:`_vector` does)."""
    if type(value) is float or type(value) is int:  # a Python scalar (not a bool): broadcast
        return _full(rows, float(value))
    arr = _numeric(value, what, label)  # a copy, as in _matrix
    if arr.ndim == 0:
        arr = _full(rows, float(arr))
    elif arr.ndim == 2 and 1 in arr.shape:
        arr.shape = (arr.size,)  # in place: arr stays the owner of its data
    if arr.ndim != 1 or arr.shape[0] != rows:
        raise ValueError(f"{label}: {what} must have {rows} entries, got shape {np.shape(value)}")
    return arr


def _vector(value: ArrayLike, rows: int, what: str, label: str, allow_inf: int = 0) -> np.ndarray:
    """Validate a length-``rows`` vector; scalars broadcast.

    ``allow_inf``: 0 forbids ±inf, +1 allows +inf only, -1 allows -inf only.
    """
    if type(value) is float or type(value) is int:  # a Python scalar (not a bool): broadcast
        v = float(value)
        if math.isfinite(v) or (allow_inf and v == allow_inf * _INF):
            return _frozen(_full(rows, v))
    arr = _entries(value, rows, what, label)
    # one reduction on the hot path (NaN fails every comparison, so it goes to the named
    # checks below, as does an empty vector)
    if rows and (
        (allow_inf < 0 and _max(arr, None) < _INF)
        or (allow_inf > 0 and _min(arr, None) > -_INF)
        or (allow_inf == 0 and _max(np.abs(arr), None) < _INF)
    ):
        return _frozen(arr)  # fresh, C-contiguous, the owner of its data
    return _named_vector_check(arr, what, label, allow_inf)


def _named_vector_check(arr: np.ndarray, what: str, label: str, allow_inf: int) -> np.ndarray:
    """``arr`` read-only if it has no NaN and no infinity ``allow_inf`` forbids, else the
    ``ValueError`` naming the first bad entry (``allow_inf`` as in :func:`_vector`)."""
    if np.any(np.isnan(arr)):
        i = int(np.flatnonzero(np.isnan(arr))[0])
        raise ValueError(f"{label}: {what} contains NaN at index {i}")
    if allow_inf == 0:
        bad = ~np.isfinite(arr)
    elif allow_inf > 0:
        bad = arr == -np.inf
    else:
        bad = arr == np.inf
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{label}: {what} has the non-allowed value {arr[i]!r} at index {i}")
    return _frozen(arr)


def _weight(value: ArrayLike, rows: int, label: str) -> np.ndarray:
    if (type(value) is float or type(value) is int) and 0 < value < math.inf:
        return _frozen(_full(rows, float(value)))  # a valid Python scalar (the default)
    w = _vector(value, rows, "weight", label)
    if not w.min() > 0:
        i = int(np.flatnonzero(w <= 0)[0])
        raise ValueError(f"{label}: weight must be > 0, got {w[i]!r} at row {i}")
    return w


def _check_order(lower: np.ndarray, upper: np.ndarray, label: str, where: str = "row") -> None:
    bad = lower > upper
    if np.count_nonzero(bad):
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{label}: lower > upper at {where} {i} ({lower[i]!r} > {upper[i]!r})")


def _limits(
    lower: ArrayLike, upper: ArrayLike, rows: int, label: str, where: str
) -> tuple[np.ndarray, np.ndarray]:
    """Validated read-only ``(lower, upper)`` of ``rows`` entries: no NaN, ``-inf`` only in
    ``lower``, ``+inf`` only in ``upper``, ``lower ≤ upper`` (``where``: "row" or "index" in
    the message).

    Three reductions on the hot path (``lower ≤ upper`` fails for NaN on either side and for
    ``lower > upper``; ``max(lower) < +inf`` and ``min(upper) > −inf`` for the infinities);
    only if one fails, the checks of :func:`_vector` and :func:`_check_order` name the
    problem. (``lower − upper ≤ 0`` would take one reduction but overflows, with numpy's
    warning, on large finite limits such as ``±1e308``.)
    """
    lo = _entries(lower, rows, "lower", label)
    try:
        hi = _entries(upper, rows, "upper", label)
    except (TypeError, ValueError):
        _named_vector_check(lo, "lower", label, -1)  # a bad lower is named first, as ever
        raise
    if (
        rows
        and _max(lo, None) < _INF
        and _min(hi, None) > -_INF
        and _min(np.less_equal(lo, hi), None)
    ):
        return _frozen(lo), _frozen(hi)
    lo = _named_vector_check(lo, "lower", label, -1)
    hi = _named_vector_check(hi, "upper", label, +1)
    _check_order(lo, hi, label, where)
    return lo, hi


def _is_identity(A: np.ndarray) -> bool:
    """Is ``A`` exactly the identity matrix? (Posture-like tasks; lets solvers skip an SVD.)
    ``n`` non-zero entries, all of them ones on the diagonal."""
    n = A.shape[0]
    return n == A.shape[1] and np.count_nonzero(A) == n and bool((A.diagonal() == 1.0).all())


def _bad_box(lower: np.ndarray, upper: np.ndarray) -> bool:
    """NaN, ``lower = +inf``, ``upper = −inf`` or ``lower > upper`` anywhere."""
    return bool(not (lower <= upper).all() or lower.max() == np.inf or upper.min() == -np.inf)


class _Task:
    """What every task shares: a name, a label for messages and cached row weights."""

    kind = "Task"
    name = ""
    #: Incremented whenever the matrix (``A`` or ``C``) or the weights change; the
    #: right-hand sides and limits do not count. Lets a persistent solver
    #: (:class:`qpcoord.core.persistent.PersistentQP`) keep its factorisation while it holds.
    matrix_version = 0
    #: Attributes a cached factorisation depends on: set once at construction, then changed
    #: only by ``update`` (a rebinding, ``task.A = J``, is ``update(A=J)``: the module's
    #: rebinding rule)
    _MATRIX_ATTRS: frozenset[str] = frozenset()
    #: the validated row weights, their square roots and whether all are 1 (_set_weight)
    weight: np.ndarray
    sqrt_weight: np.ndarray
    unit_weight: bool
    #: each task's validated ``update(...)`` (its own arguments)
    update: Callable[..., Any]

    def __setattr__(self, name: str, value: Any) -> None:
        if name in self._MATRIX_ATTRS and name in self.__dict__:
            self.update(**{name: value})  # validated, copied, counted in matrix_version
            return
        _setattr(self, name, value)
        TASK_WRITES[0] += 1

    @property
    def label(self) -> str:
        """Human-readable name used in messages."""
        return _label(self.kind, self.name)

    def _set_weight(self, w: np.ndarray, given: object = None) -> None:
        """Keep the validated weights ``w`` (``given``: what the caller passed, if known)."""
        _setattr(self, "weight", w)
        if (type(given) is float or type(given) is int) and given == 1:
            _setattr(self, "unit_weight", True)  # the default weight, broadcast: all ones
        else:
            _setattr(self, "unit_weight", bool(w[0] == 1.0 and (w == 1.0).all()))
        #: ``√weight`` (cached: weights rarely change between control steps); the weight
        #: itself when every weight is 1
        _setattr(self, "sqrt_weight", w if self.unit_weight else _frozen(np.sqrt(w)))


class Equality(_Task):
    """Least-squares task ``minimise ‖diag(√w)(A x − b)‖²``.

    Parameters
    ----------
    A : array_like, shape (m, n)
        Task matrix (a 1-D array is one row). Units: task units per unit of ``x``.
    b : array_like, shape (m,)
        Target, in task units (a scalar broadcasts).
    weight : float or array_like, shape (m,)
        Positive weight of each row inside its level (default 1). Within a strict
        hierarchy a level's overall scale does not matter; relative row weights do.
    name : str
        Used in error messages and reports.
    """

    kind = "Equality"
    _MATRIX_ATTRS = frozenset(("A", "weight"))
    # written through the instance dict by the constructor and update (one dict update)
    A: np.ndarray
    b: np.ndarray
    is_identity: bool

    def __init__(self, A: ArrayLike, b: ArrayLike, weight: ArrayLike = 1.0, name: str = "") -> None:
        name = str(name)
        label = _label(self.kind, name)
        A = _matrix(A, "A", label)
        m = A.shape[0]
        b = _vector(b, m, "b", label)
        w = _weight(weight, m, label)
        # the instance dict written directly: none of these is set yet, so _Task.__setattr__
        # would only pass them on
        self.__dict__.update(name=name, A=A, is_identity=_is_identity(A), b=b)
        self._set_weight(w, weight)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, variables)."""
        return self.A.shape

    def update(
        self,
        A: ArrayLike | None = None,
        b: ArrayLike | None = None,
        weight: ArrayLike | None = None,
    ) -> Equality:
        """Replace numbers in place (same shape), validating them. Returns ``self``.

        All-or-nothing: if any argument is rejected, the task keeps its old numbers.
        """
        label = self.label
        m = self.A.shape[0]
        newA = newb = neww = None
        if A is not None:
            newA = _matrix(A, "A", label)
            if newA.shape != self.A.shape:
                raise ValueError(
                    f"{label}: update changes A's shape {self.A.shape} to {newA.shape}"
                )
        if b is not None:
            newb = _vector(b, m, "b", label)
        if weight is not None:
            neww = _weight(weight, m, label)
        if newA is not None:
            _setattr(self, "A", newA)
            _setattr(self, "is_identity", _is_identity(newA))
        if newb is not None:
            _setattr(self, "b", newb)
        if neww is not None:
            self._set_weight(neww)
        if newA is not None or neww is not None:
            _setattr(self, "matrix_version", self.matrix_version + 1)
        TASK_WRITES[0] += 1
        return self

    def _assign(self, A: np.ndarray | None = None, b: np.ndarray | None = None) -> Equality:
        """Trusted per-step path for library-built tasks: same shapes, values copied in place.

        Only finiteness is checked (one reduction); shapes are the caller's contract.
        """
        if A is not None:
            if not all_finite(A):
                raise ValueError(f"{self.label}: A contains a non-finite value")
            _w(self.A)[...] = A
            _setattr(self, "is_identity", False)
            _setattr(self, "matrix_version", self.matrix_version + 1)
        if b is not None:
            if not all_finite(b):
                raise ValueError(f"{self.label}: b contains a non-finite value")
            _w(self.b)[...] = b
        return self

    def residual(self, x: np.ndarray) -> np.ndarray:
        """Weighted residual ``diag(√w)(A x − b)`` (task units)."""
        return np.sqrt(self.weight) * (self.A @ x - self.b)

    def __repr__(self) -> str:
        return f"Equality(rows={self.A.shape[0]}, n={self.A.shape[1]}, name={self.name!r})"


class Inequality(_Task):
    """Two-sided linear inequality ``lower ≤ C x ≤ upper``.

    Parameters
    ----------
    C : array_like, shape (m, n)
        Constraint matrix (a 1-D array is one row).
    lower, upper : float or array_like, shape (m,), optional
        Bounds in the units of ``C x``; ``None`` means unbounded on that side. ``-inf`` is
        allowed in ``lower`` and ``+inf`` in ``upper``. At least one side must be given.
    weight : float or array_like, shape (m,)
        Positive weight of each row's squared violation within its level (default 1).
    name : str
        Used in error messages and reports.
    """

    kind = "Inequality"
    _MATRIX_ATTRS = frozenset(("C", "weight"))
    # written through the instance dict by the constructor and update (one dict update)
    C: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    def __init__(
        self,
        C: ArrayLike,
        lower: ArrayLike | None = None,
        upper: ArrayLike | None = None,
        weight: ArrayLike = 1.0,
        name: str = "",
    ) -> None:
        name = str(name)
        label = _label(self.kind, name)
        if lower is None and upper is None:
            raise ValueError(f"{label}: give lower, upper or both")
        C = _matrix(C, "C", label)
        m = C.shape[0]
        lo, hi = _limits(
            -_INF if lower is None else lower, _INF if upper is None else upper, m, label, "row"
        )
        w = _weight(weight, m, label)
        # the instance dict written directly, as in Equality.__init__
        self.__dict__.update(name=name, C=C, lower=lo, upper=hi)
        self._set_weight(w, weight)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, variables)."""
        return self.C.shape

    def update(
        self,
        C: ArrayLike | None = None,
        lower: ArrayLike | None = None,
        upper: ArrayLike | None = None,
        weight: ArrayLike | None = None,
    ) -> Inequality:
        """Replace numbers in place (same shape), validating them. Returns ``self``.

        All-or-nothing: if any argument is rejected, the task keeps its old numbers.
        """
        label = self.label
        m = self.C.shape[0]
        newC = neww = None
        if C is not None:
            newC = _matrix(C, "C", label)
            if newC.shape != self.C.shape:
                raise ValueError(
                    f"{label}: update changes C's shape {self.C.shape} to {newC.shape}"
                )
        if lower is not None and upper is not None:
            lo, hi = _limits(lower, upper, m, label, "row")
        else:
            lo = self.lower if lower is None else _vector(lower, m, "lower", label, allow_inf=-1)
            hi = self.upper if upper is None else _vector(upper, m, "upper", label, allow_inf=+1)
            _check_order(lo, hi, label)
        if weight is not None:
            neww = _weight(weight, m, label)
        if newC is not None:
            _setattr(self, "C", newC)
        _setattr(self, "lower", lo)
        _setattr(self, "upper", hi)
        if neww is not None:
            self._set_weight(neww)
        if newC is not None or neww is not None:
            _setattr(self, "matrix_version", self.matrix_version + 1)
        TASK_WRITES[0] += 1
        return self

    def _assign(
        self, lower: ArrayLike, upper: ArrayLike, C: np.ndarray | None = None
    ) -> Inequality:
        """Trusted per-step path: new bounds of the same length (NaN and order checked) and
        optionally a new ``C`` of the same shape (finiteness checked). Scalars broadcast."""
        lower, upper = np.asarray(lower), np.asarray(upper)
        if _bad_box(lower, upper):
            _check_order(lower, upper, self.label)
            raise ValueError(f"{self.label}: bounds contain NaN or ±inf on the wrong side")
        if C is not None:
            if not all_finite(C):
                raise ValueError(f"{self.label}: C contains a non-finite value")
            _w(self.C)[...] = C
            _setattr(self, "matrix_version", self.matrix_version + 1)
        _w(self.lower)[...] = lower
        _w(self.upper)[...] = upper
        return self

    def violation(self, x: np.ndarray) -> np.ndarray:
        """Weighted violation ``√w · (C x − clip(C x, lower, upper))`` (units of ``C x``)."""
        cx = self.C @ x
        return np.sqrt(self.weight) * (cx - np.clip(cx, self.lower, self.upper))

    def __repr__(self) -> str:
        return f"Inequality(rows={self.C.shape[0]}, n={self.C.shape[1]}, name={self.name!r})"


class Bounds:
    """Box ``lower ≤ x ≤ upper`` on the decision variable; always hard.

    Parameters
    ----------
    lower, upper : float or array_like, shape (n,)
        Bounds in the units of ``x``; ``None`` or ``∓inf`` leaves that side open. Scalars
        broadcast to each stack's ``n`` (one scalar ``Bounds`` may serve several stacks).
    name : str
        Used in error messages.
    """

    kind = "Bounds"
    #: the validated arrays (absent while the bounds are scalars: ``n is None``)
    lower: np.ndarray
    upper: np.ndarray
    # written through the instance dict (not through __setattr__, which validates lower/upper)
    name: str
    version: int
    n: int | None
    _lower_in: Any
    _upper_in: Any

    def __setattr__(self, name: str, value: Any) -> None:
        # bounds.lower = ... is update(lower=...): validated, counted in version (the
        # module's rebinding rule); the class's own writes go through _set
        if name == "lower" or name == "upper":
            self.update(**{name: value})
            return
        _setattr(self, name, value)

    def __init__(
        self, lower: ArrayLike | None = None, upper: ArrayLike | None = None, name: str = "bounds"
    ) -> None:
        d = self.__dict__  # not through Bounds.__setattr__: nothing to update yet
        d["name"] = str(name)
        d["version"] = 0  # incremented by update(): stacks re-read the bounds then
        self._set(-_INF if lower is None else lower, _INF if upper is None else upper)

    def _set(self, lower: ArrayLike, upper: ArrayLike) -> None:
        n = None
        for v in (lower, upper):
            if type(v) is np.ndarray:  # the common case, without np.ndim/np.size's wrappers
                if v.ndim > 0:
                    n = v.size
            elif np.ndim(v) > 0:
                n = int(np.size(v))
        lo, hi = self._validate(lower, upper, 1 if n is None else n)
        d = self.__dict__
        if n is None:
            d["_lower_in"], d["_upper_in"], d["n"] = lower, upper, n
        else:
            # the validated copies, not the caller's arrays (a later update re-reads them)
            d["_lower_in"], d["_upper_in"], d["n"] = lo, hi, n
            d["lower"], d["upper"] = lo, hi

    def _validate(
        self, lower: ArrayLike, upper: ArrayLike, n: int
    ) -> tuple[np.ndarray, np.ndarray]:
        return _limits(lower, upper, n, _label(self.kind, self.name), "index")

    @property
    def label(self) -> str:
        """Human-readable name used in messages."""
        return _label(self.kind, self.name)

    def resolve(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Validated ``(lower, upper)`` arrays of length ``n``."""
        if self.n is not None:
            if self.n != n:
                raise ValueError(
                    f"{self.label}: has {self.n} entries but the tasks have {n} columns"
                )
            return self.lower, self.upper
        return self._validate(self._lower_in, self._upper_in, n)

    def update(self, lower: ArrayLike | None = None, upper: ArrayLike | None = None) -> Bounds:
        """Replace the bounds, validating them (all-or-nothing). Returns ``self``.

        A ``Bounds`` built with arrays keeps its length; one built with scalars may take
        scalars or arrays.
        """
        new_lo = self._lower_in if lower is None else lower
        new_hi = self._upper_in if upper is None else upper
        if self.n is not None:
            lo, hi = self._validate(new_lo, new_hi, self.n)  # names a wrong length
            _setattr(self, "_lower_in", lo)
            _setattr(self, "_upper_in", hi)
            _setattr(self, "lower", lo)
            _setattr(self, "upper", hi)
        else:
            self._set(new_lo, new_hi)
        _setattr(self, "version", self.version + 1)
        return self

    def _writable(self) -> tuple[np.ndarray, np.ndarray]:
        """Writable arrays behind ``lower`` and ``upper`` (same memory), for library code that
        fills the box in place every step (the IK's joint limits); the writer must call
        :meth:`_touch` afterwards. Bounds built from scalars have none (``ValueError``)."""
        if self.n is None:
            raise ValueError(f"{self.label}: built from scalars, it has no arrays to write")
        return _w(self.lower), _w(self.upper)

    def _touch(self) -> Bounds:
        """Mark ``lower``/``upper`` as changed after the library wrote them in place (the
        writer guarantees ``lower ≤ upper`` and no NaN)."""
        # per-step code: the instance dict written directly (not through Bounds.__setattr__)
        d = self.__dict__
        d["_lower_in"], d["_upper_in"] = d["lower"], d["upper"]
        d["version"] += 1
        return self

    def __repr__(self) -> str:
        return f"Bounds(n={self.n}, name={self.name!r})"


def _first_bad(arr: np.ndarray, bad: np.ndarray, what: str, label: str) -> str | None:
    if not bad.any():
        return None
    idx = tuple(int(i) for i in np.argwhere(bad)[0])
    where = f"index {idx[0]}" if len(idx) == 1 else f"row {idx[0]}, column {idx[1]}"
    return f"{label}: {what} contains {float(arr[idx])!r} at {where}"


def find_bad_value(task: Equality | Inequality | Bounds) -> str | None:
    """Message naming the first NaN, wrong-sided infinity or ``lower > upper`` in a task's or
    a :class:`Bounds`' arrays, or ``None`` if there is none (used by the solve-time check)."""
    label = task.label
    if isinstance(task, Equality):
        checks = [(task.A, "A"), (task.b, "b"), (task.weight, "weight")]
        for arr, what in checks:
            msg = _first_bad(arr, ~np.isfinite(arr), what, label)
            if msg:
                return msg
        return None
    if isinstance(task, Inequality):
        msg = _first_bad(task.C, ~np.isfinite(task.C), "C", label)
        if msg:
            return msg
        lo, hi = task.lower, task.upper
    elif isinstance(task, Bounds):
        if task.n is None:
            return None
        lo, hi = task.lower, task.upper
    else:
        return None
    msg = _first_bad(lo, np.isnan(lo) | (lo == np.inf), "lower", label) or _first_bad(
        hi, np.isnan(hi) | (hi == -np.inf), "upper", label
    )
    if msg:
        return msg
    bad = lo > hi
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        return f"{label}: lower > upper at index {i} ({lo[i]!r} > {hi[i]!r})"
    return None


Task = Equality | Inequality
TaskLevel = Sequence[Task]
