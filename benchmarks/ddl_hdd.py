"""Per-period cost of the HDD benchmark's designed controller against its 19.84 µs period.

    python benchmarks/ddl_hdd.py [--data DIR] [--repeats 3]

Designs the benchmark's LQG (``qpcoord.ddl.benchmarks.hdd.design_controller``, about 40 s),
reduces it (``hdd.reduced_controller``) and times one controller update per period in the
forms a real-time loop would run:

* the observer form with clipping (``law.step``: estimate, gain, clip to range and rate),
  numpy, full order;
* the state-space form ``u = C x + D e; x ← A x + B e`` with preallocated buffers, numpy,
  full and reduced order;
* the reduced law in modal form (complex diagonal ``A``), run by scipy's compiled
  ``lfilter`` one first-order mode at a time over a whole record: the throughput of a
  compiled loop (per sample), not a call per period — the reference for a C implementation.

µs per step: median over batches of 1000 steps, the range over ``--repeats`` runs. Flops per
step: dense ``2n² + 6n + 4``; modal ``6`` per real and ``12`` per complex mode, ``+ 4``. Reports,
does not assert.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from scipy import signal

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks._table import markdown, preamble, span  # noqa: E402
from qpcoord.ddl.benchmarks import hdd  # noqa: E402

BATCH = 1000


def _errors(n: int) -> np.ndarray:
    return 1e-9 * np.random.default_rng(0).standard_normal(n)


def time_observer(law, n: int) -> float:
    """Median µs of ``law.step(e)`` over batches."""
    law.reset()
    e = _errors(n)
    out = []
    for k in range(0, n, BATCH):
        t0 = time.perf_counter()
        for x in e[k : k + BATCH]:
            law.step(x)
        out.append((time.perf_counter() - t0) / BATCH * 1e6)
    law.reset()
    return statistics.median(out)


def time_state_space(ss, n: int) -> float:
    """Median µs of ``u = C x + D e; x ← A x + B e`` (numpy, preallocated) over batches."""
    a, b, c, d, _ = (np.ascontiguousarray(x, dtype=float) for x in ss)
    b, d = b[:, 0].copy(), d[:, 0].copy()
    x, xn, u = np.zeros(a.shape[0]), np.zeros(a.shape[0]), np.zeros(2)
    e = _errors(n)
    out = []
    for k in range(0, n, BATCH):
        t0 = time.perf_counter()
        for ek in e[k : k + BATCH]:
            np.dot(c, x, out=u)
            u += d * ek
            np.dot(a, x, out=xn)
            xn += b * ek
            x, xn = xn, x
        out.append((time.perf_counter() - t0) / BATCH * 1e6)
    return statistics.median(out)


def modal(ss):
    """``ss`` with ``A`` diagonalised: (eigenvalues, B, C, D) of one mode per complex-conjugate
    pair (the pair's output is twice the real part) and per real eigenvalue."""
    a, b, c, d, _ = ss
    lam, v = np.linalg.eig(a)
    bm = np.linalg.solve(v, b)[:, 0]
    cm = c @ v
    keep = lam.imag >= 0.0  # one of each conjugate pair
    w = np.where(lam.imag > 0.0, 2.0, 1.0)
    return lam[keep], bm[keep], cm[:, keep] * w[keep][None, :], d[:, 0]


def time_modal_lfilter(ss, n: int) -> tuple[float, float]:
    """µs per sample of the modal form through ``lfilter`` over a record of ``n`` samples,
    and the largest deviation from the state-space form's output (relative to its peak)."""
    lam, bm, cm, d = modal(ss)
    e = _errors(n)
    ec = e.astype(complex)
    t0 = time.perf_counter()
    u = np.outer(d, e)
    for li, bi, ci in zip(lam, bm, cm.T, strict=True):
        x = signal.lfilter([0.0, bi], [1.0, -li], ec)
        u += np.outer(ci, x).real
    dt = (time.perf_counter() - t0) / n * 1e6
    a, b, c, dd, _ = ss
    xs = np.zeros(a.shape[0])
    ref = np.empty((2, 2000))
    for k in range(2000):
        ref[:, k] = c @ xs + dd[:, 0] * e[k]
        xs = a @ xs + b[:, 0] * e[k]
    dev = float(np.max(np.abs(u[:, :2000] - ref)) / np.max(np.abs(ref)))
    return dt, dev


def flops_dense(n: int) -> int:
    return 2 * n * n + 6 * n + 4


def flops_modal(ss) -> int:
    lam = modal(ss)[0]
    n_complex = int(np.sum(lam.imag > 0.0))
    return 6 * (lam.size - n_complex) + 12 * n_complex + 4


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="../shared/data/hdd", help="benchmark data directory")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=20000)
    args = ap.parse_args()
    bench = hdd.load(args.data)
    law = hdd.design_controller(bench)
    full = law.state_space()
    red = hdd.reduced_controller(law)
    n_full, n_red = full[0].shape[0], red[0].shape[0]
    runs: dict[str, list[float]] = {k: [] for k in ("obs", "ss_full", "ss_red", "modal")}
    dev = 0.0
    for _ in range(args.repeats):
        runs["obs"].append(time_observer(law, args.steps))
        runs["ss_full"].append(time_state_space(full, args.steps))
        runs["ss_red"].append(time_state_space(red, args.steps))
        t, dev = time_modal_lfilter(red, 20 * args.steps)
        runs["modal"].append(t)
    ts = bench.Ts * 1e6
    rows = [
        (
            "observer form with clipping (`law.step`), numpy",
            n_full,
            flops_dense(n_full) + 8 * n_full,
            runs["obs"],
        ),
        ("state space, numpy", n_full, flops_dense(n_full), runs["ss_full"]),
        ("state space, numpy, reduced", n_red, flops_dense(n_red), runs["ss_red"]),
        (
            "modal, reduced, compiled `lfilter` (per sample of a record)",
            n_red,
            flops_modal(red),
            runs["modal"],
        ),
    ]
    print(preamble())
    print()
    print(
        markdown(
            ("form", "order", "flops/step", "µs/step", "% of Ts"),
            [
                (name, n, f, span(v, "{:.2f}"), span([100 * x / ts for x in v], "{:.0f}"))
                for name, n, f, v in rows
            ],
            "lrrrr",
        )
    )
    print()
    print(
        f"Ts = {ts:.2f} µs; the modal form's output agrees with the state-space form's to "
        f"{dev:.1e} of its peak; {args.repeats} runs of {args.steps} steps."
    )


if __name__ == "__main__":
    main()
