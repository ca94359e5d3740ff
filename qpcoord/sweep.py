"""Deprecated alias of :mod:`qpcoord.studies.sweep` (removed in the next release)."""

from ._deprecated import moved

moved(__name__, "qpcoord.studies.sweep")
