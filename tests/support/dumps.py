"""Stacks stored level by level in ``.npz`` files (``tests/data``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import qpcoord as qc

#: The suite's data directory.
DATA = Path(__file__).resolve().parents[1] / "data"


def spec_from_npz(path: Path) -> dict:
    """The ``Stack`` keyword arguments (``levels``, ``bounds``, ``constraints``) of a stack
    stored level by level as ``L{k}_{j}_eq_{A,b,w}`` / ``L{k}_{j}_in_{C,lo,hi,w}``, with
    optional bounds ``bounds_{lb,ub}`` and hard constraints ``H{j}_eq_{A,b}`` /
    ``H{j}_in_{C,lo,hi}``; fresh tasks on every call."""
    with np.load(path) as f:
        d = {k: f[k] for k in f.files}
    levels: dict[int, dict[int, qc.Equality | qc.Inequality]] = {}
    hard: dict[int, qc.Equality | qc.Inequality] = {}
    for key in d:
        if key.startswith("bounds_"):
            continue
        if key.startswith("H"):
            j, kind, _ = key.split("_")
            j = int(j[1:])
            p = f"H{j}_{kind}_"
            if kind == "eq":
                hard[j] = qc.Equality(d[p + "A"], d[p + "b"])
            else:
                hard[j] = qc.Inequality(d[p + "C"], d[p + "lo"], d[p + "hi"])
            continue
        k, j, kind, _ = key.split("_")
        k, j = int(k[1:]), int(j)
        if j in levels.setdefault(k, {}):
            continue
        p = f"L{k}_{j}_{kind}_"
        if kind == "eq":
            task = qc.Equality(d[p + "A"], d[p + "b"], weight=d[p + "w"])
        else:
            task = qc.Inequality(d[p + "C"], d[p + "lo"], d[p + "hi"], weight=d[p + "w"])
        levels[k][j] = task
    bounds = qc.Bounds(d["bounds_lb"], d["bounds_ub"]) if "bounds_lb" in d else None
    return dict(
        levels=[[levels[k][j] for j in sorted(levels[k])] for k in sorted(levels)],
        bounds=bounds,
        constraints=[hard[j] for j in sorted(hard)] or None,
    )
