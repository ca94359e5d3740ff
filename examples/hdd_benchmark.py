"""The IEEJ HDD dual-stage benchmark: the reference controller and one designed with qpcoord.

    python examples/hdd_benchmark.py [--data DIR] [--save PATH]

Loads the benchmark's numbers from DIR (default ``../shared/data/hdd``), evaluates the
benchmark's reference controller, an LQG designed by
``qpcoord.ddl.benchmarks.hdd.design_controller`` (its models only, no evaluation seed) and
that LQG reduced by balanced truncation (``hdd.reduced_controller``) on the nine plant cases
with the benchmark's own evaluation (1.1 s, 120 revolutions), and prints 3σ (% of the track
pitch), max |y_cp| (nm, PZT stroke 50 nm) and the peak sensitivity (dB, 2000 frequencies)
per case, with the orders and the cost of an update per period. With ``--save PATH`` the
reduced controller is written as one discrete system at Ts from the measured error
e = −y + d_RRO (m) to (u_vcm, u_pzt) — the benchmark's C_d, used with its multirate filters
F_m — as an ``.npz`` with ``A``, ``B``, ``C`` (2 rows), ``D`` (2 × 1), ``Ts``.
Takes about two minutes (design ≈ 30 s, 27 evaluations ≈ 2 s each).
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from qpcoord.ddl import sensitivity
from qpcoord.ddl.benchmarks import hdd


class _Law:
    def __init__(self, ss):
        self._ss = ss

    def state_space(self):
        return self._ss


def peak_db(bench, ss, case: int) -> float:
    plant = hdd.linear_plant(bench, case, disturbance_models=False)
    f = np.geomspace(10.0, 0.499 / bench.Ts, 2000)
    return float(20.0 * np.log10(np.max(np.abs(sensitivity(plant, _Law(ss), f)))))


def step_cost(law, n: int = 20000) -> float:
    """Median µs of one ``law.step(e)`` (observer form, numpy), batches of 1000."""
    law.reset()
    e = 1e-9 * np.random.default_rng(0).standard_normal(n)
    out = []
    for k in range(0, n, 1000):
        t0 = time.perf_counter()
        for x in e[k : k + 1000]:
            law.step(x)
        out.append((time.perf_counter() - t0) / 1000 * 1e6)
    law.reset()
    return float(np.median(out))


def ss_cost(ss, n: int = 20000) -> float:
    """Median µs of the real-time form ``u = C x + D e; x ← A x + B e`` (numpy, preallocated
    buffers), batches of 1000."""
    a, b, c, d, _ = (np.ascontiguousarray(x, dtype=float) for x in ss)
    b, d = b[:, 0].copy(), d[:, 0].copy()
    x, xn, u = np.zeros(a.shape[0]), np.zeros(a.shape[0]), np.zeros(2)
    e = 1e-9 * np.random.default_rng(0).standard_normal(n)
    out = []
    for k in range(0, n, 1000):
        t0 = time.perf_counter()
        for ek in e[k : k + 1000]:
            np.dot(c, x, out=u)
            u += d * ek
            np.dot(a, x, out=xn)
            xn += b * ek
            x, xn = xn, x
        out.append((time.perf_counter() - t0) / 1000 * 1e6)
    return float(np.median(out))


def save(path: Path, ss) -> None:
    """Write the controller atomically (no half-written file)."""
    a, b, c, d, ts = ss
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=".npz", dir=path.parent)
    os.close(fd)
    try:
        np.savez(tmp, A=a, B=b, C=c, D=d, Ts=np.float64(ts))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="../shared/data/hdd", help="benchmark data directory")
    ap.add_argument("--save", default=None, help="write the designed controller (.npz)")
    args = ap.parse_args()
    bench = hdd.load(args.data)
    t0 = time.perf_counter()
    law = hdd.design_controller(bench)
    full = law.state_space()
    reduced = hdd.reduced_controller(law)
    t_design = time.perf_counter() - t0
    reference = hdd.reference_controller(bench)
    print(f"# {platform.machine()}, Python {platform.python_version()}; data {args.data}")
    print(
        f"designed LQG: order {full[0].shape[0]}, reduced to {reduced[0].shape[0]} "
        f"(balanced truncation), designed in {t_design:.1f} s, measurement noise "
        f"{law.scales['measurement_noise']:.3g} m; update per period, numpy: "
        f"{step_cost(law):.1f} µs (observer form with clipping), {ss_cost(full):.1f} µs "
        f"(state-space form), {ss_cost(reduced):.1f} µs (reduced); Ts = {bench.Ts * 1e6:.2f} µs"
    )
    laws = (("reference", reference), ("LQG", full), ("reduced", reduced))
    head = "| case |" + "".join(
        f" {n} 3σ % | max \\|y_cp\\| nm | peak \\|S\\| dB |" for n, _ in laws
    )
    print(head)
    print("|---|" + "---|---|---|" * len(laws))
    worst = {n: 0.0 for n, _ in laws}
    ok = {n: True for n, _ in laws}
    for case in hdd.CASES:
        row = f"| {case} |"
        for name, ss in laws:
            r = hdd.evaluate(bench, ss, case)
            worst[name] = max(worst[name], r["sigma3_pct"])
            pk = peak_db(bench, ss, case)
            ok[name] &= r["pzt_ok"] and pk <= 6.0
            row += f" {r['sigma3_pct']:.2f} | {r['pzt_max'] * 1e9:.2f} | {pk:.2f} |"
        print(row, flush=True)
    for name, _ in laws[1:]:
        met = "met" if worst[name] <= 7.0 else "NOT met"
        print(
            f"{name}: worst 3σ {worst[name]:.2f} % (goal 7 %: {met}; reference "
            f"{worst['reference']:.2f} %, published 14.54 %); PZT inside 50 nm and peak |S| "
            f"<= 6 dB on every case: {'yes' if ok[name] else 'NO'}"
        )
    if args.save:
        save(Path(args.save), reduced)
        print(f"wrote {args.save} (the reduced law, order {reduced[0].shape[0]})")


if __name__ == "__main__":
    main()
