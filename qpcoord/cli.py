"""The ``qpcoord`` console command.

``qpcoord solvers``        installed QP backends, with versions, default first; the native build
``qpcoord demo``           a small end-to-end stack solve (3R arm tracking a circle)
``qpcoord bench stack``    per-step solve-time benchmark of 3-level stacks
``qpcoord bench ik``       Panda differential IK, qpcoord vs Pink, per-step times and errors
``qpcoord ddl track``      DDL coordinator on Kolmogorov OPD references, metrics per seed
``qpcoord ddl compare``    every DDL controller on the same cases: Table 6.1 and 6.2 forms
``qpcoord ddl design``     tune the coordinator for a recorded reference (REFERENCE.npy)
``qpcoord reproduce``      run the chapters' reproductions, write report.md / report.html
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["main"]


def _cmd_solvers(args: argparse.Namespace) -> int:
    from .core.backends import _DIRECT, default_solver, solver_versions

    versions = solver_versions()
    default = default_solver()
    print(f"{'solver':<10} {'version':<10} path")
    for name, version in versions.items():
        path = "direct (dense)" if name in _DIRECT else "qpsolvers"
        mark = "  <- default" if name == default else ""
        print(f"{name:<10} {version:<10} {path}{mark}")
    from .core import native

    build = native.variant()  # the build load() picks (QPCOORD_NATIVE_ISA overrides)
    if build is None:
        print("native engine: not built (the Python engine solves)")
    else:
        print(f"native engine: {build} ({native.VARIANTS[build][0]})")
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from .studies.demo import run_demo

    print(run_demo(solver=args.solver, steps=args.steps))
    return 0


def _cmd_bench(args: argparse.Namespace) -> int:
    from threadpoolctl import threadpool_limits

    from .studies.bench_stack import format_table, run_stack_bench

    solvers = [args.solver] if args.solver else None
    with threadpool_limits(limits=1):
        rows = run_stack_bench(steps=args.steps, solvers=solvers, quick=args.quick)
    print(format_table(rows))
    return 0


def _cmd_bench_ik(args: argparse.Namespace) -> int:
    from threadpoolctl import threadpool_limits

    from .studies.bench_ik import format_ik_table, pink_available, run_ik_bench

    if not pink_available():
        print("note: pin-pink is not installed (pip install 'qpcoord[bench]'): qpcoord rows only")
    scenarios = ("waypoints", "tight") if args.scenario == "both" else (args.scenario,)
    steps = 40 if args.quick else args.steps
    rows = []
    with threadpool_limits(limits=1):
        for scenario in scenarios:
            rows += run_ik_bench(steps=steps, solver=args.solver, scenario=scenario)
    print(format_ik_table(rows))
    return 0


def _cmd_ddl_track(args: argparse.Namespace) -> int:
    import time

    from . import ddl

    if args.seeds < 1:
        raise ValueError(f"--seeds must be >= 1, got {args.seeds}")
    print(
        f"SisoCoordinator, preset {args.preset!r}, {args.duration:g} s at {args.fs:g} Hz, "
        f"{args.seeds} seed(s)"
    )
    print(
        f"{'seed':>4} {'RMSE nm':>8} {'max nm':>7} {'mean nm':>8} {'P W':>6} "
        f"{'margin µm':>9} {'sat':>4} {'sync':>5} {'run s':>6}"
    )
    for seed in range(args.seeds):
        r = ddl.kolmogorov_opd(args.duration, args.fs, seed=seed, preset=args.preset)
        t0 = time.perf_counter()
        run = ddl.simulate(
            ddl.DualStage(),
            ddl.SisoCoordinator(),
            r,
            args.fs,
            seed=seed,
            progress=sys.stderr.isatty(),  # a \r progress line: terminals only
        )
        m = run.metrics
        print(
            f"{seed:4d} {m['rmse'] * 1e9:8.1f} {m['max_abs'] * 1e9:7.1f} "
            f"{m['mean_abs'] * 1e9:8.1f} {m['power']:6.2f} {m['fine_margin_min'] * 1e6:9.2f} "
            f"{m['saturated_steps']:4d} {'LOST' if m['lost_sync'] else 'ok':>5} "
            f"{time.perf_counter() - t0:6.2f}"
        )
    return 0


def _cmd_ddl_design(args: argparse.Namespace) -> int:
    from pathlib import Path

    import numpy as np

    from . import ddl

    r = np.load(args.reference, allow_pickle=False)
    plant = ddl.DualStage()
    check = ddl.check_reference(r, args.fs, plant)
    print(f"reference: {r.size} samples at {args.fs:g} Hz; check: {check.verdict} — {check.reason}")
    ctl, rep = ddl.design_coordinator(r, args.fs, plant)
    print(rep.summary())
    seeds = (2001, 2002, 2003)
    runs = []
    for seed in seeds:
        fresh = rep.psd.synthesize(args.duration, args.fs, seed=seed)
        runs.append(ddl.simulate(plant, ctl, fresh, args.fs, seed=seed))
    ms = [run.metrics for run in runs]
    print(
        f"fresh seeds {seeds}, {args.duration:g} s: RMSE "
        + ", ".join(f"{m['rmse'] * 1e9:.1f}" for m in ms)
        + " nm; min margin "
        + ", ".join(f"{m['fine_margin_min'] * 1e6:.2f}" for m in ms)
        + " µm; saturated "
        + ", ".join(str(m["saturated_steps"]) for m in ms)
    )
    from .studies.figures import _pyplot, save

    plt = _pyplot()
    run = ddl.simulate(plant, ctl, r, args.fs)
    fp = plant.fine
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    ax[0].plot(run.t, run.y_f * 1e6, lw=0.6, label="fine stage")
    for lim in (fp.stroke_min, fp.stroke_max):
        ax[0].axhline(lim * 1e6, color="k", lw=1)
    for lim in (fp.stroke_min + rep.margin, fp.stroke_max - rep.margin):
        ax[0].axhline(lim * 1e6, color="r", ls="--", lw=0.8)
    ax[0].set(xlabel="t (s)", ylabel="y_f (µm)", title="fine stage vs its stroke (margin dashed)")
    f = rep.psd.f
    ax[1].loglog(f, rep.psd.S, lw=0.8, label="reference PSD")
    e = run.error
    w = np.hanning(e.size)
    pe = 2.0 * np.abs(np.fft.rfft((e - e.mean()) * w)) ** 2 / (args.fs * np.sum(w * w))
    fe = np.fft.rfftfreq(e.size, 1.0 / args.fs)
    ax[1].loglog(fe[1:], pe[1:], lw=0.5, label="error (this record)")
    ax[1].set(xlabel="f (Hz)", ylabel="m²/Hz", title="error spectrum vs reference PSD")
    ax[1].legend(fontsize=8)
    out = save(fig, Path(args.out) / "ddl_design.png")
    print(f"figure: {out}")
    return 0 if rep.met else 1


def _cmd_ddl_compare(args: argparse.Namespace) -> int:
    from threadpoolctl import threadpool_limits

    from .ddl.compare import compare, default_controllers, format_grid, format_table

    if args.seeds < 1:
        raise ValueError(f"--seeds must be >= 1, got {args.seeds}")
    duration, step_duration = (1.0, 3.0) if args.quick else (args.duration, 6.0)
    with threadpool_limits(limits=1):
        rows = compare(
            default_controllers(),
            seeds=tuple(range(args.seeds)),
            duration=duration,
            fs=args.fs,
            step_duration=step_duration,
            progress=sys.stderr.isatty(),
        )
    print(format_table(rows))
    print()
    print(format_grid(rows))
    return 0


def _cmd_reproduce(args: argparse.Namespace) -> int:
    from .studies.claims import CLAIM_STATUSES
    from .studies.reproduce import ExamplesNotFoundError, run

    try:
        report = run(
            chapters=args.chapters or None,
            out=args.out,
            quick=args.quick,
            jobs=args.jobs,
            timeout=args.timeout,
            examples_dir=args.examples,
            progress=not args.no_progress,
            bench=not args.no_bench,
        )
    except ExamplesNotFoundError as exc:
        print(f"qpcoord: error: {exc}", file=sys.stderr)
        return 2
    c = report.counts
    print(f"{'script':<22} {'chapter':<7} {'status':<8} {'wall s':>7} {'CPU s':>7}")
    for r in sorted(report.results, key=lambda r: -r.seconds):
        cpu = "-" if r.cpu_seconds is None else f"{r.cpu_seconds:.1f}"
        print(f"{r.name:<22} {r.chapter:<7} {r.status:<8} {r.seconds:7.1f} {cpu:>7}")
    print(
        f"{c['ok']} of {c['scripts']} scripts ran in {report.seconds:.1f} s; claims: "
        + ", ".join(f"{c[s]} {s}" for s in CLAIM_STATUSES)
        + " (thesis claims, each ID counted once)"
    )
    for r in report.failed:
        print(f"  {r.name}: {r.status}: {r.error}", file=sys.stderr)
    print(f"report: {report.markdown}\n        {report.html}")
    return 0 if report.ok else 1


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``qpcoord`` command."""
    commands = "\n".join(
        line.replace("``", "") for line in __doc__.splitlines() if line.startswith("``qpcoord")
    )
    p = argparse.ArgumentParser(
        prog="qpcoord",
        description="qpcoord: over-actuated systems coordinated by prioritised QP stacks.",
        epilog="commands:\n" + commands + "\n\nStart with: qpcoord reproduce --quick",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("solvers", help="list installed QP backends with versions")
    s.set_defaults(func=_cmd_solvers)
    d = sub.add_parser("demo", help="small end-to-end stack solve with a readable report")
    d.add_argument("--solver", default=None, help="QP backend (default: fastest installed)")
    d.add_argument("--steps", type=int, default=400, help="control steps (default 400)")
    d.set_defaults(func=_cmd_demo)
    b = sub.add_parser("bench", help="benchmarks")
    bsub = b.add_subparsers(dest="bench", required=True)
    bs = bsub.add_parser("stack", help="per-step solve time of 3-level stacks (n = 7, 30)")
    bs.add_argument("--quick", action="store_true", help="a few seconds, for smoke tests")
    bs.add_argument("--steps", type=int, default=1000, help="steps per case (default 1000)")
    bs.add_argument("--solver", default=None, help="only this backend")
    bs.set_defaults(func=_cmd_bench)
    bi = bsub.add_parser("ik", help="Panda differential IK: qpcoord vs Pink (per-step µs, errors)")
    bi.add_argument("--quick", action="store_true", help="40 steps, for smoke tests")
    bi.add_argument("--steps", type=int, default=2000, help="steps per controller (default 2000)")
    bi.add_argument("--solver", default="daqp", help="QP backend for all (default daqp)")
    bi.add_argument(
        "--scenario", choices=("waypoints", "tight", "both"), default="both", help="motion"
    )
    bi.set_defaults(func=_cmd_bench_ik)
    dd = sub.add_parser("ddl", help="chapter 6 dual-stage delay line")
    dsub = dd.add_subparsers(dest="ddl", required=True)
    dt = dsub.add_parser("track", help="coordinator on Kolmogorov OPD: RMSE, power, margins")
    dt.add_argument("--seeds", type=int, default=3, help="references (seeds 0…N-1, default 3)")
    dt.add_argument("--duration", type=float, default=10.0, help="seconds (default 10)")
    dt.add_argument("--fs", type=float, default=8000.0, help="control rate, Hz (default 8000)")
    dt.add_argument("--preset", default="paranal_250hz", help="reference preset")
    dt.set_defaults(func=_cmd_ddl_track)
    dc = dsub.add_parser("compare", help="every controller on the same cases (Table 6.1/6.2)")
    dc.add_argument("--quick", action="store_true", help="1 s tracking, 3 s steps")
    dc.add_argument("--seeds", type=int, default=1, help="Kolmogorov seeds (default 1)")
    dc.add_argument("--duration", type=float, default=10.0, help="tracking seconds (10)")
    dc.add_argument("--fs", type=float, default=8000.0, help="control rate, Hz (8000)")
    dc.set_defaults(func=_cmd_ddl_compare)
    dg = dsub.add_parser("design", help="tune the coordinator for a reference (.npy, metres)")
    dg.add_argument("reference", help="1-D .npy file of the reference, m")
    dg.add_argument("--fs", type=float, default=8000.0, help="its sampling rate, Hz (8000)")
    dg.add_argument("--out", default=".", help="folder of the figure (default .)")
    dg.add_argument("--duration", type=float, default=2.0, help="fresh-seed runs, s (2)")
    dg.set_defaults(func=_cmd_ddl_design)
    rp = sub.add_parser("reproduce", help="run the thesis reproductions, write one report")
    rp.add_argument(
        "chapters", nargs="*", help="core, 4, 5, 6, A, B, C (also ch4, appA...; default: all)"
    )
    rp.add_argument("--out", default="reproduce-out", help="output folder (reproduce-out)")
    rp.add_argument("--quick", action="store_true", help="short runs (CI, < 2 min on 2 cores)")
    rp.add_argument("--jobs", type=int, default=None, help="scripts at once (default: cores)")
    rp.add_argument("--timeout", type=float, default=None, help="s per script (300 / 3600)")
    rp.add_argument("--examples", default=None, help="examples folder (default: the repo's)")
    rp.add_argument("--no-bench", action="store_true", help="skip the solver comparison")
    rp.add_argument("--no-progress", action="store_true", help="no progress bar")
    rp.set_defaults(func=_cmd_reproduce)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``qpcoord`` console script."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except ValueError as exc:
        print(f"qpcoord: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
