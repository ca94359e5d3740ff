"""A child Python whose malloc and realloc calls are counted (a preloaded shim), for the tests
that a native call allocates nothing per step."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

#: tests/: on the child's path (``support`` is imported from there)
TESTS = Path(__file__).resolve().parents[1]
#: tests/kinematics: put on the child's path as ``{tests}`` (its scripts build their IK
#: stacks with the builders of the test module that runs them)
KINEMATICS_TESTS = TESTS / "kinematics"

_COUNTING_MALLOC = r"""
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stddef.h>
static long long calls = 0;
static void* (*next_malloc)(size_t) = 0;
static void* (*next_realloc)(void*, size_t) = 0;
long long qpcoord_malloc_calls(void) { return calls; }
void* malloc(size_t s) {
  if (!next_malloc) next_malloc = dlsym(RTLD_NEXT, "malloc");
  ++calls;
  return next_malloc(s);
}
void* realloc(void* p, size_t s) {
  if (!next_realloc) next_realloc = dlsym(RTLD_NEXT, "realloc");
  ++calls;
  return next_realloc(p, s);
}
"""


def run_counting_malloc(tmp_path: Path, script: str, env: dict | None = None) -> str:
    """Run ``script`` (a template with ``{tests}``: tests/kinematics, ``{lib}``: the shim, whose
    ``qpcoord_malloc_calls()`` counts malloc/realloc calls) in a fresh Python with the
    counting shim preloaded and ``env`` added to the environment; its stdout. Skips without
    a C compiler or glibc."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None or not sys.platform.startswith("linux"):
        pytest.skip("needs a C compiler and glibc's dlsym(RTLD_NEXT)")
    src, lib = tmp_path / "count.c", tmp_path / "libcount.so"
    src.write_text(_COUNTING_MALLOC)
    subprocess.run([cc, "-shared", "-fPIC", "-O2", "-o", str(lib), str(src), "-ldl"], check=True)
    proc = subprocess.run(
        [sys.executable, "-c", script.format(tests=str(KINEMATICS_TESTS), lib=str(lib))],
        capture_output=True,
        text=True,
        env={
            **os.environ,
            **(env or {}),
            "PYTHONPATH": os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]),
            "LD_PRELOAD": str(lib),
            "OPENBLAS_NUM_THREADS": "1",
        },
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout
