"""Every example script runs in --quick mode and writes its summary."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted((ROOT / "examples").glob("*.py"))


def test_there_are_examples():
    assert SCRIPTS


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.name)
def test_example_quick(script, tmp_path):
    proc = subprocess.run(
        [sys.executable, str(script), "--quick", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary
    # every example states what it checked against the thesis (qpcoord reproduce's report)
    from qpcoord.studies.claims import claim

    rows = summary.get("claims")
    assert rows, f"{script.name}: summary.json has no claims"
    assert len({r["id"] for r in rows}) == len(rows), "claim ids must be unique"
    for row in rows:
        assert claim(**row) == row  # valid status, text fields, notes where needed
    assert list(tmp_path.rglob("*.png")), f"{script.name} wrote no figure"


def test_the_examples_index_lists_every_script():
    index = (ROOT / "examples" / "README.md").read_text()
    listed = set(re.findall(r"^\| `([\w]+\.py)` \|", index, re.M))
    assert listed == {p.name for p in SCRIPTS}


def test_write_json_is_atomic(tmp_path):
    from qpcoord.studies.files import write_json

    target = tmp_path / "sub" / "summary.json"
    write_json(target, {"a": 1})
    assert target.read_text().startswith("{")
    with pytest.raises(TypeError):
        write_json(target, {"a": object()})  # not serialisable: the old file stays whole
    assert '"a": 1' in target.read_text()
    assert not (tmp_path / "sub" / "summary.json.tmp").exists()


def test_claim_rows_are_checked():
    from qpcoord.studies.claims import claim

    row = claim("x", "a claim", "Fig 1: 3", "3.0", "reproduced")
    assert row["status"] == "reproduced" and row["note"] == ""
    with pytest.raises(ValueError, match="status"):
        claim("x", "a claim", "Fig 1", "3", "ok")
    with pytest.raises(ValueError, match="note"):
        claim("x", "a claim", "Fig 1", "3", "differs")
    with pytest.raises(ValueError, match="measured"):
        claim("x", "a claim", "Fig 1", " ", "reproduced")
