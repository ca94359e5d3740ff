"""Classic recursive null-space projection (``method="nullspace"``), thesis Def. 5.4.

Equality levels only: ``x₁ = A₁⁺ b₁``, then for each lower level
``xᵢ = xᵢ₋₁ + (Aᵢ Nᵢ₋₁)⁺ (bᵢ − Aᵢ xᵢ₋₁)`` with the reduced null-space projector
``Nᵢ = Nᵢ₋₁ − (Aᵢ Nᵢ₋₁)⁺ (Aᵢ Nᵢ₋₁)`` of the thesis (Siciliano & Slotine's recursion). The
projector is carried as an orthonormal basis ``Nᵢ = Zᵢ Zᵢᵀ`` (``Aᵢ Nᵢ₋₁`` becomes
``Aᵢ Zᵢ₋₁``): the explicit ``n × n`` projector accumulates round-off that the rank test
then mistakes for freedom, which let lower levels disturb higher ones (1.85 instead of
7e-15 on a 3 + 2-row stack in 4 variables). With exact pseudo-inverses this equals the
strict hierarchy on equality-only stacks; the pseudo-inverses use the same damping filter
as the other methods (:mod:`qpcoord.core.linalg`). Hard equality constraints act as a level
above level 0 that must be met exactly.
"""

from __future__ import annotations

import numpy as np

from ..compile import CompiledStack
from ..elimination import CHECK_TOL
from ..errors import InfeasibleError
from ..linalg import filtered_svd

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
    x = np.zeros(P.n)
    Z = None  # basis of the current null space (None: identity)
    ranks = []
    hard = P.hard.m_eq > 0
    levels = ([P.hard] if hard else []) + list(P.levels)
    for i, L in enumerate(levels):
        if Z is not None and Z.shape[1] == 0:
            ranks.append(0)
            continue
        M = L.Ae if Z is None else L.Ae @ Z
        U, s, Vt, rank, g, _ = filtered_svd(
            M, 0.0 if (i == 0 and hard) else damping, float(np.linalg.norm(L.Ae))
        )
        ranks.append(rank)
        if rank == 0:
            continue
        step = Vt[:rank].T @ (g * (U[:, :rank].T @ (L.be - L.Ae @ x)))
        x = x + (step if Z is None else Z @ step)
        Z = Vt[rank:].T if Z is None else Z @ Vt[rank:].T
        if i == 0 and hard:
            res = L.Ae @ x - L.be
            scale = max(1.0, float(np.max(np.abs(L.be))))
            if float(np.max(np.abs(res))) > CHECK_TOL * scale:
                names = ", ".join(t.label for t in P.hard.eqs)
                raise InfeasibleError(
                    f"hard equality constraints are inconsistent ({names}): "
                    f"least-squares residual {np.linalg.norm(res):.3g}"
                )
    if hard:
        ranks = ranks[1:]
    return x, {"qp_calls": 0, "level_ranks": ranks}
