"""``docs/custom-task.md`` (writing your own task): its python blocks form one program, run in
order in one namespace, as a reader pasting them would (the same rule as
``tests/test_docs.py`` for the other runnable pages)."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

PAGE = Path(__file__).resolve().parents[2] / "docs" / "custom-task.md"


def _blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", PAGE.read_text(encoding="utf-8"), re.S)


def test_the_page_has_python_blocks():
    assert len(_blocks()) >= 6


def test_the_snippets_of_the_custom_task_page_run(capsys):
    namespace: dict = {}
    for i, code in enumerate(_blocks()):
        exec(compile(code, f"docs/custom-task.md block {i}", "exec"), namespace)
    out = capsys.readouterr().out
    assert "height error" in out and "optimal" in out
    # the page's custom task is a KinematicTask subclass used at a level, as a band, hard
    from qpcoord.kinematics import KinematicTask

    assert issubclass(namespace["Height"], KinematicTask)
    assert namespace["above_floor"].kind == "band"
