"""Seeded stack families of the solver comparison, and their exact references.

Stacks are built from seeded ``numpy`` generators: Gaussian entries and targets of order 1,
``n ≤ 12``. Every family keeps the numbers away from the degenerate cases in which a strict
hierarchy is ill-posed: non-zero singular values (also of the projected levels) stay above
~1e-4·s₀ (far above the damping threshold 1e-7·s₀, so damped and exact pseudo-inverses
coincide) and inequality violations at an optimum are either 0 or ≥ ~1e-3.

A case is ``(family name, seed)`` (:data:`CASES`); :func:`build` makes fresh tasks for it,
:func:`stack` a stack without fallback backends, :func:`reference` the
:func:`support.oracle.lexicographic` solution (cached).
"""

from __future__ import annotations

import functools

import numpy as np

import qpcoord as qc

from .oracle import OracleResult, lexicographic


def _conditioned(rng, m: int, n: int, cond: float) -> np.ndarray:
    """Random ``m × n`` matrix with singular values log-spaced over ``[1/cond, 1]``."""
    k = min(m, n)
    U, _ = np.linalg.qr(rng.standard_normal((m, m)))
    V, _ = np.linalg.qr(rng.standard_normal((n, n)))
    return (U[:, :k] * np.logspace(0, -np.log10(cond), k)) @ V[:, :k].T


def _eq(rng, m, n, scale=1.0, **kw):
    return qc.Equality(rng.standard_normal((m, n)), scale * rng.standard_normal(m), **kw)


#: name -> (builder(rng) -> dict(levels, bounds, constraints), tags)
FAMILIES: dict = {}


def family(*tags):
    def register(fn):
        FAMILIES[fn.__name__] = (fn, frozenset(tags))
        return fn

    return register


@family("eq_only", "feasible")
def feasible_eq(rng):
    """3 equality levels of 2, 3, 3 rows in n = 10: all satisfiable, 2 free dofs left."""
    return dict(levels=[_eq(rng, m, 10) for m in (2, 3, 3)])


@family("eq_only")
def conflicting_eq(rng):
    """3, 3, 4 rows in n = 7: level 2 has 1 dof left and conflicts with the levels above."""
    return dict(levels=[_eq(rng, m, 7) for m in (3, 3, 4)])


@family("eq_only")
def rank_deficient_eq(rng):
    """Duplicate and linearly dependent rows, within a level (consistent and inconsistent
    targets) and across levels (a lower level repeating a higher level's rows)."""
    n = 8
    A = rng.standard_normal((2, n))
    b = rng.standard_normal(2)
    A0 = np.vstack([A, A[0] + 2 * A[1], A[1]])  # row 2 consistent, row 3 conflicting
    b0 = np.concatenate([b, [b[0] + 2 * b[1], b[1] + 0.7]])
    A1 = np.vstack([A[0], 3 * A[1], rng.standard_normal((3, n))])  # 2 rows of level 0
    A2 = rng.standard_normal((2, n))
    A2 = np.vstack([A2, A2.sum(0)])  # a sum row with an independent target
    return dict(
        levels=[
            qc.Equality(A0, b0),
            qc.Equality(A1, rng.standard_normal(5)),
            qc.Equality(A2, rng.standard_normal(3)),
        ]
    )


@family("eq_only", "feasible")
def ill_conditioned_feasible(rng):
    """Singular values of every level log-spaced over 1e4; 3 + 3 + 2 rows in n = 9."""
    return dict(
        levels=[
            qc.Equality(_conditioned(rng, m, 9, 1e4), rng.standard_normal(m)) for m in (3, 3, 2)
        ]
    )


@family("eq_only")
def ill_conditioned_conflicting(rng):
    """Singular values spread over 1e4; 3 + 3 + 3 rows in n = 6."""
    return dict(
        levels=[
            qc.Equality(_conditioned(rng, m, 6, 1e4), rng.standard_normal(m)) for m in (3, 3, 3)
        ]
    )


@family("eq_only")
def weighted_eq(rng):
    """Row weights 1e-2 … 1e2 inside conflicting levels (2, 3, 4 rows in n = 6)."""
    return dict(levels=[_eq(rng, m, 6, weight=np.logspace(-2, 2, m)) for m in (2, 3, 4)])


@family("eq_only")
def hard_equalities(rng):
    """Hard equalities (one dependent, consistent row) and three conflicting levels."""
    n = 9
    A = rng.standard_normal((2, n))
    b = rng.standard_normal(2)
    hard = qc.Equality(np.vstack([A, A[0] - A[1]]), np.append(b, b[0] - b[1]))
    return dict(levels=[_eq(rng, m, n) for m in (3, 3, 3)], constraints=[hard])


@family("eq_only")
def saturated_top(rng):
    """Level 0 is square and invertible: the lower levels have no freedom left."""
    n = 5
    return dict(levels=[_eq(rng, n, n), _eq(rng, 2, n), _eq(rng, 3, n)])


@family()
def bounded_eq(rng):
    """Equality levels pushing against active bounds (n = 8): QPs at every level."""
    n = 8
    return dict(
        levels=[
            _eq(rng, 3, n, scale=2.0),
            _eq(rng, 2, n),
            qc.Equality(np.eye(n), rng.uniform(-1, 1, n)),
        ],
        bounds=qc.Bounds(-0.5 * np.ones(n), 0.5 * np.ones(n)),
    )


@family()
def inequality_levels(rng):
    """Inequality-only levels under active bounds: level 0 has a row the bounds make
    unreachable, level 1 contains a contradictory pair (c·x ≥ 1 and c·x ≤ −1), level 2 an
    equality that drives more bounds active."""
    n = 8
    C0 = rng.standard_normal((4, n))
    c = rng.standard_normal(n)
    C1 = np.vstack([c, c, rng.standard_normal((2, n))])
    return dict(
        levels=[
            qc.Inequality(C0, [0.5, -np.inf, 6.0, -1.0], [np.inf, 0.2, np.inf, 1.0]),
            qc.Inequality(C1, [1.0, -np.inf, -0.3, 0.4], [np.inf, -1.0, 0.3, np.inf]),
            _eq(rng, 3, n, scale=3.0),
        ],
        bounds=qc.Bounds(-np.ones(n), np.ones(n)),
    )


@family()
def mixed_levels(rng):
    """Equality and Inequality tasks in the same level, bounds, a posture task last."""
    n = 10
    return dict(
        levels=[
            [_eq(rng, 2, n), qc.Inequality(rng.standard_normal((3, n)), upper=-1.5)],
            [_eq(rng, 4, n, scale=2.0), qc.Inequality(rng.standard_normal((2, n)), -0.2, 0.2)],
            qc.Equality(np.eye(n), rng.uniform(-1, 1, n)),
        ],
        bounds=qc.Bounds(-0.8, 0.8),
    )


@family()
def hard_mixed(rng):
    """Hard equality + hard two-sided inequality + bounds; the min-norm point of the hard
    equalities violates the hard inequalities, so the hard phase needs its QP."""
    n = 10
    A = rng.standard_normal((2, n))
    C = rng.standard_normal((3, n))
    x0 = np.linalg.pinv(A) @ rng.standard_normal(2)
    hard = [
        qc.Equality(A, A @ x0),
        qc.Inequality(C, C @ x0 + 0.3, C @ x0 + 0.8),  # excludes x0 itself
    ]
    return dict(
        levels=[
            _eq(rng, 3, n, scale=3.0),
            [_eq(rng, 3, n), qc.Inequality(rng.standard_normal((2, n)), lower=1.0)],
            qc.Equality(np.eye(n), np.zeros(n)),
        ],
        constraints=hard,
        bounds=qc.Bounds(-1.0, 1.0),
    )


@family()
def weighted_mixed(rng):
    """Row weights 0.1 … 10 (equalities) and 0.2, 5 (inequalities); satisfiable level 0,
    conflicting level 1 (weights 1e-2 … 1e2), bounds."""
    n = 8
    return dict(
        levels=[
            [
                _eq(rng, 3, n, weight=[1.0, 10.0, 0.1]),
                qc.Inequality(
                    rng.standard_normal((2, n)), [2.0, -np.inf], [np.inf, -2.0], weight=[5.0, 0.2]
                ),
            ],
            _eq(rng, 7, n, weight=np.logspace(-2, 2, 7)),
        ],
        bounds=qc.Bounds(-2.0, 2.0),
    )


@family()
def ill_conditioned_bounded(rng):
    """A level with singular values over 1e4 whose target needs |x| ≫ 1, clipped by the
    bounds; a weighted inequality level; a posture task."""
    n = 8
    return dict(
        levels=[
            qc.Equality(_conditioned(rng, 3, n, 1e4), rng.standard_normal(3)),
            qc.Inequality(_conditioned(rng, 3, n, 1e2), lower=0.4, weight=[1.0, 4.0, 0.25]),
            qc.Equality(np.eye(n), rng.uniform(-1, 1, n)),
        ],
        bounds=qc.Bounds(-1.0, 1.0),
    )


@family("feasible")
def feasible_mixed(rng):
    """Every level can be met exactly (equalities through a point x0 inside loose bounds,
    inequalities with margin around x0); the min-norm step then moves x away from x0."""
    n = 10
    x0 = rng.uniform(-0.5, 0.5, n)
    A0, A1 = rng.standard_normal((2, n)), rng.standard_normal((3, n))
    C0, C1 = rng.standard_normal((3, n)), rng.standard_normal((2, n))
    return dict(
        levels=[
            [qc.Equality(A0, A0 @ x0), qc.Inequality(C0, lower=C0 @ x0 - 0.1)],
            [qc.Equality(A1, A1 @ x0), qc.Inequality(C1, C1 @ x0 - 0.2, C1 @ x0 + 0.2)],
        ],
        bounds=qc.Bounds(-2.0, 2.0),
    )


SEEDS = (0, 1, 2)
CASES = [(name, seed) for name in FAMILIES for seed in SEEDS]
EQ_CASES = [c for c in CASES if "eq_only" in FAMILIES[c[0]][1]]
FEASIBLE_CASES = [c for c in CASES if "feasible" in FAMILIES[c[0]][1]]
INEQ_CASES = [c for c in CASES if "eq_only" not in FAMILIES[c[0]][1]]


def case_ids(cases) -> list[str]:
    """Test ids of ``cases``: ``family-seed``."""
    return [f"{name}-{seed}" for name, seed in cases]


def build(name: str, seed: int) -> dict:
    """Fresh tasks for one case (tasks are mutable; never share them between stacks)."""
    spec = FAMILIES[name][0](np.random.default_rng(seed))
    spec.setdefault("bounds", None)
    spec.setdefault("constraints", None)
    return spec


def stack(spec: dict) -> qc.Stack:
    # fallback=False: each backend answers on its own (no silent help from another)
    return qc.Stack(
        spec["levels"], bounds=spec["bounds"], constraints=spec["constraints"], fallback=False
    )


@functools.cache
def reference(name: str, seed: int) -> OracleResult:
    spec = build(name, seed)
    return lexicographic(spec["levels"], spec["bounds"], spec["constraints"])
