"""The rule that judges Fig 4.7 / Remark 4.4 on the found 5R arms,
fixed before the first run, in ``examples/ch4_long_runs.py``: per-arm outcomes and the claim
status they give."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

_PATH = Path(__file__).resolve().parents[2] / "examples" / "ch4_long_runs.py"
_spec = importlib.util.spec_from_file_location("ch4_long_runs", _PATH)
ch4 = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ch4)


def _per(*multiples):
    """Per-step convergence results: an int m converges on m·T, None does not converge."""
    return {
        f"T/{s}": {
            "converges": m is not None,
            "multiple": m if m is not None else 1,
            "final_gap_rad": 1e-10 if m is not None else 0.1,
            "decades_last_half": 3.0 if m is not None else 0.2,
        }
        for s, m in zip(ch4.FOUND_STEPS, multiples, strict=True)
    }


@pytest.mark.parametrize(
    ("multiples", "err", "outcome"),
    [
        ((7, 7), 1e-6, "closes mT"),
        ((1, 1), 1e-6, "closes 1T"),
        ((None, None), 1e-6, "no cycle"),
        ((7, None), 1e-6, "step-dependent"),
        ((7, 14), 1e-6, "step-dependent"),
        ((7, 7), 0.5, "path lost"),
    ],
)
def test_arm_outcome(multiples, err, outcome):
    assert ch4.found_arm_outcome(_per(*multiples), err) == outcome


def _study(arms, periods=ch4.FOUND_PERIODS):
    rows = []
    for multiples, err in arms:
        per = _per(*multiples)
        rows.append({"per_step": per, "outcome": ch4.found_arm_outcome(per, err)})
    return {"periods": periods, "steps": list(ch4.FOUND_STEPS), "arms": rows}


@pytest.mark.parametrize(
    ("arms", "status"),
    [
        ([((7, 7), 1e-6), ((12, 12), 1e-6), ((7, 7), 0.5)], "reproduced"),
        ([((1, 1), 1e-6), ((None, None), 1e-6), ((1, 1), 1e-6)], "differs"),
        ([((7, 7), 1e-6), ((None, None), 1e-6)], "inconclusive"),  # depends on the arm
        ([((1, 1), 1e-6), ((None, 9), 1e-6)], "inconclusive"),  # m ≥ 2 at one step
        ([((7, 7), 1e-6), ((7, 7), 0.5)], "inconclusive"),  # one arm keeps the path
    ],
)
def test_claim_status(arms, status):
    assert ch4.found_arms_status(_study(arms))[0] == status


def test_short_run_or_no_study_decides_nothing():
    arms = [((7, 7), 1e-6), ((12, 12), 1e-6)]
    assert ch4.found_arms_status(_study(arms, periods=ch4.DECIDE - 1))[0] == "inconclusive"
    assert ch4.found_arms_status(None)[0] == "inconclusive"
