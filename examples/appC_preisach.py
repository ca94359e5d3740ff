"""Appendix C: Preisach hysteresis model and its inverse as an open-loop compensator.

A synthetic piezo stack (0–10 V → ≈ 30 µm) whose hysteresis is *not* the identified model
— ``RelayPiezo``: 3000 explicit relay hysterons at seeded random switching values (off any
mesh), a quadratic anhysteretic part and a small Bouc–Wen term that breaks wipe-out and
congruency — is identified from simulated first-order reversal curves on a 21-level mesh
(0.5 V) read through a 1.25 nm metrology. The inverse model (Eqs C.9–C.11) then drives
the stack open loop on a 1 Hz sine (Figs C.7–C.8) and on a stochastic signal of 2 µm
peak-to-peak (Figs C.9–C.10), against the uncompensated linear command (straight line
through the major loop's end points). The same is repeated on a pure Bouc–Wen stack
(minor loops that do not close: a harsher mismatch), with a 300 Hz second-order stage
after the hysteresis (thesis Fig 6.6 bandwidth), and on meshes of 11 and 41 levels.

Measured (full run: fs = 5 kHz, sine 12 µm amplitude around 13.5 µm, errors over seconds
1–5; stochastic 20 s, white noise low-passed at 50 Hz, 2 µm peak-to-peak, seed 1), rms
uncompensated → compensated:

- relay stack, sine: 972 → 29 nm (×34), max 80 nm with compensation; stochastic:
  1712 → 86 nm, about the mean (a constant trim removed) 70 → 8 nm; identified model vs
  stack on the major loop 31 nm rms, 92 nm max;
- same with a 300 Hz second-order stage after the hysteresis: sine 998 → 58 nm,
  stochastic 1713 → 105 nm (about the mean 89 → 60 nm);
- relay stack without its Bouc–Wen term: sine 915 → 13 nm, stochastic 1690 → 12 nm;
- pure Bouc–Wen stack: sine 882 → 115 nm (×7.7), stochastic 1017 → 667 nm;
- mesh of 11 / 21 / 41 levels: compensated sine 43 / 29 / 22 nm;
- per sample: PreisachStage.step 0.9–2.6 µs, PreisachCompensator.step 1.9–4.1 µs
  (six runs, shared 2-core machine);
- thesis (real S-325): sine 902 → 79 nm, stochastic 134 → 44 nm.

The exact numbers of a run are in ``summary.json``/``summary.txt``.

Run: ``python examples/appC_preisach.py [--quick] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy import signal

from qpcoord import hysteresis as hy
from qpcoord.studies.claims import QUICK, claim
from qpcoord.studies.files import TextLog, write_json

FS = 5000.0  # Hz, lab sampling rate (thesis §6.2)
LEVELS = np.linspace(0.0, 10.0, 21)  # V, identification mesh
RESOLUTION = 1.25e-9  # m, interferometer resolution
CENTRE, AMPLITUDE = 13.5e-6, 12e-6  # m, 1 Hz sine


def rms(e) -> float:
    return float(np.sqrt(np.mean(np.square(e))))


def stochastic_reference(duration: float, fs: float, cutoff: float, p2p: float, seed: int):
    """White noise low-passed (2nd-order Butterworth, ``cutoff`` Hz), scaled to ``p2p`` m
    peak-to-peak around CENTRE (m), sampled at ``fs`` Hz."""
    rng = np.random.default_rng(seed)
    n, warm = int(round(duration * fs)), int(2 * fs)
    sos = signal.butter(2, cutoff, fs=fs, output="sos")
    w = signal.sosfilt(sos, rng.normal(size=n + warm))[warm:]
    return CENTRE + (w - 0.5 * (w.max() + w.min())) * (p2p / (w.max() - w.min()))


def second_order(fs: float, f0: float = 300.0, zeta: float = 0.7):
    """Unit-gain second-order stage (Hz, dimensionless damping), bilinear at ``fs``."""
    wn = 2 * np.pi * f0
    return signal.bilinear([wn * wn], [1.0, 2 * zeta * wn, wn * wn], fs)


def track(plant, model, ref, dyn=None) -> dict:
    """Open-loop runs of ``ref`` (m) uncompensated and compensated; outputs in m."""
    out = {}
    for name, u in (
        ("linear", model.linear_command(ref)),
        ("compensated", hy.PreisachCompensator(model).run(ref)),
    ):
        if np.any((u < model.u_min) | (u > model.u_max)):
            raise ValueError(f"{name} command leaves the amplifier range")
        plant.reset()
        x = plant.run(u)
        if dyn is not None:
            b, a = dyn
            zi = signal.lfilter_zi(b, a) * x[0]
            x = signal.lfilter(b, a, x, zi=zi)[0]
        out[name] = {"u": u, "x": x, "model_x": model.evaluate(u)}
    return out


def errors(run: dict, ref, mask) -> dict:
    d = {}
    for name, r in run.items():
        e = (r["x"] - ref)[mask]
        d[name] = {
            "rms_nm": rms(e) * 1e9,
            "rms_about_mean_nm": float(np.std(e)) * 1e9,
            "max_abs_nm": float(np.abs(e).max()) * 1e9,
            "model_vs_plant_rms_nm": rms((r["model_x"] - r["x"])[mask]) * 1e9,
        }
    d["ratio_rms"] = d["linear"]["rms_nm"] / d["compensated"]["rms_nm"]
    return d


def per_sample_us(fn, values, repeats: int = 5) -> float:
    """Median wall time (µs) of ``fn(v)`` per value over ``repeats`` passes."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for v in values:
            fn(v)
        times.append((time.perf_counter() - t0) / len(values))
    return float(np.median(times)) * 1e6


#: How the claims are judged on two synthetic stacks (chosen after both had been measured):
#: the thesis's S-325 departs from a Preisach system by an unknown
#: amount, and our two stacks bracket it -- the relay stack (3000 relays off the mesh + 4 %
#: Bouc–Wen, close to Preisach) and the pure Bouc–Wen stack (minor loops that do not close,
#: harsher than a real stack). A claim is reproduced if it holds on both, differs if it fails
#: on both, and is inconclusive if the stack decides.
STACKS = ("relay", "bouc_wen")
STACK_NAMES = {"relay": "relay stack", "bouc_wen": "Bouc–Wen stack"}


def _both(oks: dict) -> str:
    if all(oks.values()):
        return "reproduced"
    if not any(oks.values()):
        return "differs"
    return "inconclusive"


def preisach_claims(summary: dict, sine_s: float, stoch_s: float) -> list[dict]:
    """Claim rows (``qpcoord.studies.claims.claim``) for appendix C, Figs C.7–C.10.

    Judged on both synthetic stacks (:data:`STACKS`, static case): reproduced if the claim
    holds on both, differs if on neither, inconclusive if the stack decides. The sine's error
    is periodic after its first period, so any run with ≥ 1 period after the first decides
    the sine rows (both modes run a 5 s sine); the stochastic rows are judged on the 20 s
    record (both modes).

    The stochastic rows compare the *level-matched* uncompensated command, as the thesis's
    numbers imply: its "simple open-loop control" (§C.3) gives 134 nm rms on a 2 µm
    peak-to-peak signal (6.7 % of it), which excludes an uncalibrated static offset (ours,
    the straight line through the major loop's end points, is 1.7 µm off at mid-stroke);
    the thesis does not say how the operating point was set, so both commands are trimmed
    by a constant output offset (the error about its mean). The raw numbers are shown too.
    """
    plants = summary["plants"]
    missing = [k for k in STACKS if k not in plants]
    if missing:
        raise ValueError(f"appendix C claims need the stacks {STACKS}; missing {missing}")
    synthetic = (
        " The stacks are synthetic, not the thesis's S-325: how close the compensated error "
        "comes to zero is set by how far the stack departs from a Preisach system (our "
        "modelling choice), so both stacks are judged."
    )
    after = " The two-stack rule was set after both stacks had been measured."
    out = []
    sine_ok = sine_s >= 2.0  # the first period is excluded
    sine = {k: plants[k]["sine_static"] for k in STACKS}
    oks = {k: e["ratio_rms"] >= 902.0 / 79.0 for k, e in sine.items()}
    st = _both(oks) if sine_ok else "inconclusive"
    out.append(
        claim(
            "figC.8-sine-improvement",
            "The inverse Preisach compensator cuts the open-loop error on a 1 Hz sine by an "
            "order of magnitude (902 → 79 nm rms, ×11.4).",
            "App. C.3, Figs C.7–C.8: 902 → ≈ 79 nm rms, max ≈ 150 nm (hardware, piezo alone)",
            "; ".join(
                f"{STACK_NAMES[k]} {e['linear']['rms_nm']:.0f} → {e['compensated']['rms_nm']:.1f}"
                f" nm rms (×{e['ratio_rms']:.1f}), max {e['compensated']['max_abs_nm']:.0f} nm"
                for k, e in sine.items()
            ),
            st,
            "Criterion: reduction factor ≥ 902/79 = 11.4 on each stack. The uncompensated "
            "error (straight line through the major loop's end points: the sine spans the "
            "stroke) is comparable to the thesis's."
            + (
                " The stack decides: the result is not a property of the method."
                if st == "inconclusive" and sine_ok
                else ""
            )
            + synthetic
            + after
            + (
                " This run has no full sine period after the first: a ≥ 2 s sine decides."
                if not sine_ok
                else ""
            ),
            cause="our model" if st == "differs" else "",
        )
    )
    oks = {k: abs(e["compensated"]["rms_nm"] - 79.0) <= 0.3 * 79.0 for k, e in sine.items()}
    st = _both(oks) if sine_ok else "inconclusive"
    out.append(
        claim(
            "figC.8-sine-residual",
            "With compensation the 1 Hz sine is tracked open loop to ≈ 79 nm rms.",
            "App. C.3, Fig C.8: ≈ 79 nm rms, max ≈ 150 nm (1.1 % of the stroke)",
            "; ".join(
                f"{STACK_NAMES[k]} {e['compensated']['rms_nm']:.1f} nm rms, max "
                f"{e['compensated']['max_abs_nm']:.0f} nm"
                for k, e in sine.items()
            ),
            st,
            "Criterion: within ±30 % of 79 nm on each stack."
            + synthetic
            + " The hardware's 79 nm is a property of the real stack."
            + after
            + (
                " This run has no full sine period after the first: a ≥ 2 s sine decides."
                if not sine_ok
                else ""
            ),
            cause="our model" if st == "differs" else "",
        )
    )
    stoch = {k: plants[k]["stochastic_static"] for k in STACKS}
    full = stoch_s >= 20.0
    short = f" This run's stochastic record is {stoch_s:g} s; a 20 s record decides."

    def level(e, name):
        return e[name]["rms_about_mean_nm"]

    meas = "; ".join(
        f"{STACK_NAMES[k]} level-matched {level(e, 'linear'):.0f} → "
        f"{level(e, 'compensated'):.1f} nm rms "
        f"(−{100 * (1 - level(e, 'compensated') / level(e, 'linear')):.0f} %; raw "
        f"{e['linear']['rms_nm']:.0f} → {e['compensated']['rms_nm']:.0f} nm)"
        for k, e in stoch.items()
    )
    oks = {k: level(e, "compensated") <= (1 - 0.67) * level(e, "linear") for k, e in stoch.items()}
    st = _both(oks) if full else QUICK
    out.append(
        claim(
            "figC.10-stochastic-improvement",
            "On a stochastic signal (2 µm peak-to-peak) the compensator reduces the open-loop "
            "error by about 67 %.",
            "App. C.3, Figs C.9–C.10: 134 → 44 nm rms (−67 %), max ≈ 120 nm",
            meas,
            st,
            "Criterion: level-matched compensated ≤ 33 % of level-matched uncompensated on "
            "each stack (uncompensated command: see preisach_claims)."
            + (
                " The stack decides: the result is not a property of the method."
                if st == "inconclusive" and full
                else ""
            )
            + synthetic
            + after
            + (short if not full else ""),
            cause="our model" if st == "differs" else "",
        )
    )
    oks = {
        k: abs(level(e, "compensated") - 44.0) <= 0.3 * 44.0
        and abs(level(e, "linear") - 134.0) <= 0.3 * 134.0
        for k, e in stoch.items()
    }
    st = _both(oks) if full else QUICK
    out.append(
        claim(
            "figC.10-stochastic-levels",
            "Open-loop errors on the stochastic signal: 134 nm rms without, 44 nm with "
            "compensation.",
            "App. C.3, Fig C.10: 134 → 44 nm rms",
            meas,
            st,
            "Criterion: both within ±30 % of the thesis on each stack (level-matched)."
            + synthetic
            + after
            + (short if not full else ""),
            cause="our model" if st == "differs" else "",
        )
    )
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="two stacks, static stage only (CI)")
    p.add_argument("--out", type=Path, default=Path("out/appC"))
    p.add_argument("--seed", type=int, default=1, help="seed of the stochastic reference")
    args = p.parse_args(argv)
    log = TextLog()
    say = log.say

    # the claims' records are the same in both modes (a 5 s sine, a 20 s stochastic signal):
    # --quick leaves out the 300 Hz stage, the stack variants and the mesh sizes, which no
    # claim reads
    sine_s, stoch_s = 5.0, 20.0
    t = np.arange(int(sine_s * FS)) / FS
    sine = CENTRE + AMPLITUDE * np.sin(2 * np.pi * t - np.pi / 2)
    sine_mask = t >= 1.0  # after the first period (initial rise from negative saturation)
    stoch = stochastic_reference(stoch_s, FS, 50.0, 2e-6, args.seed)
    stoch_mask = np.ones(stoch.size, dtype=bool)
    summary: dict = {
        "fs_hz": FS,
        "levels_v": LEVELS.tolist(),
        "metrology_resolution_m": RESOLUTION,
        "sine": {"freq_hz": 1.0, "centre_m": CENTRE, "amplitude_m": AMPLITUDE, "seconds": sine_s},
        "stochastic": {"seconds": stoch_s, "cutoff_hz": 50.0, "p2p_m": 2e-6, "seed": args.seed},
        "thesis": {"sine_rms_nm": [902, 79], "stochastic_rms_nm": [134, 44]},
        "plants": {},
    }
    plants = {"relay": hy.RelayPiezo(seed=0), "bouc_wen": hy.BoucWenPiezo()}
    if not args.quick:
        plants["relay_without_bouc_wen"] = hy.RelayPiezo(seed=0, bouc_wen=0.0)
    figs = {}
    for pname, plant in plants.items():
        u_loop = np.r_[np.linspace(0, 10, 401), np.linspace(10, 0, 401)]
        plant.reset()
        x_loop = plant.run(u_loop)
        width = float(np.max(x_loop[401:][::-1] - x_loop[:401]))
        t0 = time.perf_counter()
        model = hy.identify(plant, LEVELS, du=0.01, resolution=RESOLUTION)
        t_id = time.perf_counter() - t0
        _, up, down = model.major_loop(401)
        loop_err = np.r_[up - x_loop[:401], down[::-1] - x_loop[401:]]
        res = {
            "stroke_m": float(x_loop.max() - x_loop.min()),
            "major_loop_width_m": width,
            "identification_s": t_id,
            "model_major_loop_error_rms_nm": rms(loop_err) * 1e9,
            "model_major_loop_error_max_nm": float(np.abs(loop_err).max()) * 1e9,
        }
        say(
            f"[{pname}] stroke {res['stroke_m'] * 1e6:.2f} µm, major-loop width "
            f"{width * 1e6:.2f} µm ({100 * width / res['stroke_m']:.1f} %); identified in "
            f"{t_id:.2f} s; model vs plant on the major loop: "
            f"{res['model_major_loop_error_rms_nm']:.1f} nm rms, "
            f"{res['model_major_loop_error_max_nm']:.1f} nm max"
        )
        cases = {"static": None} if args.quick else {"static": None, "300Hz": second_order(FS)}
        for cname, dyn in cases.items():
            run_s = track(plant, model, sine, dyn)
            run_r = track(plant, model, stoch, dyn)
            es, er = errors(run_s, sine, sine_mask), errors(run_r, stoch, stoch_mask)
            res[f"sine_{cname}"], res[f"stochastic_{cname}"] = es, er
            for label, e in (("sine", es), ("stochastic", er)):
                say(
                    f"  {cname:>6} {label:>10}: rms {e['linear']['rms_nm']:7.1f} → "
                    f"{e['compensated']['rms_nm']:6.1f} nm (×{e['ratio_rms']:.1f}); about mean "
                    f"{e['linear']['rms_about_mean_nm']:6.1f} → "
                    f"{e['compensated']['rms_about_mean_nm']:5.1f} nm; max "
                    f"{e['linear']['max_abs_nm']:6.1f} → {e['compensated']['max_abs_nm']:5.1f} nm;"
                    f" model vs plant (uncompensated input) "
                    f"{e['linear']['model_vs_plant_rms_nm']:.1f} nm rms"
                )
            if pname == "relay" and cname == "static":
                figs = {"sine": run_s, "stoch": run_r, "loop": (u_loop, x_loop, model)}
        summary["plants"][pname] = res

    if not args.quick:  # mesh size on the relay stack, sine, static
        plant = plants["relay"]
        mesh = {}
        for n in (11, 41):
            m = hy.identify(plant, np.linspace(0, 10, n), du=0.01, resolution=RESOLUTION)
            e = errors(track(plant, m, sine), sine, sine_mask)
            mesh[str(n)] = e["compensated"]["rms_nm"]
        mesh["21"] = summary["plants"]["relay"]["sine_static"]["compensated"]["rms_nm"]
        summary["mesh_levels_vs_sine_rms_nm"] = mesh
        say(
            "mesh levels → compensated sine rms (nm): "
            + str({k: round(v, 1) for k, v in mesh.items()})
        )

    # per-sample costs (relay model), median of 5 passes
    model = figs["loop"][2]
    us = np.clip(figs["stoch"]["compensated"]["u"][:10000], model.u_min, model.u_max).tolist()
    xs = stoch[:10000].tolist()
    stage, comp = hy.PreisachStage(model), hy.PreisachCompensator(model)

    def vec_cost(u) -> float:  # µs per sample, median of 5
        times = []
        for _ in range(5):
            t0 = time.perf_counter()
            model.evaluate(u)
            times.append((time.perf_counter() - t0) / u.size)
        return float(np.median(times)) * 1e6

    vec_us = vec_cost(np.asarray(us))
    u_sine = figs["sine"]["compensated"]["u"]
    timing = {
        "stage_step_us": per_sample_us(stage.step, us),
        "compensator_step_us": per_sample_us(comp.step, xs),
        "evaluate_vectorised_us_per_sample": vec_us,
        "evaluate_vectorised_us_per_sample_sine": vec_cost(u_sine),
        "reversals_per_sample_stochastic": float(np.mean(np.diff(np.sign(np.diff(us))) != 0)),
        "relay_piezo_step_us": per_sample_us(plants["relay"].step, us[:2000], repeats=3),
        "stored_extrema_end": len(stage.extrema),
    }
    summary["timing"] = timing
    say(
        f"per sample: PreisachStage.step {timing['stage_step_us']:.2f} µs, "
        f"PreisachCompensator.step {timing['compensator_step_us']:.2f} µs, vectorised "
        f"evaluate {vec_us:.2f} µs (stochastic input, 10000 samples), "
        f"{timing['evaluate_vectorised_us_per_sample_sine']:.3f} µs (sine input)"
    )

    summary["claims"] = preisach_claims(summary, sine_s, stoch_s)
    for c in summary["claims"]:
        say(f"claim {c['id']}: {c['measured']} → {c['status']}")

    try:
        from qpcoord.studies.figures import _pyplot, save
    except ImportError:  # pragma: no cover - matplotlib missing
        say("matplotlib not installed: figures skipped")
    else:
        plt = _pyplot()
        for key, ref, tt, fname, title in (
            ("sine", sine, t, "fig_c7_c8_sine.png", "1 Hz sine (Figs C.7–C.8)"),
            (
                "stoch",
                stoch,
                np.arange(stoch.size) / FS,
                "fig_c9_c10_stochastic.png",
                "stochastic signal (Figs C.9–C.10)",
            ),
        ):
            run = figs[key]
            fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 5.5))
            z = tt <= 2.0  # the first 2 s, to see the signal
            a1.plot(tt[z], ref[z] * 1e6, "k:", lw=1.2, label="reference")
            a1.plot(tt[z], run["linear"]["x"][z] * 1e6, "--", lw=0.9, label="without compensation")
            a1.plot(tt[z], run["compensated"]["x"][z] * 1e6, lw=0.9, label="with compensation")
            a1.set_ylabel("x (µm)")
            a1.set_title(f"relay stack, open loop, {title}")
            a1.legend(fontsize=7)
            a2.plot(tt, (run["linear"]["x"] - ref) * 1e9, "--", lw=0.9, label="without")
            a2.plot(tt, (run["compensated"]["x"] - ref) * 1e9, lw=0.9, label="with")
            a2.set_xlabel("t (s)")
            a2.set_ylabel("error (nm)")
            a2.legend(fontsize=7)
            save(fig, args.out / fname)
        u_loop, x_loop, model = figs["loop"]
        u, up, down = model.major_loop(401)
        fig, ax = plt.subplots(figsize=(5, 4))
        ax.plot(u_loop, x_loop * 1e6, "k", lw=1.0, label="relay stack")
        ax.plot(u, up * 1e6, "--", lw=0.9, label="Preisach model, up")
        ax.plot(u, down * 1e6, "--", lw=0.9, label="Preisach model, down")
        ax.set_xlabel("u (V)")
        ax.set_ylabel("x (µm)")
        ax.set_title("major loop")
        ax.legend(fontsize=7)
        save(fig, args.out / "major_loop.png")
    log.write(args.out / "summary.txt")
    write_json(args.out / "summary.json", summary)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
