"""The example scripts' claim rules fed cases that must fail (or must not be decided).

Each script's claim function is called on hand-made run summaries: a passing case, then the
same with one measured value pushed past its criterion. An identity (holds by construction)
must still be able to fail: a failing identity is a bug and shows as ``differs``.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from qpcoord.studies.claims import QUICK

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"_example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _status(rows: list[dict], row_id: str) -> str:
    return next(r["status"] for r in rows if r["id"] == row_id)


def test_ch4_leaves_rules_fail():
    m = _script("ch4_leaves")
    row = {
        "min_singular_value_J_omega": 0.2,
        "leaf_c4_c5": [4.5, 2.1],
        "leaf_drift_max_rad": 1e-14,
        "closure_error_per_period_rad": [1e-6, 1e-14, 1e-14],
    }
    other = {**row, "leaf_c4_c5": [4.9, 2.6]}
    good = m.claims([row, other])
    assert _status(good, "ex4.4-stays-on-leaf") == "identity"
    assert _status(good, "lemma4.2-each-leaf-periodic") == "reproduced"
    bad = m.claims([{**row, "leaf_drift_max_rad": 1e-6}, other])
    assert _status(bad, "ex4.4-stays-on-leaf") == "differs"
    bad = m.claims([{**row, "closure_error_per_period_rad": [1e-6, 1e-14, 1e-3]}, other])
    assert _status(bad, "lemma4.2-each-leaf-periodic") == "differs"
    bad = m.claims([row, {**other, "leaf_c4_c5": row["leaf_c4_c5"]}])
    assert _status(bad, "lemma4.2-leaf-changes") == "differs"
    short = [{**r, "closure_error_per_period_rad": [1e-6, 1e-14]} for r in (row, other)]
    assert _status(m.claims(short), "lemma4.2-each-leaf-periodic") == QUICK


def test_ch5_compliant_plane_can_fail():
    m = _script("ch5_compliant")
    resp = {"closure": [1e-9, 1e-9, 1e-9], "plane_residual": 1e-15, "path_length": 2.7}
    summary = {
        "responses": [resp, {**resp, "path_length": 3.0}],
        "periods": 3,
        "pseudo_inverse": {"closure": [0.3] * 3, "periods_to_closure_1e_6": None},
    }
    assert _status(m.claims(summary, 0.1), "eq5.20-plane") == "identity"
    assert _status(m.claims(summary, 0.1), "fig5.9-periodic") == "reproduced"
    summary["responses"][1] = {**resp, "plane_residual": 1e-6}
    assert _status(m.claims(summary, 0.1), "eq5.20-plane") == "differs"
    summary["responses"][1] = {**resp, "closure": [1e-9, 1e-3, 1e-9]}
    assert _status(m.claims(summary, 0.1), "fig5.9-periodic") == "differs"
    assert _status(m.claims(summary, 1e-5), "fig5.8a-cycle-per-qbar") == "differs"


def test_ch5_fixed_point_rules_fail():
    m = _script("ch5_fixed_point")
    row = {
        "max_V_increase": 0.0,
        "dist_to_global_min_rad": 1e-12,
        "final_speed_rad_s": 1e-18,
        "dist_to_slsqp_local_rad": 1e-12,
    }
    result = {"rows": [row], "duration_s": m.DURATION, "local_minima_of_g_on_fibre": [0.06]}
    good = m.claims(result)
    assert _status(good, "prop5.1-lyapunov") == "identity"
    assert _status(good, "prop5.1-fixed-point") == "reproduced"
    bad = m.claims({**result, "rows": [{**row, "max_V_increase": 1e-6}]})
    assert _status(bad, "prop5.1-lyapunov") == "differs"
    bad = m.claims({**result, "rows": [{**row, "dist_to_global_min_rad": 0.5}]})
    assert _status(bad, "prop5.1-fixed-point") == "differs"
    short = {**result, "duration_s": 1.0, "rows": [{**row, "dist_to_global_min_rad": 0.5}]}
    assert _status(m.claims(short), "prop5.1-fixed-point") == QUICK


def _lc_row(alpha, band, bound, **kw):
    return {
        "alpha": alpha,
        "gain": 10.0,
        "steps_per_period": 200,
        "diverged": None,
        "periods": 25,
        "periods_to_closure_1e-6": 5,
        "final_closure_rad": 1e-15,
        "min_sigma_J_final_cycle": 0.7,
        "band_max_abs_q1_minus_pi2_rad": band,
        "eq513_bound_rad": bound,
        "eq513_holds": band <= bound,
        "lambda_over_kappa": 2.6,
        "lambda_max_norm_Jpinv_Ydot_along_run": 1.3,
        "eq513_bound_run_lambda_rad": 0.42,
        "n1_squared_at_extremum": 0.39,
        "band_from_stationarity_rad": band,
        **kw,
    }


@pytest.mark.parametrize("quick", [False, True])
def test_ch5_limit_cycle_rules_fail(quick):
    m = _script("ch5_limit_cycle")
    pinv = {
        "alpha": None,
        "closure_error_per_period_rad": [0.3] * 25,
        "periods_to_closure_1e-6": None,
    }
    good = {"rows": [_lc_row(3.0, 0.44, 0.52), pinv]}
    rows = m.claims(good, quick=quick)
    # quick cannot apply the full rule (every α): never "reproduced" there
    want = QUICK if quick else "reproduced"
    assert _status(rows, "eq5.13-band") == want
    assert _status(rows, "thm5.1-alpha3") == want
    bad = {"rows": [_lc_row(3.0, 0.44, 0.52), _lc_row(10.0, 0.50, 0.24), pinv]}
    assert _status(m.claims(bad, quick=quick), "eq5.13-band") == "differs"
    open_ = {"rows": [_lc_row(3.0, 0.44, 0.52, **{"periods_to_closure_1e-6": None}), pinv]}
    assert _status(m.claims(open_, quick=quick), "thm5.1-alpha3") == "differs"
