"""Deprecated alias of :mod:`qpcoord.core.methods.weighted` (removed in the next release)."""

from ._deprecated import moved

moved(__name__, "qpcoord.core.methods.weighted")
