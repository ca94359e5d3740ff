"""Compare LexLS's solutions with qpcoord's on the dumped problems (``lexls_driver.cpp``).

    python benchmarks/lexls/compare.py FILE.bin X_LEXLS.bin X_QPCOORD.bin

Both x files hold one x per solve (float64, the drivers' XOUT); the first ``steps`` solves
(one pass) are compared. Prints, per level, the largest gap between the two level values
(``‖Aeq x − beq‖² + ‖sw·viol(C x)‖²`` of that level, relative to ``max(1, value)``), the
largest bound and hard-row violation of each, and the largest ``|Δx|``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the benchmarks' table writer
from _table import markdown, preamble  # noqa: E402


def read(path: str):
    with open(path, "rb") as fh:
        raw = fh.read()
    head = np.frombuffer(raw[:24], dtype=np.int64)
    n, blocks, has_bounds = (int(v) for v in head)
    steps = int(np.frombuffer(raw[32:40], dtype=np.int64)[0])
    off = 40
    meq = np.frombuffer(raw[off : off + 8 * blocks], dtype=np.int64).astype(int)
    off += 8 * blocks
    mi = np.frombuffer(raw[off : off + 8 * blocks], dtype=np.int64).astype(int)
    off += 8 * blocks
    data = np.frombuffer(raw[off:], dtype=np.float64)
    me, mn = int(meq.sum()), int(mi.sum())
    per = me * n + me + mn * n + 3 * mn + 2 * n
    out = []
    for s in range(steps):
        p = data[per * s : per * (s + 1)]
        parts, k = [], 0
        for size in (me * n, me, mn * n, mn, mn, mn, n, n):
            parts.append(p[k : k + size])
            k += size
        Aeq, beq, C, lo, hi, sw, lb, ub = parts
        out.append((Aeq.reshape(me, n), beq, C.reshape(mn, n), lo, hi, sw, lb, ub))
    return n, meq, mi, bool(has_bounds), out


def values(meq, mi, prob, x):
    Aeq, beq, C, lo, hi, sw, lb, ub = prob
    req = Aeq @ x - beq
    cx = C @ x
    viol = sw * (np.maximum(lo - cx, 0.0) + np.maximum(cx - hi, 0.0))
    vals, e, i = [], 0, 0
    for b in range(len(meq)):
        re_, vi = req[e : e + meq[b]], viol[i : i + mi[b]]
        vals.append(float(re_ @ re_ + vi @ vi))
        e += meq[b]
        i += mi[b]
    box = max(float(np.max(lb - x, initial=0.0)), float(np.max(x - ub, initial=0.0)))
    return np.array(vals), box


def main() -> int:
    dump, xa, xb = sys.argv[1:4]
    n, meq, mi, _, probs = read(dump)
    XA = np.fromfile(xa).reshape(-1, n)[: len(probs)]
    XB = np.fromfile(xb).reshape(-1, n)[: len(probs)]
    gaps = np.zeros(len(meq))
    box_a = box_b = dx = 0.0
    for prob, a, b in zip(probs, XA, XB, strict=True):
        va, ba = values(meq, mi, prob, a)
        vb, bb = values(meq, mi, prob, b)
        gaps = np.maximum(gaps, np.abs(va - vb) / np.maximum(1.0, np.maximum(va, vb)))
        box_a, box_b = max(box_a, ba), max(box_b, bb)
        dx = max(dx, float(np.abs(a - b).max()))
    print(preamble() + "\n")
    head = ("level (0 = hard)", "largest gap, relative to max(1, value)")
    print(markdown(head, [(i, f"{g:.2g}") for i, g in enumerate(gaps)], "rr"))
    print(f"\nBound violation: first {box_a:.2g}, second {box_b:.2g}; largest |Δx| {dx:.3g}.")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
