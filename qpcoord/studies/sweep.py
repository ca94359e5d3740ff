"""Parameter sweeps at scale: one function over a grid or a list of samples, in parallel.

The studies that run by the thousand — DDL seeds × plant mismatch, Poincaré grids of initial
configurations, long runs for Conjecture 4.1 — are one function called on many independent
points. :func:`sweep` runs them on one of four backends and returns the results **in input
order**, whatever the backend::

    from qpcoord.studies.sweep import sweep, grid, seeds

    def rmse(seed, gain):                    # module-level: picklable for worker processes
        ...
        return run.metrics["rmse"]

    out = sweep(rmse, {"seed": seeds(20), "gain": [0.8, 1.0, 1.2]})   # 60 runs, joblib
    out = sweep(rmse, grid(seed=seeds(20), gain=[0.8, 1.2]), backend=client)   # Dask

Backends
--------
``"serial"``
    A plain loop in the calling process (debugging, reference results).
``"processes"`` (default)
    joblib's loky worker processes (the reusable pool: workers outlive one sweep, so the
    second sweep does not pay their start-up). ``fn`` and the points are pickled with
    cloudpickle: lambdas and closures work, open files, locks and generators do not.
``"threads"``
    joblib's thread pool, for ``fn`` that release the GIL (waiting on a subprocess, I/O,
    long numpy/scipy calls). Pure-Python ``fn`` gain nothing from threads.
a ``distributed.Client``
    An existing Dask cluster (``client.map`` with ``pure=False``, results gathered as they
    complete). The cluster decides the parallelism: ``n_jobs`` is ignored.

BLAS threads
------------
Sweep points are small problems run side by side: a multithreaded BLAS on small matrices
only adds contention (this repository measured ~100× slowdowns with threaded OpenBLAS on two
cores). Every backend therefore runs ``fn`` with one BLAS/OpenMP thread:

* the calling process holds ``threadpoolctl.threadpool_limits(1)`` for the duration of the
  sweep (serial and threads backends, in-process Dask workers); the previous limits are
  restored afterwards, also when nested sweeps or several threads overlap;
* loky workers are started with joblib's ``inner_max_num_threads=1`` (``OMP_NUM_THREADS``,
  ``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS``… set to 1 before any library loads);
* every worker process (loky or Dask) also applies ``threadpool_limits(1)`` to the libraries
  it has loaded, once, and again whenever new modules were imported since (``threadpool_limits``
  costs ≈ 5 ms, too much to pay per point). Dask's own nanny sets the same environment
  variables by default; the limit stays in force in those worker processes.

Nested sweeps
-------------
A sweep called by ``fn`` while it runs in a parallel sweep's worker (a loky process, a
thread of the threads backend, a Dask task) defaults to ``n_jobs=1`` and runs in that
worker: the cores are already busy, and a pool of pools only oversubscribes them. Pass
``n_jobs`` explicitly to override. A sweep inside a *serial* sweep uses the cores as usual.

Results are identical bit for bit between backends when ``fn`` is deterministic given its
point (seed it from the point, e.g. with :func:`seeds`, never from global state).

The module itself is callable: ``qpcoord.studies.sweep(fn, grid_or_samples, backend=...)`` is
:func:`sweep` (the module stays a module: ``qpcoord.studies.sweep.grid``, ``import
qpcoord.studies.sweep``).
"""

from __future__ import annotations

import itertools
import operator
import os
import pickle
import reprlib
import sys
import threading
import traceback
import types
import uuid
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["sweep", "grid", "seeds", "SweepError", "BACKENDS"]

#: The backend names :func:`sweep` accepts (or a ``distributed.Client`` instance).
BACKENDS = ("serial", "processes", "threads")

_repr = reprlib.Repr()
_repr.maxstring = 60
_repr.maxother = 60
_repr.maxlist = _repr.maxtuple = _repr.maxdict = 8


class SweepError(RuntimeError):
    """``fn`` raised on one point of a sweep.

    Chained from the original exception (``err.__cause__``). For worker processes the
    original is a pickled copy and its traceback is the worker's, kept as text in
    :attr:`remote_traceback` and at the end of the message.

    Attributes
    ----------
    index : int
        Position of the failing point in the input (0-based; for a grid, the C-order index).
    point : object
        The point itself (the dict of keyword arguments, or the positional argument).
    remote_traceback : str or None
        Traceback formatted in the worker process (None for serial and threads backends,
        whose ``__cause__`` carries the live traceback).
    """

    def __init__(self, message: str, index: int, point: Any, remote_traceback: str | None = None):
        super().__init__(message, index, point, remote_traceback)
        self.index = index
        self.point = point
        self.remote_traceback = remote_traceback

    def __str__(self) -> str:
        return str(self.args[0])


# --------------------------------------------------------------------------- points


def _axis_values(name: str, values: Any) -> list:
    if isinstance(values, (str, bytes, Mapping, set, frozenset)):
        kind = type(values).__name__
        raise ValueError(
            f"grid axis {name!r} must be an ordered sequence of values, got a {kind}: "
            f"{_repr.repr(values)}"
        )
    try:
        out = list(values)
    except TypeError:
        raise ValueError(
            f"grid axis {name!r} must be a sequence of values, got {_repr.repr(values)}"
        ) from None
    if not out:
        raise ValueError(f"grid axis {name!r} is empty: every axis needs at least one value")
    return out


def grid(**axes: Sequence) -> list[dict]:
    """Cartesian product of named axes, as a list of keyword-argument dicts.

    Parameters
    ----------
    **axes : sequence
        ``name=values``; each a non-empty ordered sequence (list, tuple, range, 1-D numpy
        array — elements are kept as they are, e.g. ``numpy.float64``). Strings, sets and
        mappings are refused (a string is not a list of values, a set has no order).

    Returns
    -------
    list of dict
        One dict per point, in C order: the last axis varies fastest, as
        ``itertools.product`` and ``numpy.ndindex``. The length is the product of the axis
        lengths; point ``i`` of axes of lengths ``(n0, n1, …)`` has the multi-index
        ``numpy.unravel_index(i, (n0, n1, …))``.

    Raises
    ------
    ValueError
        If no axis is given, or an axis is empty or not a sequence (the message names it).

    Examples
    --------
    >>> grid(seed=[0, 1], gain=[0.8, 1.2])
    [{'seed': 0, 'gain': 0.8}, {'seed': 0, 'gain': 1.2}, {'seed': 1, 'gain': 0.8}, {'seed': 1, 'gain': 1.2}]
    """  # noqa: E501
    if not axes:
        raise ValueError("grid() needs at least one axis, e.g. grid(seed=seeds(10))")
    names = list(axes)
    values = [_axis_values(name, axes[name]) for name in names]
    return [dict(zip(names, combo, strict=True)) for combo in itertools.product(*values)]


def seeds(n: int, root: int = 0) -> list[int]:
    """``n`` independent, reproducible integer seeds for parallel runs.

    The seeds come from ``numpy.random.SeedSequence(root).spawn(n)``: child ``i`` is the
    same for every ``n > i`` (growing a study keeps its first runs), and the streams of
    ``numpy.random.default_rng(seed)`` for different children are independent — unlike
    ``range(n)`` seeds of a generator whose streams are only *probably* unrelated, or seeds
    drawn from one generator, which can collide.

    Parameters
    ----------
    n : int
        Number of seeds, ≥ 1.
    root : int
        Entropy of the root ``SeedSequence`` (non-negative): another study, another root.

    Returns
    -------
    list of int
        ``n`` Python ints in ``[0, 2**63)`` (a non-negative int64: accepted by
        ``numpy.random.default_rng`` and by every qpcoord ``seed=`` argument; take
        ``seed % 2**32`` for APIs limited to 32 bits).

    Raises
    ------
    ValueError
        If ``n`` is not an integer ≥ 1 or ``root`` not a non-negative integer.
    """
    n = _int_at_least("n", n, 1)
    root = _int_at_least("root", root, 0)
    children = np.random.SeedSequence(root).spawn(n)
    return [int(c.generate_state(1, dtype=np.uint64)[0] >> np.uint64(1)) for c in children]


def _int_at_least(name: str, value: Any, low: int) -> int:
    if isinstance(value, bool):
        raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    try:
        out = operator.index(value)
    except TypeError:
        raise ValueError(f"{name} must be an integer >= {low}, got {value!r}") from None
    if out < low:
        raise ValueError(f"{name} must be an integer >= {low}, got {value!r}")
    return out


def _points(grid_or_samples: Any) -> list:
    if isinstance(grid_or_samples, Mapping):
        if not grid_or_samples:
            return []
        bad = [k for k in grid_or_samples if not isinstance(k, str)]
        if bad:
            raise ValueError(
                f"grid_or_samples: a mapping is a grid of keyword arguments, its keys must be "
                f"strings, got {bad[0]!r}"
            )
        return grid(**grid_or_samples)
    if hasattr(grid_or_samples, "columns") and hasattr(grid_or_samples, "to_dict"):
        return grid_or_samples.to_dict("records")  # a pandas DataFrame: one row per point
    if isinstance(grid_or_samples, (str, bytes, set, frozenset)) or not isinstance(
        grid_or_samples, Iterable
    ):
        raise ValueError(
            "grid_or_samples must be a mapping name -> values (a grid) or an ordered sequence "
            f"of points, got {type(grid_or_samples).__name__}: {_repr.repr(grid_or_samples)}"
        )
    return list(grid_or_samples)


# --------------------------------------------------------------------------- BLAS threads


class _OneBlasThread:
    """Process-wide, reference-counted ``threadpool_limits(1)``: safe to enter from several
    threads and nested sweeps (the first entry applies it, the last exit restores)."""

    _lock = threading.Lock()
    _depth = 0
    _limiter = None

    def __enter__(self) -> _OneBlasThread:
        cls = type(self)
        with cls._lock:
            if cls._depth == 0:
                from threadpoolctl import threadpool_limits

                cls._limiter = threadpool_limits(limits=1)
            cls._depth += 1
        return self

    def __exit__(self, *exc) -> None:
        cls = type(self)
        with cls._lock:
            cls._depth -= 1
            if cls._depth == 0 and cls._limiter is not None:
                cls._limiter.restore_original_limits()
                cls._limiter = None


_worker_limit_state: tuple[int, int] | None = None  # (pid, len(sys.modules)) when last applied


def _limit_worker_process() -> None:
    """One BLAS thread in a worker process: applied once, re-applied after new imports."""
    global _worker_limit_state
    state = (os.getpid(), len(sys.modules))
    if _worker_limit_state != state:
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=1)  # kept: worker processes belong to the pool
        _worker_limit_state = (os.getpid(), len(sys.modules))


# --------------------------------------------------------------------------- worker side


@dataclass(frozen=True)
class _Failure:
    """What a worker returns instead of raising (so every backend reports the same way)."""

    exc: BaseException
    traceback: str | None


def _portable(exc: BaseException) -> BaseException:
    """``exc`` if it survives a pickle round trip, else a RuntimeError carrying its text."""
    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:
        return RuntimeError(f"{type(exc).__module__}.{type(exc).__qualname__}: {exc}")


_worker = threading.local()  # .active: this thread is running a point of a parallel sweep


def _in_worker() -> bool:
    return getattr(_worker, "active", False)


class _Call:
    """Picklable wrapper run by the workers: ``(index, point) -> (index, ok, value)``.

    ``remote``: exceptions must cross a process boundary (pickled, traceback as text).
    ``parallel``: the call runs in a pool worker; nested sweeps then default to one job.
    """

    def __init__(self, fn: Callable, remote: bool, parallel: bool):
        self.fn = fn
        self.remote = remote
        self.parallel = parallel
        self.parent_pid = os.getpid()

    def __call__(self, index: int, point: Any) -> tuple[int, bool, Any]:
        if self.remote and os.getpid() != self.parent_pid:
            _limit_worker_process()
        outer = _in_worker()
        _worker.active = outer or self.parallel
        try:
            if isinstance(point, Mapping):
                value = self.fn(**point)
            else:
                value = self.fn(point)
        except Exception as exc:
            if self.remote:
                tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
                return index, False, _Failure(_portable(exc), tb)
            return index, False, _Failure(exc, None)
        finally:
            _worker.active = outer
        return index, True, value


class _Box:
    """Opaque holder of a point for Dask (which would otherwise look inside tuples/dicts)."""

    __slots__ = ("index", "point")

    def __init__(self, index: int, point: Any):
        self.index = index
        self.point = point

    def __getstate__(self):
        return self.index, self.point

    def __setstate__(self, state):
        self.index, self.point = state


class _BoxCall:
    __slots__ = ("call",)

    def __init__(self, call: _Call):
        self.call = call

    def __getstate__(self):
        return self.call

    def __setstate__(self, state):
        self.call = state

    def __call__(self, box: _Box) -> tuple[int, bool, Any]:
        return self.call(box.index, box.point)


# --------------------------------------------------------------------------- collection


class _Collector:
    """Gathers ``(index, ok, value)`` in any completion order; raises the failure of the
    *lowest* failing index as soon as every lower index has succeeded, so that which error
    is reported does not depend on scheduling."""

    def __init__(self, points: list, progress: Any, desc: str | None):
        self.points = points
        self.n = len(points)
        self.results: list[Any] = [None] * self.n
        self.done = [False] * self.n
        self.count = 0
        self.prefix = 0  # every index < prefix is done and succeeded
        self.failures: dict[int, _Failure] = {}
        self.bar = None
        self.callback = None
        if progress is True:
            from tqdm import tqdm

            self.bar = tqdm(total=self.n, desc=desc or "sweep", file=sys.stderr)
        elif callable(progress):
            self.callback = progress
            progress(0, self.n)

    def add(self, index: int, ok: bool, value: Any) -> None:
        self.done[index] = True
        self.count += 1
        if ok:
            self.results[index] = value
        else:
            self.failures[index] = value
        if self.bar is not None:
            self.bar.update(1)
        if self.callback is not None:
            self.callback(self.count, self.n)
        while self.prefix < self.n and self.done[self.prefix] and self.prefix not in self.failures:
            self.prefix += 1
        if self.prefix < self.n and self.prefix in self.failures:
            self.raise_failure(self.prefix)

    def raise_failure(self, index: int) -> None:
        failure = self.failures[index]
        exc = failure.exc
        point = self.points[index]
        if isinstance(point, Mapping):
            call = "fn(" + ", ".join(f"{k}={_repr.repr(v)}" for k, v in point.items()) + ")"
        else:
            call = f"fn({_repr.repr(point)})"
        message = (
            f"sweep point {index} (of {self.n}) failed: {call} raised {type(exc).__name__}: {exc}"
        )
        if failure.traceback:
            message += "\n\nTraceback in the worker:\n" + failure.traceback.rstrip()
        raise SweepError(message, index, point, failure.traceback) from exc

    def finish(self) -> list:
        if self.failures:  # pragma: no cover - add() raises first; defensive
            self.raise_failure(min(self.failures))
        if self.count != self.n:  # pragma: no cover - a backend lost results
            missing = [i for i, d in enumerate(self.done) if not d][:5]
            raise RuntimeError(f"sweep lost the results of points {missing}")
        return self.results

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


# --------------------------------------------------------------------------- sweep


def _default_jobs() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _check_picklable(fn: Callable, points: list, backend_name: str) -> None:
    try:
        import cloudpickle  # joblib >= 1.5 and distributed depend on it
    except ImportError:  # pragma: no cover - older joblib vendors it
        from joblib.externals import cloudpickle

    try:
        cloudpickle.dumps(fn)
    except Exception as exc:
        raise TypeError(
            f"fn {fn!r} cannot be pickled, so it cannot be sent to the workers of "
            f"backend={backend_name} ({type(exc).__name__}: {exc}). Define it at module "
            "level without unpicklable state (open files, locks, generators, solver handles "
            "built outside fn), or use backend='threads' or 'serial'."
        ) from exc
    for index, point in enumerate(points):
        try:
            cloudpickle.dumps(point)
        except Exception as exc:
            raise TypeError(
                f"point {index} ({_repr.repr(point)}) cannot be pickled for backend="
                f"{backend_name} ({type(exc).__name__}: {exc}); use backend='threads' or "
                "'serial', or pass picklable data and build the object inside fn."
            ) from exc


def _dask_client(backend: Any):
    distributed = sys.modules.get("distributed")
    if distributed is not None and isinstance(backend, distributed.Client):
        return backend
    return None


def sweep(
    fn: Callable,
    grid_or_samples: Mapping[str, Sequence] | Iterable,
    *,
    backend: str | Any = "processes",
    n_jobs: int | None = None,
    progress: bool | Callable[[int, int], Any] = False,
    desc: str | None = None,
) -> list:
    """Call ``fn`` on every point of a grid or list of samples, in parallel, in input order.

    Parameters
    ----------
    fn : callable
        Called once per point; must not depend on shared mutable state (each worker has its
        own copy of everything). Process backends pickle it (cloudpickle).
    grid_or_samples : mapping or sequence
        A mapping ``name -> values``: the Cartesian product, exactly :func:`grid` (``**``),
        each point called as ``fn(**point)``. A sequence (or any ordered iterable: a
        generator, the rows of a numpy array): one call per element, ``fn(**e)`` if the
        element is a dict (a mapping), else ``fn(e)``. A pandas DataFrame: one call per row,
        ``fn(**row)``. An empty mapping or sequence gives ``[]`` without starting any worker.
    backend : {"processes", "serial", "threads"} or distributed.Client
        Where the calls run (see the module docstring). Default joblib processes (loky).
    n_jobs : int, optional
        Number of workers, ≥ 1 (default: the cores this process may run on,
        ``len(os.sched_getaffinity(0))``; but 1 for a sweep called by ``fn`` of a parallel
        sweep, whose cores are already busy). Never more workers than points; one worker
        runs in the calling process. Ignored for a Dask client (the cluster decides).
    progress : bool or callable
        ``True``: a tqdm bar on stderr. A callable: called as ``progress(done, total)``
        with ``(0, total)`` first, then after each completed point, ending with
        ``(total, total)``; it runs in the calling process, in completion order.
    desc : str, optional
        Label of the tqdm bar (default ``"sweep"``).

    Returns
    -------
    list
        ``[fn(point) for point in points]``: same length and order as the input (grid
        points in C order), whatever the backend and completion order.

    Raises
    ------
    SweepError
        If ``fn`` raised for a point: ``.index``, ``.point``, chained from the original
        exception. With several failures, the lowest failing index is reported (the sweep
        stops as soon as every lower point has succeeded; queued points are cancelled).
    ValueError
        For an unknown ``backend``, ``n_jobs`` < 1 or not an integer, or a malformed grid
        (an empty axis — named — or a string instead of a sequence).
    TypeError
        If ``fn`` or a point cannot be pickled for a process or Dask backend (checked before
        any worker starts).

    Notes
    -----
    Each point runs with one BLAS thread (module docstring). Exceptions that are not
    ``Exception`` subclasses (``KeyboardInterrupt``, ``SystemExit``) are not wrapped, nor are
    failures of the machinery itself (a worker process killed, a Dask ``KilledWorker``).
    After a failure joblib restarts its loky workers on next use (a few seconds).

    Requires joblib ≥ 1.4 (``return_as="generator_unordered"``).
    """
    client = None
    if isinstance(backend, str):
        if backend not in BACKENDS:
            raise ValueError(
                f"backend must be one of {BACKENDS} or a dask distributed.Client, "
                f"got backend={backend!r}"
            )
        backend_name = backend
    else:
        client = _dask_client(backend)
        if client is None:
            raise ValueError(
                f"backend must be one of {BACKENDS} or a dask distributed.Client, "
                f"got backend={backend!r}"
            )
        backend_name = "dask"
    if not callable(fn):
        raise TypeError(f"fn must be callable, got {fn!r}")
    if n_jobs is None:
        # inside a worker of a parallel sweep: no pool of pools (cores are already busy)
        n_jobs = 1 if _in_worker() else _default_jobs()
    else:
        n_jobs = _int_at_least("n_jobs", n_jobs, 1)
    if not (progress is False or progress is True or callable(progress)):
        raise ValueError(
            f"progress must be True, False or a callable(done, total), got {progress!r}"
        )

    points = _points(grid_or_samples)
    remote = backend_name in ("processes", "dask")
    if remote and points:  # before any worker starts or progress is shown
        _check_picklable(fn, points, repr(backend) if client is None else "<Client>")
    collector = _Collector(points, progress, desc)
    try:
        if not points:
            return collector.finish()
        jobs = min(n_jobs, len(points))
        inline = backend_name == "serial" or (backend_name != "dask" and jobs == 1)
        call = _Call(fn, remote=remote and not inline, parallel=not inline)
        with _OneBlasThread():
            if inline:
                for index, point in enumerate(points):
                    collector.add(*call(index, point))
            elif client is not None:
                _run_dask(client, call, points, collector)
            else:
                _run_joblib(backend_name, jobs, call, points, collector)
        return collector.finish()
    finally:
        collector.close()


def _run_joblib(backend_name: str, jobs: int, call: _Call, points: list, collector) -> None:
    from joblib import Parallel, delayed, parallel_config

    if backend_name == "processes":
        config = parallel_config(backend="loky", inner_max_num_threads=1)
    else:
        config = parallel_config(backend="threading")
    with config:
        # batch_size "auto" groups quick points; ordered dispatch keeps low indices first.
        parallel = Parallel(n_jobs=jobs, return_as="generator_unordered")
        results = parallel(delayed(call)(i, p) for i, p in enumerate(points))
        try:
            for item in results:
                collector.add(*item)
        finally:
            # On an error joblib cancels what is still queued (and, for loky, restarts the
            # workers on next use); its warning about the cancelled tasks is noise beside the
            # SweepError being raised.
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", message=r".*tasks which were still being")
                results.close()


def _run_dask(client, call: _Call, points: list, collector) -> None:
    from distributed import as_completed

    token = uuid.uuid4().hex[:8]
    name = getattr(call.fn, "__name__", type(call.fn).__name__)
    keys = [f"sweep-{name}-{token}-{i}" for i in range(len(points))]
    boxes = [_Box(i, p) for i, p in enumerate(points)]
    futures = client.map(_BoxCall(call), boxes, key=keys, pure=False)
    try:
        for _future, item in as_completed(futures, with_results=True):
            collector.add(*item)
    finally:
        client.cancel(futures)


class _CallableModule(types.ModuleType):
    """This module's type: calling the module calls :func:`sweep`."""

    def __call__(self, fn: Callable, grid_or_samples: Any, **options: Any) -> list:
        return sweep(fn, grid_or_samples, **options)


sys.modules[__name__].__class__ = _CallableModule
