"""Chapter 6, §6.3 and Fig 6.14: two DDLs on one optical path, with and without predictor.

DDL 1 tracks the reference; its error minus a derivative prediction ``k ẏ1`` is the reference
of DDL 2 (``qpcoord.ddl.two_ddl``). Both DDLs are the full simulated loops (nonlinear plant +
thesis coordinator, 8 kHz). Frequency responses are measured (H1, white-noise reference of
0.2 µm rms) for one DDL, two DDLs (k = 0) and two DDLs + predictor; the −3 dB bandwidths and
their ratios are the "bandwidth gain" (thesis ≈ 1.6). Step responses (1 µm) give overshoot and
rise time (Fig 6.14b). The analytic combination ``2F − F² − k s F²`` of the measured single
response is compared with the measured dual response, and the thesis's own model -- a
second-order F (ωn = 300 Hz) -- gives the gain of ``2F − F²`` against ζ (1.49 at ζ 0.5, 1.58
at 0.6, 1.71 at 0.7): Fig 6.6's data are not available to fit ζ, so the 1.6 is judged over ζ.

The predictor gain k is not given in the thesis. It is chosen here by a stated rule: on a
grid, the k with the smallest step overshoot among those whose −3 dB bandwidth is not below
that of the dual scheme without predictor.

``--quick`` is the full run (4 s FRF records, 9 predictor gains, 5 s of CPU): 1 s records
widen the estimation noise in the gap of Eq 6.3 and 3 gains change the chosen predictor, so a
shorter run would decide the same rules on weaker evidence.

Run: ``python examples/ch6_two_ddl.py [--quick] [--out DIR]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import qpcoord.ddl as ddl
from qpcoord.ddl.two_ddl import analytic_gain, combine, two_ddl_frf, two_ddl_steps
from qpcoord.studies.claims import claim
from qpcoord.studies.criteria import within
from qpcoord.studies.files import TextLog, write_json

FS = 8000.0
ZETAS = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)  # damping grid of the analytic gain
THESIS_GAIN = 1.6
GAIN_TOL = 0.10  # relative


def zeta_sweep(fn: float) -> dict:
    """Analytic gain of ``2F − F²`` for a second-order ``F`` (ωn = ``fn`` Hz) against ζ, and
    the ζ interval (bisection on the monotone gain) where it is within ±10 % of 1.6."""
    table = {z: analytic_gain(z, fn)["gain"] for z in ZETAS}

    def solve(target):
        lo, hi = 0.05, 2.0  # the gain rises monotonically with ζ on this interval
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if analytic_gain(mid, fn)["gain"] < target else (lo, mid)
        return 0.5 * (lo + hi)

    band = (solve((1 - GAIN_TOL) * THESIS_GAIN), solve((1 + GAIN_TOL) * THESIS_GAIN))
    return {"gain_by_zeta": table, "zeta_band": band}


def two_ddl_claims(o: dict, s: dict, k: float, gap: float, analytic: dict) -> list[dict]:
    """Claim rows (``qpcoord.studies.claims.claim``) for §6.3 / Fig 6.14 from the chosen predictor.

    ``o``, ``s``: frequency-response and step results at the chosen gain ``k`` (s); ``gap``:
    max relative gap between ``2F − F²`` of the measured single loop and the measured dual
    loop, 5–400 Hz; ``analytic``: :func:`zeta_sweep` plus ``fn``, ``fine_damping`` and
    ``gain_at_fine_damping``. Every run is the full one (``--quick`` included).
    """
    out = []
    gain = o["gain_dual_pred"]
    lo, hi = analytic["zeta_band"]
    zf, gf = analytic["fine_damping"], analytic["gain_at_fine_damping"]
    table = ", ".join(f"{g:.2f} at ζ {z:g}" for z, g in analytic["gain_by_zeta"].items())
    ok = within(gain, THESIS_GAIN, GAIN_TOL)
    # judged on our loops only: the analytic second-order F is shown as context, not as
    # evidence -- its ζ is free, and some ζ in 0.3–1.0 always gives 1.6 ± 10 %
    st = "reproduced" if ok else "differs"
    out.append(
        claim(
            "fig6.14a-bandwidth-gain",
            "Two DDLs combined through their references (with the derivative predictor) "
            "raise the −3 dB bandwidth by a factor of nearly 1.6, no controller gain changed.",
            "§6.3 and Fig 6.14a: bandwidth enhancement by a factor of nearly 1.6",
            f"our loops: gain {gain:.2f} with predictor (k = {k:.1e} s), {o['gain_dual']:.2f} "
            f"without; −3 dB {o['bw_single']:.0f} / {o['bw_dual']:.0f} / "
            f"{o['bw_dual_pred']:.0f} Hz (one DDL / two / two + predictor). Analytic 2F − F² "
            f"with a second-order F ({analytic['fn']:g} Hz): {table}; within ±10 % of 1.6 "
            f"for ζ in {lo:.2f}–{hi:.2f}; our piezo model's ζ = {zf:g} gives {gf:.2f}",
            st,
            f"Criterion: gain within ±{100 * GAIN_TOL:g} % of 1.6 on our loops. The analytic "
            "second-order F is context, not a test: its ζ is not given, and some ζ in the "
            "plausible 0.3–1.0 always gives 1.6 ± 10 %, so a rule on it could not fail; it does "
            "not decide the row."
            + (
                f" Our F (fine PI + piezo, no resonant peak) is not second order and gives "
                f"{gain:.2f}: the gain depends on F's shape, which our loop design fixes and "
                "the thesis does not give."
                if st == "differs"
                else ""
            ),
            cause="our model" if st == "differs" else "",
        )
    )
    ok = gap <= 0.05
    st = "reproduced" if ok else "differs"
    out.append(
        claim(
            "eq-two-ddl-combination",
            "Without predictor the two-DDL response is Y/R = 2F − F² of the single-DDL "
            "closed loop F.",
            "§6.3: Y/R = 2F − F² − F² P₁ (P₁ = 0 without predictor)",
            f"max relative gap {100 * gap:.1f} % between 2F − F² of the measured single "
            "response and the measured dual response, 5–400 Hz",
            st,
            "Criterion: gap ≤ 5 %. Both DDLs are the full nonlinear loops (plant + "
            "coordinator), so the formula is checked, not assumed."
            + (" The nonlinear loops do not combine linearly here." if st == "differs" else ""),
        )
    )
    ok = k > 0 and s["rise_dual_pred"] < s["rise_single"] and s["rise_dual"] < s["rise_single"]
    st = "reproduced" if ok else "differs"
    out.append(
        claim(
            "fig6.14b-step-faster",
            "The two-DDL scheme responds faster to a step than one DDL.",
            'Fig 6.14b: "the time constant comparison of the step responses is very '
            'conclusive" (no numbers)',
            f"1 µm step rise time (10–90 %) {1e3 * s['rise_single']:.3f} ms one DDL, "
            f"{1e3 * s['rise_dual']:.3f} ms two, {1e3 * s['rise_dual_pred']:.3f} ms two + "
            "predictor",
            st,
            "Criterion: both two-DDL rise times shorter than the single DDL's (the step runs "
            "are the same in every run)."
            + (" A two-DDL response is not faster." if st == "differs" else ""),
        )
    )
    ok = k > 0 and s["overshoot_dual_pred"] < s["overshoot_dual"]
    st = "reproduced" if ok else "differs"
    out.append(
        claim(
            "fig6.14b-predictor-overshoot",
            "The derivative predictor P₁ avoids the large overshoot of the combined DDLs.",
            '§6.3: the prediction P₁ y₁ is added "to avoid ... producing large overshoots"; '
            "Fig 6.14b (no numbers)",
            f"1 µm step overshoot {100 * s['overshoot_single']:.1f} % one DDL, "
            f"{100 * s['overshoot_dual']:.1f} % two, {100 * s['overshoot_dual_pred']:.1f} % two "
            f"+ predictor (k = {k:.1e} s)",
            st,
            "Criterion: chosen k > 0 and overshoot with predictor below that without. k is not "
            "in the thesis; rule: smallest overshoot among the grid gains that keep the "
            "bandwidth at least the dual scheme's."
            + (" The predictor did not reduce the overshoot." if st == "differs" else ""),
        )
    )
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument(
        "--quick", action="store_true", help="the full run (4 s records, 9 gains is CI-sized)"
    )
    p.add_argument("--out", type=Path, default=Path("out/ch6_two_ddl"))
    args = p.parse_args(argv)
    log = TextLog()
    say = log.say
    duration = 4.0
    grid = [0.0, 1e-4, 2e-4, 3e-4, 4e-4, 5e-4, 6e-4, 7e-4, 8e-4]
    plant, ctl = ddl.DualStage, ddl.SisoCoordinator
    sweep = []
    say(
        f"{'k (s)':>8} {'bw single':>9} {'bw dual':>8} {'bw d+P':>8} {'gain':>5} "
        f"{'overshoot d+P':>13}"
    )
    for k in grid:
        o = two_ddl_frf(plant, ctl, FS, k, duration=duration)
        s = two_ddl_steps(plant, ctl, FS, k)
        sweep.append({"k": k, "frf": o, "steps": s})
        say(
            f"{k:8.1e} {o['bw_single']:9.1f} {o['bw_dual']:8.1f} {o['bw_dual_pred']:8.1f} "
            f"{o['gain_dual_pred']:5.2f} {s['overshoot_dual_pred']:13.3f}"
        )
    eligible = [w for w in sweep if w["frf"]["bw_dual_pred"] >= w["frf"]["bw_dual"] - 1e-9]
    best = min(eligible, key=lambda w: w["steps"]["overshoot_dual_pred"])
    o, s, k = best["frf"], best["steps"], best["k"]
    # analytic combination of the measured single response vs the measured dual response
    band = (o["f"] > 5) & (o["f"] < 400)
    pred = combine(o["single"], 2j * np.pi * o["f"], 0.0)
    mismatch = float(np.max(np.abs(pred[band] - o["dual"][band]) / np.abs(o["dual"][band])))
    say(f"\nchosen predictor k = {k:.1e} s")
    say(
        f"-3 dB bandwidth: single {o['bw_single']:.1f} Hz, dual {o['bw_dual']:.1f} Hz, "
        f"dual + predictor {o['bw_dual_pred']:.1f} Hz"
    )
    say(
        f"bandwidth gain: dual {o['gain_dual']:.2f}, dual + predictor {o['gain_dual_pred']:.2f} "
        "(thesis ≈ 1.6)"
    )
    say(
        "step overshoot: single {:.1%}, dual {:.1%}, dual + predictor {:.1%}; rise (10–90 %) "
        "{:.3f} / {:.3f} / {:.3f} ms".format(
            s["overshoot_single"],
            s["overshoot_dual"],
            s["overshoot_dual_pred"],
            s["rise_single"] * 1e3,
            s["rise_dual"] * 1e3,
            s["rise_dual_pred"] * 1e3,
        )
    )
    say(f"max relative gap |(2F − F²) − measured dual| / |dual|, 5–400 Hz: {mismatch:.3f}")
    fine = ddl.DualStage().fine
    analytic = zeta_sweep(fine.natural_frequency)
    analytic["fn"] = fine.natural_frequency
    analytic["fine_damping"] = fine.damping
    analytic["gain_at_fine_damping"] = analytic_gain(fine.damping, fine.natural_frequency)["gain"]
    say(
        f"analytic 2F − F², second-order F at {fine.natural_frequency:g} Hz: "
        + ", ".join(f"ζ {z:g}: {g:.2f}" for z, g in analytic["gain_by_zeta"].items())
        + " (within ±10 % of 1.6 for ζ {:.2f}–{:.2f})".format(*analytic["zeta_band"])
    )
    claims = two_ddl_claims(o, s, k, mismatch, analytic)
    for c in claims:
        say(f"claim {c['id']}: {c['measured']} → {c['status']}")
    try:
        from qpcoord.studies.figures import _pyplot, save
    except ImportError:  # pragma: no cover
        say("matplotlib not installed: figures skipped")
    else:
        plt = _pyplot()
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
        sel = (o["f"] > 5) & (o["f"] < 2000)
        for key, style, lab in (
            ("single", "--", "one DDL"),
            ("dual", "-.", "two DDLs"),
            ("dual_pred", "-", f"two DDLs + predictor (k={k:.0e} s)"),
        ):
            ax[0].semilogx(o["f"][sel], 20 * np.log10(np.abs(o[key][sel])), style, label=lab)
        ax[0].axhline(-3, color="k", lw=0.6, ls=":")
        ax[0].set_ylim(-20, 10)
        ax[0].set_xlabel("f (Hz)")
        ax[0].set_ylabel("|Y/R| (dB)")
        ax[0].set_title("measured closed loops (cf. Fig 6.14a)")
        ax[0].legend(fontsize=7)
        for key, style in (("single", "--"), ("dual", "-."), ("dual_pred", "-")):
            ax[1].plot(s["t"] * 1e3, s[key] * 1e6, style, label=key)
        ax[1].plot(s["t"] * 1e3, s["r"] * 1e6, "k:", lw=0.8)
        ax[1].set_xlabel("t (ms)")
        ax[1].set_ylabel("µm")
        ax[1].set_title("1 µm step (cf. Fig 6.14b)")
        ax[1].legend(fontsize=7)
        save(fig, args.out / "two_ddl.png")
    log.write(args.out / "summary.txt")
    write_json(
        args.out / "summary.json",
        {
            "fs_hz": FS,
            "predictor_k_s": k,
            "bw_single_hz": o["bw_single"],
            "bw_dual_hz": o["bw_dual"],
            "bw_dual_pred_hz": o["bw_dual_pred"],
            "bandwidth_gain_dual": o["gain_dual"],
            "bandwidth_gain_dual_pred": o["gain_dual_pred"],
            "thesis_bandwidth_gain": 1.6,
            "overshoot": {n: s[f"overshoot_{n}"] for n in ("single", "dual", "dual_pred")},
            "rise_time_s": {n: s[f"rise_{n}"] for n in ("single", "dual", "dual_pred")},
            "analytic_vs_measured_dual_max_rel_gap": mismatch,
            "analytic_second_order": {
                "natural_frequency_hz": analytic["fn"],
                "gain_by_zeta": {str(z): g for z, g in analytic["gain_by_zeta"].items()},
                "zeta_band_within_10pct_of_1.6": list(analytic["zeta_band"]),
                "gain_at_fine_damping": analytic["gain_at_fine_damping"],
            },
            "claims": claims,
            "sweep": [
                {
                    "k_s": w["k"],
                    "bw_dual_pred_hz": w["frf"]["bw_dual_pred"],
                    "overshoot_dual_pred": w["steps"]["overshoot_dual_pred"],
                }
                for w in sweep
            ],
        },
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
