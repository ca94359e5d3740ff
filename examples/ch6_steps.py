"""Chapter 6, Fig 6.19: 5000 µm steps at the centre of the stroke and towards its end.

The thesis coordinator (``SisoCoordinator``) on the DDL plant at 8 kHz: a 5 mm reference step
at the centre (−2.5 → +2.5 mm, no flexure load) and towards the extremity (27.5 → 32.5 mm,
flexure load ≈ 118 → 139 N). The rate limit of the field phase (Eq 6.1, 3 mm/s by default)
turns the step into a ramp of the carriage, as in the thesis ("the input saturation is
present by imposing a ramp"). During the move the 30 µm piezo necessarily saturates — that is
reported (saturated steps), not an error; the stepper must stay synchronised.

Reported: time to come within 100 nm and 10 nm of the final value for good, lost
synchronism, saturated steps, final error.

Run: ``python examples/ch6_steps.py [--quick] [--out DIR]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import qpcoord.ddl as ddl
from qpcoord.ddl.references import fig619_steps
from qpcoord.studies.claims import QUICK, claim
from qpcoord.studies.files import TextLog, write_json

FS = 8000.0


def settle_time(run, tol: float, t0: float) -> float:
    """Time after ``t0`` (s) from which |error| stays below ``tol`` (m); inf if never."""
    bad = np.flatnonzero(np.abs(run.error) > tol)
    if bad.size == 0:
        return 0.0
    if bad[-1] == run.error.size - 1:
        return float("inf")
    return float(run.t[bad[-1] + 1] - t0)


def step_claims(rows: dict, duration: float, t0: float, quick: bool) -> list[dict]:
    """Claim rows (``qpcoord.studies.claims.claim``) for Fig 6.19 from the two step cases.

    A step "is followed" when the stepper never loses synchronism and the output comes
    within 100 nm for good with at least 0.5 s of the run left to see it hold.
    """
    hold = 0.5  # s of the run that must remain after settling
    out = []
    centre = rows["centre"]["settle_100nm_s"]
    for name, fig in (("centre", "6.19a"), ("extremity", "6.19b")):
        rw = rows[name]
        settled = rw["settle_100nm_s"] <= duration - t0 - hold
        ok = settled and not rw["lost_sync"]
        if name == "extremity":
            ok = ok and rw["settle_100nm_s"] <= 1.25 * centre
        # a --quick run (2.5 s) cannot show the output stays within 100 nm over the full
        # run's 4 s: only a lost synchronism (final in any run) decides it
        if rw["lost_sync"]:
            st = "differs"
        elif quick:
            st = QUICK
        else:
            st = "reproduced" if ok else "differs"
        crit = (
            "Criterion: no lost synchronism and within 100 nm for good, with ≥ 0.5 s of run "
            "left after settling"
            + (
                ", settling no more than 25 % later than at the centre."
                if name == "extremity"
                else "."
            )
        )
        why = {
            "reproduced": "",
            QUICK: f" This --quick run ({duration:g} s) cannot show the output holds over "
            "the full run's 4 s; the full run decides.",
            "differs": " The step was not followed as the thesis reports (see measured).",
        }[st]
        where = (
            "at the centre of the stroke (no flexure load)"
            if name == "centre"
            else "towards the end of the stroke (flexure load ≈ 118 → 139 N)"
        )
        out.append(
            claim(
                f"fig{fig}-step-{name}",
                f"The direct-coil coordinator follows a 5000 µm step {where} without "
                "losing synchronism.",
                f'Fig {fig} and §6.4.2: direct coil "has no problems to follow the reference"',
                f"within 100 nm for good {rw['settle_100nm_s']:.2f} s after the step "
                f"({duration:g} s run); synchronism {'LOST' if rw['lost_sync'] else 'kept'}; "
                f"fine stage saturated {rw['saturated_steps']} steps during the move",
                st,
                crit + why + " The piezo saturates during the ramp (30 µm stroke against a "
                "5 mm step): the thesis does not say whether its piezo did.",
            )
        )
    vmax = max(rw["max_carriage_speed_mm_s"] for rw in rows.values())
    out.append(
        claim(
            "step-rate-limit",
            "A rate limit on the field phase turns the step into a ramp of the carriage.",
            'not in the thesis as a number (§6.4.2: "strict rate limitations for speed")',
            f"peak carriage speed {vmax:.2f} mm/s against the 3 mm/s phase rate limit",
            "not in thesis",
            "The peak exceeds 3 mm/s by the ringing of the 120 Hz mode at the ramp ends.",
        )
    )
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="2.5 s runs (CI)")
    p.add_argument("--out", type=Path, default=Path("out/ch6_steps"))
    args = p.parse_args(argv)
    log = TextLog()
    say = log.say
    duration = 2.5 if args.quick else 4.0
    t0 = 0.1
    rows, runs = {}, {}
    say(f"5 mm steps, SisoCoordinator, {FS:.0f} Hz, {duration:g} s")
    say(f"{'case':>10} {'t(100nm) s':>10} {'t(10nm) s':>10} {'sat steps':>9} {'sync':>5}")
    for name, r in fig619_steps(duration, FS).items():
        run = ddl.simulate(ddl.DualStage(), ddl.SisoCoordinator(), r, FS)
        m = run.metrics
        rows[name] = {
            "start_m": float(r[0]),
            "stop_m": float(r[-1]),
            "settle_100nm_s": settle_time(run, 100e-9, t0),
            "settle_10nm_s": settle_time(run, 10e-9, t0),
            "final_error_nm": float(run.error[-1] * 1e9),
            "saturated_steps": m["saturated_steps"],
            "lost_sync": m["lost_sync"],
            "coarse_stop_steps": m["coarse_stop_steps"],
            "max_carriage_speed_mm_s": float(np.max(np.abs(np.diff(run.y_c))) * FS * 1e3),
        }
        runs[name] = run
        rw = rows[name]
        say(
            f"{name:>10} {rw['settle_100nm_s']:10.3f} {rw['settle_10nm_s']:10.3f} "
            f"{rw['saturated_steps']:9d} {'LOST' if rw['lost_sync'] else 'ok':>5}"
        )
    claims = step_claims(rows, duration, t0, args.quick)
    for c in claims:
        say(f"claim {c['id']}: {c['measured']} → {c['status']}")
    try:
        from qpcoord.studies.figures import _pyplot, save
    except ImportError:  # pragma: no cover
        say("matplotlib not installed: figures skipped")
    else:
        plt = _pyplot()
        fig, ax = plt.subplots(1, 2, figsize=(9, 3.5))
        for a, (name, run) in zip(ax, runs.items(), strict=True):
            a.plot(run.t, run.r * 1e3, lw=1.0, label="reference")
            a.plot(run.t, run.y * 1e3, "--", lw=1.0, label="output y")
            a.set_xlabel("t (s)")
            a.set_ylabel("mm")
            a.set_title(f"5000 µm step, {name} (cf. Fig 6.19)")
            a.legend(fontsize=7)
        save(fig, args.out / "steps.png")
    log.write(args.out / "summary.txt")
    write_json(
        args.out / "summary.json",
        {"fs_hz": FS, "duration_s": duration, "cases": rows, "claims": claims},
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
