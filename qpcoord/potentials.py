"""Deprecated alias of :mod:`qpcoord.coordination.potentials` (removed in the next release)."""

from ._deprecated import moved

moved(__name__, "qpcoord.coordination.potentials")
