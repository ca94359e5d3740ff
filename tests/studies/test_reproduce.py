"""``qpcoord reproduce``: running example scripts, failures, timeouts and the report."""

from __future__ import annotations

import json
import re
import textwrap
from pathlib import Path

import pytest

from qpcoord import reproduce
from qpcoord.cli import main
from qpcoord.studies import render

ROOT = Path(__file__).resolve().parents[2]

GOOD = '''
"""A fake chapter 4 reproduction: one claim, one figure."""
import argparse, sys
from pathlib import Path
from qpcoord.studies.claims import claim
from qpcoord.studies.files import write_json

p = argparse.ArgumentParser()
p.add_argument("--quick", action="store_true")
p.add_argument("--out", type=Path)
a = p.parse_args()
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
fig, ax = plt.subplots(figsize=(2, 1.5))
ax.plot([0, 1], [0, 1])
a.out.mkdir(parents=True, exist_ok=True)
fig.savefig(a.out / "line.png", dpi=40)
rows = [
    claim("c1", "Closure <error> & drift | per period", "Fig 4.3: 1e-12", "3.0e-13",
          "reproduced"),
    claim("c2", "Quick flag seen", "n/a", str(a.quick), "not in thesis"),
]
write_json(a.out / "summary.json", {"claims": rows})
print("fine")
'''

NO_CLAIMS = '''
"""A fake core example without claims."""
import argparse
from pathlib import Path
from qpcoord.studies.files import write_json
p = argparse.ArgumentParser()
p.add_argument("--quick", action="store_true")
p.add_argument("--out", type=Path)
a = p.parse_args()
write_json(a.out / "summary.json", {"rows": [1, 2]})
'''

FAIL = '''
"""A fake chapter 5 example that raises."""
import sys
print("about to fail")
raise RuntimeError("boom: the <b>thing</b> broke")
'''

SLOW = '''
"""A fake appendix C example that never ends."""
import time
print("sleeping", flush=True)
time.sleep(60)
'''


@pytest.fixture
def fake_examples(tmp_path) -> Path:
    d = tmp_path / "examples"
    d.mkdir()
    (d / "ch4_good.py").write_text(textwrap.dedent(GOOD))
    (d / "core_noclaims.py").write_text(textwrap.dedent(NO_CLAIMS))
    (d / "README.md").write_text(
        "| script | what |\n|---|---|\n| `ch4_good.py` | Fig 4.3: the good one |\n"
    )
    return d


def _add_failing(d: Path) -> None:
    (d / "ch5_fail.py").write_text(textwrap.dedent(FAIL))
    (d / "appC_slow.py").write_text(textwrap.dedent(SLOW))


def test_chapter_names():
    assert reproduce.normalise_chapters(None) == list(reproduce.CHAPTERS)
    assert reproduce.normalise_chapters(["appA", "ch4", "4", "c", "CORE"]) == [
        "core",
        "4",
        "A",
        "C",
    ]
    with pytest.raises(ValueError, match=r"unknown chapter 'ch9'.*core, 4, 5, 6, A, B, C"):
        reproduce.normalise_chapters(["4", "ch9"])
    assert reproduce.chapter_of("ch6_flexure.py") == "B"
    assert reproduce.chapter_of("ch6_compare.py") == "6"
    assert reproduce.chapter_of("panda_circle_ik.py") == "core"
    assert reproduce.chapter_of("appA_shoulder.py") == "A"
    assert reproduce.chapter_of("misc.py") is None


def test_every_real_example_has_a_chapter():
    by_chapter, unmapped = reproduce.discover(ROOT / "examples")
    assert not unmapped, unmapped
    assert all(by_chapter[c] for c in ("core", "4", "5", "6", "A", "B", "C"))


def test_good_run_writes_report(fake_examples, tmp_path):
    out = tmp_path / "out"
    rep = reproduce.run(
        out=out, quick=True, jobs=2, examples_dir=fake_examples, progress=False, bench=False
    )
    assert rep.ok and rep.counts["ok"] == 2 and rep.counts["reproduced"] == 1
    assert rep.counts["no claims"] == 1
    good = next(r for r in rep.results if r.name == "ch4_good")
    assert good.chapter == "4" and good.description == "Fig 4.3: the good one"
    assert [f.name for f in good.figures] == ["line.png"]
    assert good.claims[1]["measured"] == "True"  # --quick was passed
    assert (out / "4" / "ch4_good.log").read_text().strip() == "fine"
    md = rep.markdown.read_text()
    assert "Closure <error> & drift \\| per period" in md
    assert "![line.png](4/ch4_good/line.png)" in md
    assert "No claims recorded" in md and "core_noclaims" in md
    assert "Solver comparison" in md and "disabled" in md
    assert "ch6_compare was not run" in md
    page = rep.html.read_text()
    assert "Closure &lt;error&gt; &amp; drift | per period" in page
    assert re.search(r'<img alt="line.png" src="data:image/png;base64,iVBORw0KGgo', page)
    # self-contained: no external references of any kind
    assert not re.search(r'(src|href)="(?!data:|#)', page), "external reference in the html"
    assert "<script" not in page and "<link" not in page and "@import" not in page
    data = json.loads(rep.json.read_text())
    assert data["counts"]["reproduced"] == 1 and data["quick"] is True
    assert not list(out.rglob("*.tmp"))


def test_failure_and_timeout_are_reported(fake_examples, tmp_path):
    _add_failing(fake_examples)
    out = tmp_path / "out"
    rep = reproduce.run(
        out=out,
        quick=True,
        jobs=4,
        timeout=8,
        examples_dir=fake_examples,
        progress=False,
        bench=False,
    )
    by = {r.name: r for r in rep.results}
    assert by["ch5_fail"].status == "failed" and by["ch5_fail"].returncode == 1
    assert "boom" in by["ch5_fail"].stderr_tail
    assert by["appC_slow"].status == "timeout" and "timed out after 8 s" in by["appC_slow"].error
    assert by["ch4_good"].ok and not rep.ok
    assert [r.name for r in rep.results] == ["core_noclaims", "ch4_good", "ch5_fail", "appC_slow"]
    md = rep.markdown.read_text()
    assert "RuntimeError: boom" in md and "timed out" in md
    page = rep.html.read_text()
    assert "boom: the &lt;b&gt;thing&lt;/b&gt; broke" in page and "<b>thing" not in page


def test_stale_outputs_are_removed(fake_examples, tmp_path):
    out = tmp_path / "out"
    stale = out / "4" / "ch4_good" / "old_figure.png"
    stale.parent.mkdir(parents=True)
    stale.write_bytes(b"not a png")
    rep = reproduce.run(
        "4", out=out, quick=True, examples_dir=fake_examples, progress=False, bench=False
    )
    assert rep.chapters == ["4"] and [f.name for f in rep.results[0].figures] == ["line.png"]


def test_report_files_stay_whole_when_rendering_fails(fake_examples, tmp_path, monkeypatch):
    out = tmp_path / "out"
    reproduce.run("core", out=out, examples_dir=fake_examples, progress=False, bench=False)
    before = (out / "report.md").read_text()

    def broken(report):
        raise RuntimeError("renderer broke")

    import qpcoord.studies.render as rr

    monkeypatch.setattr(rr, "render_html", broken)
    with pytest.raises(RuntimeError, match="renderer broke"):
        reproduce.run("core", out=out, examples_dir=fake_examples, progress=False, bench=False)
    assert (out / "report.md").read_text() == before
    assert not list(out.glob("*.tmp"))


def test_missing_examples_is_a_clear_error(tmp_path, capsys):
    with pytest.raises(reproduce.ExamplesNotFoundError, match="Clone the repository"):
        reproduce.run(out=tmp_path / "o", examples_dir=tmp_path / "nope", progress=False)
    assert main(["reproduce", "--examples", str(tmp_path / "nope"), "--out", str(tmp_path)]) == 2
    assert "Clone the repository" in capsys.readouterr().err


def test_default_examples_must_be_a_repo_checkout(fake_examples, monkeypatch):
    # an installed (non-editable) package: <site-packages>/examples is not ours
    monkeypatch.setattr(reproduce, "default_examples_dir", lambda: fake_examples)
    with pytest.raises(reproduce.ExamplesNotFoundError, match="--examples DIR"):
        reproduce.discover()
    (fake_examples.parent / "pyproject.toml").write_text('[project]\nname = "qpcoord"\n')
    assert reproduce.discover()[0]["4"][0].name == "ch4_good.py"


def test_cli_exit_codes(fake_examples, tmp_path, capsys):
    common = ["--examples", str(fake_examples), "--no-progress", "--no-bench", "--quick"]
    assert main(["reproduce", "ch9", "--out", str(tmp_path / "a"), *common]) == 2
    err = capsys.readouterr().err
    assert "unknown chapter 'ch9'" in err and "core, 4, 5, 6, A, B, C" in err
    assert main(["reproduce", "ch4", "core", "--out", str(tmp_path / "b"), *common]) == 0
    out = capsys.readouterr().out
    assert "2 of 2 scripts ran" in out and "report.html" in out
    (fake_examples / "ch5_fail.py").write_text(textwrap.dedent(FAIL))
    assert main(["reproduce", "5", "--out", str(tmp_path / "c"), *common]) == 1
    assert "ch5_fail: failed" in capsys.readouterr().err
    assert (tmp_path / "c" / "report.html").is_file()


COMPARE = '''
"""A fake ch6_compare: per-step controller times."""
import argparse
from pathlib import Path
from qpcoord.studies.files import write_json
p = argparse.ArgumentParser()
p.add_argument("--quick", action="store_true")
p.add_argument("--out", type=Path)
a = p.parse_args()
rows = [
    {"controller": c, "case": k, "seed": s, "error": None,
     "step_time_median": 1e-6 * (10 + s), "step_time_p99": 1e-6 * (50 + s)}
    for c in ("coordinator", "MPC") for k in ("kolmogorov", "step_centre") for s in (0, 1, 2)
]
write_json(a.out / "summary.json", {"rows": rows})
'''


def test_timing_tables(fake_examples, tmp_path, monkeypatch):
    import qpcoord.studies.bench_stack

    (fake_examples / "ch6_compare.py").write_text(textwrap.dedent(COMPARE))
    fake_rows = [
        {"n": 7, "method": m, "solver": "daqp", "steps": 25, "median_us": us, "p90_us": 2 * us,
         "p99_us": 3 * us, "qp_calls_mean": 1.0, "qp_calls_max": 1, "bounds_active": 0.25,
         "limits_active": float("nan"), "failures": 0, "note": "", "failure_messages": []}
        for m, us in (("hierarchical", 300.0), ("weighted", 200.0))
    ]  # fmt: skip
    monkeypatch.setattr(qpcoord.studies.bench_stack, "run_stack_bench", lambda **kw: fake_rows)
    rep = reproduce.run(["core", "6"], out=tmp_path, examples_dir=fake_examples, progress=False)
    assert rep.ok, rep.bench.get("traceback")
    assert rep.bench["rows"][0]["limits_active"] is None  # NaN → null in JSON
    md = rep.markdown.read_text()
    assert "| coordinator | 11.0 / 51.0 | 11.0 / 51.0 |" in md  # medians over 3 seeds
    assert "| 7 | daqp | 300 / 900 | 200 / 600 |" in md
    assert "n = 7, daqp: 1.50" in md
    assert "| 7 | hierarchical | daqp | 25 | 300 | 600 | 900 | 1.00 | 25 % | – | 0 |" in md
    page = rep.html.read_text()
    assert "11.0 / 51.0" in page and "Solver comparison" in page
    timing = json.loads(rep.json.read_text())["step_timing"]
    assert {r["controller"] for r in timing["ddl"]} == {"coordinator", "MPC"}


def test_real_chapter_quick(tmp_path):
    """Appendix B: one real script, the fastest chapter."""
    rep = reproduce.run("B", out=tmp_path, quick=True, progress=False, bench=False)
    assert rep.ok, [(r.name, r.error, r.stderr_tail) for r in rep.failed]
    assert [r.name for r in rep.results] == ["ch6_flexure"]
    assert rep.results[0].figures
    assert "Appendix B" in rep.markdown.read_text()


DUPLICATE = '''
"""A fake {name}: Table 6.1's direct-coil RMSE (a claim several scripts check)."""
import argparse
from pathlib import Path
from qpcoord.studies.claims import claim
from qpcoord.studies.files import write_json
p = argparse.ArgumentParser()
p.add_argument("--quick", action="store_true")
p.add_argument("--out", type=Path)
a = p.parse_args()
rows = [claim("{row}", "RMSE 25 nm", "Table 6.1", "24 nm", "reproduced")]
rows += [claim("fig6.6-piezo-bandwidth", "300 Hz", "Fig 6.6", "301 Hz", "reproduced")] * {extra}
write_json(a.out / "summary.json", {{"claims": rows}})
'''


def test_a_thesis_claim_is_counted_once(tmp_path):
    """Two scripts check T6.1-direct-coil-rmse: one claim, two rows; an input the register
    marks calibrated is shown as such, never as reproduced."""
    d = tmp_path / "examples"
    d.mkdir()
    (d / "ch6_tracking.py").write_text(
        DUPLICATE.format(name="ch6_tracking", row="table6.1-rmse", extra=1)
    )
    (d / "sweep_ddl_seeds.py").write_text(
        DUPLICATE.format(name="sweep", row="table6.1-rmse-nominal", extra=0)
    )  # fmt: skip
    rep = reproduce.run("6", out=tmp_path / "out", examples_dir=d, progress=False, bench=False)
    assert rep.ok
    c = rep.counts
    assert (c["rows"], c["reproduced"], c["calibrated"], c["differs"]) == (3, 1, 1, 0)
    assert set(rep.claims) == {"T6.1-direct-coil-rmse", "Fig6.6-piezo-300Hz"}
    md = rep.markdown.read_text()
    assert "## Thesis claims by ID" in md
    assert (
        "| T6.1-direct-coil-rmse | reproduced |  | ch6_tracking: table6.1-rmse → reproduced;" in md
    )
    assert "calibrated (row: reproduced)" in md
    total = next(row for key, row in render.summary_rows(rep) if key == "total")
    assert total["reproduced"] == 1 and total["rows"] == 3 and total["calibrated"] == 1
    assert json.loads(rep.json.read_text())["counts"]["reproduced"] == 1
