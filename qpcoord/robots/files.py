"""Where the robot description files shipped with qpcoord (top-level ``robots/``) are."""

from __future__ import annotations

from importlib import resources

__all__ = ["description_path"]


def description_path(filename: str):
    """Path of a description file shipped in ``robots/`` (a :mod:`importlib.resources` path)."""
    path = resources.files("qpcoord.robots.descriptions").joinpath(filename)
    if not path.is_file():
        raise ValueError(f"no robot description file {filename!r} is installed")
    return path
