"""Deprecated alias of :mod:`qpcoord.kinematics.paths` (removed in the next release)."""

from ._deprecated import moved

moved(__name__, "qpcoord.kinematics.paths")
