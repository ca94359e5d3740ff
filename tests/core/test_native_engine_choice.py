"""Which engine ``Stack.solve`` and ``solve_stack`` use: the native engine by default where
it is built, the Python engine for other methods and backends, one warning and the Python
engine where it is not built, and the errors of a bad ``engine`` argument.

The fallback tests run everywhere: they simulate a missing extension.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from support.native_engine import needs_native
from support.stacks import clipped_stack

import qpcoord as qc
from qpcoord.core import native


def test_default_falls_back_with_one_warning(missing_extension, monkeypatch):
    monkeypatch.setattr(native, "DEFAULT_ENGINE", "native")
    s = clipped_stack()
    with pytest.warns(RuntimeWarning, match="native engine is not built") as rec:
        sol = s.solve()
    assert len(rec) == 1
    assert rec[0].filename == __file__  # stacklevel: the user's call
    assert sol.solver != "native"
    np.testing.assert_allclose(sol.x, [1.0, 1.0, 1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert s.solve().solver != "native"  # once per process


def test_explicit_native_without_extension_raises(missing_extension):
    with pytest.raises(native.NativeUnavailableError, match="not built"):
        clipped_stack().solve(engine="native")
    with pytest.raises(ImportError):
        clipped_stack().solve(engine="native")


def test_python_default_never_warns(missing_extension, monkeypatch):
    monkeypatch.setattr(native, "DEFAULT_ENGINE", "python")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert clipped_stack().solve().solver != "native"
        assert clipped_stack().solve(engine="python").solver != "native"


@needs_native
def test_default_is_native_where_built():
    """``engine=None`` on a hierarchical stack without ``solver=`` is the native engine."""
    assert native.DEFAULT_ENGINE == "native"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert clipped_stack().solve().solver == "native"
        assert qc.solve_stack([qc.Equality(np.eye(2), [1.0, 2.0])]).solver == "native"
    assert clipped_stack().solve(engine="python").solver != "native"


def test_engine_argument_errors():
    s = clipped_stack()
    with pytest.raises(ValueError, match="unknown engine 'fast'"):
        s.solve(engine="fast")
    with pytest.raises(ValueError, match="method='nullspace'"):
        s.solve(method="nullspace", engine="native")
    with pytest.raises(ValueError, match="solver='daqp'"):
        s.solve(solver="daqp", engine="native")


def test_default_uses_python_for_other_methods(monkeypatch):
    monkeypatch.setattr(native, "DEFAULT_ENGINE", "native")
    s = clipped_stack()
    assert (
        qc.Stack([qc.Equality(np.eye(2), [1.0, 2.0])]).solve(method="nullspace").solver != "native"
    )
    assert s.solve(solver="daqp").solver == "daqp"


@needs_native
def test_solve_stack_engine():
    sol = qc.solve_stack([qc.Equality(np.eye(2), [3.0, -3.0])], engine="native")
    assert sol.solver == "native"
    np.testing.assert_allclose(sol.x, [3.0, -3.0])
