"""The three solve methods of a :class:`~qpcoord.Stack`: ``hierarchical`` (strict,
lexicographic), ``nullspace`` (projection formula) and ``weighted`` (one QP)."""
