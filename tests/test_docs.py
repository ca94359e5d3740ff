"""The documentation site builds with MkDocs in strict mode (warnings are errors).

mkdocs, mkdocs-material and mkdocstrings are in the ``test`` extra: if they are missing this
test fails (it does not skip), so CI cannot pass with an unbuilt site.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from support.pages import FENCE, page_blocks

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


# -- every page's snippets run, and print what the page shows ---------------------------------
#
# Convention, for README.md and every page of docs/:
#
# * A block fenced exactly ```` ```python ```` runs, in page order, in one namespace per page (as
#   a reader pasting them would), with the working directory a fresh temporary folder.
# * A block with anything after ``python`` on its fence line (````python title="sketch: not
#   run"````) is shown only; its title says why (a placeholder, another library, a long study).
# * A ```` ```text ```` block right after a run block (blank lines between are allowed) is what
#   that block prints. The printed output must match it: text word for word (runs of blank
#   space are one space), ``…`` in the page stands for any text (a time, a path), and numbers
#   match within NUMBER_RTOL relative or NUMBER_ATOL absolute.
# * A run block that prints must be followed by its output block.

#: A page prints values rounded to 3-4 significant digits; the last digit may flip between
#: BLAS kernels or CPUs (one unit of the 4th digit is at most 1e-3 of the value), so 2e-3.
NUMBER_RTOL = 2e-3
#: The pages print SI quantities (m, rad, s) and residuals of unit-scale tasks; values under
#: 1e-6 are at the solvers' tolerances (CHECK_TOL 1e-6, KKT_TOL 1e-9 relative) and rounding
#: (1e-17 on one machine, 3e-16 on another): they are compared absolutely, all equal to 0.
NUMBER_ATOL = 1e-6

_NUMBER = r"[-+−]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def _pages() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _pattern(expected: str) -> tuple[re.Pattern, list[float]]:
    """A regex matching the printed text the page shows, and the numbers it shows in order."""
    parts, numbers = [], []
    pieces = [p for p in re.split(f"({_NUMBER}|…|\\s+)", expected.strip()) if p]
    for k, piece in enumerate(pieces):
        if piece == "…":
            parts.append(".*?")
        elif piece.isspace():
            # blank space separating two words or numbers is required; elsewhere (numpy's
            # "[ 0.05" against "[0.05", a column's padding) any amount, none included
            between = pieces[k - 1][-1:].isalnum() and pieces[k + 1][:1].isalnum()
            parts.append(r"\s+" if between else r"\s*")
        elif re.fullmatch(_NUMBER, piece):
            parts.append(f"({_NUMBER})")
            numbers.append(float(piece.replace("−", "-")))
        else:
            parts.append(re.escape(piece))
    return re.compile("".join(parts), re.S), numbers


def check_output(printed: str, expected: str) -> str | None:
    """``None`` when ``printed`` matches the page's ``expected`` output, else why not."""
    pattern, numbers = _pattern(expected)
    m = pattern.fullmatch(printed.strip())
    if m is None:
        return f"the page shows\n{expected.strip()}\nthe snippet prints\n{printed.strip()}"
    for shown, got in zip(numbers, m.groups(), strict=True):
        value = float(got.replace("−", "-"))
        if abs(value - shown) > max(NUMBER_ATOL, NUMBER_RTOL * abs(shown)):
            return f"the page shows {shown!r}, the snippet prints {got}:\n{printed.strip()}"
    return None


def test_output_check_compares_numbers_with_the_stated_tolerance() -> None:
    assert check_output("x = 1.0004 at 3.1e-17 m", "x = 1.000 at 0 m") is None
    assert check_output("x = 1.01", "x = 1.000") is not None
    assert check_output("took 812.5 µs\nok", "took … µs\nok") is None
    assert check_output("status 'inaccurate'", "status 'optimal'") is not None
    assert check_output("[1.  0.5]", "[1. 0.5]") is None


#: The pages show what a user's session prints: the library's default engine (native where
#: built), whatever default the Python-engine pass of the suite sets.
@pytest.mark.engine_independent
@pytest.mark.parametrize("page", [p.relative_to(ROOT).as_posix() for p in _pages()])
def test_the_snippets_of_a_page_run_and_print_what_it_shows(page, tmp_path, monkeypatch, capsys):
    path = ROOT / page
    blocks = page_blocks(path)
    if not any(kind == "run" for kind, _, _ in blocks):
        pytest.skip(f"{page} has no run block")
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__main__"}
    for i, (kind, code, expected) in enumerate(blocks):
        if kind == "shown":
            continue
        capsys.readouterr()
        exec(compile(code, f"{page} block {i}", "exec"), namespace)
        printed = capsys.readouterr().out
        if expected:
            problem = check_output(printed, expected)
            assert problem is None, f"{page} block {i}: {problem}"
        elif printed.strip():
            pytest.fail(
                f"{page} block {i} prints but the page shows no text block after it:\n{printed}"
            )


def test_shown_only_blocks_say_why() -> None:
    for path in _pages():
        text = path.read_text(encoding="utf-8")
        for m in FENCE.finditer(text):
            if m.group(1) == "python" and m.group(2).strip():
                assert "title=" in m.group(2), f"{path.name}: {m.group(0).splitlines()[0]!r}"
