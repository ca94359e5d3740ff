"""The version of qpcoord (one place: read by the package and by reproduce reports)."""

__version__ = "0.1.0"
