"""Shared pytest fixtures (keep small: several test modules use this file)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

import qpcoord as qc

# Every run of the suite (the README's command, CI) tests the property tests on hypothesis's
# derandomized examples: the same examples on every machine and every run, so that the suite
# never fails on a lucky draw. HYPOTHESIS_PROFILE=explore searches new examples instead (a
# failure found there becomes an explicit test).
settings.register_profile("derandomized", derandomize=True, database=None)
settings.register_profile("explore")
HYPOTHESIS_PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "derandomized")
if HYPOTHESIS_PROFILE not in ("derandomized", "explore"):
    raise pytest.UsageError(
        f"HYPOTHESIS_PROFILE must be derandomized or explore, got {HYPOTHESIS_PROFILE!r}"
    )
settings.load_profile(HYPOTHESIS_PROFILE)

#: ``QPCOORD_TEST_ENGINE=python`` runs the suite with the Python engine as the default of
#: ``Stack.solve`` and the IK (``native``: the native one; unset: the library's default, the
#: native engine where built). Every test passes on both engines:
#: the README's test command (CI's) runs the suite a second time with
#: ``QPCOORD_TEST_ENGINE=python``, without the ``engine_independent`` tests (builds and malloc
#: counts of native calls, the same whatever the default engine).
#: The modules below test the native engine *as the default* (its selection, its warning,
#: the native weighted path): they keep it in either run.
TEST_ENGINE = os.environ.get("QPCOORD_TEST_ENGINE", "")
if TEST_ENGINE not in ("", "python", "native"):
    raise pytest.UsageError(f"QPCOORD_TEST_ENGINE must be python or native, got {TEST_ENGINE!r}")
_NATIVE_DEFAULT_MODULES = frozenset(
    {"test_native_engine_choice", "test_native_weighted", "test_native_step"}
)


@pytest.fixture(scope="module", autouse=True)
def _test_engine(request):
    """The default engine of this module's tests under ``QPCOORD_TEST_ENGINE`` (module
    scope: hypothesis refuses function-scoped fixtures around ``@given`` tests)."""
    if not TEST_ENGINE:
        yield
        return
    from qpcoord.core import native

    name = request.module.__name__.rpartition(".")[2]
    engine = "native" if name in _NATIVE_DEFAULT_MODULES else TEST_ENGINE
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(native, "DEFAULT_ENGINE", engine)
        yield


#: Every installed QP backend, in qpcoord's preference order.
SOLVERS = qc.available_solvers()


@pytest.fixture(params=SOLVERS, ids=SOLVERS)
def solver(request) -> str:
    """Each installed QP backend in turn (test ids are the backend names)."""
    return request.param


@pytest.fixture
def rng() -> np.random.Generator:
    """A fresh, seeded generator (same numbers in every test and on every run)."""
    return np.random.default_rng(20240611)


@pytest.fixture
def missing_extension(monkeypatch):
    """Simulate an install without a C++ compiler: the native extension cannot be imported
    (``qpcoord.core.native`` falls back to the Python engine with one warning)."""
    from qpcoord.core import native

    def fail():
        raise ImportError("No module named 'qpcoord._native'")

    monkeypatch.setattr(native, "_import", fail)
    monkeypatch.setattr(native, "_module", None)
    monkeypatch.setattr(native, "_warned", False)


#: src/native: the C++ drivers' sources (the allocation tests of tests/core build them once
#: per pytest session here, 13-23 s each with -O1 on a 2-core machine, instead of once per test)
NATIVE_SRC = Path(__file__).resolve().parents[1] / "src" / "native"


def _eigen_include() -> str | None:
    """Eigen's headers as the build finds them (cmeel-eigen), else Debian's, else None."""
    for p in sys.path:
        inc = Path(p) / "cmeel.prefix" / "include" / "eigen3"
        if (inc / "Eigen" / "Dense").is_file():
            return str(inc)
    deb = Path("/usr/include/eigen3")
    return str(deb) if (deb / "Eigen" / "Dense").is_file() else None


def _build(tmp_path_factory, name: str, sources: list[str], defines: list[str]) -> Path:
    """``g++ -O1`` of ``sources`` (paths under src/native) into a session directory; skipped
    without g++ or Eigen's headers, failed instead under ``QPCOORD_REQUIRE_NATIVE=1`` (CI: the
    test extra has them)."""
    eigen, gxx = _eigen_include(), shutil.which("g++")
    if eigen is None or gxx is None:
        if os.environ.get("QPCOORD_REQUIRE_NATIVE") == "1":
            pytest.fail("no g++ or Eigen headers (cmeel-eigen) to build the C++ driver")
        pytest.skip("no g++ or Eigen headers to build the C++ driver")
    exe = tmp_path_factory.mktemp(name) / name
    subprocess.run(
        [gxx, "-O1", "-std=c++17", "-DNDEBUG", *defines, f"-I{eigen}", f"-I{NATIVE_SRC}",
         *(str(NATIVE_SRC / s) for s in sources), "-o", str(exe)],
        check=True, capture_output=True, timeout=600,
    )  # fmt: skip
    return exe


@pytest.fixture(scope="session")
def hierarchy_driver(tmp_path_factory) -> Path:
    """``src/native/tools/driver.cpp`` with the hierarchy (``driver FILE reps warm|cold``)."""
    return _build(tmp_path_factory, "driver", ["tools/driver.cpp", "hierarchy.cpp"], [])


@pytest.fixture(scope="session")
def weighted_driver(tmp_path_factory) -> Path:
    """``src/native/tools/weighted_driver.cpp`` with the weighted solver."""
    return _build(
        tmp_path_factory,
        "wdriver",
        ["tools/weighted_driver.cpp", "weighted.cpp"],
        ["-DQPCOORD_NO_BINDINGS"],
    )
