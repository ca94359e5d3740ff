"""Dump the benchmark's stacks (panda9, random50, chain30, talos) for the C++ driver.

    python src/native/tools/dump_problems.py OUT_DIR [--steps N]

Each file ``<name>.bin`` holds, in native-endian int64 / float64: n, blocks, has_bounds,
damping (float64), steps, meq[blocks], min[blocks], then per step the stacked arrays Aeq, beq,
C, lo, hi, sw, lb, ub (row-major): the compiled stack's stacked arrays, which the native solver
is bound to. Used to profile the native core without Python (``driver.cpp``).
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[3] / "benchmarks"))
import hierarchy_bench as hb  # noqa: E402

from qpcoord.core.native import NativeHierarchy  # noqa: E402


def dump(name, build, steps, out: pathlib.Path) -> None:
    rng = np.random.default_rng(0)
    sc = hb._scenario(build, rng)
    stack, move = sc["stack"], sc["move"]
    P = stack._compiled
    h = NativeHierarchy(P, stack.damping)
    blocks = [P.hard, *P.levels]
    with open(out / f"{name}.bin", "wb") as f:
        head = [h.n, len(blocks), int(P.bounds is not None)]
        f.write(np.array(head, dtype=np.int64).tobytes())
        f.write(np.array([stack.damping], dtype=np.float64).tobytes())
        f.write(np.array([steps], dtype=np.int64).tobytes())
        f.write(np.array([B.m_eq for B in blocks], dtype=np.int64).tobytes())
        f.write(np.array([B.m_in for B in blocks], dtype=np.int64).tobytes())
        x = None
        for step in range(steps):
            move(step, x)
            x, _, _ = h.solve(P)  # fills the compiled stack's stacked arrays
            for a in (P.Aeq, P.beq, P.C, P.clo, P.chi, P.csw, P.lbs, P.ubs):
                f.write(np.ascontiguousarray(a, dtype=np.float64).tobytes())


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--steps", type=int, default=50)
    a = ap.parse_args()
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, (_label, build) in hb.SCENARIOS.items():
        dump(name, build, a.steps, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
