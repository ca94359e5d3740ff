"""The published problems moved as the benchmarks move them: the benchmark scripts imported
as modules, and a published stack with its ``move(step)``."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import qpcoord as qc

from .hlsp import load

#: benchmarks/ of the repository
BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


def benchmark_module(name: str):
    """The script ``benchmarks/<name>.py`` imported as a module."""
    sys.path.insert(0, str(BENCHMARKS))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.pop(0)


def published_module():
    """``benchmarks/hierarchy_published.py`` imported (the LexLS humanoid and its moves)."""
    return benchmark_module("hierarchy_published")


def published_stack(stem: str, box: bool = False, unit: bool = False):
    """``(stack, move(step))`` of a published problem (``tests/data/hlsp``), moved as
    ``hierarchy_published.py``'s re-solve table does (``box``: simple rows as bounds;
    ``unit``: its unit-row copy)."""
    hp = published_module()
    prob = load(stem, simple_as_bounds=box)
    levels = hp.unit_rows(prob.levels) if unit else prob.levels
    return qc.Stack(levels, bounds=prob.bounds), hp._mover(levels)
