"""qpcoord.studies.sweep: order, grid semantics, errors, progress, seeds, backends (incl. Dask)."""

from __future__ import annotations

import os
import pickle
import threading

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from qpcoord.studies.sweep import BACKENDS, SweepError, grid, seeds, sweep

# Module-level functions: picklable by reference for worker processes.


def add(a, b):
    return 10 * a + b


def square(x):
    return x * x


def fail_at(x, bad=(3,)):
    if x in bad:
        raise ValueError(f"bad point {x}")
    return x


def fail_at_2_and_5(x):
    if x in (2, 5):
        raise KeyError(x)
    return x


class Unpicklable(Exception):
    """An exception that cannot be rebuilt from its args (custom __init__ signature)."""

    def __init__(self, a, b):
        super().__init__(f"{a}-{b}")


def raise_unpicklable(x):
    raise Unpicklable(x, x)


def blas_threads(x):
    from threadpoolctl import threadpool_info

    blas = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    return max(blas) if blas else 1


def slow_reversed(x):
    """Later points finish first: completion order is the reverse of input order."""
    import time

    time.sleep(0.02 * (5 - x))
    return x


def inner_jobs(x):
    """A sweep inside a sweep: how many distinct processes/threads ran the inner points."""
    import os
    import time

    def who(_):
        time.sleep(0.05)
        return os.getpid(), threading.get_ident()

    return len(set(sweep(who, range(4), backend="threads")))


def ddl_run(seed, gain):
    """A short DDL coordinator run on a mismatched plant (the example's workload)."""
    import qpcoord.ddl as ddl
    from qpcoord.ddl.compare import DesignedOn, mismatched_plant

    r = ddl.kolmogorov_opd(0.1, 8000.0, seed=seed, preset="paranal_250hz")
    ctrl = DesignedOn(ddl.SisoCoordinator(), ddl.DualStage())
    run = ddl.simulate(mismatched_plant(gain), ctrl, r, 8000.0, seed=seed)
    return run.y, run.v, run.metrics["rmse"]


LOCAL = ("serial", "threads", "processes")


# ------------------------------------------------------------------- grid / seeds


def test_grid_is_c_order_product():
    g = grid(a=[1, 2], b=list("xyz"), c=range(2))
    assert len(g) == 2 * 3 * 2
    assert g[0] == {"a": 1, "b": "x", "c": 0}
    assert g[1] == {"a": 1, "b": "x", "c": 1}  # last axis fastest
    assert g[-1] == {"a": 2, "b": "z", "c": 1}
    for i, point in enumerate(g):
        ia, ib, ic = np.unravel_index(i, (2, 3, 2))
        assert point == {"a": [1, 2][ia], "b": "xyz"[ib], "c": ic}


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(1, 4), min_size=1, max_size=4))
def test_grid_size_and_order_property(lengths):
    axes = {f"a{k}": list(range(n)) for k, n in enumerate(lengths)}
    g = grid(**axes)
    assert len(g) == int(np.prod(lengths))
    assert [tuple(p.values()) for p in g] == list(np.ndindex(*lengths))
    assert sweep(lambda **kw: tuple(kw.values()), axes, backend="serial") == list(
        np.ndindex(*lengths)
    )


def test_grid_accepts_numpy_axes():
    g = grid(x=np.linspace(0.0, 1.0, 3))
    assert [p["x"] for p in g] == [0.0, 0.5, 1.0]


@pytest.mark.parametrize("bad", [[], (), range(0), np.array([])])
def test_grid_empty_axis_is_named(bad):
    with pytest.raises(ValueError, match="'gain'"):
        grid(seed=[1, 2], gain=bad)


@pytest.mark.parametrize("bad", ["abc", {1, 2}, {"a": 1}, 3])
def test_grid_axis_must_be_ordered_sequence(bad):
    with pytest.raises(ValueError, match="'x'"):
        grid(x=bad)


def test_grid_needs_an_axis():
    with pytest.raises(ValueError, match="at least one axis"):
        grid()


def test_seeds_reproducible_and_independent():
    s = seeds(8, root=5)
    assert s == seeds(8, root=5)
    assert s[:3] == seeds(3, root=5)  # growing a study keeps its first seeds
    assert len(set(s)) == 8
    assert set(s).isdisjoint(seeds(8, root=6))
    assert all(isinstance(x, int) and 0 <= x < 2**63 for x in s)
    children = np.random.SeedSequence(5).spawn(8)
    expected = [int(c.generate_state(1, dtype=np.uint64)[0] >> np.uint64(1)) for c in children]
    assert s == expected
    draws = np.array([np.random.default_rng(x).standard_normal(2000) for x in s])
    corr = np.corrcoef(draws)
    assert np.abs(corr[~np.eye(8, dtype=bool)]).max() < 0.1


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "3"])
def test_seeds_rejects_bad_n(bad):
    with pytest.raises(ValueError, match="n must"):
        seeds(bad)


def test_seeds_rejects_negative_root():
    with pytest.raises(ValueError, match="root"):
        seeds(2, root=-1)


# ------------------------------------------------------------------- semantics, order


@pytest.mark.parametrize("backend", LOCAL)
def test_order_and_grid_semantics(backend):
    axes = {"a": [1, 2, 3], "b": [4, 5]}
    expected = [add(**p) for p in grid(**axes)]
    assert sweep(add, axes, backend=backend, n_jobs=2) == expected
    assert sweep(add, grid(**axes), backend=backend, n_jobs=2) == expected


@pytest.mark.parametrize("backend", ("threads", "processes"))
def test_order_kept_when_completion_order_is_reversed(backend):
    assert sweep(slow_reversed, range(6), backend=backend, n_jobs=2) == list(range(6))


def test_kwargs_vs_positional():
    samples = [{"a": 1, "b": 2}, (3, 4), 5]
    out = sweep(lambda *args, **kw: (args, kw), samples, backend="serial")
    assert out == [((), {"a": 1, "b": 2}), (((3, 4),), {}), ((5,), {})]


def test_generators_and_arrays_are_samples():
    assert sweep(square, (i for i in range(4)), backend="serial") == [0, 1, 4, 9]
    assert sweep(square, np.arange(3), backend="threads", n_jobs=2) == [0, 1, 4]


def test_dataframe_rows_are_kwargs():
    class Frame:  # what sweep relies on from a pandas DataFrame (pandas is optional)
        columns = ["a", "b"]

        def __iter__(self):  # a DataFrame iterates over its column names
            return iter(self.columns)

        def to_dict(self, orient):
            assert orient == "records"
            return [{"a": 1, "b": 3}, {"a": 2, "b": 4}]

    assert sweep(add, Frame(), backend="serial") == [13, 24]


@pytest.mark.parametrize("backend", LOCAL)
def test_empty_input_gives_empty_list(backend):
    calls = []
    # an unpicklable fn is fine: no worker is started, nothing is pickled
    lock = threading.Lock()
    out = sweep(lambda x: lock, [], backend=backend, progress=lambda d, t: calls.append((d, t)))
    assert out == []
    assert calls == [(0, 0)]
    assert sweep(square, {}, backend=backend) == []


def test_lambdas_work_with_processes():
    k = 3
    assert sweep(lambda x: x + k, [1, 2, 3], backend="processes", n_jobs=2) == [4, 5, 6]


# ------------------------------------------------------------------- errors


@pytest.mark.parametrize("bad", ["loky", "dask", "Serial", None, 3, object()])
def test_bad_backend(bad):
    with pytest.raises(ValueError, match="backend") as info:
        sweep(square, [1], backend=bad)
    assert repr(bad) in str(info.value)


@pytest.mark.parametrize("bad", [0, -2, 1.5, True, "2"])
def test_bad_n_jobs(bad):
    with pytest.raises(ValueError, match="n_jobs"):
        sweep(square, [1], n_jobs=bad)


def test_bad_inputs():
    with pytest.raises(ValueError, match="'seed'"):
        sweep(add, {"seed": [], "b": [1]})
    with pytest.raises(ValueError, match="grid_or_samples"):
        sweep(square, "abc")
    with pytest.raises(ValueError, match="grid_or_samples"):
        sweep(square, 5)
    with pytest.raises(ValueError, match="keys must be strings"):
        sweep(square, {1: [1, 2]})
    with pytest.raises(ValueError, match="progress"):
        sweep(square, [1], progress="yes")
    with pytest.raises(TypeError, match="callable"):
        sweep(None, [1])


@pytest.mark.parametrize("backend", LOCAL)
def test_fn_raising_gives_sweep_error(backend):
    with pytest.raises(SweepError) as info:
        sweep(fail_at, range(6), backend=backend, n_jobs=2)
    err = info.value
    assert isinstance(err, RuntimeError)
    assert err.index == 3 and err.point == 3
    assert isinstance(err.__cause__, ValueError)
    assert "bad point 3" in str(err.__cause__)
    assert "point 3" in str(err) and "ValueError" in str(err)
    if backend == "processes":
        assert "fail_at" in err.remote_traceback  # the worker's traceback is kept as text
    else:
        assert err.remote_traceback is None


@pytest.mark.parametrize("backend", LOCAL)
def test_lowest_failing_index_is_reported(backend):
    with pytest.raises(SweepError) as info:
        sweep(fail_at_2_and_5, range(8), backend=backend, n_jobs=2)
    assert info.value.index == 2
    assert isinstance(info.value.__cause__, KeyError)


def test_sweep_error_names_grid_point():
    with pytest.raises(SweepError) as info:
        sweep(lambda a, b: 1 / (a - b), {"a": [1, 2], "b": [2, 1]}, backend="serial")
    assert info.value.index == 1 and info.value.point == {"a": 1, "b": 1}
    assert "a=1, b=1" in str(info.value)
    assert isinstance(info.value.__cause__, ZeroDivisionError)


def test_sweep_error_pickles():
    err = pickle.loads(pickle.dumps(SweepError("msg", 4, {"a": 1})))
    assert (err.index, err.point, str(err)) == (4, {"a": 1}, "msg")


def test_unpicklable_exception_from_worker():
    with pytest.raises(SweepError) as info:
        sweep(raise_unpicklable, [7, 8], backend="processes", n_jobs=2)
    assert info.value.index == 0
    assert isinstance(info.value.__cause__, RuntimeError)
    assert "Unpicklable" in str(info.value.__cause__)


def test_unpicklable_fn_is_a_clear_error():
    lock = threading.Lock()
    with pytest.raises(TypeError, match="cannot be pickled"):
        sweep(lambda x: (lock, x), [1, 2], backend="processes")
    assert len(sweep(lambda x: (lock, x), [1, 2], backend="threads", n_jobs=2)) == 2


def test_unpicklable_point_is_a_clear_error():
    calls = []
    with pytest.raises(TypeError, match="point 1"):
        sweep(
            square, [1, threading.Lock()], backend="processes", progress=lambda *c: calls.append(c)
        )
    assert calls == []  # refused before anything started


# ------------------------------------------------------------------- progress, threads


@pytest.mark.parametrize("backend", LOCAL)
def test_progress_callable(backend):
    calls = []
    sweep(square, range(7), backend=backend, n_jobs=2, progress=lambda d, t: calls.append((d, t)))
    assert calls == [(k, 7) for k in range(8)]


def test_progress_bar(capsys):
    assert sweep(square, range(3), backend="serial", progress=True, desc="squares") == [0, 1, 4]
    assert "squares" in capsys.readouterr().err


def test_one_blas_thread_then_restored():
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=2, user_api="blas"):
        assert blas_threads(0) == 2
        assert sweep(blas_threads, range(4), backend="serial") == [1] * 4
        assert sweep(blas_threads, range(4), backend="threads", n_jobs=2) == [1] * 4
        assert blas_threads(0) == 2
    assert sweep(blas_threads, range(4), backend="processes", n_jobs=2) == [1] * 4


@pytest.mark.parametrize("backend", ("threads", "processes"))
def test_nested_sweep_runs_inside_the_worker(backend):
    # inside a parallel sweep, an inner sweep defaults to one job: no pool of pools
    assert sweep(inner_jobs, range(2), backend=backend, n_jobs=2) == [1, 1]
    # outside (and inside a serial sweep) it uses the cores
    if len(os.sched_getaffinity(0)) > 1:
        assert inner_jobs(0) > 1
        assert sweep(inner_jobs, range(1), backend="serial")[0] > 1


def test_backends_constant():
    assert BACKENDS == ("serial", "processes", "threads")


# ------------------------------------------------------------------- a real workload


def test_ddl_runs_bit_for_bit_across_backends():
    points = grid(seed=seeds(2, root=1), gain=[0.8, 1.2])
    serial = sweep(ddl_run, points, backend="serial")
    parallel = sweep(ddl_run, points, backend="processes", n_jobs=2)
    assert len(parallel) == 4
    for (y0, v0, e0), (y1, v1, e1) in zip(serial, parallel, strict=True):
        assert np.array_equal(y0, y1) and np.array_equal(v0, v1) and e0 == e1
    assert serial[0][2] != serial[1][2]  # the mismatch changes the run


# ------------------------------------------------------------------- Dask


@pytest.fixture(scope="module")
def dask_client():
    distributed = pytest.importorskip("distributed")
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0"
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        yield client


def test_dask_order_grid_and_progress(dask_client):
    calls = []
    out = sweep(
        add, {"a": [1, 2, 3], "b": [4, 5]}, backend=dask_client, progress=lambda *c: calls.append(c)
    )
    assert out == [add(**p) for p in grid(a=[1, 2, 3], b=[4, 5])]
    assert calls[0] == (0, 6) and calls[-1] == (6, 6)
    assert sweep(slow_reversed, range(6), backend=dask_client) == list(range(6))
    # tuples are points, not dask tasks: (callable, arg) must reach fn untouched
    assert sweep(lambda p: p, [(square, 3)], backend=dask_client) == [(square, 3)]


def test_dask_errors(dask_client):
    with pytest.raises(SweepError) as info:
        sweep(fail_at_2_and_5, range(8), backend=dask_client)
    assert info.value.index == 2 and info.value.point == 2
    assert isinstance(info.value.__cause__, KeyError)
    assert sweep(square, [], backend=dask_client) == []
    with pytest.raises(ValueError, match="n_jobs"):
        sweep(square, [1], backend=dask_client, n_jobs=0)


def test_dask_process_cluster_runs_ddl_like_serial():
    distributed = pytest.importorskip("distributed")
    points = grid(seed=seeds(1, root=2), gain=[0.8, 1.2])
    serial = sweep(ddl_run, points, backend="serial")
    with (
        distributed.LocalCluster(
            n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        out = sweep(ddl_run, points, backend=client)
        assert sweep(blas_threads, range(2), backend=client) == [1, 1]
    for (y0, v0, e0), (y1, v1, e1) in zip(serial, out, strict=True):
        assert np.array_equal(y0, y1) and np.array_equal(v0, v1) and e0 == e1


def test_the_module_is_callable_as_the_issue_spells_it():
    """``qpcoord.studies.sweep(fn, grid, backend=...)`` is ``qpcoord.studies.sweep.sweep``; the
    module keeps
    its other names and its module type."""
    import types

    import qpcoord as qc
    import qpcoord.studies.sweep as module

    assert module is qc.sweep and isinstance(module, types.ModuleType)
    assert qc.sweep(add, {"a": [1, 2], "b": [10]}, backend="serial") == [add(1, 10), add(2, 10)]
    with pytest.raises(ValueError, match="backend"):
        qc.sweep(add, [1], backend="gpu")
    assert qc.sweep.grid(a=[1]) == [{"a": 1}]
