"""The package layout: one-way layers, no import circle, the public names of ``qc``.

The layers (``pyproject.toml``, ``[tool.importlinter]``) are checked with import-linter's
``layers`` contract; circles with grimp's import graph (the one import-linter builds), run-time
imports only: an import under ``if TYPE_CHECKING:`` is for annotations and is never executed.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import grimp
import pytest
import tomllib
from importlinter import api as importlinter_api  # noqa: F401  (the dependency is present)

import qpcoord

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = Path(qpcoord.__file__).resolve().parent

#: ``qc.__all__`` of qpcoord 0.1: every name must stay.
PUBLIC_0_1 = """AlgorithmicSingularity Bounds Equality IK InfeasibleError Inequality JointLimits
METHODS OneFormTask PositionBand PositionTask PostureTask PotentialTask Robot Solution
SolverError Stack Trajectory analysis ddl hysteresis musculo reproduce sweep geometry
VelocityLimits available_solvers default_solver ik_step inverse_kinematics paths potentials
robots schemes simulate solve_stack solver_versions task_manifold""".split()


def _cycles(graph: grimp.ImportGraph) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found: list[list[str]] = []
    counter = 0
    for root in sorted(graph.modules):
        if root in index:
            continue
        work = [(root, iter(sorted(graph.find_modules_directly_imported_by(root))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            advanced = False
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append(
                        (child, iter(sorted(graph.find_modules_directly_imported_by(child))))
                    )
                    advanced = True
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            if advanced:
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    m = stack.pop()
                    on_stack.discard(m)
                    component.append(m)
                    if m == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


@pytest.fixture(scope="module")
def graph() -> grimp.ImportGraph:
    return grimp.build_graph("qpcoord", exclude_type_checking_imports=True, cache_dir=None)


def test_no_import_circle(graph):
    """No two modules of qpcoord import each other, directly or through others (imports
    inside functions count: they run too)."""
    assert _cycles(graph) == []


def test_cycle_finder_finds_a_circle():
    """The check above can fail: a graph with a 3-module circle is reported."""
    g = grimp.ImportGraph()
    for a, b in [("p.a", "p.b"), ("p.b", "p.c"), ("p.c", "p.a"), ("p.c", "p.d")]:
        g.add_import(importer=a, imported=b)
    assert _cycles(g) == [["p.a", "p.b", "p.c"]]


def test_layers_contract_is_kept():
    """import-linter's ``layers`` contract of pyproject.toml: cli > studies > robots |
    coordination | ddl | musculo | hysteresis > kinematics > core."""
    exe = Path(sys.executable).with_name("lint-imports")
    proc = subprocess.run(
        [str(exe) if exe.exists() else "lint-imports", "--no-cache"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "1 kept, 0 broken" in proc.stdout


def test_every_package_is_installed():
    """Every folder of qpcoord/ with an ``__init__.py`` lies under a folder that pyproject's
    ``[tool.scikit-build] wheel.packages`` copies into the wheel, and ``robots/`` (with every
    kind of data file it holds) is installed as ``qpcoord.robots.descriptions`` by
    CMakeLists.txt (a wheel built without -e would miss them otherwise)."""
    roots = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["scikit-build"]["wheel"][
        "packages"
    ]
    roots = [roots] if isinstance(roots, str) else list(roots)
    for root in roots:
        assert (ROOT / root / "__init__.py").is_file(), root
    found = {p.parent.relative_to(ROOT).as_posix() for p in PACKAGE.rglob("__init__.py")}
    missed = {f for f in found if not any(f == r or f.startswith(r + "/") for r in roots)}
    assert missed == set()
    cmake = (ROOT / "CMakeLists.txt").read_text()
    assert "DIRECTORY robots/\n  DESTINATION qpcoord/robots/descriptions" in cmake
    suffixes = {p.suffix for p in (ROOT / "robots").iterdir() if p.is_file()}
    assert suffixes, "robots/ is empty"
    for suffix in suffixes:
        assert f'PATTERN "*{suffix}"' in cmake, f"robots/*{suffix} is not installed"


def test_public_names_of_0_1_are_kept():
    """``import qpcoord as qc`` still exposes every name of 0.1, and each resolves."""
    import qpcoord as qc

    missing = [n for n in PUBLIC_0_1 if n not in qc.__all__]
    assert missing == []
    for name in PUBLIC_0_1:
        assert getattr(qc, name) is not None


def test_qc_analysis_is_the_periodicity_module():
    """``qc.analysis`` (DESIGN.md's name: ``qc.analysis.closure_errors``, ...) is the module
    :mod:`qpcoord.coordination.periodicity`; it has no module file of its own."""
    import qpcoord as qc
    from qpcoord.coordination import periodicity

    assert qc.analysis is periodicity
    for name in ("closure_errors", "poincare_section", "detect_period"):
        assert callable(getattr(qc.analysis, name)), name
    assert not (PACKAGE / "analysis.py").exists()
