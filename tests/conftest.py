"""Shared pytest fixtures (keep small: several test modules use this file)."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import settings

import qpcoord as qc

# CI (CI=true) runs every property test on hypothesis's derandomized examples: the same
# examples on every run, so a landing never depends on a lucky draw. Local runs keep exploring
# new examples (a failure found there becomes an explicit test).
settings.register_profile("ci", derandomize=True, database=None)
if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
    settings.load_profile("ci")

#: Every installed QP backend, in qpcoord's preference order.
SOLVERS = qc.available_solvers()


@pytest.fixture(params=SOLVERS, ids=SOLVERS)
def solver(request) -> str:
    """Each installed QP backend in turn (test ids are the backend names)."""
    return request.param


@pytest.fixture
def rng() -> np.random.Generator:
    """A fresh, seeded generator (same numbers in every test and on every run)."""
    return np.random.default_rng(20240611)


@pytest.fixture
def missing_extension(monkeypatch):
    """Simulate an install without a C++ compiler: the native extension cannot be imported
    (``qpcoord.core.native`` falls back to the Python engine with one warning)."""
    from qpcoord.core import native

    def fail():
        raise ImportError("No module named 'qpcoord._native'")

    monkeypatch.setattr(native, "_import", fail)
    monkeypatch.setattr(native, "_module", None)
    monkeypatch.setattr(native, "_warned", False)
