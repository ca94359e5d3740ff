"""No heap allocation in a native call after the first: the C++ drivers (built once per
session by ``tests/conftest.py``; ``src/native/tools/count_allocations.hpp`` counts malloc,
calloc, realloc and the aligned forms, where Eigen's storage allocates) replay moving problems
that exercise every stage of the strict hierarchy and the weighted QP.
"""

from __future__ import annotations

import importlib.util
import subprocess
from pathlib import Path

import numpy as np
import pytest
from support.native_engine import needs_native
from support.stacks import hard_random_stack, hard_row_stack, inequality_shifts

import qpcoord as qc


def _hard_row_scenario(rng) -> dict:
    """Hard rows that x = 0 breaks (the least-violation phase runs), one level, moving."""
    s, _, shift = hard_row_stack(rng)

    def move(step, x=None):
        shift(step)

    return {"stack": s, "move": move, "daqp": None}


def _conflict_scenario(rng) -> dict:
    """Conflicting inequality levels with moving rows: misses, seeds, drops (downdates)."""
    s = hard_random_stack(int(rng.integers(100)), n=30, levels=6)
    shift = inequality_shifts(s)

    def move(step, x=None):
        shift(step)

    return {"stack": s, "move": move, "daqp": None}


def _small_damped_scenario(rng) -> dict:
    """Small levels (n = 10 < 16 columns: the size below which Eigen 3.4's BDCSVD built a
    local JacobiSVD per call) with near-singular equality rows under a large damping, so the
    closed form goes by the SVD, not the QR; a moving inequality level before them changes
    the free dimension r from call to call (the projected matrices change width)."""
    n = 10
    A1 = rng.standard_normal((3, n))
    A1[2] = A1[0] + 1e-4 * rng.standard_normal(n)  # a singular value below the damping
    A2 = rng.standard_normal((4, n))
    A2[3] = A2[1] - 1e-4 * rng.standard_normal(n)
    C0 = rng.standard_normal((4, n))
    eq1 = qc.Equality(A1, rng.standard_normal(3))
    ineq = qc.Inequality(C0, -0.3 * np.ones(4), 0.3 * np.ones(4))
    eq2 = qc.Equality(A2, rng.standard_normal(4))
    s = qc.Stack([[ineq], [eq1], [eq2]], bounds=qc.Bounds(-2.0, 2.0), damping=1e-2)
    b1, b2, lo = eq1.b.copy(), eq2.b.copy(), ineq.lower.copy()

    def move(step, x=None):
        eq1.update(b=b1 + 0.5 * np.sin(0.9 * step))
        eq2.update(b=b2 * (1.0 + 0.4 * np.cos(0.6 * step)))
        shift = 0.25 * np.sin(1.3 * step + np.arange(4))  # rows enter and leave the active set
        ineq.update(lower=lo + shift, upper=lo + shift + 0.6)

    return {"stack": s, "move": move, "daqp": None}


@pytest.mark.engine_independent
@needs_native
def test_the_native_call_allocates_nothing_after_the_first(tmp_path, hierarchy_driver):
    """The C++ driver (src/native/tools/driver.cpp; tools/count_allocations.hpp counts malloc,
    calloc, realloc and the aligned forms, where Eigen's storage allocates) replays moving
    stacks that exercise every stage — the hard phase, levels with misses, seeded starts, QR
    appends and downdates, the minimum-norm step, damped closed forms by the SVD on small
    levels whose width changes, the slack step of the moving LexLS humanoid's 72-row level —
    warm and cold: no heap allocation in any call after the first pass, and every call
    succeeds."""
    root = Path(__file__).resolve().parents[2]
    tools = root / "src" / "native" / "tools"
    spec = importlib.util.spec_from_file_location("dump_problems", tools / "dump_problems.py")
    dp = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(dp)
    scenarios = {
        "hard": _hard_row_scenario,
        "conflict": _conflict_scenario,
        "small_damped": _small_damped_scenario,
    }
    for name, make in scenarios.items():
        dp.dump(name, make, 12, tmp_path)
    dp.dump_stack("humanoid", *dp.published("humanoid"), 6, tmp_path)
    exe = hierarchy_driver
    for name in [*scenarios, "humanoid"]:
        for mode in ("warm", "cold"):
            out = subprocess.run(
                [str(exe), str(tmp_path / f"{name}.bin"), "3" if name in scenarios else "2", mode],
                capture_output=True, text=True, timeout=300,
            )  # fmt: skip
            assert out.returncode == 0, (name, mode, out.stderr)
            assert "allocations after the first pass 0" in out.stdout, (name, mode, out.stdout)


@pytest.mark.engine_independent
@needs_native
def test_the_weighted_qp_allocates_nothing_after_the_first(weighted_driver):
    """``src/native/tools/weighted_driver.cpp`` counts heap allocations (malloc, where Eigen
    allocates, and ``operator new``) over 2 000 solves after the first: 0 with the factor
    kept and 0 with it rebuilt every call (the rebuild made 3 mallocs per call, products with
    strided views of the rows, until they were copied into a contiguous buffer)."""
    import subprocess

    exe = str(weighted_driver)
    out = subprocess.run([exe, "12"], check=True, capture_output=True, text=True).stdout
    lines = out.strip().splitlines()
    assert len(lines) == 2, out
    assert all(line.endswith("allocations after the first 0") for line in lines), out
