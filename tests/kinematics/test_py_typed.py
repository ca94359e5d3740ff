"""qpcoord ships ``py.typed`` (PEP 561), declared as package data so wheels carry it."""

from __future__ import annotations

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
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert "py.typed" in config["tool"]["setuptools"]["package-data"]["qpcoord"]
