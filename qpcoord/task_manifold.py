"""Deprecated alias of :mod:`qpcoord.coordination.task_manifold` (removed in the next release)."""

from ._deprecated import moved

moved(__name__, "qpcoord.coordination.task_manifold")
