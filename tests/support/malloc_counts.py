"""The child side of :mod:`support.counting_malloc`: the preloaded shim's count of malloc and
realloc calls, and what a repeated call makes once its first calls are over. Imported only by
the scripts that :func:`support.counting_malloc.native_malloc_counts` runs."""

from __future__ import annotations

import ctypes
from collections.abc import Callable

import numpy as np

#: uncounted calls first: a native step sizes its caches in its first calls (the second
#: allocates them, the third uses them)
WARM_CALLS = 20
#: counted calls: one allocation every few hundred calls still shows
COUNTED_CALLS = 500

# the shim is preloaded, so its counter is in the process's global symbol scope
_counter = ctypes.CDLL(None).qpcoord_malloc_calls
_counter.restype = ctypes.c_longlong


def malloc_calls() -> int:
    """malloc and realloc calls of this process so far."""
    return int(_counter())


def mallocs_in(call: Callable[[], object], runs: int = COUNTED_CALLS) -> int:
    """malloc and realloc calls made by ``runs`` calls of ``call``."""
    before = malloc_calls()
    for _ in range(runs):
        call()
    return malloc_calls() - before


def print_mallocs(name: str, call: Callable[[], object]) -> None:
    """Print the line ``name count``: the malloc calls of :data:`COUNTED_CALLS` calls of
    ``call`` after :data:`WARM_CALLS` uncounted ones."""
    for _ in range(WARM_CALLS):
        call()
    print(name, mallocs_in(call))


def print_step_mallocs(name: str, ik, q: np.ndarray, integrate: bool = True) -> None:
    """:func:`print_mallocs` of the extension's step of ``ik`` (a ``qpcoord.IK`` on the native
    engine) at ``q`` and the robot's kinematics as they are: warm-started, 10 s time limit,
    ``q_next`` integrated by the step if ``integrate``; each uncounted call must succeed
    (code 0)."""
    step = ik._native._solver.step
    for _ in range(WARM_CALLS):
        assert step(q, True, 10.0, integrate) == 0
    print(name, mallocs_in(lambda: step(q, True, 10.0, integrate)))
