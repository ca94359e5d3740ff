"""The runnable snippets of the README and the pages of ``docs/``.

A block fenced exactly ```` ```python ```` runs, in page order, in one namespace per page (as
a reader pasting them would); a block with anything after ``python`` on its fence line is
shown only (``tests/test_docs.py`` states the whole convention and checks what each block
prints).
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: A fenced block: its language, the rest of its fence line, its code.
FENCE = re.compile(r"^```([\w-]*)([^\n]*)\n(.*?)^```[ \t]*$", re.S | re.M)


def page_blocks(path: Path) -> list[tuple[str, str, str]]:
    """``(kind, code, expected_output)`` per python block of the page, in page order: kind is
    ``"run"`` or ``"shown"`` (a title after ``python``), expected_output the text block that
    follows a run block or ``""``."""
    text = path.read_text(encoding="utf-8")
    fences = list(FENCE.finditer(text))
    out = []
    for k, m in enumerate(fences):
        lang, rest, code = m.group(1), m.group(2).strip(), m.group(3)
        if lang != "python":
            continue
        expected = ""
        if k + 1 < len(fences):
            nxt = fences[k + 1]
            if nxt.group(1) == "text" and not text[m.end() : nxt.start()].strip():
                expected = nxt.group(3)
        out.append(("shown" if rest else "run", code, expected))
    return out


def run_blocks(path: Path) -> list[str]:
    """The code of the page's run blocks, in page order."""
    return [code for kind, code, _ in page_blocks(path) if kind == "run"]


def run_page(path: Path) -> dict:
    """Run the page's run blocks in order in one namespace (``__name__`` is ``"__main__"``),
    each compiled as ``"<page> block <i>"`` so that a traceback names it; the namespace."""
    name = path.relative_to(ROOT).as_posix() if path.is_relative_to(ROOT) else str(path)
    namespace: dict = {"__name__": "__main__"}
    for i, code in enumerate(run_blocks(path)):
        exec(compile(code, f"{name} block {i}", "exec"), namespace)  # noqa: S102
    return namespace
