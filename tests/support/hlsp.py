"""Published hierarchical least-squares test problems (``tests/data/hlsp/``) as ``qc.Stack``.

Each ``.npz`` holds ``n``, ``num_levels`` and per level ``A{k}``, ``lower{k}``, ``upper{k}``
(±inf where open), ``eq{k}`` (rows with ``lower == upper``) and ``simple{k}`` (rows that
are simple variable bounds: a single unit entry, LexLS's ``SIMPLE_BOUNDS_OBJECTIVE``, given
there as 1-based variable indices); ``lexls_solution`` where the source publishes one
(see ``tests/data/hlsp/README.md``). Level ``k`` minimises the squared violation of its
rows, lexicographically (level 0 first).

Mapping. Rows with ``lower == upper`` become one :class:`qc.Equality` per level (``A x = b``),
the others one :class:`qc.Inequality` (``lower ≤ C x ≤ upper``), all of weight 1 (the
sources weigh every row alike). In LexLS the simple bounds are an *objective* like any other
(objective 0, minimised in the least-squares sense), not hard constraints. Only the
humanoid has them, as the whole of level 0, with ``lower ≤ upper`` on every row: the
level-0 optimum is then zero violation and its optimal set is exactly the box, so the
lexicographic problem is the same with the box as hard :class:`qc.Bounds`.
``load(..., simple_as_bounds=True)`` does that (only where it is the same problem: level 0
all simple, consistent, else ``ValueError``); the default keeps the rows as level 0 (the
published form). soth's joint limits (``soth_sot`` level 0, an identity) are not flagged
simple in the source and stay a level.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

import qpcoord as qc

DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data", "hlsp")

#: Every published problem (file stem).
NAMES = tuple(sorted(f[:-4] for f in os.listdir(DATA) if f.endswith(".npz")))


@dataclass
class Problem:
    name: str
    n: int
    levels: list  # per level: a task or a list of tasks
    bounds: qc.Bounds | None
    #: the published solution (LexLS), else None
    solution: np.ndarray | None
    source: str

    def stack(self, **options) -> qc.Stack:
        """A fresh :class:`qc.Stack` of the problem (``options`` go to ``qc.Stack``)."""
        return qc.Stack(self.levels, bounds=self.bounds, **options)


def _level(A, lo, up):
    eq = lo == up
    tasks = []
    if eq.any():
        tasks.append(qc.Equality(A[eq], lo[eq]))
    if (~eq).any():
        tasks.append(qc.Inequality(A[~eq], lo[~eq], up[~eq]))
    return tasks[0] if len(tasks) == 1 else tasks


def _box(A, lo, up, n):
    """The box of simple-bound rows (several rows on one variable intersect)."""
    var = np.argmax(np.abs(A), axis=1)
    sign = A[np.arange(A.shape[0]), var]
    if not np.all(np.abs(sign) == 1.0) or np.count_nonzero(A) != A.shape[0]:
        raise ValueError("simple_as_bounds: level 0 rows are not unit rows")
    # a row -x_j: lower ≤ -x_j ≤ upper  ⇔  -upper ≤ x_j ≤ -lower
    rlo = np.where(sign > 0, lo, -up)
    rup = np.where(sign > 0, up, -lo)
    lb, ub = np.full(n, -np.inf), np.full(n, np.inf)
    np.maximum.at(lb, var, rlo)
    np.minimum.at(ub, var, rup)
    if np.any(lb > ub):
        raise ValueError("simple_as_bounds: level 0 bounds are inconsistent (not a box)")
    return qc.Bounds(lb, ub)


def load(name: str, simple_as_bounds: bool = False) -> Problem:
    """One published problem by file stem (see :data:`NAMES`)."""
    if name not in NAMES:
        raise ValueError(f"name must be one of {NAMES}, got {name!r}")
    d = np.load(os.path.join(DATA, name + ".npz"), allow_pickle=False)
    n = int(d["n"])
    raw = [
        (np.asarray(d[f"A{k}"], float), np.asarray(d[f"lower{k}"], float),
         np.asarray(d[f"upper{k}"], float), np.asarray(d[f"simple{k}"], bool))
        for k in range(int(d["num_levels"]))
    ]  # fmt: skip
    bounds = None
    if simple_as_bounds:
        A, lo, up, simple = raw[0]
        if not simple.all():
            raise ValueError(f"simple_as_bounds: level 0 of {name} is not all simple bounds")
        bounds = _box(A, lo, up, n)
        raw = raw[1:]
    levels = [_level(A, lo, up) for A, lo, up, _ in raw]
    sol = np.asarray(d["lexls_solution"], float) if "lexls_solution" in d.files else None
    return Problem(name, n, levels, bounds, sol, str(d["source"]))
