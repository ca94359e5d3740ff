"""Time of the DDL simulation: plant step, coordinator step, and a full 10 s run at 5 and 8 kHz.

    python benchmarks/ddl_bench.py            # 10 s runs at 5 and 8 kHz, 3 repeats (~10 s)
    python benchmarks/ddl_bench.py --quick    # 1 s runs, 1 repeat
    python benchmarks/ddl_bench.py --json rows.json

Prints its machine and command, then one row per rate: µs per step of the plant alone, of the
coordinator alone, of the whole closed loop inside ``qpcoord.ddl.simulate`` (plant +
controller + logging), the wall time of the run (median of the repeats) and the tracking
RMSE. The goal of chapter 6 is a 10 s run at 8 kHz in under 2 s (≈ 25 µs per step); this
script reports, it does not assert.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time

import qpcoord.ddl as ddl

try:
    from benchmarks._table import markdown, preamble
except ImportError:  # run as a script from benchmarks/
    from _table import markdown, preamble


def time_plant(fs: float, steps: int) -> float:
    """µs per plant step with constant direct-coil commands (median of 3 batches)."""
    plant = ddl.DualStage()
    out = []
    for _ in range(3):
        plant.reset(fs)
        a = plant.equilibrium_phase(1.5)
        ia, ib = 1.5 * math.sin(a), 1.5 * math.cos(a)
        step = plant.step
        t0 = time.perf_counter()
        for k in range(steps):
            step(5.0 + 1e-3 * (k & 7), ia, ib)
        out.append((time.perf_counter() - t0) / steps * 1e6)
    return statistics.median(out)


def time_controller(fs: float, steps: int) -> float:
    """µs per SisoCoordinator step on a frozen measurement (median of 3 batches)."""
    plant = ddl.DualStage()
    ctl = ddl.SisoCoordinator()
    out = []
    for _ in range(3):
        y = plant.reset(fs)
        ctl.reset(plant, fs, y, y)
        step = ctl.step
        t0 = time.perf_counter()
        for k in range(steps):
            step(y, y + 1e-9 * (k & 7))
        out.append((time.perf_counter() - t0) / steps * 1e6)
    return statistics.median(out)


def run(duration: float, rates, repeats: int) -> list[dict]:
    rows = []
    for fs in rates:
        n = int(round(duration * fs))
        r = ddl.kolmogorov_opd(duration, fs, seed=0, preset="paranal_250hz")
        walls = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            res = ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(), r, fs)
            walls.append(time.perf_counter() - t0)
        wall = statistics.median(walls)
        rows.append(
            {
                "fs_hz": fs,
                "duration_s": duration,
                "steps": n,
                "plant_us": time_plant(fs, min(n, 20000)),
                "controller_us": time_controller(fs, min(n, 20000)),
                "loop_us": res.metrics["wall_time"] / n * 1e6,
                "run_wall_s": wall,
                "rmse_nm": res.metrics["rmse"] * 1e9,
            }
        )
    return rows


def format_rows(rows, repeats: int) -> str:
    """Markdown table of :func:`run` rows, with the line that says what was timed."""
    head = ("fs (Hz)", "T (s)", "steps", "plant µs", "coordinator µs", "loop µs", "run (s)")
    body = [
        (f"{r['fs_hz']:.0f}", f"{r['duration_s']:.1f}", r["steps"], f"{r['plant_us']:.2f}",
         f"{r['controller_us']:.2f}", f"{r['loop_us']:.2f}", f"{r['run_wall_s']:.2f}",
         f"{r['rmse_nm']:.1f}")
        for r in rows
    ]  # fmt: skip
    title = (
        "`qpcoord.ddl.simulate` of the SISO coordinator on the Kolmogorov disturbance "
        f"(preset paranal_250hz, seed 0); run: the median wall time of {repeats} run(s); plant, "
        "coordinator: µs per step alone (median of 3 batches); loop: µs per step inside the run:"
    )
    return f"{title}\n\n" + markdown((*head, "RMSE nm"), body, "rrrrrrrr")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="1 s runs, 1 repeat")
    p.add_argument("--json", default=None, help="also write the rows to this JSON file")
    args = p.parse_args(argv)
    repeats = 1 if args.quick else 3
    rows = run(1.0 if args.quick else 10.0, (5000.0, 8000.0), repeats)
    print(preamble())
    print(format_rows(rows, repeats))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
