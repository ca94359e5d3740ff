"""The benchmarks' shared output: markdown tables, the machine line, the command line, ranges
over runs, and the splice of a table into ``benchmarks/README.md`` between its markers.

Every script prints :func:`preamble` (machine and command) and then its tables, so that the
README's block for a benchmark is exactly what its command prints (``python -m benchmarks
--write`` puts it there).
"""

from __future__ import annotations

import math
import os
import platform
import re
import shlex
import subprocess
import sys
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: The markers around a benchmark's table in the README: ``<!-- table: NAME -->`` … ``<!--
#: /table -->``; the lines between them belong to the writer, the rest to the prose.
BEGIN = "<!-- table: {name} -->"
END = "<!-- /table -->"


def markdown(header: Sequence[str], rows: Iterable[Sequence[object]], align: str = "") -> str:
    """A markdown table; ``align`` one letter per column, ``l`` or ``r`` (missing: ``l``).

    Cells (and headers) are ``str(cell)`` with ``|`` escaped; a row of the wrong length
    raises ``ValueError``.
    """
    cells = [[str(c).replace("|", "\\|") for c in r] for r in (header, *rows)]
    for r in cells:
        if len(r) != len(header):
            raise ValueError(f"row {r!r} has {len(r)} cells, the header {len(header)}")
    rule = ["---:" if align[i : i + 1] == "r" else "---" for i in range(len(header))]
    lines = [cells[0], rule, *cells[1:]]
    return "\n".join("| " + " | ".join(line) + " |" for line in lines)


def sig3(v: float) -> str:
    """``v`` with three significant digits and no exponent (``1234.4`` → ``1234``, ``12.34`` →
    ``12.3``, ``0.1234`` → ``0.123``)."""
    if v != v or v in (math.inf, -math.inf):
        return str(v)
    digits = 0 if v == 0 else max(0, 2 - math.floor(math.log10(abs(v))))
    return f"{v:.{digits}f}"


def span(values: Sequence[float], fmt: str | Callable[[float], str] = "{:.1f}") -> str:
    """``min–max`` of the values of several runs, each through ``fmt`` (a format string or a
    function such as :func:`sig3`); one value if both ends print alike."""
    if len(values) == 0:
        return "–"
    show = fmt.format if isinstance(fmt, str) else fmt
    lo, hi = show(min(values)), show(max(values))
    return lo if lo == hi else f"{lo}–{hi}"


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _blas() -> str:
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return "BLAS unknown (no threadpoolctl)"
    found = []  # every BLAS loaded so far (numpy's, and another library's own copy)
    for info in threadpool_info():
        if info.get("user_api") == "blas":
            kernel = info.get("architecture") or "?"
            name = f"{info.get('internal_api', 'blas')} {info.get('version', '')}".strip()
            if f"{name} {kernel} kernel" not in found:
                found.append(f"{name} {kernel} kernel")
    return ", ".join(sorted(found)) or "BLAS not loaded"


def _commit() -> str:
    def git(*args: str) -> str:
        out = subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)
        return out.stdout.strip() if out.returncode == 0 else ""

    head = git("rev-parse", "--short", "HEAD")
    if not head:
        return "qpcoord (no git checkout)"
    modified = git("status", "--porcelain", "--untracked-files=no", "--", "qpcoord", "src")
    return f"qpcoord `{head}`" + (" with local changes" if modified else "")


def machine() -> str:
    """One line: CPU model, cores, the 1-minute load at the start, the BLAS kernel
    (threadpoolctl), Python and numpy versions, and the qpcoord commit."""
    import numpy as np

    load = f", load {os.getloadavg()[0]:.1f}" if hasattr(os, "getloadavg") else ""
    return (
        f"{_cpu()}, {os.cpu_count()} cores{load}; {_blas()}; Python "
        f"{platform.python_version()}, numpy {np.__version__}; {_commit()}"
    )


def command(argv: Sequence[str] | None = None) -> str:
    """The command that reproduces this run, from the repository root."""
    argv = sys.argv if argv is None else argv
    script = Path(argv[0]).resolve()
    try:
        shown = str(script.relative_to(ROOT))
    except ValueError:
        shown = str(argv[0])
    return shlex.join(["python", shown, *argv[1:]])


def preamble(argv: Sequence[str] | None = None) -> str:
    """The line every benchmark prints first: its machine and its command."""
    return f"Machine: {machine()}. Command: `{command(argv)}`"


def splice(text: str, name: str, block: str) -> str:
    """``text`` with the lines between ``name``'s markers replaced by ``block``.

    Raises ``ValueError`` naming the table if its markers are missing, repeated or out of
    order (the text is then not changed by the caller).
    """
    begin = BEGIN.format(name=name)
    pattern = re.compile(rf"^{re.escape(begin)}[ \t]*\n(.*?)^{re.escape(END)}[ \t]*$", re.M | re.S)
    found = pattern.findall(text)
    if len(found) != 1:
        raise ValueError(f"table {name!r}: {len(found)} marker pairs {begin} … {END} (need 1)")
    body = block.strip("\n") + "\n"
    return pattern.sub(lambda m: f"{begin}\n{body}{END}", text, count=1)


def write_tables(pages: dict[Path, dict[str, str]]) -> None:
    """Splice every table into its page, all or none: every page's new text is made (a
    missing marker raises) before any is written; each goes to a temporary file beside its
    page that replaces it in one rename."""
    texts = {}
    for path, blocks in pages.items():
        text = path.read_text()
        for name, block in blocks.items():
            text = splice(text, name, block)
        texts[path] = text
    for path, text in texts.items():
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_text(text)
        os.replace(tmp, path)
