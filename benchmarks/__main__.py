"""Run the benchmarks and (``--write``) put their tables into ``benchmarks/README.md`` (and
the dual-stage ones into ``benchmarks/ddl.md``).

    python -m benchmarks                      # every table, printed
    python -m benchmarks stack_bench --quick  # one benchmark, its smoke configuration
    python -m benchmarks --write              # every table, written into the README

Each table is what one command prints (its machine line, its command, its tables); ``--write``
replaces the lines between the table's markers ``<!-- table: NAME -->`` and ``<!-- /table -->``
and leaves the prose. The scripts run one after the other, each in its own process with one
BLAS thread. If any run fails, nothing is written.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from ._table import ROOT, splice, write_tables

HERE = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Table:
    """A table of a page: the script that prints it, with its full and its smoke arguments,
    and the page (a file of ``benchmarks/``) that holds it."""

    script: str
    full: tuple[str, ...]
    quick: tuple[str, ...]
    page: str = "README.md"


#: The README's tables in its order. ``hierarchy_published`` leaves out scs, which does not
#: solve the humanoid within the default 10 s time limit (the script then exits with status 1).
TABLES: dict[str, Table] = {
    "hierarchy_bench": Table(
        "hierarchy_bench.py",
        ("--steps", "300", "--no-python", "--runs", "4"),
        (
            "--quick",
            "--scenario",
            "panda9",
            "--scenario",
            "chain30",
            "--runs",
            "2",
        ),
    ),
    "hierarchy_published_resolve": Table(
        "hierarchy_published.py",
        ("--resolve", "--steps", "60", "--problem", "lexls_test01_humanoid", "--runs", "2"),
        ("--resolve", "--steps", "6", "--problem", "soth_sot", "--runs", "2"),
    ),
    "hierarchy_published": Table(
        "hierarchy_published.py",
        tuple(
            a
            for s in ("daqp", "quadprog", "proxqp", "piqp", "clarabel", "highs", "osqp")
            for a in ("--solver", s)
        )
        + ("--problem", "lexls_test01_humanoid", "--problem", "soth_sot"),
        ("--solver", "daqp", "--problem", "soth_sot", "--repeats", "2"),
    ),
    "lexls": Table("lexls/bench.py", (), ("--quick",)),
    "engine_agreement": Table("engine_agreement.py", ("--seeds", "400"), ("--seeds", "4")),
    "oneshot": Table("oneshot.py", ("--runs", "3"), ("--steps", "200")),
    "stack_bench": Table(
        "stack_bench.py",
        ("--solver", "daqp"),
        ("--quick", "--solver", "daqp", "--sizes", "7"),
    ),
    "weighted_bench": Table("weighted_bench.py", (), ("--quick",)),
    "ik_peers": Table(
        "ik_peers.py",
        (),
        ("--quick", "--no-placo", "--no-pink", "--scenario", "panda-position"),
    ),
    "native_ik_step": Table("native_ik_step.py", (), ("--steps", "30", "--runs", "2")),
    "native_ik_kinds": Table("native_ik_kinds.py", (), ("--steps", "30", "--runs", "1")),
    "collision_bench": Table("collision_bench.py", (), ("--steps", "30")),
    "cell_stacks": Table("cell_stacks.py", (), ("--steps", "30", "--runs", "1")),
    "edges": Table("edges.py", ("--pairs", "300"), ("--steps", "600", "--pairs", "5"), "edges.md"),
    "mpc_bench": Table("mpc_bench.py", (), ("--quick", "--steps", "600"), "ddl.md"),
    "ddl_bench": Table("ddl_bench.py", (), ("--quick",), "ddl.md"),
    "ddl_margin": Table("ddl_margin.py", (), ("--quick",), "ddl.md"),
    "ddl_hdd": Table("ddl_hdd.py", (), ("--repeats", "1", "--steps", "2000"), "ddl.md"),
}


def _select(names: list[str]) -> list[str]:
    """Table names from table or script names (``hierarchy_published`` selects both of its
    tables only if given as ``hierarchy_published.py``)."""
    if not names:
        return list(TABLES)
    chosen: list[str] = []
    for name in names:
        if name in TABLES:
            hits = [name]
        else:
            hits = [k for k, t in TABLES.items() if t.script in (name, f"{name}.py")]
        if not hits:
            raise SystemExit(f"unknown benchmark {name!r}; known: {', '.join(TABLES)}")
        chosen += [h for h in hits if h not in chosen]
    return chosen


def run(name: str, quick: bool) -> tuple[int, str, str]:
    """Run one table's command; its exit status, its stdout and its stderr."""
    table = TABLES[name]
    args = table.quick if quick else table.full
    one = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    env = {**os.environ, **one}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
    proc = subprocess.run(
        [sys.executable, str(Path("benchmarks") / table.script), *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
    )
    return proc.returncode, proc.stdout, proc.stderr


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", metavar="NAME", help=f"tables: {', '.join(TABLES)}")
    ap.add_argument("--quick", action="store_true", help="each script's smoke configuration")
    ap.add_argument("--write", action="store_true", help="splice the tables into their pages")
    ap.add_argument("--dir", type=Path, default=HERE, help="the folder of the pages --write edits")
    args = ap.parse_args(argv)
    if args.quick and args.write and args.dir.resolve() == HERE.resolve():
        ap.error("--quick --write would put smoke-run numbers into the pages; give --dir")
    names = _select(args.names)
    pages = {TABLES[n].page for n in names}
    if args.write:  # every marker pair present before anything runs
        texts = {page: (args.dir / page).read_text() for page in pages}
        for name in names:
            splice(texts[TABLES[name].page], name, "")
    blocks: dict[str, str] = {}
    failed: list[str] = []
    for name in names:
        t0 = time.perf_counter()
        code, out, err = run(name, args.quick)
        took = time.perf_counter() - t0
        print(f"<!-- table: {name} ({took:.0f} s) -->\n{out.rstrip()}\n", flush=True)
        if code != 0:
            failed.append(name)
            sys.stderr.write(f"{name}: exit status {code}\n{err[-4000:]}\n")
            continue
        blocks[name] = out
    if failed:
        sys.stderr.write(f"failed: {', '.join(failed)}; no page changed\n")
        return 1
    if args.write:
        write_tables(
            {
                args.dir / page: {n: b for n, b in blocks.items() if TABLES[n].page == page}
                for page in sorted(pages)
            }
        )
        print(f"wrote {len(blocks)} table(s) into {', '.join(sorted(pages))}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
