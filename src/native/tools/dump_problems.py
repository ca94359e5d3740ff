"""Dump the benchmarks' stacks for the C++ driver: hierarchy_bench's scenarios (panda9,
random50, chain30, talos) and the published problems of hierarchy_published's re-solve table
(the LexLS humanoid, its box form, soth_sot; each moved as that table's ``moved`` steps).

    python src/native/tools/dump_problems.py OUT_DIR [--steps N] [--only NAME ...]

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

ROOT = pathlib.Path(__file__).resolve().parents[3]
sys.path[:0] = [str(ROOT / "benchmarks"), str(ROOT / "tests"), str(ROOT / "tests" / "core")]
import hierarchy_bench as hb  # noqa: E402
import hierarchy_published as hp  # noqa: E402
from support.hlsp import load  # noqa: E402

import qpcoord as qc  # noqa: E402
from qpcoord.core.native import NativeHierarchy  # noqa: E402

#: Published problems dumped beside hierarchy_bench's scenarios: (file stem, box form).
PUBLISHED = {
    "humanoid": ("lexls_test01_humanoid", False),
    "humanoid_box": ("lexls_test01_humanoid", True),
    "soth_sot": ("soth_sot", False),
}
#: Their ``(unit rows)`` copies (each row and its bounds divided by the row's norm, as
#: hierarchy_published's table): file stem -> the PUBLISHED entry.
UNIT_ROWS = {"humanoid_unit": "humanoid", "humanoid_box_unit": "humanoid_box"}


def published(name: str) -> tuple[qc.Stack, object]:
    """(stack, move(step, x)) of a published problem of :data:`PUBLISHED`."""
    unit = name in UNIT_ROWS
    stem, box = PUBLISHED[UNIT_ROWS.get(name, name)]
    prob = load(stem, simple_as_bounds=box)
    levels = hp.unit_rows(prob.levels) if unit else prob.levels
    mover = hp._mover(levels)
    return qc.Stack(levels, bounds=prob.bounds), lambda step, x=None: mover(step)


def dump(name, build, steps, out: pathlib.Path) -> None:
    """Dump a hierarchy_bench-style builder's scenario (``build(rng)``, seed 0)."""
    sc = hb._scenario(build, np.random.default_rng(0))
    dump_stack(name, sc["stack"], sc["move"], steps, out)


def dump_stack(name, stack, move, steps, out: pathlib.Path) -> None:
    """Dump ``steps`` steps of ``stack``, moved by ``move(step, x)`` before each."""
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
    names = [*hb.SCENARIOS, *PUBLISHED, *UNIT_ROWS]
    ap.add_argument("--only", action="append", choices=names, help="these problems only")
    a = ap.parse_args()
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    for name in a.only or names:
        if name in PUBLISHED or name in UNIT_ROWS:
            dump_stack(name, *published(name), a.steps, out)
        else:
            dump(name, hb.SCENARIOS[name][1], a.steps, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
