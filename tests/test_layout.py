"""The package layout: one-way layers, no import circle, the public names of ``qc``.

The layers (``pyproject.toml``, ``[tool.importlinter]``) are checked with import-linter's
``layers`` contract. Circles are found on an import graph read from the source (``ast``):
every ``import`` statement counts, at module level, inside a function (a lazy import runs
too) and under ``if TYPE_CHECKING:`` (the annotation ties the two modules all the same), for
the modules of ``qpcoord`` and for the benchmark scripts of ``benchmarks/``.
"""

from __future__ import annotations

import ast
import subprocess
import sys
import textwrap
from pathlib import Path

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


def package_modules(package_dir: Path) -> dict[str, Path]:
    """Module name -> file of every module of the package at ``package_dir`` (folders
    without an ``__init__.py`` are not packages: skipped with everything below them)."""
    out: dict[str, Path] = {}

    def walk(folder: Path, prefix: str) -> None:
        for path in sorted(folder.iterdir()):
            if path.is_dir() and not path.is_symlink() and (path / "__init__.py").is_file():
                walk(path, f"{prefix}.{path.name}")
            elif path.suffix == ".py" and path.is_file():
                out[prefix if path.name == "__init__.py" else f"{prefix}.{path.stem}"] = path

    walk(package_dir, package_dir.name)
    return out


def script_modules(folder: Path) -> dict[str, Path]:
    """Module name -> file of the scripts of a folder that import each other by name."""
    return {path.stem: path for path in sorted(folder.glob("*.py"))}


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """``importer -> {imported}`` among ``modules`` from every import statement of each file
    (``ast.walk``: function bodies and ``if TYPE_CHECKING:`` blocks included). ``from p
    import name`` imports the module ``p.name`` if there is one, else ``p``; ``import a.b.c``
    the deepest module of ``a.b.c`` in ``modules``."""

    def deepest(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".") if package else []
                    parts = parts[: len(parts) - (node.level - 1)]
                    base = ".".join([*parts, base] if base else parts)
                for alias in node.names:
                    full = f"{base}.{alias.name}" if base else alias.name
                    targets.append(full if full in modules else base)
            for target in targets:
                found = deepest(target)
                if found is not None and found != name:
                    graph[name].add(found)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
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
                    work.append((child, iter(sorted(graph.get(child, ())))))
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


def test_no_import_circle_in_qpcoord():
    """No two modules of qpcoord import each other, directly or through others, whatever the
    kind of import (module level, lazy in a function, under ``TYPE_CHECKING``)."""
    modules = package_modules(PACKAGE)
    assert {"qpcoord", "qpcoord.core.stack", "qpcoord.kinematics.ik"} <= set(modules)
    graph = import_graph(modules)
    assert "qpcoord.core.persistent" in graph["qpcoord.core.stack"]  # the graph has edges
    assert cycles(graph) == []


def test_no_import_circle_among_benchmarks():
    """The benchmark scripts (which import each other by name) form no circle either."""
    modules = script_modules(ROOT / "benchmarks")
    graph = import_graph(modules)
    assert any(graph.values())  # the scripts' imports of each other are seen
    assert cycles(graph) == []


def test_cycle_finder_finds_a_circle():
    """The check above can fail: a graph with a 3-module circle is reported."""
    g = {"p.a": {"p.b"}, "p.b": {"p.c"}, "p.c": {"p.a", "p.d"}, "p.d": set()}
    assert cycles(g) == [["p.a", "p.b", "p.c"]]


def test_import_graph_sees_lazy_and_type_checking_imports(tmp_path):
    """A circle closed only by a function-level import and an ``if TYPE_CHECKING:`` import
    (relative, ``from . import``, ``from .x import``, ``import p.x``) is found."""
    pkg = tmp_path / "p"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .sub.b import B\n"
    )
    (pkg / "sub" / "b.py").write_text("def f():\n    from .. import c\n")
    (pkg / "c.py").write_text("def g():\n    import p.a\n")
    (pkg / "d.py").write_text("from .a import x\n")
    modules = package_modules(pkg)
    assert set(modules) == {"p", "p.a", "p.sub", "p.sub.b", "p.c", "p.d"}
    graph = import_graph(modules)
    assert graph["p.a"] == {"p.sub.b"}
    assert graph["p.sub.b"] == {"p.c"}
    assert graph["p.d"] == {"p.a"}
    assert cycles(graph) == [["p.a", "p.c", "p.sub.b"]]


def _is_venv(folder: Path) -> bool:
    """A virtual environment (``.venv``, ``benchmarks/.placo-venv``, ...): not the project's."""
    return folder.name.endswith("venv") or (folder / "pyvenv.cfg").is_file()


def python_files(folder: Path) -> list[Path]:
    """The ``.py`` files under ``folder``, virtual environments and caches left out."""
    out: list[Path] = []
    for path in sorted(folder.iterdir()):
        if path.is_dir() and not path.is_symlink():
            if not (_is_venv(path) or path.name == "__pycache__"):
                out += python_files(path)
        elif path.suffix == ".py" and path.is_file():
            out.append(path)
    return out


def imported_names(tree: ast.AST, line: int = 1) -> list[tuple[int, str]]:
    """``(line, dotted name)`` of every import of ``tree`` (``import a.b``: ``a.b``; ``from a
    import b``: ``a`` and ``a.b``), and of every string literal of it that parses as Python
    (a script run in a child Python: ``subprocess.run([sys.executable, "-c", script])``),
    recursively; ``line``: the file's line of the tree's first line."""
    found: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        at = line + getattr(node, "lineno", 1) - 1
        if isinstance(node, ast.Import):
            found += [(at, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            found += [(at, base)] + [(at, f"{base}.{alias.name}") for alias in node.names]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            try:
                script = ast.parse(textwrap.dedent(node.value))
            except (SyntaxError, ValueError):  # prose, not a script
                continue
            found += imported_names(script, at)
    return found


def imports_of_test_modules(folders: list[Path]) -> list[str]:
    """``file:line: module`` for every import of a test module (``test_*.py`` under a folder of
    ``folders``) by any ``.py`` file of ``folders``: by name (``import test_x``, ``from
    test_x import f``: pytest's prepend mode puts each test folder on the path), relative
    (``from .test_x import f``) or dotted (``tests.core.test_x``, ``from tests.core import
    test_x``); at module level, in a function, under ``TYPE_CHECKING`` or in a script (a
    string literal) run in a child Python alike."""
    files = [path for folder in folders for path in python_files(folder)]
    stems = {path.stem for path in files if path.name.startswith("test_")}
    found: list[str] = []
    for path in files:
        for line, name in imported_names(ast.parse(path.read_text(), str(path))):
            hit = [part for part in name.split(".") if part in stems]
            if hit:
                rel = path.relative_to(folders[0].parent)
                found.append(f"{rel}:{line}: {hit[0]}")
    return sorted(set(found), key=lambda f: (f.split(":")[0], int(f.split(":")[1])))


def test_no_test_module_imports_a_test_module():
    """Tests and benchmarks share problem builders, oracles and fixtures through
    ``tests/support`` (or a benchmark's own module), never through a test module."""
    folders = [ROOT / "tests", ROOT / "benchmarks"]
    files = [path for folder in folders for path in python_files(folder)]
    assert any(path.name.startswith("test_") for path in files)
    assert not any(".placo-venv" in path.parts for path in files)
    assert imports_of_test_modules(folders) == []


def test_test_module_imports_are_found(tmp_path):
    """The check above can fail: every kind of import of a test module is reported (a
    script's in a string literal too, at its line of the file), and imports of support
    modules, of ``conftest`` and of libraries, and prose naming a test module, are not."""
    tests, bench = tmp_path / "tests", tmp_path / "benchmarks"
    (tests / "core").mkdir(parents=True)
    (tests / "support").mkdir()
    (bench / ".venv" / "lib").mkdir(parents=True)
    (tests / "core" / "test_a.py").write_text("from support.stacks import s\nimport pytest\n")
    (tests / "core" / "test_b.py").write_text("def f():\n    from test_a import g\n")
    (tests / "core" / "test_c.py").write_text("import tests.core.test_a as t\n")
    (tests / "core" / "test_d.py").write_text("from tests.core import test_a\n")
    (tests / "core" / "test_e.py").write_text("from .test_a import g\nfrom conftest import S\n")
    (tests / "support" / "stacks.py").write_text("import test_a\n")
    (tests / "core" / "test_f.py").write_text(
        '"""A test module (``from test_a import g``: prose)."""\n'
        "import subprocess, sys\n"
        "\n"
        'SCRIPT = r"""\n'
        "import numpy as np\n"
        "from test_a import g\n"
        '"""\n'
        'INDENTED = """\n'
        "    import test_a as t\n"
        '"""\n'
        'subprocess.run([sys.executable, "-c", "import os; import tests.core.test_a"])\n'
    )
    (bench / "bench.py").write_text("from support.stacks import s\n")
    (bench / ".venv" / "lib" / "test_x.py").write_text("import test_a\n")
    assert imports_of_test_modules([tests, bench]) == [
        "tests/core/test_b.py:2: test_a",
        "tests/core/test_c.py:1: test_a",
        "tests/core/test_d.py:1: test_a",
        "tests/core/test_e.py:1: test_a",
        "tests/core/test_f.py:6: test_a",
        "tests/core/test_f.py:9: test_a",
        "tests/core/test_f.py:11: test_a",
        "tests/support/stacks.py:1: test_a",
    ]


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
