"""Deprecated alias of :mod:`qpcoord.kinematics.robot` (removed in the next release)."""

from ._deprecated import moved

moved(__name__, "qpcoord.kinematics.robot")
