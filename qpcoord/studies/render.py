"""Rendering of a :class:`qpcoord.studies.reproduce.Report` as Markdown and as self-contained HTML.

``report.md`` links figures relatively (it sits in the output folder next to them);
``report.html`` embeds them (base64 PNG) and uses inline CSS only: it can be mailed or
uploaded as a CI artifact on its own. Every text taken from a script (claims, errors,
standard error) is escaped.
"""

from __future__ import annotations

import base64
import html
import math
import os
import re
from pathlib import Path

from .chapters import CHAPTERS
from .claim_ids import CONTRADICTIONS, lookup
from .claims import CAUSES, CLAIM_STATUSES, count_claims
from .timing import step_timing

__all__ = ["render_html", "render_markdown", "summary_rows"]

#: Columns of the summary table: scripts, claim rows, then *thesis claims* (one per ID) per
#: status, ``differs`` also split by cause class.
SUMMARY_COLUMNS = (
    ("scripts", "ok", "failed", "rows")
    + CLAIM_STATUSES[:2]
    + tuple(f"differs: {c}" for c in CAUSES)
    + CLAIM_STATUSES[2:]
    + ("no claims recorded",)
)

_CLAIM_HEAD = ("claim ID", "claim", "thesis", "measured", "status", "note")

_ID_HEAD = ("claim ID", "status", "cause", "rows (script: row → status)")

_STATUS_TEXT = (
    "Every thesis claim has one ID (several scripts may check it; it is counted once). "
    "Statuses: reproduced (the thesis number or behaviour is met; the note gives the "
    "criterion); differs (we measured something else; the note says why, and the cause class "
    "says whose: thesis error, hardware data, our model); inconclusive (this run cannot "
    "decide: see the note); identity (holds by construction -- an identity, our own "
    "solver's residual or constraint: checked, not counted as reproduced); calibrated (an "
    "input taken from the thesis: shown, not counted as reproduced); own check (no thesis "
    "number). docs/reproduce.md explains the classes."
)


# --------------------------------------------------------------------------- shared data


def _chapter_title(key: str) -> str:
    return CHAPTERS.get(key, key)


def _fmt_s(seconds: float) -> str:
    if seconds < 60:
        return f"{seconds:.1f} s"
    return f"{int(seconds // 60)} min {seconds % 60:04.1f} s"


def _num(v, digits: int = 1) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    if isinstance(v, (int, float)):
        return f"{v:.{digits}f}"
    return str(v)


def _times(r) -> str:
    """``"12.3 s"`` or ``"12.3 s, CPU 4.5 s"``."""
    text = _fmt_s(r.seconds)
    return text if r.cpu_seconds is None else f"{text}, CPU {_fmt_s(r.cpu_seconds)}"


def _run_time_rows(report) -> list[list[str]]:
    """Scripts by decreasing wall time: name, chapter, status, wall s, CPU s."""
    rows = sorted(report.results, key=lambda r: -r.seconds)
    return [
        [r.name, r.chapter, _script_status(r), f"{r.seconds:.1f}", _num(r.cpu_seconds)]
        for r in rows
    ]


_RUN_TIME_HEAD = ("script", "chapter", "status", "wall s", "CPU s")


def _run_time_note(report) -> str:
    wall = sum(r.seconds for r in report.results)
    cpu = sum(r.cpu_seconds or 0.0 for r in report.results)
    jobs = report.environment.get("jobs", "?")
    return (
        f"{jobs} at a time: {_fmt_s(report.seconds)} in all (sum of script wall times "
        f"{_fmt_s(wall)}, of CPU times {_fmt_s(cpu)}; the solver comparison "
        f"{_fmt_s(report.bench.get('seconds', 0.0))})."
    )


def _script_status(r) -> str:
    if r.ok:
        return "ok"
    return "timed out" if r.status == "timeout" else "failed"


def summary_rows(report) -> list[tuple[str, dict[str, int]]]:
    """Counts per chapter for the summary table, then a ``"total"`` row.

    Scripts and rows are counted per chapter of the script; thesis claims once each, in the
    chapter of their home row (:func:`qpcoord.studies.claims.thesis_claims`).

    Returns
    -------
    list of (str, dict)
        ``(chapter key or "total", {column: count})`` with the columns of
        :data:`SUMMARY_COLUMNS`.
    """
    claims = list(report.claims.values())
    rows = []
    total = dict.fromkeys(SUMMARY_COLUMNS, 0)
    for c in report.chapters:
        counts = dict.fromkeys(SUMMARY_COLUMNS, 0)
        for r in report.results:
            if r.chapter != c:
                continue
            counts["scripts"] += 1
            counts["ok" if r.ok else "failed"] += 1
            counts["rows"] += len(r.claims)
            if r.ok and not r.claims:
                counts["no claims recorded"] += 1
        by_status = count_claims(x for x in claims if x["chapter"] == c)
        for k in SUMMARY_COLUMNS:
            if k in by_status:
                counts[k] = by_status[k]
        rows.append((c, counts))
        for k, v in counts.items():
            total[k] += v
    rows.append(("total", total))
    return rows


def _row_cells(r, row: dict) -> list[str]:
    """A script's claim row for the tables: its thesis-claim ID first, the cause with
    ``differs``, and ``calibrated`` / ``identity`` for a claim the register marks so."""
    from .claim_ids import claim_id

    entry = lookup(r.name, row["id"])
    cid = claim_id(r.name, row["id"], row["status"])
    status = row["status"]
    if entry is not None and entry.calibrated and status != "calibrated":
        status = f"calibrated (row: {status})"
    elif entry is not None and entry.identity and status not in ("identity", "differs"):
        status = f"identity (row: {status})"
    elif status == "differs":
        cause = row.get("cause") or (entry.cause if entry else "") or "unclassified"
        status = f"differs ({cause})"
    return [cid, row["claim"], row["thesis"], row["measured"], status, row["note"]]


def _id_rows(report) -> list[list[str]]:
    """One line per thesis claim (own checks left out): ID, status, cause, its rows."""
    out = []
    for c in sorted(report.claims.values(), key=lambda x: (x["chapter"], x["id"])):
        if c["status"] == "own check":
            continue
        rows = "; ".join(f"{x['script']}: {x['id']} → {x['status']}" for x in c["rows"])
        out.append([c["id"], c["status"], c["cause"], rows])
    return out


_CONTRA_HEAD = ("contradiction", "about", "the thesis says", "claims it bears on")

_CONTRA_TEXT = (
    "Places where the thesis states incompatible things about one quantity. No run can "
    "decide which place is right; the claims they bear on say so in their notes."
)


def _contradiction_rows(report) -> list[list[str]]:
    """The register's contradictions that bear on a claim of this run."""
    return [
        [c.id, c.about, "; ".join(f"{w}: {t}" for w, t in c.says), ", ".join(c.claims)]
        for c in CONTRADICTIONS
        if any(cid in report.claims for cid in c.claims)
    ]


def _header_items(report) -> list[tuple[str, str]]:
    env = report.environment
    solvers = env.get("solvers") or {}
    return [
        ("date", env.get("date", "?")),
        ("qpcoord", str(env.get("qpcoord", "?"))),
        ("Python", str(env.get("python", "?"))),
        ("numpy", str(env.get("numpy", "?"))),
        ("QP backends", ", ".join(f"{k} {v}" for k, v in solvers.items()) or "none"),
        ("machine", f"{env.get('cores', '?')} usable cores, {env.get('platform', '?')}"),
        (
            "mode",
            (
                "quick (`--quick`: shortened runs; many claims can only be inconclusive)"
                if report.quick
                else "full"
            )
            + f", {env.get('jobs', '?')} scripts at a time",
        ),
        ("chapters", ", ".join(report.chapters)),
        ("total wall time", _fmt_s(report.seconds)),
    ]


def _verdict(report) -> str:
    n = len(report.results)
    bad = [r for r in report.results if not r.ok]
    text = f"{n - len(bad)} of {n} scripts ran"
    if bad:
        text += "; not ok: " + ", ".join(f"{r.name} ({_script_status(r)})" for r in bad)
    if "error" in report.bench:
        text += "; the solver comparison failed"
    return text + "."


def _ddl_pivot(timing: dict) -> tuple[list[str], list[tuple[str, list[str]]]]:
    """DDL step times as controller rows × case columns of ``"median / p99"`` µs."""
    rows = timing.get("ddl") or []
    cases = list(dict.fromkeys(r["case"] for r in rows))
    ctls = list(dict.fromkeys(r["controller"] for r in rows))
    cell = {(r["controller"], r["case"]): r for r in rows}
    body = []
    for c in ctls:
        cells = []
        for case in cases:
            r = cell.get((c, case))
            cells.append(f"{_num(r['median_us'])} / {_num(r['p99_us'])}" if r else "–")
        body.append((str(c), cells))
    return [str(c) for c in cases], body


_STACK_NOTE = (
    "Per-step time of the 3-level stack (task updates + solve), µs: median / 99th "
    "percentile; steps per loop in the solver comparison's table."
)


def _stack_pivot(timing: dict) -> tuple[list[str], list[list[str]]]:
    """Stack-bench step times as (n, backend) rows × method columns of ``"median / p99"``."""
    rows = timing.get("stack") or []
    methods = list(dict.fromkeys(str(r["method"]) for r in rows))
    keys = list(dict.fromkeys((r["n"], str(r["solver"])) for r in rows))
    cell = {(r["n"], str(r["solver"]), str(r["method"])): r for r in rows}
    body = []
    for n, solver in keys:
        cells = []
        for m in methods:
            r = cell.get((n, solver, m))
            cells.append(f"{_num(r['median_us'], 0)} / {_num(r['p99_us'], 0)}" if r else "–")
        body.append([str(n), solver, *cells])
    return ["n", "backend", *methods], body


_BENCH_HEAD = (
    "n",
    "method",
    "solver",
    "steps",
    "median µs",
    "p90 µs",
    "p99 µs",
    "QP calls/step",
    "bounds active",
    "limits active",
    "failures",
    "note",
)


def _bench_cells(r: dict) -> list[str]:
    def pct(v):
        return "–" if v is None else f"{100 * v:.0f} %"

    return [
        str(r.get("n")),
        str(r.get("method")),
        str(r.get("solver")),
        str(r.get("steps")),
        _num(r.get("median_us"), 0),
        _num(r.get("p90_us"), 0),
        _num(r.get("p99_us"), 0),
        _num(r.get("qp_calls_mean"), 2),
        pct(r.get("bounds_active")),
        pct(r.get("limits_active")),
        str(r.get("failures")),
        str(r.get("note") or ""),
    ]


def _bench_ratios(rows: list[dict]) -> list[str]:
    """Hierarchical / weighted median ratio per size and backend (one line each)."""
    by = {(r["n"], r["method"], r["solver"]): r for r in rows}
    out = []
    for (n, m, s), r in by.items():
        if m != "hierarchical":
            continue
        w = by.get((n, "weighted", s))
        if w and r.get("median_us") and w.get("median_us"):
            out.append(f"n = {n}, {s}: {r['median_us'] / w['median_us']:.2f}")
    return out


# --------------------------------------------------------------------------- Markdown


def _md(text) -> str:
    """A Markdown table cell: pipes escaped, one line."""
    s = str(text if text is not None else "")
    s = s.replace("\\", "\\\\").replace("|", "\\|")
    return re.sub(r"\s*\n\s*", " ", s).strip()


def _md_table(head: list[str] | tuple, body: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(_md(h) for h in head) + " |"]
    lines.append("|" + "---|" * len(head))
    for row in body:
        lines.append("| " + " | ".join(_md(c) for c in row) + " |")
    return lines


def _fence(text: str) -> list[str]:
    ticks = max([3] + [len(m) + 1 for m in re.findall(r"`{3,}", text)])
    return ["`" * ticks + "text", text, "`" * ticks]


def _rel(path: Path, base: Path) -> str:
    try:
        rel = os.path.relpath(path, base)
    except ValueError:  # pragma: no cover (other drive on Windows)
        rel = str(path)
    return Path(rel).as_posix()


def render_markdown(report) -> str:
    """The report as Markdown (figures linked relative to the report's folder).

    Parameters
    ----------
    report : qpcoord.studies.reproduce.Report

    Returns
    -------
    str
    """
    base = report.out
    L = ["# qpcoord: reproduction of *Overactuated Systems Coordination*", ""]
    L += _md_table(["", ""], [[k, v] for k, v in _header_items(report)])
    L += ["", f"**Result:** {_verdict(report)}", ""]
    L += [_STATUS_TEXT, "", "## Summary of claims", ""]
    body = []
    for key, counts in summary_rows(report):
        name = "total" if key == "total" else _chapter_title(key)
        body.append([name] + [str(counts[c]) for c in SUMMARY_COLUMNS])
    L += _md_table(["chapter", *SUMMARY_COLUMNS], body)
    L += ["", "## Thesis claims by ID", ""]
    L += _md_table(_ID_HEAD, _id_rows(report))
    contra = _contradiction_rows(report)
    if contra:
        L += ["", "## Thesis contradictions", "", _CONTRA_TEXT, ""]
        L += _md_table(_CONTRA_HEAD, contra)
    if report.unmapped:
        L += [
            "",
            "Not run (no chapter for their name in `qpcoord.studies.reproduce.SCRIPT_CHAPTERS`): "
            + ", ".join(f"`{p.name}`" for p in report.unmapped),
        ]
    for c in report.chapters:
        L += ["", f"## {_chapter_title(c)}", ""]
        results = [r for r in report.results if r.chapter == c]
        if not results:
            L += ["No example script for this chapter.", ""]
        for r in results:
            L += [f"### `{r.name}.py`: {_script_status(r)}, {_times(r)}", ""]
            if r.description:
                L += [r.description, ""]
            logs = [p for p in (r.log, r.err_log) if p is not None]
            if logs:
                L += ["Logs: " + ", ".join(f"[{p.name}]({_rel(p, base)})" for p in logs), ""]
            if not r.ok:
                L += [f"**{_script_status(r).capitalize()}:** {_md(r.error)}", ""]
                if r.stderr_tail:
                    L += ["Last lines of its standard error:", ""]
                    L += _fence(r.stderr_tail) + [""]
                continue
            if not r.claims:
                why = "empty list" if r.has_claims else "no `claims` in its summary.json"
                L += [f"*No claims recorded* ({why}).", ""]
            else:
                L += _md_table(_CLAIM_HEAD, [_row_cells(r, row) for row in r.claims])
                L += [""]
            for f in r.figures:
                L += [f"![{_md(f.name)}]({_rel(f, base)})", ""]
    timing = step_timing(report)
    L += ["## Solver comparison: 3-level stacks (`qpcoord.studies.bench_stack`)", ""]
    b = report.bench
    if "rows" in b:
        L += [
            "Closed-loop velocity IK of spatial chains with n joints; per-step time of "
            "`task.update` + `stack.solve`, BLAS on one thread"
            + (", quick sizes (25 steps, 5 for the sparse backends)" if b.get("quick") else "")
            + f"; {_fmt_s(b.get('seconds', 0.0))}. Only ratios within one run are meaningful.",
            "",
        ]
        L += _md_table(_BENCH_HEAD, [_bench_cells(r) for r in b["rows"]])
        ratios = _bench_ratios(b["rows"])
        if ratios:
            L += ["", "Hierarchical / weighted median time: " + "; ".join(ratios) + "."]
        L += [""]
    elif "error" in b:
        L += [f"**Failed:** {_md(b['error'])}", ""]
        if b.get("traceback"):
            L += _fence(b["traceback"].rstrip()) + [""]
    else:
        L += [f"Not available: {b.get('skipped', 'not run')}.", ""]
    L += ["## Per-step timing", "", "### DDL controllers (`ch6_compare`, 8 kHz loop)", ""]
    if timing["ddl"]:
        cases, body = _ddl_pivot(timing)
        L += [
            "Controller time per control step, µs: median / 99th percentile (medians over seeds).",
            "",
        ]
        L += _md_table(["controller", *cases], [[c, *cells] for c, cells in body])
        L += [""]
    else:
        L += [f"Not available: {timing['ddl_note']}.", ""]
    L += ["### Stack solve per backend (solver comparison above)", ""]
    if timing["stack"]:
        head, body = _stack_pivot(timing)
        L += [_STACK_NOTE, ""]
        L += _md_table(head, body)
        L += [""]
    else:
        L += [f"Not available: {timing['stack_note']}.", ""]
    L += ["## Run times", "", f"{len(report.results)} scripts, {_run_time_note(report)}", ""]
    L += _md_table(_RUN_TIME_HEAD, _run_time_rows(report))
    return "\n".join(L)


# --------------------------------------------------------------------------- HTML

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1100px;
margin:2em auto;padding:0 1em;color:#222;line-height:1.45}
h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:2em}
h3{margin-top:1.6em}code,pre{font-family:ui-monospace,Menlo,Consolas,monospace;font-size:.9em}
pre{background:#f6f6f6;padding:.6em;overflow-x:auto;border:1px solid #ddd}
table{border-collapse:collapse;margin:.6em 0;font-size:.9em}
th,td{border:1px solid #ccc;padding:.25em .5em;vertical-align:top;text-align:left}
th{background:#f0f0f0}td.num{text-align:right}
.reproduced{background:#e3f5e1}.differs{background:#fde2e1}.inconclusive{background:#fff5d6}.inconclusive-quick{background:#fff5d6}
.own-check{background:#e8eef9}.calibrated{background:#eeeeee}.identity{background:#eeeeee}.ok{color:#1a7f37;font-weight:600}
.failed,.timed-out{color:#c62828;font-weight:600}
img{max-width:100%;border:1px solid #ddd;margin:.4em 0}figure{margin:.8em 0}
figcaption{font-size:.85em;color:#555}.muted{color:#666}
"""


def _e(text) -> str:
    return html.escape(str(text if text is not None else ""), quote=True)


def _css_class(status: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", str(status).lower()).strip("-")


def _h_table(head, body, num_cols=(), row_classes=None) -> list[str]:
    out = ["<table>", "<tr>" + "".join(f"<th>{_e(h)}</th>" for h in head) + "</tr>"]
    for i, row in enumerate(body):
        cls = f' class="{_e(row_classes[i])}"' if row_classes and row_classes[i] else ""
        cells = "".join(
            f'<td class="num">{_e(c)}</td>' if j in num_cols else f"<td>{_e(c)}</td>"
            for j, c in enumerate(row)
        )
        out.append(f"<tr{cls}>{cells}</tr>")
    out.append("</table>")
    return out


def _img(path: Path) -> str:
    try:
        data = base64.b64encode(path.read_bytes()).decode("ascii")
    except OSError as exc:
        return f'<p class="muted">figure {_e(path.name)} unreadable: {_e(exc)}</p>'
    return (
        f'<figure><img alt="{_e(path.name)}" src="data:image/png;base64,{data}">'
        f"<figcaption>{_e(path.name)}</figcaption></figure>"
    )


def render_html(report) -> str:
    """The report as one self-contained HTML page (figures embedded, inline CSS, no scripts).

    Parameters
    ----------
    report : qpcoord.studies.reproduce.Report

    Returns
    -------
    str
    """
    title = "qpcoord: reproduction of Overactuated Systems Coordination"
    H = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{_e(title)}</h1>",
    ]
    H += _h_table(["", ""], [[k, v.replace("`", "")] for k, v in _header_items(report)])
    H += [f"<p><strong>Result:</strong> {_e(_verdict(report))}</p>"]
    H += [f"<p>{_e(_STATUS_TEXT)}</p>"]
    H += ['<h2 id="summary">Summary of claims</h2>']
    body = []
    for key, counts in summary_rows(report):
        name = "total" if key == "total" else _chapter_title(key)
        body.append([name] + [str(counts[c]) for c in SUMMARY_COLUMNS])
    H += _h_table(["chapter", *SUMMARY_COLUMNS], body, num_cols=range(1, 1 + len(SUMMARY_COLUMNS)))
    H += ['<h2 id="claim-ids">Thesis claims by ID</h2>']
    ids = _id_rows(report)
    H += _h_table(_ID_HEAD, ids, row_classes=[_css_class(x[1]) for x in ids])
    contra = _contradiction_rows(report)
    if contra:
        H += ['<h2 id="contradictions">Thesis contradictions</h2>', f"<p>{_e(_CONTRA_TEXT)}</p>"]
        H += _h_table(_CONTRA_HEAD, contra)
    if report.unmapped:
        H += [
            "<p>Not run (no chapter for their name in <code>SCRIPT_CHAPTERS</code>): "
            + ", ".join(f"<code>{_e(p.name)}</code>" for p in report.unmapped)
            + "</p>"
        ]
    toc = [
        f'<li><a href="#ch-{_css_class(c)}">{_e(_chapter_title(c))}</a></li>'
        for c in report.chapters
    ]
    toc += [
        '<li><a href="#solvers">Solver comparison</a></li>',
        '<li><a href="#timing">Per-step timing</a></li>',
        '<li><a href="#times">Run times</a></li>',
    ]
    H += ["<ul>", *toc, "</ul>"]
    for c in report.chapters:
        H += [f'<h2 id="ch-{_css_class(c)}">{_e(_chapter_title(c))}</h2>']
        results = [r for r in report.results if r.chapter == c]
        if not results:
            H += ["<p>No example script for this chapter.</p>"]
        for r in results:
            st = _script_status(r)
            H += [
                f'<h3 id="{_e(r.name)}"><code>{_e(r.name)}.py</code>: '
                f'<span class="{_css_class(st)}">{_e(st)}</span>, {_e(_times(r))}</h3>'
            ]
            if r.description:
                H += [f"<p>{_e(r.description)}</p>"]
            logs = [p for p in (r.log, r.err_log) if p is not None]
            if logs:
                H += [
                    '<p class="muted">Logs: '
                    + ", ".join(f"<code>{_e(_rel(p, report.out))}</code>" for p in logs)
                    + "</p>"
                ]
            if not r.ok:
                H += [
                    f'<p><strong class="failed">{_e(st.capitalize())}:</strong> {_e(r.error)}</p>'
                ]
                if r.stderr_tail:
                    H += [
                        "<p>Last lines of its standard error:</p>",
                        f"<pre>{_e(r.stderr_tail)}</pre>",
                    ]
                continue
            if not r.claims:
                why = "empty list" if r.has_claims else "no claims in its summary.json"
                H += [f'<p class="muted"><em>No claims recorded</em> ({_e(why)}).</p>']
            else:
                H += _h_table(
                    _CLAIM_HEAD,
                    [_row_cells(r, row) for row in r.claims],
                    row_classes=[_css_class(row["status"]) for row in r.claims],
                )
            H += [_img(f) for f in r.figures]
    H += ['<h2 id="solvers">Solver comparison: 3-level stacks (qpcoord.studies.bench_stack)</h2>']
    b = report.bench
    if "rows" in b:
        H += [
            "<p>Closed-loop velocity IK of spatial chains with n joints; per-step time of "
            "<code>task.update</code> + <code>stack.solve</code>, BLAS on one thread"
            + (", quick sizes (25 steps, 5 for the sparse backends)" if b.get("quick") else "")
            + f"; {_e(_fmt_s(b.get('seconds', 0.0)))}. Only ratios within one run are "
            "meaningful.</p>"
        ]
        H += _h_table(
            _BENCH_HEAD, [_bench_cells(r) for r in b["rows"]], num_cols=(0, 3, 4, 5, 6, 7)
        )
        ratios = _bench_ratios(b["rows"])
        if ratios:
            H += [f"<p>Hierarchical / weighted median time: {_e('; '.join(ratios))}.</p>"]
    elif "error" in b:
        H += [f'<p><strong class="failed">Failed:</strong> {_e(b["error"])}</p>']
        if b.get("traceback"):
            H += [f"<pre>{_e(b['traceback'].rstrip())}</pre>"]
    else:
        H += [f"<p>Not available: {_e(b.get('skipped', 'not run'))}.</p>"]
    timing = step_timing(report)
    H += [
        '<h2 id="timing">Per-step timing</h2>',
        "<h3>DDL controllers (ch6_compare, 8 kHz loop)</h3>",
    ]
    if timing["ddl"]:
        cases, body = _ddl_pivot(timing)
        H += [
            "<p>Controller time per control step, µs: median / 99th percentile (medians "
            "over seeds).</p>"
        ]
        H += _h_table(
            ["controller", *cases],
            [[c, *cells] for c, cells in body],
            num_cols=range(1, 1 + len(cases)),
        )
    else:
        H += [f"<p>Not available: {_e(timing['ddl_note'])}.</p>"]
    H += ["<h3>Stack solve per backend (solver comparison above)</h3>"]
    if timing["stack"]:
        head, body = _stack_pivot(timing)
        H += [f"<p>{_e(_STACK_NOTE)}</p>"]
        H += _h_table(head, body, num_cols=range(2, len(head)))
    else:
        H += [f"<p>Not available: {_e(timing['stack_note'])}.</p>"]
    H += [
        '<h2 id="times">Run times</h2>',
        f"<p>{len(report.results)} scripts, {_e(_run_time_note(report))}</p>",
    ]
    H += _h_table(_RUN_TIME_HEAD, _run_time_rows(report), num_cols=(3, 4))
    H += ["</body></html>"]
    return "\n".join(H)
