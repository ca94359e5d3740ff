"""Deprecated alias of :mod:`qpcoord.core.backends` (removed in the next release)."""

from ._deprecated import moved

moved(__name__, "qpcoord.core.backends")
