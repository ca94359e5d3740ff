"""Per-step timing tables of a reproduction run, from its scripts' summaries and its bench."""

from __future__ import annotations

__all__ = ["step_timing"]


def step_timing(report) -> dict:
    """Per-step timing table: DDL controllers (``ch6_compare``) and stack-bench backends.

    Parameters
    ----------
    report : qpcoord.studies.reproduce.Report
        A run's report (what is read: ``results``, each with ``name``, ``ok``, ``status``,
        ``error`` and ``summary``, and ``bench``).

    Returns
    -------
    dict
        ``{"ddl": rows or None, "ddl_note": str, "stack": rows or None, "stack_note": str}``;
        DDL rows ``{"controller", "case", "median_us", "p99_us", "runs"}`` (medians over
        seeds of the per-run median and 99th percentile of the controller time per 8 kHz
        step), stack rows ``{"n", "method", "solver", "median_us", "p99_us", "steps"}``.
    """
    import statistics

    out: dict = {"ddl": None, "ddl_note": "", "stack": None, "stack_note": ""}
    cmp = next((r for r in report.results if r.name == "ch6_compare"), None)
    if cmp is None:
        out["ddl_note"] = "ch6_compare was not run (chapter 6 not selected)"
    elif not cmp.ok or not cmp.summary:
        out["ddl_note"] = f"ch6_compare {cmp.status}: {cmp.error}"
    else:
        rows = [
            r
            for r in cmp.summary.get("rows", [])
            if isinstance(r, dict) and not r.get("error") and r.get("step_time_median") is not None
        ]
        groups: dict[tuple, list] = {}
        for r in rows:
            groups.setdefault((r.get("controller"), r.get("case")), []).append(r)
        table = []
        for (ctl, case), rs in groups.items():
            med = [r["step_time_median"] for r in rs if r.get("step_time_median") is not None]
            p99 = [r["step_time_p99"] for r in rs if r.get("step_time_p99") is not None]
            table.append(
                {
                    "controller": ctl,
                    "case": case,
                    "median_us": statistics.median(med) * 1e6 if med else None,
                    "p99_us": statistics.median(p99) * 1e6 if p99 else None,
                    "runs": len(rs),
                }
            )
        out["ddl"] = table
        if not table:
            out["ddl_note"] = "ch6_compare's summary.json has no step_time_median in its rows"
    b = report.bench
    if "rows" in b:
        out["stack"] = [
            {k: r.get(k) for k in ("n", "method", "solver", "median_us", "p99_us", "steps")}
            for r in b["rows"]
        ]
    else:
        out["stack_note"] = b.get("skipped") or f"solver comparison failed: {b.get('error')}"
    return out
