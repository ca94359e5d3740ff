"""Run the thesis reproductions and write one report (``qpcoord reproduce``).

Every example script of the repository (``examples/*.py``) reproduces part of a thesis
chapter; this module runs them (each as a subprocess, several at once), gathers what each
wrote (``summary.json`` with its ``"claims"`` rows, PNG figures), runs the solver comparison
of :mod:`qpcoord.studies.bench_stack` and writes ``report.md``, a self-contained ``report.html`` and
``report.json`` under the output folder::

    from qpcoord.studies.reproduce import run
    report = run(chapters=["4", "B"], out="reproduce-out", quick=True)
    report.markdown, report.html, report.counts

Layout of the output folder: ``OUT/<chapter>/<script>/`` is the script's own ``--out``
folder (figures, ``summary.json``, ``summary.txt``), ``OUT/<chapter>/<script>.log`` its
standard output and ``OUT/<chapter>/<script>.err.log`` its standard error.

The chapter of a script comes from its file name, in one table (:data:`SCRIPT_CHAPTERS`).
"""

from __future__ import annotations

import ast
import datetime as _dt
import os
import platform
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from .chapters import CHAPTERS, SCRIPT_CHAPTERS, STANDALONE_SCRIPTS
from .claims import count_claims, thesis_claims
from .timing import step_timing

__all__ = [
    "CHAPTERS",
    "SCRIPT_CHAPTERS",
    "ExamplesNotFoundError",
    "Report",
    "ScriptResult",
    "chapter_of",
    "default_examples_dir",
    "discover",
    "normalise_chapters",
    "run",
]

#: Per-script time limit (s) when ``timeout`` is not given: quick / full runs.
DEFAULT_TIMEOUT = {True: 300.0, False: 3600.0}

#: Lines of a failed script's standard error kept in the report.
STDERR_TAIL_LINES = 25

#: Pseudo-script name of the in-process solver comparison
# (:func:`qpcoord.studies.bench_stack.run_stack_bench`).
BENCH_NAME = "solver comparison (qpcoord.studies.bench_stack)"


class ExamplesNotFoundError(FileNotFoundError):
    """The example scripts are not where :func:`run` looked (they live in the repository)."""


# --------------------------------------------------------------------------- chapters


def _canonical(name: str) -> str | None:
    """Canonical chapter key of a user-given name (``"ch4"`` → ``"4"``, ``"appA"`` → ``"A"``)."""
    s = str(name).strip().lower().replace(" ", "").replace("_", "").replace("-", "")
    if s == "core":
        return "core"
    for prefix in ("chapter", "ch", "appendix", "app"):
        if s.startswith(prefix) and len(s) > len(prefix):
            s = s[len(prefix) :]
            break
    if s in ("4", "5", "6"):
        return s
    if s in ("a", "b", "c"):
        return s.upper()
    return None


def normalise_chapters(chapters: str | Iterable[str] | None) -> list[str]:
    """Validate chapter names and return their canonical keys in report order.

    Parameters
    ----------
    chapters : str or iterable of str or None
        Names such as ``"4"``, ``"ch4"``, ``"A"``, ``"appA"``, ``"core"`` (case-insensitive).
        ``None`` or an empty list means every chapter.

    Returns
    -------
    list of str
        Keys of :data:`CHAPTERS`, without duplicates, in :data:`CHAPTERS` order.

    Raises
    ------
    ValueError
        If a name is not a chapter; the message names it and lists the valid names.
    """
    if chapters is None:
        return list(CHAPTERS)
    if isinstance(chapters, str):
        chapters = [chapters]
    chosen = set()
    for name in chapters:
        key = _canonical(name)
        if key is None:
            valid = ", ".join(CHAPTERS)
            raise ValueError(
                f"unknown chapter {name!r}; valid chapters: {valid} "
                "(also written ch4, ch5, ch6, appA, appB, appC)"
            )
        chosen.add(key)
    return [c for c in CHAPTERS if c in chosen] if chosen else list(CHAPTERS)


def chapter_of(script: str | Path) -> str | None:
    """Chapter key of an example script from its file name (:data:`SCRIPT_CHAPTERS`), or None."""
    stem = Path(script).stem
    for prefix, chapter in SCRIPT_CHAPTERS:
        if stem.startswith(prefix):
            return chapter
    return None


# --------------------------------------------------------------------------- discovery


def default_examples_dir() -> Path:
    """The repository's ``examples/`` folder next to the installed package (editable install)."""
    return Path(__file__).resolve().parents[2] / "examples"


def _is_repo_checkout(root: Path) -> bool:
    """Is ``root`` a qpcoord source tree (its ``pyproject.toml`` names the project)?"""
    try:
        text = (root / "pyproject.toml").read_text(encoding="utf-8")
    except OSError:
        return False
    return re.search(r'^name\s*=\s*"qpcoord"', text, re.M) is not None


def _readme_descriptions(examples_dir: Path) -> dict[str, str]:
    """``stem → one-line description`` from the table of ``examples/README.md`` (if any)."""
    readme = examples_dir / "README.md"
    out: dict[str, str] = {}
    if not readme.is_file():
        return out
    pattern = re.compile(r"^\|\s*`([^`]+)\.py`\s*\|\s*(.*?)\s*\|\s*$")
    for line in readme.read_text(encoding="utf-8", errors="replace").splitlines():
        m = pattern.match(line.strip())
        if m:
            out[m.group(1)] = m.group(2)
    return out


def _docstring_line(script: Path) -> str:
    """First line of a script's module docstring, without importing it ("" if none)."""
    try:
        doc = ast.get_docstring(ast.parse(script.read_text(encoding="utf-8")))
    except (OSError, SyntaxError, ValueError):
        return ""
    return doc.strip().splitlines()[0].strip() if doc and doc.strip() else ""


def discover(examples_dir: str | Path | None = None) -> tuple[dict[str, list[Path]], list[Path]]:
    """Example scripts by chapter.

    Parameters
    ----------
    examples_dir : path, optional
        Folder of the scripts (default :func:`default_examples_dir`).

    Returns
    -------
    by_chapter : dict
        Chapter key → sorted script paths (every key of :data:`CHAPTERS`, possibly empty).
    unmapped : list of Path
        Scripts whose name matches no prefix of :data:`SCRIPT_CHAPTERS`.

    Raises
    ------
    ExamplesNotFoundError
        If the folder does not exist or holds no ``*.py`` script.
    """
    folder = Path(examples_dir) if examples_dir is not None else default_examples_dir()
    scripts = sorted(folder.glob("*.py")) if folder.is_dir() else []
    if examples_dir is None and not _is_repo_checkout(folder.parent):
        scripts = []  # an installed package: site-packages/examples is someone else's
    if not scripts:
        raise ExamplesNotFoundError(
            f"no example scripts in {folder}: they are not installed with the package. "
            "Clone the repository (git clone <qpcoord repository> && pip install -e ./qpcoord) "
            "and run from it, or pass --examples DIR (Python: examples_dir=DIR)."
        )
    by_chapter: dict[str, list[Path]] = {c: [] for c in CHAPTERS}
    unmapped = []
    for s in scripts:
        if s.stem in STANDALONE_SCRIPTS:
            continue
        c = chapter_of(s)
        if c is None:
            unmapped.append(s)
        else:
            by_chapter[c].append(s)
    return by_chapter, unmapped


# --------------------------------------------------------------------------- results


@dataclass
class ScriptResult:
    """What one example script did.

    Attributes
    ----------
    name : str
        Script stem (``"ch4_leaves"``), or :data:`BENCH_NAME` for the solver comparison.
    chapter : str
        Chapter key.
    script : Path or None
        Script path (None for the in-process benchmark).
    status : str
        ``"ok"``, ``"failed"`` or ``"timeout"``.
    seconds : float
        Wall time.
    cpu_seconds : float or None
        CPU time of the script (user + system; None where the OS does not say).
    returncode : int or None
        Exit code of the subprocess (None if killed at the timeout or in-process).
    out_dir : Path or None
        The script's ``--out`` folder.
    log, err_log : Path or None
        Standard output and standard error of the script.
    description : str
        One line from ``examples/README.md`` (else the script's docstring).
    error : str
        Why it failed ("" if ok).
    stderr_tail : str
        Last lines of standard error (kept for failures).
    claims : list of dict
        The ``"claims"`` rows of its ``summary.json`` (see :func:`qpcoord.studies.files.claim`).
    has_claims : bool
        Whether ``summary.json`` had a ``"claims"`` list at all.
    figures : list of Path
        PNG files it wrote, sorted.
    summary : dict or None
        Its whole ``summary.json`` (not written to ``report.json``).
    """

    name: str
    chapter: str
    script: Path | None = None
    status: str = "failed"
    seconds: float = 0.0
    cpu_seconds: float | None = None
    returncode: int | None = None
    out_dir: Path | None = None
    log: Path | None = None
    err_log: Path | None = None
    description: str = ""
    error: str = ""
    stderr_tail: str = ""
    claims: list[dict] = field(default_factory=list)
    has_claims: bool = False
    figures: list[Path] = field(default_factory=list)
    summary: dict | None = None

    @property
    def ok(self) -> bool:
        """True if the script exited 0 and left a readable ``summary.json``."""
        return self.status == "ok"

    def to_dict(self) -> dict:
        """JSON-ready form (paths as strings, without ``summary``)."""
        return {
            "name": self.name,
            "chapter": self.chapter,
            "script": str(self.script) if self.script else None,
            "status": self.status,
            "seconds": round(self.seconds, 3),
            "cpu_seconds": None if self.cpu_seconds is None else round(self.cpu_seconds, 3),
            "returncode": self.returncode,
            "out_dir": str(self.out_dir) if self.out_dir else None,
            "log": str(self.log) if self.log else None,
            "err_log": str(self.err_log) if self.err_log else None,
            "description": self.description,
            "error": self.error,
            "stderr_tail": self.stderr_tail,
            "has_claims": self.has_claims,
            "claims": self.claims,
            "figures": [str(f) for f in self.figures],
        }


@dataclass
class Report:
    """Result of :func:`run`: where the report is and what each script did.

    Attributes
    ----------
    out : Path
        Output folder.
    markdown, html, json : Path
        ``report.md``, ``report.html``, ``report.json`` in ``out``.
    quick : bool
        Quick (CI) or full run.
    chapters : list of str
        Chapters run.
    results : list of ScriptResult
        One per script, in report order.
    unmapped : list of Path
        Scripts in the examples folder that belong to no chapter (not run).
    bench : dict
        Solver comparison: ``{"rows": [...], "seconds": s}`` or ``{"error": ...}`` or
        ``{"skipped": reason}``.
    environment : dict
        Date, versions, QP backends, cores, jobs.
    seconds : float
        Total wall time.
    """

    out: Path
    markdown: Path
    html: Path
    json: Path
    quick: bool
    chapters: list[str]
    results: list[ScriptResult]
    unmapped: list[Path] = field(default_factory=list)
    bench: dict = field(default_factory=dict)
    environment: dict = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def failed(self) -> list[ScriptResult]:
        """Scripts that failed or timed out (and the benchmark, if it failed)."""
        out = [r for r in self.results if not r.ok]
        if "error" in self.bench:
            out.append(
                ScriptResult(BENCH_NAME, "core", status="failed", error=str(self.bench["error"]))
            )
        return out

    @property
    def ok(self) -> bool:
        """True if every script and the benchmark ran."""
        return not self.failed

    @property
    def claims(self) -> dict[str, dict]:
        """Thesis claims by ID, merged from every script's rows
        (:func:`qpcoord.studies.claims.thesis_claims`)."""
        return thesis_claims(
            (r.chapter, r.name, row) for r in self.results if r.ok for row in r.claims
        )

    @property
    def counts(self) -> dict[str, int]:
        """Scripts ``ok`` / ``failed`` / ``timeout``, claim ``rows``, and *thesis claims* (by ID,
        each counted once) per status, with ``"differs: <cause>"`` per cause class.

        ``"not in thesis"`` repeats ``"own check"`` (its older name, read by callers).
        """
        out = {"scripts": len(self.results), "ok": 0, "failed": 0, "timeout": 0}
        out["no claims"] = 0
        out["rows"] = 0
        for r in self.results:
            out[r.status] = out.get(r.status, 0) + 1
            if r.ok and not r.claims:
                out["no claims"] += 1
            out["rows"] += len(r.claims)
        out.update(count_claims(self.claims.values()))
        out["not in thesis"] = out["own check"]
        return out

    def to_dict(self) -> dict:
        """JSON-ready form (written as ``report.json``)."""
        return {
            "quick": self.quick,
            "chapters": self.chapters,
            "seconds": round(self.seconds, 3),
            "environment": self.environment,
            "counts": self.counts,
            "claims": sorted(self.claims.values(), key=lambda c: (c["chapter"], c["id"])),
            "results": [r.to_dict() for r in self.results],
            "unmapped": [str(p) for p in self.unmapped],
            "bench": self.bench,
            "step_timing": step_timing(self),
        }


# --------------------------------------------------------------------------- running

_LIVE: set[subprocess.Popen] = set()
_LIVE_LOCK = threading.Lock()


def _child_env() -> dict[str, str]:
    env = dict(os.environ)
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env[var] = "1"
    env["MPLBACKEND"] = "Agg"
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _kill(proc: subprocess.Popen) -> None:
    """Kill a script and everything it started (its own process group on POSIX)."""
    try:
        if os.name == "posix":
            os.killpg(proc.pid, signal.SIGKILL)
        else:  # pragma: no cover
            proc.kill()
    except (ProcessLookupError, PermissionError, OSError):
        pass


def _wait(proc: subprocess.Popen, timeout: float) -> tuple[int, float | None]:
    """Wait for ``proc``; its exit code and CPU time (user + system, s; POSIX only).

    Raises ``subprocess.TimeoutExpired`` after ``timeout`` s (the process is left running).
    """
    if not hasattr(os, "wait4"):  # pragma: no cover (Windows)
        return proc.wait(timeout=timeout), None
    deadline = time.monotonic() + timeout
    pause = 0.005
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid == proc.pid:
            proc.returncode = os.waitstatus_to_exitcode(status)
            return proc.returncode, usage.ru_utime + usage.ru_stime
        if time.monotonic() >= deadline:
            raise subprocess.TimeoutExpired(proc.args, timeout)
        time.sleep(pause)
        pause = min(0.1, 2 * pause)


def _tail(path: Path | None, lines: int = STDERR_TAIL_LINES) -> str:
    if path is None or not path.is_file():
        return ""
    text = path.read_text(encoding="utf-8", errors="replace").rstrip()
    return "\n".join(text.splitlines()[-lines:])


def _run_script(
    script: Path, chapter: str, out: Path, quick: bool, timeout: float, description: str
) -> ScriptResult:
    """Run one example as a subprocess and collect what it wrote; never raises."""
    stem = script.stem
    res = ScriptResult(name=stem, chapter=chapter, script=script, description=description)
    res.out_dir = out / chapter / stem
    res.log = out / chapter / f"{stem}.log"
    res.err_log = out / chapter / f"{stem}.err.log"
    t0 = time.perf_counter()
    try:
        if res.out_dir.exists():  # stale figures/summary of an earlier run would mislead
            shutil.rmtree(res.out_dir)
        res.out_dir.mkdir(parents=True, exist_ok=True)
        cmd = [sys.executable, str(script)] + (["--quick"] if quick else [])
        cmd += ["--out", str(res.out_dir)]
        with open(res.log, "wb") as fo, open(res.err_log, "wb") as fe:
            proc = subprocess.Popen(
                cmd,
                stdout=fo,
                stderr=fe,
                stdin=subprocess.DEVNULL,
                env=_child_env(),
                cwd=str(out),
                start_new_session=(os.name == "posix"),
            )
            with _LIVE_LOCK:
                _LIVE.add(proc)
            try:
                res.returncode, res.cpu_seconds = _wait(proc, timeout)
            except subprocess.TimeoutExpired:
                _kill(proc)
                proc.wait()
                res.status = "timeout"
                res.error = f"timed out after {timeout:g} s (killed)"
            except BaseException:  # Ctrl-C while waiting: do not leave the script running
                _kill(proc)
                proc.wait()
                raise
            finally:
                with _LIVE_LOCK:
                    _LIVE.discard(proc)
        res.seconds = time.perf_counter() - t0
        if res.status != "timeout":
            if res.returncode != 0:
                res.error = f"exit code {res.returncode}"
            else:
                _collect(res)
    except Exception as exc:  # the runner itself: record, keep the other scripts going
        res.seconds = time.perf_counter() - t0
        res.status = "failed"
        res.error = f"runner error: {type(exc).__name__}: {exc}"
    if not res.ok:
        res.stderr_tail = _tail(res.err_log)
    return res


def _collect(res: ScriptResult) -> None:
    """Read ``summary.json`` (claims) and the figures of a script that exited 0."""
    import json

    path = res.out_dir / "summary.json"
    res.figures = sorted(p for p in res.out_dir.rglob("*.png") if ".tmp" not in p.name)
    if not path.is_file():
        last = _tail(res.log, 1).strip() if res.log else ""
        res.status = "failed"
        res.error = "exited 0 but wrote no summary.json" + (f" (it said: {last})" if last else "")
        return
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        res.status, res.error = "failed", f"unreadable summary.json: {exc}"
        return
    res.summary = summary if isinstance(summary, dict) else {"value": summary}
    res.status = "ok"
    claims = res.summary.get("claims")
    if isinstance(claims, list):
        res.has_claims = True
        keys = ("id", "claim", "thesis", "measured", "status", "note", "cause")
        for row in claims:
            if isinstance(row, dict):
                row = {k: str(row.get(k, "") or "") for k in keys}
                if row["status"] == "not in thesis":  # the older name of "own check"
                    row["status"] = "own check"
                res.claims.append(row)
            else:
                res.claims.append(
                    {
                        "id": "?",
                        "claim": str(row),
                        "thesis": "",
                        "measured": "",
                        "status": "invalid",
                        "note": "malformed claim row",
                        "cause": "",
                    }
                )


def _run_bench(quick: bool) -> tuple[dict, float]:
    """Solver comparison on 3-level stacks, in-process with BLAS on one thread."""
    from threadpoolctl import threadpool_limits

    from .bench_stack import format_table, run_stack_bench

    t0 = time.perf_counter()
    try:
        with threadpool_limits(limits=1):
            if quick:
                rows = run_stack_bench(quick=True)
            else:  # full steps for the fast backends; the slow sparse ones get 200
                rows = run_stack_bench(steps=1000, slow_steps=200)
        rows = [{k: v for k, v in r.items() if k != "failure_messages"} for r in rows]
        out = {"rows": _json_safe(rows), "text": format_table(rows), "quick": quick}
    except Exception as exc:
        out = {"error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc()}
    dt = time.perf_counter() - t0
    out["seconds"] = round(dt, 3)
    return out, dt


def _json_safe(v):
    import math

    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {str(k): _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x) for x in v]
    if hasattr(v, "item") and callable(v.item):  # numpy scalar
        return _json_safe(v.item())
    return v


def environment(quick: bool, jobs: int) -> dict:
    """Date, versions (qpcoord, Python, numpy, QP backends), cores and run mode."""
    import numpy as np

    from .._version import __version__
    from ..core.backends import solver_versions

    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover
        cores = os.cpu_count() or 1
    return {
        "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC"),
        "qpcoord": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "platform": platform.platform(),
        "solvers": solver_versions(),
        "cores": cores,
        "jobs": jobs,
        "mode": "quick" if quick else "full",
    }


def _job(kind: str, **kw) -> ScriptResult | tuple[dict, float]:
    """One unit of work for :func:`qpcoord.studies.sweep.sweep` (dict items arrive as keywords)."""
    if kind == "bench":
        return _run_bench(kw["quick"])
    return _run_script(
        kw["script"], kw["chapter"], kw["out"], kw["quick"], kw["timeout"], kw["description"]
    )


def _expected_seconds(out: Path, quick: bool) -> dict[str, float]:
    """Per-script wall times of an earlier report in ``out`` with the same mode (for ordering)."""
    import json

    try:
        old = json.loads((out / "report.json").read_text(encoding="utf-8"))
        if bool(old.get("quick")) != quick:
            return {}
        return {r["name"]: float(r["seconds"]) for r in old.get("results", [])}
    except (OSError, ValueError, KeyError, TypeError):
        return {}


def run(
    chapters: str | Sequence[str] | None = None,
    out: str | Path = "reproduce-out",
    quick: bool = False,
    jobs: int | None = None,
    timeout: float | None = None,
    examples_dir: str | Path | None = None,
    progress: bool | Callable[[int, int], None] = True,
    bench: bool = True,
) -> Report:
    """Run the chapters' reproductions and write ``report.md``, ``report.html``, ``report.json``.

    Each example script runs as ``python script [--quick] --out OUT/<chapter>/<stem>`` with
    BLAS/OpenMP limited to one thread, ``jobs`` at a time (:func:`qpcoord.studies.sweep.sweep`,
    thread backend: the work is in the subprocesses). A script that fails or times out is
    recorded with the tail of its standard error; the others still run and the report is
    still written. The solver comparison (:func:`qpcoord.studies.bench_stack.run_stack_bench`) runs
    in-process as one more job when the ``core`` chapter is selected.

    Parameters
    ----------
    chapters : str or sequence of str, optional
        Chapters to run (``"core"``, ``"4"``, ``"5"``, ``"6"``, ``"A"``, ``"B"``, ``"C"``;
        ``"ch4"``, ``"appA"`` … also accepted). Default: all.
    out : path
        Output folder (created). Scripts' earlier outputs in it are replaced.
    quick : bool
        Pass ``--quick`` to every script and run the benchmark in quick mode (CI).
    jobs : int, optional
        Scripts run at once (default: the number of usable cores).
    timeout : float, optional
        Per-script time limit in s (default :data:`DEFAULT_TIMEOUT`: 300 quick, 3600 full).
    examples_dir : path, optional
        Folder of the example scripts (default: the repository's ``examples/``).
    progress : bool or callable
        Progress bar on stderr (tqdm), or ``callable(done, total)``.
    bench : bool
        Run the solver comparison (with the ``core`` chapter). False: say it was skipped.

    Returns
    -------
    Report
        Paths and per-script results; ``report.ok`` is False if anything failed.

    Raises
    ------
    ValueError
        Unknown chapter name, or ``jobs`` / ``timeout`` not positive.
    ExamplesNotFoundError
        The examples folder is missing (clone the repository).
    """
    from .files import write_json, write_text
    from .render import render_html, render_markdown
    from .sweep import sweep

    t0 = time.perf_counter()
    keys = normalise_chapters(chapters)
    if jobs is None:
        try:
            jobs = len(os.sched_getaffinity(0))
        except AttributeError:  # pragma: no cover
            jobs = os.cpu_count() or 1
    jobs = int(jobs)
    if jobs < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    timeout = DEFAULT_TIMEOUT[bool(quick)] if timeout is None else float(timeout)
    if not timeout > 0:
        raise ValueError(f"timeout must be > 0 s, got {timeout}")
    folder = Path(examples_dir) if examples_dir is not None else default_examples_dir()
    by_chapter, unmapped = discover(folder)
    descriptions = _readme_descriptions(folder)
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)

    items = []
    for c in keys:
        for s in by_chapter[c]:
            items.append(
                {
                    "kind": "script",
                    "script": s.resolve(),
                    "chapter": c,
                    "out": out,
                    "quick": bool(quick),
                    "timeout": timeout,
                    "description": descriptions.get(s.stem) or _docstring_line(s),
                }
            )
    run_bench = bench and "core" in keys
    if run_bench:
        items.append({"kind": "bench", "quick": bool(quick), "name": BENCH_NAME})
    # longest first (times of an earlier report in `out`, if any): shorter total wall time
    expected = _expected_seconds(out, bool(quick))
    order = sorted(
        range(len(items)),
        key=lambda i: -expected.get(items[i].get("name") or items[i]["script"].stem, 0.0),
    )
    env = environment(bool(quick), jobs)
    try:
        done = (
            sweep(
                _job,
                [items[i] for i in order],
                backend="threads",
                n_jobs=jobs,
                progress=progress,
                desc="reproduce",
            )
            if items
            else []
        )
    except BaseException:
        # Ctrl-C or a runner bug: kill the scripts we started (their own process groups)
        with _LIVE_LOCK:
            live = list(_LIVE)
        for proc in live:
            _kill(proc)
        raise
    outputs = [None] * len(items)
    for i, r in zip(order, done, strict=True):
        outputs[i] = r
    results = []
    bench_out: dict = {}
    for item, r in zip(items, outputs, strict=True):
        if item["kind"] == "bench":
            bench_out = r[0]
        else:
            results.append(r)
    if not run_bench:
        bench_out = {
            "skipped": "not run (chapter core not selected)"
            if bench
            else "not run (disabled: --no-bench)"
        }
    report = Report(
        out=out,
        markdown=out / "report.md",
        html=out / "report.html",
        json=out / "report.json",
        quick=bool(quick),
        chapters=keys,
        results=results,
        unmapped=unmapped,
        bench=bench_out,
        environment=env,
    )
    report.seconds = time.perf_counter() - t0
    env["wall_seconds"] = round(report.seconds, 1)
    # render everything first: a renderer error leaves the previous report files untouched
    data, md, page = report.to_dict(), render_markdown(report), render_html(report)
    write_json(report.json, data)
    write_text(report.markdown, md)
    write_text(report.html, page)
    return report
