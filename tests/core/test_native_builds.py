"""The builds of the native engine: ``qpcoord._native`` (baseline x86-64) and
``qpcoord._native_x86_64_v3`` (``-march=x86-64-v3``: AVX2, FMA, BMI2), from the same sources.

The loader (:func:`qpcoord.core.native.load`) imports the highest-level build the running CPU
and OS support (the baseline build reads CPUID and XGETBV), ``QPCOORD_NATIVE_ISA`` overrides
it, and a variant that is missing or stale falls back to the baseline. Every build must give
the Python engine's answers at the suite's tolerances (level values 1e-9 relative, ``x`` where
unique): FMA rounds differently, so the builds agree to rounding, not bit for bit. The rest of
the suite runs the build ``load()`` picks; run it with ``QPCOORD_NATIVE_ISA=baseline`` for the
other one.
"""

from __future__ import annotations

import os
import platform
import shutil
import subprocess
import sys
import types
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from support.families import CASES, build, stack
from support.hlsp import load
from support.native_engine import BUILT, LEVEL_TOL, X_TOL, assert_same, needs_native
from support.published import published_module
from support.strategies import stacks
from support.weighted import assert_same_weighted

import qpcoord as qc
from qpcoord.core import native
from qpcoord.kinematics import frame_tasks
from qpcoord.kinematics.frame_tasks import FrameTask

#: the builds this machine has and can run (lowest level first)
VARIANTS = native.built_variants() if BUILT else ()
X86_64_LINUX = sys.platform.startswith("linux") and platform.machine() in ("x86_64", "AMD64")


@pytest.fixture
def fresh_load(monkeypatch):
    """``load()`` chooses again (as in a new process), with ``QPCOORD_NATIVE_ISA`` unset."""
    monkeypatch.setattr(native, "_module", None)
    monkeypatch.delenv(native.ISA_ENV, raising=False)
    return monkeypatch


def _use(monkeypatch, name: str) -> types.ModuleType:
    """Make ``name`` the build every adapter gets from ``load()`` (for this test)."""
    mod = native.import_variant(name)
    monkeypatch.setattr(native, "_module", mod)
    assert native.variant() == name
    return mod


# ---------------------------------------------------------------------------------------
# the loader
# ---------------------------------------------------------------------------------------


def _level_from_proc_cpuinfo() -> int:
    """The x86-64 level from the kernel's flags (the kernel clears the AVX flags when it does
    not save the AVX state)."""
    flags: set[str] = set()
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("flags"):
            flags = set(line.split(":", 1)[1].split())
            break
    v2 = {"pni", "ssse3", "cx16", "sse4_1", "sse4_2", "popcnt", "lahf_lm"}
    v3 = {"avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "abm", "movbe", "xsave"}
    v4 = {"avx512f", "avx512bw", "avx512cd", "avx512dq", "avx512vl"}
    level = 1
    for need, lv in ((v2, 2), (v2 | v3, 3), (v2 | v3 | v4, 4)):
        if need <= flags:
            level = lv
    return level


@needs_native
@pytest.mark.skipif(not X86_64_LINUX, reason="x86-64 Linux (/proc/cpuinfo)")
def test_the_cpu_level_is_the_kernels():
    assert native.cpu_level() == _level_from_proc_cpuinfo()


@needs_native
def test_the_default_is_the_highest_build_the_cpu_runs(fresh_load):
    assert VARIANTS[0] == "baseline"
    assert native.variant() == VARIANTS[-1] == native.load().ISA
    if X86_64_LINUX and native.cpu_level() >= 3 and os.environ.get("QPCOORD_REQUIRE_NATIVE"):
        # CI (GCC 12 on x86-64): the variant must be built, not silently left out by CMake
        assert "x86-64-v3" in VARIANTS


@needs_native
@pytest.mark.parametrize("name", VARIANTS)
def test_the_environment_variable_picks_the_build(fresh_load, name):
    fresh_load.setenv(native.ISA_ENV, name)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert native.variant() == name
    assert native.load().ISA == name
    assert native.load() is native.import_variant(name)
    fresh_load.setattr(native, "_module", None)
    fresh_load.setenv(native.ISA_ENV, "auto")
    assert native.variant() == VARIANTS[-1]


@needs_native
def test_frame_tasks_follow_a_build_swapped_after_their_first_use(fresh_load):
    """frame_tasks' native rigid-transform functions are those of the module ``load()``
    holds now, not of the one it held at their first call (they were ``functools.cache``d:
    stale after ``QPCOORD_NATIVE_ISA`` and a fresh ``load()``)."""
    for name in (*VARIANTS, VARIANTS[0]):
        fresh_load.setattr(native, "_module", None)
        fresh_load.setenv(native.ISA_ENV, name)
        mod = native.load()
        assert mod.ISA == name
        assert frame_tasks._native_rigid() is mod.spatial_rigid_ok
        assert frame_tasks._native_rigid_copy() is mod.spatial_rigid_copy


@needs_native
@pytest.mark.parametrize("value", ["avx2", "x86-64-v4", "native", "BASELINE"])
def test_an_unknown_value_is_named(fresh_load, value):
    fresh_load.setenv(native.ISA_ENV, value)
    with pytest.raises(ValueError, match=f"QPCOORD_NATIVE_ISA='{value}' is not a native"):
        native.load()
    with pytest.raises(ValueError, match="name='avx2' is not a native engine variant"):
        native.import_variant("avx2")


@needs_native
def test_an_older_cpu_gets_the_baseline(fresh_load):
    """A CPU (or OS) below x86-64-v3: the default is the baseline; asking for the variant is
    an error, never an import that would die of SIGILL."""
    fresh_load.setattr(native, "cpu_level", lambda: 2)
    imported = []
    real = native._import_module
    fresh_load.setattr(native, "_import_module", lambda name: imported.append(name) or real(name))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert native.variant() == "baseline"
    assert imported == [native.MODULE]  # the variant was not even imported
    assert native.built_variants() == ("baseline",)
    fresh_load.setattr(native, "_module", None)
    fresh_load.setenv(native.ISA_ENV, "x86-64-v3")
    with pytest.raises(ValueError, match="needs x86-64 level 3, this CPU and OS support level 2"):
        native.load()
    with pytest.raises(ValueError, match="illegal instruction"):
        native.import_variant("x86-64-v3")


def _fake_variant(monkeypatch, make):
    """The variant's import replaced by ``make()`` (raise, or a stale module)."""
    real = native._import_module
    name = native.VARIANTS["x86-64-v3"][0]
    monkeypatch.setattr(native, "_import_module", lambda m: make() if m == name else real(m))
    monkeypatch.setattr(native, "cpu_level", lambda: 3)


def _missing():
    raise ImportError("No module named 'qpcoord._native_x86_64_v3'")


def _stale_abi():
    return types.SimpleNamespace(ABI_VERSION=native.ABI_VERSION - 1, ISA="x86-64-v3")


def _wrong_isa():
    return types.SimpleNamespace(ABI_VERSION=native.ABI_VERSION, ISA="baseline")


@needs_native
@pytest.mark.parametrize("make", [_missing, _stale_abi, _wrong_isa])
def test_a_missing_or_stale_variant_falls_back_to_the_baseline(fresh_load, make):
    """Silently by default (the library never prints); with a warning naming the variable
    when it was asked for."""
    _fake_variant(fresh_load, make)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert native.variant() == "baseline"
        assert native.built_variants() == ("baseline",)
    with pytest.raises(native.NativeUnavailableError, match="x86_64_v3"):
        native.import_variant("x86-64-v3")
    fresh_load.setattr(native, "_module", None)
    fresh_load.setenv(native.ISA_ENV, "x86-64-v3")
    with pytest.warns(RuntimeWarning, match="QPCOORD_NATIVE_ISA=x86-64-v3: .*using the baseline"):
        assert native.variant() == "baseline"


def test_no_build_means_no_variant(missing_extension):
    assert native.variant() is None
    assert native.built_variants() == ()


@needs_native
def test_the_cli_names_the_build():
    out = subprocess.run(
        [sys.executable, "-m", "qpcoord.cli", "solvers"],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, native.ISA_ENV: "baseline"},
    ).stdout
    assert "native engine: baseline (qpcoord._native)" in out


# AVX (VEX/EVEX-encoded: every mnemonic starts with v) and the BMI1/BMI2/LZCNT/MOVBE
# instructions, which an x86-64 CPU before Haswell does not have
_BMI = {"andn", "bextr", "blsi", "blsmsk", "blsr", "bzhi", "lzcnt", "movbe", "mulx", "pdep"}
_BMI |= {"pext", "rorx", "sarx", "shlx", "shrx"}


def _count_beyond_x86_64(path: str) -> int:
    out = subprocess.run(
        ["objdump", "-d", "--no-show-raw-insn", path], capture_output=True, text=True, check=True
    ).stdout
    count = 0
    for line in out.splitlines():
        parts = line.split("\t")
        if len(parts) >= 2 and parts[0].strip().endswith(":"):
            mnemonic = parts[1].split(" ", 1)[0]
            count += mnemonic.startswith("v") or mnemonic in _BMI or mnemonic[:-1] in _BMI
    return count


@needs_native
@pytest.mark.skipif(shutil.which("objdump") is None or not X86_64_LINUX, reason="no objdump")
def test_the_baseline_build_runs_on_any_x86_64():
    """No AVX, BMI or LZCNT instruction in the baseline module (a global -march would put
    some there and kill the library on an older CPU); the variant has them."""
    assert _count_beyond_x86_64(native.import_variant("baseline").__file__) == 0
    if "x86-64-v3" in VARIANTS:
        assert _count_beyond_x86_64(native.import_variant("x86-64-v3").__file__) > 1000


# ---------------------------------------------------------------------------------------
# every build gives the Python engine's answers
# ---------------------------------------------------------------------------------------


@needs_native
@pytest.mark.parametrize("name", VARIANTS)
def test_every_build_matches_python(monkeypatch, name):
    """Strict hierarchy and weighted QP on the solver-comparison cases."""
    _use(monkeypatch, name)
    for case, seed in CASES:
        spec = build(case, seed)
        sp = stack(spec).solve(engine="python")
        sn = stack(spec).solve(engine="native")
        assert sn.status == "optimal", (case, seed)
        assert_same(sp, sn)
        spec = build(case, seed)
        wp = stack(spec).solve(method="weighted", engine="python")
        wn = stack(spec).solve(method="weighted", engine="native")
        assert_same_weighted(stack(build(case, seed)), wp, wn)


@pytest.mark.skipif(len(VARIANTS) < 2, reason="one build only")
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(stacks())
def test_the_builds_agree_on_random_stacks(spec):
    """Each build against the Python engine and against each other, cold and warm."""
    sp = stack(spec).solve(engine="python")
    assume(sp.status == "optimal")
    solved = {}
    with pytest.MonkeyPatch.context() as mp:
        for name in VARIANTS:
            _use(mp, name)
            s = stack(spec)
            solved[name] = (s.solve(engine="native"), s.solve(engine="native"))
            for sn in solved[name]:
                assert_same(sp, sn)
    base = solved["baseline"]
    for name in VARIANTS[1:]:
        for a, b in zip(base, solved[name], strict=True):
            rb = np.asarray(a.level_residuals)
            gap = np.abs(np.asarray(b.level_residuals) - rb)
            assert np.all(gap <= LEVEL_TOL * np.maximum(1.0, rb))
            scale = max(1.0, float(np.max(np.abs(a.x))))
            assert np.max(np.abs(b.x - a.x)) <= X_TOL * scale


@needs_native
@pytest.mark.parametrize("name", VARIANTS)
def test_every_build_solves_the_moving_humanoid(monkeypatch, name):
    """The LexLS humanoid (88 variables, 5 levels) moved as hierarchy_published's re-solve
    table, warm: the level values of the Python engine (x is not unique there)."""
    hp = published_module()

    _use(monkeypatch, name)
    prob = load("lexls_test01_humanoid")
    s = qc.Stack(prob.levels, bounds=prob.bounds)
    move = hp._mover(prob.levels)
    for step in range(4):
        move(step)
        sn = s.solve(engine="native")
        ref = np.asarray(s.solve(engine="python").level_residuals)
        gap = np.abs(np.asarray(sn.level_residuals) - ref)
        assert np.all(gap <= LEVEL_TOL * np.maximum(1.0, ref)), (step, gap)
        assert step == 0 or sn.info["warm_start_hits"] > 0


@needs_native
@pytest.mark.parametrize("method", ["hierarchical", "weighted"])
def test_every_build_gives_the_same_ik_step(monkeypatch, method):
    """One native IK step per control step on the Panda (pose, posture; kernels, box, QP and
    integration in C++): the builds' velocities agree to rounding over 20 steps."""
    robot = qc.robots.load("panda")
    frame = "panda_hand_tcp"
    runs = {}
    for name in VARIANTS:
        mod = _use(monkeypatch, name)
        assert frame_tasks._native_rigid_copy() is mod.spatial_rigid_copy  # set_target's
        q = robot.random_configuration(3)
        target = robot.frame_pose(q, frame).copy()
        target[:3, 3] += [0.05, -0.03, 0.04]
        task = FrameTask(robot, frame, target, gain=4.0)
        levels = [task, qc.PostureTask(robot, robot.random_configuration(9), gain=1.5)]
        ik = qc.IK(robot, levels, 0.01, method=method, engine="native")
        assert ik._native is not None
        vs = []
        for _ in range(20):
            v, _ = ik.step(q)
            vs.append(v.copy())
            q = robot.integrate(q, v, 0.01)
        runs[name] = np.array(vs)
    for name in VARIANTS[1:]:
        np.testing.assert_allclose(runs[name], runs["baseline"], rtol=0, atol=1e-9)
