"""A child Python whose malloc and realloc calls are counted (a preloaded shim), for the tests
that a native call allocates nothing per step. The child's scripts count with
:mod:`support.malloc_counts`."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from qpcoord.core import native

#: tests/: on the child's path (its scripts build their problems with ``support``'s builders)
TESTS = Path(__file__).resolve().parents[1]
#: the first line every script of :func:`native_malloc_counts` prints: the build it loaded
_VARIANT_LINE = "import qpcoord.core.native\nprint('variant', qpcoord.core.native.variant())\n"

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
    """Run the Python source ``script`` in a fresh Python with the counting shim preloaded
    (:mod:`support.malloc_counts` reads its count), tests/ on its path and ``env`` added to
    the environment; its stdout. Skips without a C compiler or glibc."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None or not sys.platform.startswith("linux"):
        pytest.skip("needs a C compiler and glibc's dlsym(RTLD_NEXT)")
    src, lib = tmp_path / "count.c", tmp_path / "libcount.so"
    src.write_text(_COUNTING_MALLOC)
    subprocess.run([cc, "-shared", "-fPIC", "-O2", "-o", str(lib), str(src), "-ldl"], check=True)
    path = [str(TESTS), os.environ.get("PYTHONPATH", "")]
    proc = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        env={
            **os.environ,
            **(env or {}),
            "PYTHONPATH": os.pathsep.join(path),
            "LD_PRELOAD": str(lib),
            "OPENBLAS_NUM_THREADS": "1",
        },
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


def native_malloc_counts(tmp_path: Path, script: str, build: str) -> dict[str, int]:
    """Run ``script`` as :func:`run_counting_malloc` does, on the extension's build ``build``
    (``QPCOORD_NATIVE_ISA``), and return the counts it printed as ``name count`` lines
    (:func:`support.malloc_counts.print_mallocs`) by name. Asserts that the child loaded
    ``build``."""
    out = run_counting_malloc(tmp_path, _VARIANT_LINE + script, {native.ISA_ENV: build})
    lines = [line.split() for line in out.splitlines()]
    assert lines and lines[0] == ["variant", build], out
    counts = {}
    for line in lines[1:]:
        assert len(line) == 2 and line[1].lstrip("-").isdigit(), out
        counts[line[0]] = int(line[1])
    assert len(counts) == len(lines) - 1, f"a name printed twice: {out}"
    return counts
