"""Exceptions raised by qpcoord.

Bad *input* (wrong shapes, NaN/inf, ``lower > upper``, unknown solver names, an empty
stack) raises the built-in :class:`ValueError` with a message naming the offending task.
The two classes below are for problems that are well-formed but cannot be solved.
"""

from __future__ import annotations

__all__ = ["InfeasibleError", "SolverError"]


class InfeasibleError(RuntimeError):
    """The hard part of a problem (bounds and hard constraints) has no solution.

    Soft levels of a stack never raise this: their violation is minimised instead.
    """


class SolverError(RuntimeError):
    """A QP backend failed, returned a non-finite point, or returned a point that does
    not satisfy the hard constraints to tolerance. qpcoord never returns such a point."""
