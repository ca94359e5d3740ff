"""Shared pytest fixtures (keep small: several test modules use this file)."""

from __future__ import annotations

import numpy as np
import pytest

import qpcoord as qc

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
