"""Deprecated alias of :mod:`qpcoord.studies.bench_stack` (removed in the next release)."""

from ._deprecated import moved

moved(__name__, "qpcoord.studies.bench_stack")
