"""The documentation site builds with MkDocs in strict mode (warnings are errors).

mkdocs, mkdocs-material and mkdocstrings are in the ``test`` extra: if they are missing this
test fails (it does not skip), so CI cannot pass with an unbuilt site.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Pages that must exist in the built site (path under the site root, text it must contain).
PAGES = {
    "index.html": "prioritised QP stack",
    "getting-started/index.html": "Reproducing the thesis results",
    "concepts/index.html": "InfeasibleError",
    "control-loop/index.html": "solve_theta",
    "solvers/index.html": "stack_bench.py",
    "ch6/index.html": "SisoCoordinator",
    "appB/index.html": "BladeFlexure",
    # API pages generated from docstrings by mkdocstrings
    "api/core/stack/index.html": 'id="qpcoord.core.stack.solve_stack"',
    "api/core/persistent/index.html": 'id="qpcoord.core.persistent.PersistentQP"',
    "api/ddl/controllers/index.html": 'id="qpcoord.ddl.mpc.MPC"',
}


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    for module in ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python"):
        try:
            found = importlib.util.find_spec(module) is not None
        except ModuleNotFoundError:  # a dotted name whose parent is missing
            found = False
        if not found:
            pytest.fail(f"{module} is not installed: pip install -e '.[test]'")
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, (
        f"mkdocs build --strict failed (exit {proc.returncode}):\n{proc.stdout}\n{proc.stderr}"
    )
    return out


def test_strict_build_has_no_warnings(site: Path) -> None:
    assert (site / "index.html").is_file()


@pytest.mark.parametrize("page", sorted(PAGES))
def test_page_built(site: Path, page: str) -> None:
    path = site / page
    assert path.is_file(), f"{page} missing from the built site"
    assert PAGES[page] in path.read_text(encoding="utf-8"), f"{PAGES[page]!r} not in {page}"


def test_figures_copied(site: Path) -> None:
    images = sorted(p.name for p in (site / "img").glob("*.png"))
    assert images, "no figure in the built site"
    total = sum(p.stat().st_size for p in (ROOT / "docs" / "img").glob("*.png"))
    assert total < 4_000_000, f"docs/img holds {total / 1e6:.1f} MB of figures (limit 4 MB)"


#: Pages whose ``python`` blocks form a complete program, run in order in one namespace (as a
#: reader pasting them would). The other pages' blocks are sketches with placeholders
#: (``...``, a user's own ``run_control_loop``), or run long studies tested elsewhere.
RUNNABLE_PAGES = [
    "index.md",
    "concepts.md",
    "getting-started.md",
    "kinematics.md",
    "ch5.md",
    "appA.md",
    "appB.md",
]


@pytest.mark.parametrize("page", RUNNABLE_PAGES)
def test_the_snippets_of_a_page_run(page, capsys):
    import re

    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / page).read_text(), re.S)
    assert blocks, f"{page} has no python block"
    namespace: dict = {}
    for i, code in enumerate(blocks):
        exec(compile(code, f"docs/{page} block {i}", "exec"), namespace)
