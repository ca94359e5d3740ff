"""qpcoord ships ``py.typed`` (PEP 561), declared as package data so wheels carry it."""

from __future__ import annotations

import fnmatch
import importlib.resources
import sys
from pathlib import Path

import pytest

import qpcoord

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    tomllib = pytest.importorskip("tomli")

ROOT = Path(__file__).resolve().parents[2]


def test_py_typed_is_in_the_package():
    assert importlib.resources.files(qpcoord).joinpath("py.typed").is_file()


def test_py_typed_is_package_data():
    """scikit-build-core copies the whole qpcoord/ folder (wheel.packages), py.typed with it,
    unless a wheel.exclude pattern drops it."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    wheel = config["tool"]["scikit-build"]["wheel"]
    assert "qpcoord" in wheel["packages"]
    assert (ROOT / "qpcoord" / "py.typed").is_file()
    excluded = [p for p in wheel["exclude"] if fnmatch.fnmatch("qpcoord/py.typed", p)]
    assert excluded == []
