"""Classic recursive null-space projection (``method="nullspace"``), thesis Def. 5.4.

Equality levels only: ``x₁ = A₁⁺ b₁``, then for each lower level
``xᵢ = xᵢ₋₁ + (Aᵢ Nᵢ₋₁)⁺ (bᵢ − Aᵢ xᵢ₋₁)`` and ``Nᵢ = Nᵢ₋₁ − (Aᵢ Nᵢ₋₁)⁺ (Aᵢ Nᵢ₋₁)``, the
reduced null-space projectors of the thesis (Siciliano & Slotine's recursion). With exact
pseudo-inverses this equals the strict hierarchy on equality-only stacks; the
pseudo-inverses use the same damping filter as the other methods (:mod:`qpcoord.linalg`).
Hard equality constraints act as a level above level 0 that must be met exactly.
"""

from __future__ import annotations

import numpy as np

from .errors import InfeasibleError
from .linalg import filtered_svd
from .problem import CompiledStack
from .reduced import CHECK_TOL

__all__ = ["solve_nullspace", "check_equality_only"]


def check_equality_only(P: CompiledStack) -> None:
    """Raise ``ValueError`` naming the first inequality task or the bounds."""
    if P.bounds is not None:
        raise ValueError(
            f"method='nullspace' handles equality tasks only, but the stack has {P.bounds.label}; "
            "use method='hierarchical'"
        )
    for where, L in [("constraints", P.hard)] + [(f"level {k}", L) for k, L in enumerate(P.levels)]:
        if L.ineqs:
            raise ValueError(
                f"method='nullspace' handles equality tasks only, but {where} has "
                f"{L.ineqs[0].label}; use method='hierarchical'"
            )


def solve_nullspace(P: CompiledStack, damping: float) -> tuple[np.ndarray, dict]:
    """Recursive projection solve of an equality-only compiled stack. Returns ``(x, info)``."""
    n = P.n
    x = np.zeros(n)
    N = np.eye(n)
    ranks = []
    levels = ([P.hard] if P.hard.m_eq else []) + list(P.levels)
    for i, L in enumerate(levels):
        M = L.Ae @ N
        U, s, Vt, rank, g = filtered_svd(M, 0.0 if (i == 0 and P.hard.m_eq) else damping)
        ranks.append(rank)
        if rank == 0:
            continue
        Vr = Vt[:rank]
        Mp = (Vr.T * g) @ U[:, :rank].T  # damped pseudo-inverse of M
        x = x + Mp @ (L.be - L.Ae @ x)
        N = N - Vr.T @ Vr  # N projects on null(A_1..A_i); Vr spans row(M) ⊂ range(N)
        if i == 0 and P.hard.m_eq:
            res = L.Ae @ x - L.be
            scale = max(1.0, float(np.max(np.abs(L.be))))
            if float(np.max(np.abs(res))) > CHECK_TOL * scale:
                raise InfeasibleError(
                    "hard equality constraints are inconsistent: least-squares residual "
                    f"{np.linalg.norm(res):.3g}"
                )
    if P.hard.m_eq:
        ranks = ranks[1:]
    return x, {"qp_calls": 0, "level_ranks": ranks}
