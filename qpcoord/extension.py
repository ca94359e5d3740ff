"""Deprecated alias of :mod:`qpcoord.coordination.extensions` (removed in the next release)."""

from ._deprecated import moved

moved(__name__, "qpcoord.coordination.extensions")
