"""Output files written by examples, studies and the CLI: whole or not at all."""

from __future__ import annotations

import json
import os
from pathlib import Path

__all__ = ["write_json", "write_text", "TextLog"]


def write_json(path, data) -> Path:
    """Write ``data`` as indented JSON to ``path`` atomically (temporary file + rename).

    The parent folder is created. A reader never sees a half-written file: if encoding
    fails (e.g. a non-serialisable value), ``path`` is left as it was and the temporary file
    is removed.

    Returns
    -------
    Path
        The written path.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    try:
        tmp.write_text(json.dumps(data, indent=2))
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def write_text(path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (temporary file + rename); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    try:
        tmp.write_text(text if text.endswith("\n") else text + "\n")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


class TextLog:
    """Lines printed as they come and kept for a ``summary.txt`` (examples, CLI)."""

    def __init__(self) -> None:
        self.lines: list[str] = []

    def say(self, text: str) -> None:
        """Print ``text`` and keep it."""
        print(text)
        self.lines.append(text)

    def write(self, path) -> Path:
        """Write the kept lines atomically to ``path``."""
        return write_text(path, "\n".join(self.lines))
