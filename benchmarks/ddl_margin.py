"""Coarse-loop gain margin of the DDL coordinator: predicted (linear model) vs measured on the
simulated plant, over a grid of coarse bandwidths.

    python benchmarks/ddl_margin.py            # 10 bandwidths × 3 carriage positions
    python benchmarks/ddl_margin.py --quick    # 3 bandwidths

Per bandwidth: the gain margin that ``SisoCoordinator.reset`` and ``design_coordinator`` use
(``loops.coarse_gain_margin``, the smallest over the carriage's operating points) and, at the
stroke centre, half a full step from it (the detent's softest point) and next to a stroke
end, the margin predicted there and the one measured by ``stability.simulated_coarse_margin``
(coarse gain raised until the kicked carriage mode grows; friction and quantisation off).
The last column is the carriage's ringing with friction on (the plant as simulated), on a
100 µm/s ramp from the stroke centre: rms of y_c band-passed at 0.5–2× the carriage mode over
the last second of 1.5 s — a friction-bounded limit cycle where the margin is < 1. Reports,
does not assert.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy import signal

import qpcoord.ddl as ddl
from qpcoord.ddl.loops import _gain_margin_at, coarse_gain_margin, coarse_operating_points
from qpcoord.ddl.stability import simulated_coarse_margin

try:
    from benchmarks._table import markdown, preamble
except ImportError:  # run as a script from benchmarks/
    from _table import markdown, preamble

FS = 8000.0


def ramp_ringing(bandwidth: float, speed: float = 1.0e-4, duration: float = 1.5) -> float:
    """rms (m) of the carriage's motion around its mode on a ramp, friction on."""
    plant = ddl.DualStage()
    n = int(duration * FS)
    r = speed * np.arange(n) / FS
    y = plant.reset(FS, 0.0)
    ctl = ddl.SisoCoordinator(coarse_bandwidth=bandwidth)
    ctl.reset(plant, FS, y, 0.0, check_margin=False)
    yc = np.empty(n)
    for k in range(n):
        y = plant.step(*ctl.step(y, r[k]))
        yc[k] = plant.y_c
    f0 = plant.coarse_resonance(0.0)
    sos = signal.butter(2, [0.5 * f0, 2.0 * f0], "bandpass", fs=FS, output="sos")
    band = signal.sosfiltfilt(sos, yc)
    return float(np.std(band[-int(FS) :]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 bandwidths instead of 10")
    args = ap.parse_args(argv)
    bws = (1.0, 4.0, 6.0) if args.quick else (0.5, 1.0, 2.0, 3.0, 4.0, 4.4, 5.0, 6.0, 8.0, 12.0)
    plant = ddl.DualStage()
    pts = {"centre": 0.0, "softest": coarse_operating_points(plant)[0]}
    pts["end"] = coarse_operating_points(plant)[1]
    print(preamble())
    print(
        f"The default DualStage at {FS:g} Hz; per carriage position, the gain margin "
        "predicted / simulated (their difference); ringing: rms of the carriage mode on a "
        "100 µm/s ramp, friction on:\n"
    )
    head = ["f_bw (Hz)", "margin used (dB)"]
    head += [f"{name} ({y * 1e3:+.3f} mm)" for name, y in pts.items()]
    head += ["ringing (nm)"]
    body = []
    for bw in bws:
        ctl = ddl.SisoCoordinator(coarse_bandwidth=bw)
        gm = coarse_gain_margin(ctl, plant, FS, n=4000)[0]
        row = [f"{bw:g}", f"{20 * np.log10(gm):+.2f}"]
        for y in pts.values():
            pred = _gain_margin_at(ctl, plant, FS, 4000, y)[0]
            meas = simulated_coarse_margin(plant, FS, bw, y_c=y)
            row.append(f"{pred:.3f} / {meas:.3f} ({100 * (meas / pred - 1):+.1f} %)")
        row.append(f"{ramp_ringing(bw) * 1e9:.1f}")
        body.append(row)
    print(markdown(head, body, "r" * len(head)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
