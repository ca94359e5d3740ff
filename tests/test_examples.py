"""Every example script runs in --quick mode and writes its summary; the quick verdicts are
the verdict file's (tests/studies/verdicts.json).

The quick reproduction runs ONCE per pytest session (``qpcoord.studies.reproduce.run(quick=True)``,
two scripts at a time, each its own ``python examples/<name>.py --quick`` process); the
per-script tests and the verdict test read its results.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest

from qpcoord.studies.chapters import STANDALONE_SCRIPTS

#: the examples run as their own processes (``qpcoord reproduce``), on the library's default
#: engine whatever ``QPCOORD_TEST_ENGINE`` says: not repeated in the Python-engine pass
pytestmark = pytest.mark.engine_independent

ROOT = Path(__file__).resolve().parents[1]
ALL_SCRIPTS = sorted((ROOT / "examples").glob("*.py"))
#: the scripts the quick reproduction runs (not the standalone benchmark scripts)
SCRIPTS = [p for p in ALL_SCRIPTS if p.stem not in STANDALONE_SCRIPTS]
VERDICTS = ROOT / "tests" / "studies" / "verdicts.json"

#: Thesis claims the quick run must decide (reach the full run's verdict): those whose quick
#: run is the full run's (Lemma 4.1, Thm 4.2, Lemma 4.2, §5.3.5, Fig 5.9, §6.3, appendices A
#: and C) and the ch6 spec, judged on the same references in both.
QUICK_MUST_DECIDE = (
    "Def5.4-decoupling",
    "Lem4.1-not-involutive",
    "Thm4.2-periodic",
    "Thm4.2-involutive",
    "Sec5.3.5-limits-level",
    "Lem4.2-each-leaf-periodic",
    "Fig5.9-periodic",
    "Spec6.1.2-rmse-70nm",
    "Eq6.3-two-ddl-combination",
    "Fig6.14a-bandwidth-gain-1.6",
    "EqA.19-generalised-forces",
    "EqA.24-force-bounds",
    "SecA.3.2-pinv-pushes",
    "EqA.28-stress-optimal",
    "FigC.8-sine-improvement",
    "FigC.8-sine-residual",
    "FigC.10-stochastic-levels",
    "FigA.3-forward-tracking",
)


@pytest.fixture(scope="session")
def quick_report(tmp_path_factory):
    from qpcoord.studies.reproduce import run

    jobs = max(1, min(2, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 2))
    out = tmp_path_factory.mktemp("reproduce-quick")
    return run(out=out, quick=True, jobs=jobs, progress=False, bench=False, timeout=300)


def test_there_are_examples():
    assert SCRIPTS


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: p.name)
def test_example_quick(script, quick_report):
    res = next((r for r in quick_report.results if r.name == script.stem), None)
    assert res is not None, f"{script.name} was not run by the quick reproduction"
    assert res.ok, f"{res.error}\n{res.stderr_tail}"
    summary = json.loads((res.out_dir / "summary.json").read_text())
    assert summary
    # every example states what it checked against the thesis (qpcoord reproduce's report)
    from qpcoord.studies.claims import claim

    rows = summary.get("claims")
    assert rows, f"{script.name}: summary.json has no claims"
    assert len({r["id"] for r in rows}) == len(rows), "claim ids must be unique"
    for row in rows:
        # valid status, text fields, notes where needed ("not in thesis" reads "own check")
        again = claim(**row)
        assert again == {**row, "status": again["status"], "cause": row.get("cause", "")}
    assert list(res.out_dir.rglob("*.png")), f"{script.name} wrote no figure"


def test_quick_verdicts_are_the_verdict_files(quick_report):
    """A changed quick verdict must be a deliberate edit of tests/studies/verdicts.json."""
    from qpcoord.studies.claims import load_verdicts, verdict_mismatches

    assert quick_report.ok, [(r.name, r.error) for r in quick_report.failed]
    claims = quick_report.claims
    assert not [c for c in claims if c.startswith("unregistered:")], "rows without a claim ID"
    problems = verdict_mismatches(claims, load_verdicts(VERDICTS), "quick")
    assert not problems, "\n".join(problems)
    # "decides" = reaches the full run's verdict: a claim that is inconclusive on substance
    # (e.g. the two hysteresis stacks disagree) is decided when the full run says the same
    full = {c: v["full"] for c, v in load_verdicts(VERDICTS).items()}
    undecided = [c for c in QUICK_MUST_DECIDE if claims[c]["status"] != full[c]]
    assert not undecided, f"the quick run must decide {undecided}"


def test_the_examples_index_lists_every_script():
    index = (ROOT / "examples" / "README.md").read_text()
    listed = set(re.findall(r"^\| `([\w]+\.py)` \|", index, re.M))
    assert listed == {p.name for p in ALL_SCRIPTS}


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
    with pytest.raises(ValueError, match="note"):
        claim("x", "a claim", "Fig 1", "3", "calibrated")
    with pytest.raises(ValueError, match="cause"):
        claim("x", "a claim", "Fig 1", "3", "differs", "why", cause="bad luck")
    with pytest.raises(ValueError, match="only given for 'differs'"):
        claim("x", "a claim", "Fig 1", "3", "reproduced", cause="our model")
    assert claim("x", "a claim", "Fig 1", "3", "not in thesis")["status"] == "own check"
    row = claim("x", "a claim", "Fig 1", "3", "differs", "why", cause="thesis error")
    assert row["cause"] == "thesis error"


def test_thesis_claims_count_once():
    from qpcoord.studies.claims import claim, count_claims, thesis_claims

    rep = claim("table6.1-rmse", "c", "T6.1", "25 nm", "reproduced")
    dif = claim("table6.1-coordinator", "c", "T6.1", "40 nm", "differs", "why")
    inc = claim("table6.1-rmse-nominal", "c", "T6.1", "?", "inconclusive", "short")
    cal = claim("fig6.6-piezo-bandwidth", "c", "F6.6", "300 Hz", "reproduced")
    own = claim("mine", "c", "n/a", "1", "not in thesis")
    rows = [
        ("6", "ch6_tracking", rep),
        ("6", "ch6_compare", dif),
        ("6", "sweep_ddl_seeds", inc),
        ("6", "ch6_tracking", cal),
        ("6", "ch6_tracking", own),
    ]
    claims = thesis_claims(rows)
    assert set(claims) == {
        "T6.1-direct-coil-rmse",
        "Fig6.6-piezo-300Hz",
        "own:ch6_tracking:mine",
    }
    rmse = claims["T6.1-direct-coil-rmse"]
    assert rmse["status"] == "differs" and rmse["cause"] == "our model"  # register default
    assert len(rmse["rows"]) == 3
    assert claims["Fig6.6-piezo-300Hz"]["status"] == "calibrated"  # an input, not a result
    counts = count_claims(claims.values())
    assert counts["differs"] == 1 and counts["differs: our model"] == 1
    assert counts["calibrated"] == 1 and counts["own check"] == 1 and counts["reproduced"] == 0
    # without the differing row the claim is reproduced once, not twice
    again = thesis_claims([rows[0], rows[2]])
    assert count_claims(again.values())["reproduced"] == 1
