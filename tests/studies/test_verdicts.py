"""The verdict file (tests/studies/verdicts.json) and the full reproduction's verdicts.

The quick verdicts are compared in tests/test_examples.py (the quick run happens once
there); here: the file's consistency with the claim register, and (slow) the full run.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from qpcoord.studies.claim_ids import REGISTER
from qpcoord.studies.claims import claim, load_verdicts, thesis_claims, verdict_mismatches

VERDICTS = Path(__file__).with_name("verdicts.json")


def test_verdict_file_matches_the_register():
    verdicts = load_verdicts(VERDICTS)
    ids = {e.id for e in REGISTER.values()}
    assert set(verdicts) == ids, (sorted(ids - set(verdicts)), sorted(set(verdicts) - ids))
    for entry in REGISTER.values():
        v = verdicts[entry.id]
        if entry.calibrated:  # an input is never "reproduced"
            assert v["quick"] == v["full"] == "calibrated", entry.id
        else:
            assert "calibrated" not in (v["quick"], v["full"]), entry.id
        if entry.identity:  # holds by construction: never "reproduced"
            assert v["quick"] == v["full"] == "identity", entry.id
        else:
            assert "identity" not in (v["quick"], v["full"]), entry.id


def test_a_changed_verdict_is_reported(tmp_path):
    verdicts = {
        "T6.1-direct-coil-rmse": {"quick": "reproduced", "full": "reproduced"},
        "Fig6.6-piezo-300Hz": {"quick": "calibrated", "full": "calibrated"},
    }
    piezo = claim("fig6.6-piezo-bandwidth", "c", "F6.6", "300 Hz", "calibrated", "input")
    rows = [
        ("6", "ch6_tracking", claim("table6.1-rmse", "c", "T6.1", "40 nm", "differs", "why")),
        ("6", "ch6_tracking", piezo),
        ("6", "ch6_tracking", claim("mine", "c", "n/a", "1", "own check")),
    ]
    problems = verdict_mismatches(thesis_claims(rows), verdicts, "full")
    assert problems == [
        "T6.1-direct-coil-rmse: differs in this run, the verdict file says reproduced"
    ]
    assert verdict_mismatches(thesis_claims(rows[1:]), verdicts, "quick") == [
        "T6.1-direct-coil-rmse: in the verdict file, not checked by this run"
    ]
    bad = tmp_path / "v.json"
    bad.write_text(json.dumps({"X": {"quick": "differs", "full": "differs"}}))
    with pytest.raises(ValueError, match="no cause"):
        load_verdicts(bad)
    bad.write_text(json.dumps({"X": {"quick": "ok", "full": "differs"}}))
    with pytest.raises(ValueError, match="quick must be one of"):
        load_verdicts(bad)


@pytest.mark.slow
def test_full_verdicts(tmp_path):
    """The full reproduction (minutes): every verdict is the file's."""
    from qpcoord.studies.reproduce import run

    report = run(out=tmp_path, quick=False, jobs=2, progress=False, bench=False)
    assert report.ok, [(r.name, r.error) for r in report.failed]
    problems = verdict_mismatches(report.claims, load_verdicts(VERDICTS), "full")
    assert not problems, "\n".join(problems)


def test_an_identity_is_never_counted_as_reproduced():
    from qpcoord.studies.claims import count_claims

    held = claim("def5.4-level1-kept", "c", "Def 5.4", "1e-15", "identity", "by construction")
    old = claim("def5.4-strict-keeps-main", "c", "Def 5.4", "1e-15", "reproduced")
    broken = claim("def5.4-level2-kept", "c", "Def 5.4", "0.1", "differs", "a solver bug")
    claims = thesis_claims([("5", "ch5_hierarchy", held), ("core", "core_priorities", old)])
    assert claims["Def5.4-decoupling"]["status"] == "identity"
    assert count_claims(claims.values())["reproduced"] == 0
    # an identity that fails is a bug: it differs
    claims = thesis_claims([("5", "ch5_hierarchy", held), ("5", "ch5_hierarchy", broken)])
    assert claims["Def5.4-decoupling"]["status"] == "differs"
    with pytest.raises(ValueError, match="no note"):
        claim("x", "c", "t", "m", "identity")


def test_contradictions_name_registered_claims():
    from qpcoord.studies.claim_ids import CONTRADICTIONS

    ids = {e.id for e in REGISTER.values()}
    assert CONTRADICTIONS
    for c in CONTRADICTIONS:
        assert len(c.says) >= 2, c.id
        assert set(c.claims) <= ids, (c.id, set(c.claims) - ids)


def test_quick_never_decides_differently(tmp_path):
    from qpcoord.studies.claims import QUICK

    bad = tmp_path / "v.json"
    bad.write_text(json.dumps({"X": {"quick": "reproduced", "full": "inconclusive"}}))
    with pytest.raises(ValueError, match="decides differently"):
        load_verdicts(bad)
    bad.write_text(json.dumps({"X": {"quick": "inconclusive", "full": "reproduced"}}))
    with pytest.raises(ValueError, match="decides differently"):
        load_verdicts(bad)
    bad.write_text(json.dumps({"X": {"quick": QUICK, "full": QUICK}}))
    with pytest.raises(ValueError, match="never"):
        load_verdicts(bad)
    good = tmp_path / "g.json"
    good.write_text(json.dumps({"X": {"quick": QUICK, "full": "reproduced"}}))
    assert load_verdicts(good)["X"]["quick"] == QUICK


def test_the_docs_counts_are_the_verdict_files():
    """docs/reproduce.md's counts table is generated (python -m qpcoord.studies.counts)
    from the verdict file, which the quick and the full runs are compared with."""
    from qpcoord.studies.counts import BEGIN, END, _from_verdicts, counts_table

    doc = (Path(__file__).parents[2] / "docs" / "reproduce.md").read_text(encoding="utf-8")
    block = doc.split(BEGIN, 1)[1].split(END, 1)[0].strip()
    assert block == counts_table(*_from_verdicts(VERDICTS))


def test_counts_table_and_block(tmp_path):
    from qpcoord.studies.counts import BEGIN, END, counts_table, replace_block

    quick = {
        "A": ("inconclusive (quick)", ""),
        "B": ("differs", "our model"),
        "C": ("inconclusive (quick)", ""),
    }
    full = {"A": ("reproduced", ""), "B": ("differs", "our model"), "C": ("inconclusive", "")}
    table = counts_table(quick, full)
    assert "| inconclusive (quick) | 2 | 0 |" in table
    assert "| — our model | 1 | 1 |" in table
    assert "1 of its 2 `inconclusive (quick)` claims are decided by the full run" in table
    text = f"x\n{BEGIN}\nold\n{END}\ny"
    assert replace_block(text, "new") == f"x\n{BEGIN}\nnew\n{END}\ny"
    with pytest.raises(ValueError, match="no block"):
        replace_block("no markers", "new")
