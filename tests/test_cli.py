"""The console command, the demo and the README/CI contract."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from support.pages import run_blocks, run_page

from qpcoord.cli import main

ROOT = Path(__file__).resolve().parents[1]


def test_solvers_lists_every_available_backend(capsys):
    import qpcoord as qc

    assert main(["solvers"]) == 0
    out = capsys.readouterr().out
    for name in qc.available_solvers():
        assert re.search(rf"^{name}\s", out, re.M), name
    assert "<- default" in out


def test_demo_runs_and_reports_both_methods(capsys):
    assert main(["demo", "--steps", "60"]) == 0
    out = capsys.readouterr().out
    assert "hierarchical" in out and "weighted" in out
    band = re.search(r"max band violation \(rad\)\s+(\S+)\s+(\S+)", out)
    assert band, out
    # the strict hierarchy keeps the band (priority 1) while the posture (priority 2) pulls
    assert float(band.group(1)) < 1e-6


def test_unknown_solver_is_a_clean_error(capsys):
    assert main(["demo", "--steps", "5", "--solver", "nope"]) == 2
    err = capsys.readouterr().err
    assert "unknown or uninstalled solver 'nope'" in err


def test_console_script_entry_point():
    out = subprocess.run(
        [sys.executable, "-m", "qpcoord.cli", "solvers"], capture_output=True, text=True, check=True
    ).stdout
    assert "daqp" in out or "quadprog" in out


def test_readme_has_exactly_two_setup_commands_and_ci_runs_the_second():
    readme = (ROOT / "README.md").read_text()
    commands = re.findall(r"^    (python3 -m venv .*)$", readme, re.M)
    assert len(commands) == 2, commands
    assert commands[0].endswith("qpcoord reproduce --quick")
    assert 'pip install -e ".[test]"' in commands[1] and "pytest" in commands[1]
    # the suite again on the Python engine (the oracle): both engines checked on every CI run
    assert "QPCOORD_TEST_ENGINE=python python -m pytest" in commands[1]
    ci = (ROOT / ".ci" / "run").read_text()
    pattern = re.search(r"grep -m1 -E '(.*?)' README.md", ci).group(1)
    assert re.search(pattern, "    " + commands[1])
    assert "-eq 5" in ci  # pytest's "no tests collected" fails CI
    # the numeric tests again under another OpenBLAS kernel and the native baseline build
    second = re.search(r"^second=\((.*)\)$", ci, re.M).group(1).split()
    assert "OPENBLAS_CORETYPE=Prescott" in second and "QPCOORD_NATIVE_ISA=baseline" in second
    assert re.search(
        r'^run_pytest env "\$\{second\[@\]\}" .*pytest .*tests/core tests/kinematics$', ci, re.M
    )


@pytest.mark.parametrize("method", ["hierarchical", "weighted"])
def test_readme_example_runs(method):
    code = next(block for block in run_blocks(ROOT / "README.md") if "qc.Stack(" in block)
    ns: dict = {}
    exec(compile(code, "README.md", "exec"), ns)
    sol = ns["stack"].solve(method=method)
    assert sol.x.shape == (3,)


def test_ddl_track_prints_metrics_per_seed(capsys):
    assert main(["ddl", "track", "--seeds", "1", "--duration", "0.25"]) == 0
    out = capsys.readouterr().out
    row = out.strip().splitlines()[-1].split()
    assert row[0] == "0" and float(row[1]) < 70.0  # RMSE nm on the 250 Hz preset
    assert row[7] == "ok"


def test_ddl_track_bad_preset_is_a_clean_error(capsys):
    assert main(["ddl", "track", "--preset", "nope", "--duration", "0.1"]) == 2
    assert "preset" in capsys.readouterr().err


def test_every_readme_code_block_runs():
    """The README's snippets run in order, in one namespace (as a reader would paste them),
    on the default engine of the pass: also on the Python engine in the README's
    ``QPCOORD_TEST_ENGINE=python`` pass, which leaves out tests/test_docs.py's check of what
    they print (``engine_independent``); and the closure example's trajectory tracks its
    circle (``max_error``, which no block prints) within 1 mm."""
    assert len(run_blocks(ROOT / "README.md")) >= 3
    ns = run_page(ROOT / "README.md")
    assert ns["traj"].max_error < 1e-3


def test_ddl_compare_quick_prints_both_tables(capsys):
    assert main(["ddl", "compare", "--quick"]) == 0
    out = capsys.readouterr().out
    for name in ("coordinator", "LQR", "PQ", "MPC"):
        assert name in out


def test_import_is_light_and_heavy_subpackages_load_on_use():
    """``import qpcoord`` does not pull in scipy.signal (the DDL package does, ~1.4 s)."""
    code = (
        "import sys, qpcoord as qc; assert 'scipy.signal' not in sys.modules; "
        "assert qc.ddl.DualStage and qc.hysteresis.PreisachModel and qc.musculo.distribute; "
        "assert 'scipy.signal' in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_help_lists_every_command(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for command in ("solvers", "demo", "bench stack", "bench ik", "ddl track", "ddl compare"):
        assert f"qpcoord {command}" in out
    assert "qpcoord reproduce --quick" in out


def test_ddl_design_prints_the_design_and_writes_the_figure(tmp_path, capsys):
    import numpy as np

    import qpcoord.ddl as ddl

    ref = tmp_path / "ref.npy"
    np.save(ref, ddl.kolmogorov_opd(1.5, 8000.0, seed=0, preset="paranal_250hz"))
    out = tmp_path / "out"
    rc = main(["ddl", "design", str(ref), "--fs", "8000", "--out", str(out), "--duration", "1"])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "coarse bandwidth" in text and "predicted" in text and "fresh seeds" in text
    assert (out / "ddl_design.png").stat().st_size > 0
    assert not list(out.glob("*.tmp*"))
