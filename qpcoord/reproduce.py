"""Deprecated alias of :mod:`qpcoord.studies.reproduce` (removed in the next release)."""

from ._deprecated import moved

moved(__name__, "qpcoord.studies.reproduce")
