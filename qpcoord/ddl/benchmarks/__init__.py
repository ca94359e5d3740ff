"""Public dual-stage benchmarks: :mod:`.hdd` (the IEEJ hard-disk-drive head positioning)."""

from . import hdd

__all__ = ["hdd"]
