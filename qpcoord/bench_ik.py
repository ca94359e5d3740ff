"""Deprecated alias of :mod:`qpcoord.studies.bench_ik` (removed in the next release)."""

from ._deprecated import moved

moved(__name__, "qpcoord.studies.bench_ik")
