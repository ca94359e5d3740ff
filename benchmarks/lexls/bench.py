"""LexLS and qpcoord's native engine on the same problems, both as C++ drivers, warm started.

    python benchmarks/lexls/bench.py                 # 2 runs × 5 passes × 50 moved steps
    python benchmarks/lexls/bench.py --quick         # 1 run × 1 pass × 10 steps
    python benchmarks/lexls/bench.py --lexls DIR     # LexLS from DIR (default below)

LexLS (github.com/jrl-umi3218/lexls, header-only C++) is not on PyPI: ``--lexls`` names a
checkout of it (its ``include/`` is used), by default ``$LEXLS_DIR`` or ``benchmarks/.lexls``
(``git clone https://github.com/jrl-umi3218/lexls benchmarks/.lexls``). Without it the table
has the native column only and says so in one line.

The run: ``src/native/tools/dump_problems.py`` writes the problems (the moved steps of
``hierarchy_published.py``'s humanoid and soth_sot, ``hierarchy_bench.py``'s chain30 and
random50) to a temporary directory; g++ builds ``src/native/tools/driver.cpp`` (the native
engine's C++ core, without Python) and ``lexls_driver.cpp`` with the same flags (``-O2``, and
``-march=x86-64-v3`` on a CPU with AVX2 and FMA, as the extension the loader picks there);
each driver solves every problem's steps warm, the two alternating, ``--runs`` times. The gap
compares the two answers through the level values (``compare.py``).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
NATIVE = ROOT / "src" / "native"
sys.path[:0] = [str(HERE), str(HERE.parent)]  # compare.py beside it, the table writer above
from _table import markdown, preamble, sig3, span  # noqa: E402
from compare import read, values  # noqa: E402

#: (dump name, label) of the problems, in the table's order.
PROBLEMS = (
    ("humanoid", "humanoid (published rows)"),
    ("soth_sot", "soth_sot"),
    ("chain30", "chain30"),
    ("random50", "random50"),
)
MEDIAN = re.compile(r"median ([0-9.]+) us")


def eigen_include() -> Path | None:
    """Eigen's headers: cmeel-eigen's (the build's), else Debian's, else ``None``."""
    for p in sys.path:
        inc = Path(p) / "cmeel.prefix" / "include" / "eigen3"
        if (inc / "Eigen" / "Dense").is_file():
            return inc
    deb = Path("/usr/include/eigen3")
    return deb if (deb / "Eigen" / "Dense").is_file() else None


def march() -> list[str]:
    """``-march=x86-64-v3`` on a CPU with AVX2 and FMA (Linux), else nothing."""
    try:
        flags = Path("/proc/cpuinfo").read_text().split()
    except OSError:
        return []
    return ["-march=x86-64-v3"] if {"avx2", "fma"} <= set(flags) else []


def build(out: Path, sources: list[Path], includes: list[Path], name: str) -> Path:
    """``g++ -O2`` of ``sources`` into ``out/name``; raises ``RuntimeError`` with g++'s error."""
    exe = out / name
    cmd = ["g++", "-O2", *march(), "-std=c++17", "-DNDEBUG"]
    cmd += [f"-I{i}" for i in includes] + [str(s) for s in sources] + ["-o", str(exe)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"g++ failed on {sources[0].name}: {proc.stderr[-2000:]}")
    return exe


def solve(exe: Path, dump: Path, passes: int, xout: Path) -> float:
    """Median µs per warm solve of ``dump``'s steps, ``passes`` times; every x to ``xout``."""
    proc = subprocess.run(
        [str(exe), str(dump), str(passes), "warm", str(xout)], capture_output=True, text=True
    )
    found = MEDIAN.search(proc.stdout)
    if proc.returncode != 0 or found is None:
        raise RuntimeError(f"{exe.name} {dump.name}: exit {proc.returncode}: {proc.stderr[-500:]}")
    return float(found.group(1))


def gap(dump: Path, xa: Path, xb: Path) -> float:
    """The largest level-value gap of two drivers' x over the first pass (relative to
    ``max(1, value)``), the measure of ``compare.py``."""
    n, meq, mi, _, probs = read(str(dump))
    XA = np.fromfile(xa).reshape(-1, n)[: len(probs)]
    XB = np.fromfile(xb).reshape(-1, n)[: len(probs)]
    worst = 0.0
    for prob, a, b in zip(probs, XA, XB, strict=True):
        va, _ = values(meq, mi, prob, a)
        vb, _ = values(meq, mi, prob, b)
        worst = max(worst, float(np.max(np.abs(va - vb) / np.maximum(1.0, np.maximum(va, vb)))))
    return worst


def lexls_dir(arg: str | None) -> Path:
    """The LexLS checkout: ``--lexls``, else ``$LEXLS_DIR``, else ``benchmarks/.lexls``."""
    return Path(arg or os.environ.get("LEXLS_DIR") or HERE.parent / ".lexls")


def lexls_commit(path: Path) -> str:
    """``LexLS `<short commit>``` of the checkout at ``path``, for the table's caption."""
    cmd = ["git", "-C", str(path), "rev-parse", "--short", "HEAD"]
    out = subprocess.run(cmd, capture_output=True, text=True)
    return f"LexLS `{out.stdout.strip()}`" if out.returncode == 0 else "LexLS (not a git checkout)"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lexls", help="a LexLS checkout (default $LEXLS_DIR or benchmarks/.lexls)")
    ap.add_argument("--steps", type=int, default=50, help="moved steps per problem (default 50)")
    ap.add_argument("--passes", type=int, default=5, help="passes over the steps per run")
    ap.add_argument("--runs", type=int, default=2, help="cells: the range over this many runs")
    ap.add_argument("--quick", action="store_true", help="1 run × 1 pass × 10 steps")
    args = ap.parse_args(argv)
    if args.quick:
        args.steps, args.passes, args.runs = 10, 1, 1
    for flag in ("steps", "passes", "runs"):
        if getattr(args, flag) < 1:
            ap.error(f"--{flag} must be at least 1, got {getattr(args, flag)}")
    eigen = eigen_include()
    if shutil.which("g++") is None or eigen is None:
        sys.exit("lexls/bench.py needs g++ and Eigen's headers (cmeel-eigen or libeigen3-dev)")
    lexls = lexls_dir(args.lexls)
    has_lexls = (lexls / "include" / "lexls" / "lexlsi.h").is_file()
    print(preamble())
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        names = [a for name, _ in PROBLEMS for a in ("--only", name)]
        dumped = subprocess.run(
            [sys.executable, str(NATIVE / "tools" / "dump_problems.py"), tmp,
             "--steps", str(args.steps), *names],
            cwd=ROOT, capture_output=True, text=True,
        )  # fmt: skip
        if dumped.returncode != 0:
            sys.exit(f"dump_problems.py failed: {dumped.stderr[-2000:]}")
        native = build(out, [NATIVE / "tools" / "driver.cpp", NATIVE / "hierarchy.cpp"],
                       [eigen, NATIVE], "driver")  # fmt: skip
        lex = None
        if has_lexls:
            lex = build(out, [HERE / "lexls_driver.cpp"], [eigen, lexls / "include"], "lexls")
        times: dict[str, dict[str, list[float]]] = {
            p: {"lexls": [], "native": []} for p, _ in PROBLEMS
        }
        gaps: dict[str, float] = {}
        for _ in range(args.runs):  # the two drivers alternate, problem by problem
            for name, _label in PROBLEMS:
                dump = out / f"{name}.bin"
                times[name]["native"].append(solve(native, dump, args.passes, out / "xn.bin"))
                if lex is not None:
                    times[name]["lexls"].append(solve(lex, dump, args.passes, out / "xl.bin"))
                    g = gap(dump, out / "xl.bin", out / "xn.bin")
                    gaps[name] = max(gaps.get(name, 0.0), g)
        sizes = {name: read(str(out / f"{name}.bin"))[0] for name, _ in PROBLEMS}
    flags = " ".join(["g++", "-O2", *march()])
    what = (
        f"{lexls_commit(lexls)} and the native engine's driver, both `{flags}`"
        if has_lexls
        else f"The native engine's driver, `{flags}`"
    )
    print(
        f"{what}; {args.runs} run(s) × {args.passes} pass(es) × {args.steps} moved steps; "
        "median µs per warm solve, the range over the runs; gap: the largest level-value gap "
        "of the two answers, relative to max(1, value):\n"
    )
    body = [
        (label, sizes[name], span(times[name]["lexls"], sig3), span(times[name]["native"], sig3),
         f"{gaps[name]:.1e}" if name in gaps else "–")
        for name, label in PROBLEMS
    ]  # fmt: skip
    print(markdown(("problem", "n", "LexLS warm", "qpcoord native", "gap"), body, "lrrrr"))
    if not has_lexls:
        print(
            f"\nLexLS skipped: no checkout at {lexls} (git clone "
            "https://github.com/jrl-umi3218/lexls there, or give --lexls DIR)."
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
