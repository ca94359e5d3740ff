"""Griffe extension for the documentation build: reStructuredText idioms → Markdown.

qpcoord's docstrings are numpy style with a few Sphinx idioms that Markdown renders badly.
This extension rewrites, in the docstring text only (the source files are untouched):

* ``:class:`~a.b.C``` (and ``:func:``, ``:meth:``, ``:mod:``, ``:attr:``, ``:data:``,
  ``:exc:``, ``:obj:``) → ```C``` (``~`` keeps the last component, as in Sphinx);
* a paragraph of ``>>>`` lines (a doctest) → a fenced ``pycon`` block;
* ``text::`` before an indented literal block → ``text:`` (the block stays code);
* ``double backticks`` → ``single backticks`` (RST inline literals);
* a two-column RST simple table (``====  ====`` rules) → a Markdown table (a line whose
  first column is blank continues the row above).

Loaded by ``mkdocs.yml`` (``plugins.mkdocstrings.handlers.python.options.extensions``).
"""

from __future__ import annotations

import re

import griffe

_ROLE = re.compile(r":(?:py:)?(?:class|func|meth|mod|attr|data|exc|obj|const):`(~?)([^`]+)`")
_LITERAL = re.compile(r"``([^`]+?)``")


def _role(m: re.Match) -> str:
    target = m.group(2).strip()
    if m.group(1):
        target = target.rsplit(".", 1)[-1]
    return f"`{target.lstrip('.')}`"


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


_RULE = re.compile(r"^(\s*)(=+)(\s+)(=+)\s*$")


def _tables(lines: list[str]) -> list[str]:
    """Two-column RST simple tables (rule, rows, rule) → Markdown tables."""
    out: list[str] = []
    i = 0
    while i < len(lines):
        m = _RULE.match(lines[i])
        end = None
        if m:
            end = next((j for j in range(i + 1, len(lines)) if _RULE.match(lines[j])), None)
        if m is None or end is None:
            out.append(lines[i])
            i += 1
            continue
        indent = m.group(1)
        c2 = len(m.group(1)) + len(m.group(2)) + len(m.group(3))
        rows: list[list[str]] = []
        for line in lines[i + 1 : end]:
            if not line.strip():
                continue
            cut = c2
            while 0 < cut < len(line) and not line[cut - 1].isspace():
                cut += 1  # a first-column entry that overflows its rule
            first, second = line[:cut].strip(), line[cut:].strip()
            if first or not rows:
                rows.append([first, second])
            else:
                rows[-1][1] = f"{rows[-1][1]} {second}".strip()
        if out and out[-1].strip():
            out.append("")
        out.append(f"{indent}| | |")
        out.append(f"{indent}|---|---|")
        out.extend(f"{indent}| {_cell(a)} | {_cell(b)} |" for a, b in rows)
        out.append("")
        i = end + 1
    return out


def convert(text: str) -> str:
    """Return ``text`` with the RST idioms above rewritten as Markdown."""
    text = "\n".join(_tables(text.split("\n")))  # first: columns are by position
    text = _ROLE.sub(_role, text)
    text = _LITERAL.sub(r"`\1`", text)
    out: list[str] = []
    lines = text.split("\n")
    i = 0
    while i < len(lines):
        line = lines[i]
        stripped = line.lstrip()
        if stripped.startswith(">>>") and not (out and out[-1].strip().startswith("```")):
            indent = line[: len(line) - len(stripped)]
            block = []
            while i < len(lines) and lines[i].strip():
                block.append(lines[i][len(indent) :] if lines[i].startswith(indent) else lines[i])
                i += 1
            if out and out[-1].strip():
                out.append("")
            out.append(indent + "```pycon")
            out.extend(indent + b for b in block)
            out.append(indent + "```")
            continue
        if line.rstrip().endswith("::") and not line.rstrip().endswith(":::"):
            head = line.rstrip()[:-2].rstrip()
            line = head + ":" if head else ""
        out.append(line)
        i += 1
    return "\n".join(out)


class RstCompat(griffe.Extension):
    """Rewrite Sphinx roles, doctests and ``::`` literal markers in every docstring."""

    def on_object(self, *, obj, **kwargs) -> None:  # noqa: D102
        if obj.docstring is not None:
            obj.docstring.value = convert(obj.docstring.value)

    def on_package(self, *, pkg, **kwargs) -> None:  # noqa: D102
        # the top-level package is not passed to on_object; convert() is idempotent
        self.on_object(obj=pkg)
