"""Deprecated alias of :mod:`qpcoord.coordination.curvature` (removed in the next release)."""

from ._deprecated import moved

moved(__name__, "qpcoord.coordination.curvature")
