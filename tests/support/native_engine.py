"""The native engine under test: whether it is built, a solver of a compiled stack, and the
comparison of its answers with the Python engine's.

Without the extension the tests marked :data:`needs_native` skip, with the reason, and so do
those marked :data:`needs_native_weighted` without its weighted QP and those marked
:data:`needs_collision_kernel` without ``qpcoord._collision``; ``QPCOORD_REQUIRE_NATIVE=1``
(set by ``.ci/run``) makes a missing extension a failure instead (importing this module
raises).
"""

from __future__ import annotations

import os

import numpy as np
import pytest

import qpcoord as qc
from qpcoord.core import native, native_weighted
from qpcoord.kinematics import collision_kernel

#: Level values: |r_native − r_python| ≤ LEVEL_TOL·max(1, r_python).
LEVEL_TOL = 1e-9
#: x (unique): ‖x_native − x_python‖∞ ≤ X_TOL·max(1, ‖x_python‖∞).
X_TOL = 1e-7

BUILT = native.available()
if not BUILT and os.environ.get("QPCOORD_REQUIRE_NATIVE") == "1":
    raise RuntimeError(
        "QPCOORD_REQUIRE_NATIVE=1 but the native engine is not built: " + str(native._load_error)
    )
needs_native = pytest.mark.skipif(
    not BUILT, reason=f"the native engine (qpcoord._native) is not built: {native._load_error}"
)

#: the extension binds the weighted QP (``Weighted``: src/native/weighted.cpp, one of the
#: sources of every build of it in CMakeLists.txt)
WEIGHTED_BUILT = native_weighted.available()
_NO_WEIGHTED = "the native engine has no weighted QP (qpcoord._native.Weighted)"
if BUILT and not WEIGHTED_BUILT and os.environ.get("QPCOORD_REQUIRE_NATIVE") == "1":
    raise RuntimeError("QPCOORD_REQUIRE_NATIVE=1 but " + _NO_WEIGHTED)
needs_native_weighted = pytest.mark.skipif(
    not WEIGHTED_BUILT, reason=needs_native.kwargs["reason"] if not BUILT else _NO_WEIGHTED
)

#: CollisionAvoidance's native rows: the extension ``qpcoord._collision`` (built where CMake
#: finds coal's library, CMakeLists.txt)
COLLISION_BUILT = collision_kernel._collision is not None
if not COLLISION_BUILT and os.environ.get("QPCOORD_REQUIRE_NATIVE") == "1":
    raise RuntimeError("QPCOORD_REQUIRE_NATIVE=1 but qpcoord._collision is not built")
needs_collision_kernel = pytest.mark.skipif(
    not COLLISION_BUILT, reason="qpcoord._collision is not built"
)


def native_solver(stack: qc.Stack):
    """``(P, h)``: the compiled stack and a native solver of it (``h.counters``: the
    counters of its last call)."""
    from qpcoord.core.native import NativeHierarchy

    P = stack._compiled
    return P, NativeHierarchy(P, stack.damping)


def assert_same(sp: qc.Solution, sn: qc.Solution) -> None:
    """``sn`` gives ``sp``'s level values (``LEVEL_TOL`` relative) and ``x`` (``X_TOL``)."""
    rp, rn = sp.level_residuals, sn.level_residuals
    assert np.all(np.abs(rn - rp) <= LEVEL_TOL * np.maximum(1.0, rp)), (rp, rn)
    dx = np.max(np.abs(sn.x - sp.x)) / max(1.0, float(np.max(np.abs(sp.x))))
    assert dx <= X_TOL, (dx, sp.x, sn.x)


def path_check(stack: qc.Stack, P, h, counter: str, unique_x: bool = True, warm: bool = True):
    """Solve with the native solver ``h`` (``warm``: from its stored working sets, else cold;
    its caches dropped first, so that the counters count the factorisations and freezes
    computed, not restored: the cache tests test the caches) and with the Python engine:
    the same level values (``LEVEL_TOL`` relative) and, ``unique_x``, the same x
    (``X_TOL``). ``counter``: the ``Stats`` field of the path under test. Returns ``(its
    count, the native info, the Python Solution)``."""
    h._solver.invalidate_caches()
    xn, rn, infon = h.solve(P, warm=warm)
    taken = getattr(h.counters, counter)
    sp = stack.solve(engine="python")
    ref = sp.level_residuals
    assert np.all(np.abs(rn - ref) <= LEVEL_TOL * np.maximum(1.0, ref)), (rn, ref)
    if unique_x:
        scale = max(1.0, float(np.max(np.abs(sp.x))))
        assert np.max(np.abs(xn - sp.x)) <= X_TOL * scale, np.max(np.abs(xn - sp.x))
    return taken, infon, sp
