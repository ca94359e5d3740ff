"""Smoke runs of the benchmark scripts and of ``python -m benchmarks --write``; no timed
assertion.

A benchmark is a script, not a module of the package: it is run as a subprocess, as a user
runs it. The checks are on its output's content (rows, errors, limits, which rows its flags
add) and on the README's table markers, never on times.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "ik_peers.py"
LEXLS_BENCH = ROOT / "benchmarks" / "lexls" / "bench.py"


def _run(tmp_path: Path, *args: str) -> tuple[str, list[dict]]:
    out = tmp_path / "rows.json"
    stdout = _script(SCRIPT.name, "--quick", "--json", str(out), *args, timeout=600)
    return stdout, json.loads(out.read_text())


def test_quick_without_placo(tmp_path):
    pytest.importorskip("pinocchio")
    stdout, rows = _run(
        tmp_path,
        "--placo-python",
        str(tmp_path / "no-such-python"),
        "--scenario",
        "panda-position",
        "--scenario",
        "panda-pose",
        "--engines",
    )
    assert "PlaCo skipped: no interpreter at" in stdout
    if any("skipped" in r.get("note", "") for r in rows):  # example-robot-data missing
        pytest.skip(rows[0]["note"])
    solvers = {(r["scenario"], r["solver"], r["mode"]) for r in rows if "solver" in r}
    for scenario in ("panda-position", "panda-pose"):
        for s in ("qpcoord strict native", "qpcoord strict python", "qpcoord weighted native"):
            for mode in ("lockstep", "back to back"):
                assert (scenario, s, mode) in solvers
    assert not any(r["solver"] == "placo" for r in rows if "solver" in r)
    assert "alone: each solver's whole trajectory alone" in stdout
    for r in rows:
        assert r["steps"] == 60
        # hard limits hold on every step; the deadbeat hand task tracks the circle
        assert r["joint_limit_violation_rad"] <= 1e-9
        assert r["speed_limit_violation_rad_s"] <= 1e-6
        assert r["position_error_m"] < 1e-3
        assert r["p99_us"] >= r["p90_us"] >= r["median_us"] > 0
    lockstep = [r for r in rows if r["mode"] == "lockstep"]
    strict = {r["scenario"]: r for r in lockstep if r["solver"] == "qpcoord strict native"}
    python = {r["scenario"]: r for r in lockstep if r["solver"] == "qpcoord strict python"}
    for scenario, r in strict.items():  # both engines solve the same strict hierarchy
        assert r["position_error_m"] == pytest.approx(python[scenario]["position_error_m"])
    assert "orientation_error_rad" in strict["panda-pose"]
    # a solver alone follows the same trajectory as in the lockstep (same inputs per step)
    alone = {(r["scenario"], r["solver"]): r for r in rows if r["mode"] == "back to back"}
    for r in lockstep:
        twin = alone[(r["scenario"], r["solver"])]
        assert twin["steps"] == r["steps"]
        assert twin["position_error_m"] == pytest.approx(r["position_error_m"], rel=1e-9)


def test_lockstep_only(tmp_path):
    pytest.importorskip("pinocchio")
    stdout, rows = _run(
        tmp_path, "--no-placo", "--no-pink", "--no-back-to-back", "--scenario", "panda-position"
    )
    if any("skipped" in r.get("note", "") for r in rows):  # example-robot-data missing
        pytest.skip(rows[0]["note"])
    assert {r["mode"] for r in rows} == {"lockstep"}
    assert "one after the other (not run)" in stdout
    # without --engines, qpcoord's default engine and method only
    assert {r["solver"] for r in rows if "solver" in r} == {"qpcoord strict native"}


def test_rejects_too_few_steps(tmp_path):
    proc = subprocess.run(
        [sys.executable, str(SCRIPT), "--steps", "3", "--no-placo"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode != 0
    assert "--steps must be >= 20, got 3" in proc.stderr


def test_stack_bench_one_shot_table():
    """``stack_bench.py --one-shot-only``: the three calls per size, and the daqp floor solves
    the weighted QP of the same numbers (its x matches qpcoord's weighted method)."""
    pytest.importorskip("daqp")
    out = _script("stack_bench.py", "--one-shot-only", "--one-shot-steps", "20", "--sizes", "7")
    for call in ("solve_stack native", "solve_stack python", "daqp.solve floor"):
        assert f"| 7 | {call} | 18 |" in out
    note = next(line for line in out.splitlines() if line.startswith("<!-- n=7"))
    dx = float(note.split("max |dx| ")[1].split(";")[0])
    assert dx < 1e-6
    assert "daqp exit flags [1]" in note


def _script(*args: str, timeout: float = 300) -> str:
    """stdout of ``python benchmarks/ARGS...`` with one BLAS thread (exit status 0 asserted)."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / args[0]), *args[1:]],
        capture_output=True,
        text=True,
        env=env,
        timeout=timeout,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


#: (script and arguments, module it needs, a row it prints by default, what only a flag adds)
DEFAULT_OUTPUTS = [
    (("stack_bench.py", "--quick", "--solver", "daqp", "--sizes", "7"), "daqp",
     "| 7 | weighted | daqp |", "daqp.solve floor"),
    (("weighted_bench.py", "--quick"), "daqp", "| persistent n=12 | native |", "DDL MPC"),
    (("mpc_bench.py", "--quick", "--steps", "600"), "daqp", "| weighted | kolmogorov |",
     "with every backend"),
    (("hierarchy_published.py", "--resolve", "--steps", "6", "--problem", "soth_sot"), "daqp",
     "| soth_sot | 30 | moved |", "| same |"),
    (("collision_bench.py", "--steps", "20", "--no-pink", "--no-mink", "--no-placo"), "coal",
     "| qpcoord | band + self + sphere, level 0 |", "`CollisionAvoidance.update` alone"),
]  # fmt: skip


@pytest.mark.parametrize(("args", "needs", "row", "flagged"), DEFAULT_OUTPUTS)
def test_default_output_leaves_the_extra_rows_to_a_flag(args, needs, row, flagged):
    """By default a script prints what a user compares (``row``); the extra rows or tables
    (``stack_bench.py --one-shot``, ``weighted_bench.py --mpc``, ``mpc_bench.py --backends``,
    ``hierarchy_published.py --same``, ``collision_bench.py --update``) only with their
    flag."""
    pytest.importorskip(needs)
    out = _script(*args)
    assert row in out
    assert flagged not in out


def test_ddl_bench_table():
    """``ddl_bench.py --quick``: machine, command, one row per rate with positive times."""
    out = _script("ddl_bench.py", "--quick")
    lines = out.splitlines()
    assert lines[0].startswith("Machine: ")
    assert lines[0].endswith(" Command: `python benchmarks/ddl_bench.py --quick`")
    rows = {ln.split("|")[1].strip(): ln for ln in lines if ln.startswith("| ") and "0 |" in ln}
    assert set(rows) == {"5000", "8000"}
    for row in rows.values():
        cells = [c.strip() for c in row.split("|")[1:-1]]
        assert cells[1] == "1.0" and all(float(c) > 0 for c in cells[3:])


def test_ddl_margin_table():
    """``ddl_margin.py --quick``: a row per bandwidth, a predicted / simulated pair per
    carriage position."""
    out = _script("ddl_margin.py", "--quick")
    assert out.startswith("Machine: ")
    rows = [ln for ln in out.splitlines() if ln.startswith("| ") and ln[2].isdigit()]
    assert [r.split("|")[1].strip() for r in rows] == ["1", "4", "6"]
    for row in rows:
        pairs = [c for c in row.split("|") if " / " in c]
        assert len(pairs) == 3, row


def test_lexls_bench_without_lexls(tmp_path):
    """``lexls/bench.py`` without a LexLS checkout: the native driver's column for every
    problem and one line saying LexLS was skipped (g++ and Eigen's headers needed)."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(
        [sys.executable, str(LEXLS_BENCH), "--quick", "--lexls", str(tmp_path / "none")],
        capture_output=True, text=True, env=env, timeout=900,
    )  # fmt: skip
    if proc.returncode != 0 and "needs g++ and Eigen's headers" in proc.stderr:
        pytest.skip("no g++ or Eigen headers to build the C++ drivers")
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = proc.stdout
    rows = [ln.split("|") for ln in out.splitlines() if ln.startswith("| ")]
    body = {r[1].strip(): [c.strip() for c in r[2:-1]] for r in rows[2:]}
    assert set(body) == {"humanoid (published rows)", "soth_sot", "chain30", "random50"}
    for n, lexls, native, gap in body.values():
        assert int(n) > 0 and lexls == gap == "–" and float(native) > 0
    assert out.rstrip().splitlines()[-1].startswith("LexLS skipped: no checkout at ")


def test_pages_hold_every_table_with_its_command():
    """Every table of ``python -m benchmarks`` has one marker pair in its page
    (benchmarks/README.md, ddl.md or edges.md, so ``--write`` writes them all), every marker
    pair is one of them, and each block opens with its machine line, which ends with the command
    ``python -m benchmarks`` runs for it; the README stays under 300 lines."""
    import re
    import shlex

    writer = _writer()
    pages = {t.page for t in writer.TABLES.values()}
    for page in pages:
        text = (ROOT / "benchmarks" / page).read_text()
        want = {n for n, t in writer.TABLES.items() if t.page == page}
        assert set(re.findall(r"^<!-- table: (\S+) -->$", text, re.M)) == want, page
    for name, table in writer.TABLES.items():
        text = (ROOT / "benchmarks" / table.page).read_text()
        block = text.split(f"<!-- table: {name} -->\n", 1)[1].split("<!-- /table -->", 1)[0]
        lines = block.splitlines()
        assert lines[0].startswith("Machine: ") and " cores" in lines[0], name
        command = shlex.join(["python", f"benchmarks/{table.script}", *table.full])
        assert lines[0].endswith(f" Command: `{command}`"), name
    assert len((ROOT / "benchmarks" / "README.md").read_text().splitlines()) < 300


def test_oneshot_table():
    """``oneshot.py``: every call and part has its row, and the direct daqp call solves the
    stack's weighted QP (its x matches qpcoord's weighted method to daqp's tolerance)."""
    pytest.importorskip("daqp")
    out = _script("oneshot.py", "--steps", "20", "--parts")
    for row in ("tasks + Bounds", "qc.solve_stack", "Stack + solve", "daqp.solve weighted QP"):
        assert f"| {row} |" in out
    assert "| native engine: first (cold) call |" in out
    note = next(line for line in out.splitlines() if line.startswith("The direct call's QP"))
    assert "daqp exit flag 1," in note
    assert float(note.split("max |dx| ")[1].split(" ")[0]) < 1e-6


def test_engine_agreement_table():
    """``engine_agreement.py``: the category table over the seeds asked for, and every row
    it lists as silent is one (both "optimal", a level value apart by more than 1e-6; seeds
    232-234 hold one, seed 233)."""
    from qpcoord.core import native

    if not native.available():
        pytest.skip("the native engine is not built")
    out = _script("engine_agreement.py", "--seeds", "3", "--first", "232", "--show", "silent")
    assert "Seeds 232-234:" in out
    for cat in ("flagged", "scale", "silent", "other", "error"):
        assert f"| {cat} |" in out
    silent = next(ln for ln in out.splitlines() if ln.startswith("| silent |")).split("|")
    count = int(silent[2])
    tail = out.split("silent:")[-1].splitlines() if count else []
    rows = [ln for ln in tail if ln.startswith("| ") and ln[2].isdigit()]
    assert len(rows) == count
    assert [r.split("|")[1].strip() for r in rows] == (
        silent[3].strip().split(", ") if count else []
    )
    for row in rows:
        cells = [c.strip() for c in row.split("|")]
        assert cells[6] == cells[7] == "optimal" and float(cells[8]) > 1e-6, row


def test_hierarchy_bench_talos_unit_rows_is_daqp_s_problem():
    """``hierarchy_bench.py``'s ``talos_unit``: the Talos IK stack with unit rows and unit
    weights (each row that stack's row over its norm, after every move); the native engine
    and DAQP's hierarchical mode, given it, reach the Python engine's level values (DAQP's
    soft penalty normalises each row: the same lexicographic problem). No time is asserted."""
    pytest.importorskip("pinocchio")
    import numpy as np

    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import hierarchy_bench as hb
    finally:
        sys.path.pop(0)
    try:
        rows, flags = hb.run("talos unit", hb.talos_unit, 12, python=True)
    except FileNotFoundError as exc:  # example-robot-data missing
        pytest.skip(str(exc))
    assert flags <= {1, 2}  # optimal, soft optimal
    worst = {key: diff for _name, key, _m, _p90, _p99, diff in rows}
    assert worst["native warm"] <= 1e-9
    assert worst[hb.DAQP] <= 1e-5  # DAQP's own tolerance (6e-7 measured)
    sc = hb._scenario(hb.talos_unit, np.random.default_rng(0))
    sc["move"](1, np.full(sc["stack"].n, 0.01))
    for lev in sc["stack"].levels:
        for t in lev:
            M = t.A if hasattr(t, "A") else t.C
            norms = np.linalg.norm(M, axis=1)  # (a zero row of the IK stack stays zero)
            assert np.all((np.abs(norms - 1.0) <= 1e-12) | (norms == 0.0)), norms


README = """# Benchmarks

Prose before.

<!-- table: engine_agreement -->
old numbers
<!-- /table -->

Prose between.

<!-- table: other -->
other old numbers
<!-- /table -->

Prose after.
"""


def _writer():
    import importlib

    sys.path.insert(0, str(ROOT))
    try:
        return importlib.import_module("benchmarks.__main__")
    finally:
        sys.path.remove(str(ROOT))


def test_write_splices_the_table_between_its_markers(tmp_path):
    """``python -m benchmarks NAME --quick --write``: the table's block becomes what its
    command printed (machine line, command, table); the markers, the other table and the
    prose stay as they were."""
    from qpcoord.core import native

    if not native.available():
        pytest.skip("the native engine is not built")
    readme = tmp_path / "README.md"
    readme.write_text(README)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run(
        [sys.executable, "-m", "benchmarks", "engine_agreement", "--quick", "--write",
         "--dir", str(tmp_path)],
        cwd=ROOT, capture_output=True, text=True, env=env, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    text = readme.read_text()
    before, rest = text.split("<!-- table: engine_agreement -->\n")
    block, after = rest.split("<!-- /table -->\n", 1)
    assert before == README.split("<!-- table: engine_agreement -->\n")[0]
    assert after == README.split("old numbers\n<!-- /table -->\n", 1)[1]
    lines = block.splitlines()
    assert lines[0].startswith("Machine: ") and " cores" in lines[0] and "qpcoord" in lines[0]
    assert lines[0].endswith(" Command: `python benchmarks/engine_agreement.py --seeds 4`")
    assert "| category | disagreements |" in block and "old numbers" not in block
    assert block.strip() in proc.stdout  # the README holds what the command printed


def test_failed_run_or_missing_marker_leaves_the_readme_unchanged(tmp_path):
    """If one run fails, no table is written (not even the ones that succeeded); a table
    without markers is refused before anything runs."""
    writer = _writer()
    good, bad = tmp_path / "good.py", tmp_path / "bad.py"
    good.write_text("print('| a |\\n| --- |\\n| 1 |')\n")
    bad.write_text("import sys\nprint('half a table')\nsys.exit('broken')\n")
    readme = tmp_path / "README.md"
    readme.write_text(README)
    tables = {
        "engine_agreement": writer.Table(str(good), (), ()),
        "other": writer.Table(str(bad), (), ()),
    }
    orig = writer.TABLES
    writer.TABLES = tables
    try:
        assert writer.main(["--write", "--dir", str(tmp_path)]) == 1
        assert readme.read_text() == README
        assert not list(tmp_path.glob(".README.md*"))  # no temporary file left
        writer.TABLES = {**tables, "missing": writer.Table(str(good), (), ())}
        with pytest.raises(ValueError, match="table 'missing': 0 marker pairs"):
            writer.main(["missing", "--write", "--dir", str(tmp_path)])
        assert readme.read_text() == README
        assert writer.main(["engine_agreement", "--write", "--dir", str(tmp_path)]) == 0
    finally:
        writer.TABLES = orig
    text = readme.read_text()
    assert "<!-- table: engine_agreement -->\n| a |\n| --- |\n| 1 |\n<!-- /table -->" in text
    assert "other old numbers" in text and text.endswith("Prose after.\n")


def test_cell_stacks_table():
    """``cell_stacks.py``: a row per Panda and Talos stack, positive times, ratio 1 on each
    scenario's first row."""
    out = _script("cell_stacks.py", "--steps", "20", "--runs", "1")
    rows = [
        ln.split("|")[1:-1]
        for ln in out.splitlines()
        if ln.startswith("| Panda") or ln.startswith("| Talos")
    ]  # noqa: E501
    names = [r[0].strip() for r in rows]
    assert names == [
        "Panda: pose + posture",
        "Panda: + table band",
        "Panda: + sphere",
        "Panda: + self-collision + sphere",
        "Talos: feet, hand, posture",
        "Talos: + CoM in the support polygon",
    ]
    for r in rows:
        assert float(r[1]) > 0 and float(r[2]) > 0
    assert rows[0][3].strip() == rows[4][3].strip() == "1.00×"


def test_edges_table():
    """``edges.py``: one table, a row per case and solver, qpcoord and Pink in every case."""
    pytest.importorskip("pink")
    out = _script("edges.py", "--steps", "600")
    rows = [
        ln.split("|")[1:3]
        for ln in out.splitlines()
        if ln.startswith("| UR10") or ln.startswith("| Panda")
    ]  # noqa: E501
    cases = {c.strip() for c, _ in rows}
    assert len(cases) == 5
    for case in cases:
        solvers = [s.strip() for c, s in rows if c.strip() == case]
        assert any(s.startswith("qpcoord") for s in solvers), case
        assert any(s.startswith("pink") for s in solvers), case
