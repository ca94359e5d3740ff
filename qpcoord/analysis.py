"""Deprecated alias of :mod:`qpcoord.coordination.periodicity` (removed in the next release)."""

from ._deprecated import moved

moved(__name__, "qpcoord.coordination.periodicity")
