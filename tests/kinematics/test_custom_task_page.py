"""``docs/custom-task.md`` (writing your own task): its python blocks form one program, run in
order in one namespace, as a reader pasting them would (the same rule as
``tests/test_docs.py`` for the other runnable pages)."""

from __future__ import annotations

import matplotlib
from support.pages import ROOT, run_blocks, run_page

matplotlib.use("Agg")

PAGE = ROOT / "docs" / "custom-task.md"


def test_the_page_has_python_blocks():
    assert len(run_blocks(PAGE)) >= 6


def test_the_snippets_of_the_custom_task_page_run(capsys):
    namespace = run_page(PAGE)
    out = capsys.readouterr().out
    assert "height error" in out and "optimal" in out
    # the page's custom task is a KinematicTask subclass used at a level, as a band, hard
    from qpcoord.kinematics import KinematicTask

    assert issubclass(namespace["Height"], KinematicTask)
    assert namespace["above_floor"].kind == "band"
