"""Exceptions raised by qpcoord.

Bad *input* (wrong shapes, NaN/inf, ``lower > upper``, unknown solver names, an empty
stack) raises the built-in :class:`ValueError` with a message naming the offending task.
The two classes below are for problems that are well-formed but cannot be solved.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

__all__ = ["InfeasibleError", "SolverError", "AlgorithmicSingularity"]


class InfeasibleError(RuntimeError):
    """The hard part of a problem (bounds and hard constraints) has no solution.

    Soft levels of a stack never raise this: their violation is minimised instead.

    Attributes
    ----------
    conflict : tuple of ConflictRow
        The smallest set of hard rows found that cannot hold together (no row of it can be
        dropped without the others becoming consistent), each named by its task and row, or
        by the variable of a bound (and in an :class:`~qpcoord.IK` the limit and joint),
        with its violation at the point that violates them least
        (:class:`qpcoord.core.conflict.ConflictRow`, units there); the message names them
        too. Empty where none was searched (e.g. a problem outside a stack).
    """

    def __init__(self, message: str, conflict: tuple = ()) -> None:
        super().__init__(message)
        self.conflict = tuple(conflict)

    def __reduce__(self) -> tuple[type, tuple[str, tuple]]:
        return (type(self), (str(self), self.conflict))


class SolverError(RuntimeError):
    """A QP backend failed, returned a non-finite point, or returned a point that does
    not satisfy the hard constraints to tolerance. qpcoord never returns such a point."""


class AlgorithmicSingularity(ValueError):
    """A scheme's own construction lost rank along a run (thesis §5.2.4, Def. 5.2).

    Raised, for example, when the rigidly extended Jacobian ``[J; G]`` becomes singular
    although ``J`` is not. Attributes: ``q`` (rad), ``t`` (s), ``sigma`` (the smallest
    singular value relative to the largest, dimensionless).
    """

    def __init__(
        self,
        message: str,
        q: np.ndarray | None = None,
        t: float | None = None,
        sigma: float | None = None,
    ) -> None:
        super().__init__(message)
        self.q = q
        self.t = t
        self.sigma = sigma
