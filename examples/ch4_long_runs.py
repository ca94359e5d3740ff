"""Chapter 4, long runs of the pseudo-inverse scheme: do the joints settle to a cycle?

Reproduces the experiment behind thesis Fig. 4.7, Remark 4.4 and Conjecture 4.1: a
redundant arm tracks a periodic end-effector path with ``q̇ = J⁺ Ẏ`` (Eq. 4.1) for many
task periods ``T``, and the joint motion is sampled once per period (Poincaré section,
``qpcoord.coordination.periodicity``). The conjecture links the degree of redundancy ``δ = nq −
rows`` to
the convergence of the joints to a limit cycle (``δ = 1, 2``: converges, faster for
``δ = 1``; ``δ > 2``: neither periodic nor convergent).

Cases (``δ`` = joints − task rows):

- ``planar_3r`` / ``planar_4r`` / ``planar_5r`` (δ = 1, 2, 3): unit links, absolute angles,
  tracking the circle of thesis Eq. 5.1 / Fig. 5.9 (centre (1.5, 0) m, radius 0.5 m, period
  π s) -- the same circle for every ``n`` (it is reachable by all three) so that only δ
  changes. ``dt = T/100``.
- ``spatial_5r`` (δ = 2): the thesis 5R3D arm (axes chosen by qpcoord, see
  ``qpcoord.robots.spatial_5r``) tracking the Lissajous curve on the sphere of Example 4.1
  (period 2π/0.4 s), from the thesis start ``Q0_THESIS``. ``dt = T/200``.

Start configurations: ``(0, π/3, −π/3)`` for the 3R (thesis Fig. 5.9; its tip is on the
circle's start point (2, 0)); for n = 4, 5 the same zig-zag continued with growing
amplitude, ``(0, π/3, −π/3, 2π/3, −2π/3)[:n]``, moved onto (2, 0) by the start IK
(``simulate(start="ik")``). Starts with two *equal* absolute angles are avoided on purpose:
with equal links, ``J⁺`` in absolute angles commutes with permuting the joints, so
``qᵢ = qⱼ`` is an invariant set on which the arm is a shorter chain with a smaller δ (the
symmetric zig-zag ``(π/3, −π/3, π/3, −π/3)`` of the 4R closes to 1e-8 rad per period for
its first ten periods, then round-off takes it off that unstable cycle: 3e-7 rad in period
21, 0.26 rad in period 51).

Scheme: ``qc.schemes.PseudoInverse(arm, gain=1.0)``, i.e. ``q̇ = J⁺ (Ẏ_ref + K (Y_ref − Y))``
with ``K = 1/s``. The thesis integrates the open-loop map (``K = 0``); the 1/s correction
keeps the end effector on the path over hundreds of periods, so the section points all sit
on the same self-motion manifold. Integration: classical RK4, a whole number of steps per
period so the Poincaré sections fall on samples.

Measured per case (``summary.json``, one ``closure_<case>.png`` and ``joints_<case>.png``
per case): closure ``‖q(kT) − q((k−1)T)‖`` of the first and last period, raw and *wrapped*
(each joint difference taken modulo 2π into (−π, π]: a revolute joint that turned by 2π has
come back); ``qc.analysis.detect_period`` on the raw joints (multiples ≤ 8, tol 1e-6 rad);
the same test on wrapped joints for every multiple up to half the run (a full cycle of
``m`` section points must repeat within 1e-6 rad); the closest *near return* (smallest
wrapped ``‖q(KT) − q((K−m)T)‖`` over ``m``); the largest end-effector error; the smallest
singular value of ``J`` at the samples; and a step-size check: the same run at ``dt/2``,
with the first period at which the two runs' sections differ by more than 1e-3 rad.

Measured in full mode (300 periods planar, 100 spatial; 301–305 s in total on one thread,
a third for the runs below, two thirds for the dt/2 checks; ``--quick``: 10 planar and
3 spatial periods without the dt/2 runs, about 10 s)::

    case       δ   K     1st last raw wrapped cycle   near ret max err σmin J dt/2 off
    planar_3r  1 300 3.27e-1  3.28e-1 3.28e-1  none 1.3e-2@140  7.5e-3 2.7e-3        7
    planar_4r  2 300 4.27e-1  6.28e-1 6.28e-1  none  7.8e-2@35  6.5e-6 4.6e-2    never
    planar_5r  3 300 2.66e-1  2.87e-1 2.87e-1  none  8.1e-2@58  1.6e-8    1.2    never
    spatial_5r 2 100 7.41e-2     1.41    1.41  none      1.4@1  2.3e-4 1.1e-1       35

(closure of the first period, of the last period raw and wrapped, in rad; "cycle": neither
``detect_period`` on raw joints, multiples ≤ 8, nor the wrapped search, multiples ≤ K/2,
found one; "near ret" a@m: the last section point comes within a rad of the one m periods
earlier; "max err" in m; "dt/2 off": first period where the dt and dt/2 sections differ by
more than 1e-3 rad.) No case is periodic at ``dt``. The dt/2 runs: the 3R is periodic,
wrapped, with period 30·T from period 133 (a 10-period pattern with the three joints
cyclically permuted); the 4R and 5R sections agree with the ``dt`` run to 8.8e-5 and
2.4e-5 rad after 300 periods and are not periodic either; the spatial 5R sections are
2.7 rad apart at period 100, not periodic.

Longer runs of this script: ``--planar-periods 1000`` -- still no cycle for any planar arm
(near returns 3.6e-4 rad@40 for 3R, 8.3e-3@383 for 4R, 9.0e-3@404 for 5R; the 4R and 5R dt/2
sections within 3.7e-4 and 2.2e-4 rad at period 1000, the 4R's above 1e-3 for a while
from period 307); ``--spatial-periods 300`` -- no cycle, last closure 0.075 rad, dt/2 runs
apart from period 35. Separately, the 3R with
``dt = T/800`` (``qc.simulate`` directly, 305 s): periodic with period 1·T from period 19
(closure 7e-15 rad), on the invariant set ``q₂ = q₃`` = (1.318, −0.505, −0.505) rad mod 2π.

Reading: the 4R (δ = 2) and 5R (δ = 3) behave alike -- bounded per-period drift that never
decays, no return to 1e-6 rad at any multiple up to 500·T, and dt vs dt/2 differences that
grow slowly (no attracting cycle, no exponential divergence). The 3R (δ = 1) comes close to
a singularity about every 10 periods (σ_min(J) down to 2.7e-3: the circle passes through
(1, 0), at distance 1 from the base, where the arm can fold flat), and its long-run
outcome changes with the step: no cycle (T/100), a 30·T cycle (T/200), a 1·T cycle on a
lower-redundancy invariant set (T/800). The spatial 5R (δ = 2) shows no cycle within 300
periods and depends sensitively on the step (dt and dt/2 apart after 35 periods); the
closing "over a very high multiple" of Fig. 4.7 is not reproduced with this 5R model (whose
axes are qpcoord's choice, not the thesis's).

Claims (``summary["claims"]``, computed from the cases): Fig 4.7 / Remark 4.4 on the 5R
and the three clauses of Conjecture 4.1 (δ = 1, 2 converge; δ = 3 does not). "No cycle" is
only a finding after ≥ 100 periods at both dt and dt/2; a cycle at one step only is
step-dependent (inconclusive). ``--quick`` has no dt/2 runs and decides nothing.

Run: ``python examples/ch4_long_runs.py [--quick] [--out DIR]``
(``--planar-periods`` / ``--spatial-periods`` change the run lengths).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import qpcoord as qc
from qpcoord.studies.claims import claim
from qpcoord.studies.figures import closure_plot, joint_plot
from qpcoord.studies.files import TextLog, write_json

ZIGZAG = np.array([0.0, np.pi / 3, -np.pi / 3, 2 * np.pi / 3, -2 * np.pi / 3])  # rad
CLIK_GAIN = 1.0  # 1/s
TOL = 1e-6  # rad, period-detection tolerance
AGREE = 1e-3  # rad, dt vs dt/2 section agreement threshold
DECIDE = 100  # periods without a cycle (at dt and dt/2) before "no cycle" is a finding


def wrap(d: np.ndarray) -> np.ndarray:
    """Angle differences (rad) taken into (−π, π]: a 2π turn of a revolute joint is a return."""
    return np.angle(np.exp(1j * np.asarray(d, dtype=float)))


def wrapped_closure_errors(sections: np.ndarray) -> np.ndarray:
    """``‖wrap(p_k − p_{k−1})‖`` per period (rad)."""
    return np.linalg.norm(wrap(np.diff(sections, axis=0)), axis=1)


def wrapped_period(sections: np.ndarray, max_multiple: int, tol: float = TOL) -> dict:
    """Smallest ``m ≤ max_multiple`` with ``‖wrap(p_{j+m} − p_j)‖ ≤ tol`` for every ``j`` from
    some ``k`` on, over at least ``max(3, m)`` consecutive ``j`` (a whole cycle repeats)."""
    for m in range(1, max_multiple + 1):
        if len(sections) <= m:
            break
        g = np.linalg.norm(wrap(sections[m:] - sections[:-m]), axis=1)
        above = np.flatnonzero(g > tol)
        first_ok = 0 if above.size == 0 else int(above[-1]) + 1
        if len(g) - first_ok >= max(3, m):
            return {"periodic": True, "multiple": m, "settled_after": first_ok}
    return {"periodic": False, "multiple": None, "settled_after": None}


def near_return(sections: np.ndarray, max_multiple: int) -> dict:
    """Closest wrapped return of the last section point to one ``m`` periods earlier."""
    last = sections[-1]
    gaps = [
        (float(np.linalg.norm(wrap(last - sections[-1 - m]))), m)
        for m in range(1, min(max_multiple, len(sections) - 1) + 1)
    ]
    gap, m = min(gaps)
    return {"gap_rad": gap, "multiple": m}


def make_case(name: str) -> tuple:
    """``(arm, path, q0, n, delta, steps_per_period)`` for one case."""
    if name == "spatial_5r":
        arm = qc.robots.load("spatial_5r")
        return arm, qc.paths.LissajousSphere(), qc.robots.spatial_5r.Q0_THESIS, 5, 2, 200
    n = int(name.split("_")[1][0])
    arm = qc.robots.load("planar_nr", n=n)
    path = qc.paths.Circle(center=(1.5, 0.0), radius=0.5, period=np.pi)
    return arm, path, ZIGZAG[:n], n, n - 2, 100


def run_case(name: str, periods: int, out: Path, dt_half: bool = True) -> dict:
    arm, path, q0, n, delta, N = make_case(name)
    T = path.period
    dt = T / N
    t0 = time.perf_counter()
    scheme = qc.schemes.PseudoInverse(arm, gain=CLIK_GAIN)
    traj = qc.simulate(arm, scheme, path, q0, periods * T, dt)
    runtime = time.perf_counter() - t0

    sec = qc.analysis.poincare_section(traj, T)
    raw = qc.analysis.closure_errors(traj, T)
    wrapped = wrapped_closure_errors(sec)
    per = qc.analysis.detect_period(traj, T, max_multiple=8, tol=TOL)
    wper = wrapped_period(sec, max_multiple=periods // 2)
    near = near_return(sec, max_multiple=periods // 2)
    sigma_min = min(float(np.linalg.svd(arm.jacobian(q), compute_uv=False)[-1]) for q in traj.q)

    # step-size check: the same run at dt/2 (skipped by --quick)
    check = None
    if dt_half:
        t1 = time.perf_counter()
        fresh = qc.schemes.PseudoInverse(arm, gain=CLIK_GAIN)  # no state carried over
        half = qc.simulate(arm, fresh, path, q0, periods * T, dt / 2)
        sec_half = qc.analysis.poincare_section(half, T)
        diff = np.linalg.norm(sec - sec_half, axis=1)
        apart = np.flatnonzero(diff > AGREE)
        wrapped_half = wrapped_closure_errors(sec_half)
        check = {
            "dt_s": dt / 2,
            "first_period_apart": int(apart[0]) if apart.size else None,
            "threshold_rad": AGREE,
            "final_section_difference_rad": float(diff[-1]),
            "closure_last_wrapped_rad": float(wrapped_half[-1]),
            "wrapped_period": wrapped_period(sec_half, max_multiple=periods // 2),
            "max_tracking_error_m": half.max_error,
            "runtime_s": time.perf_counter() - t1,
        }

    label = f"{name}, δ = {delta}"
    curves = {"raw": raw, "wrapped (mod 2π)": wrapped}
    if check:
        curves["wrapped, dt/2"] = wrapped_half
    closure_plot(
        curves,
        out / f"closure_{name}.png",
        f"{label}: J⁺ (K = {CLIK_GAIN:g}/s), closure per period",
    )
    joint_plot(traj, out / f"joints_{name}.png", f"{label}: joints over {periods} periods", T)

    return {
        "case": name,
        "robot": arm.name,
        "n": n,
        "delta": delta,
        "path": type(path).__name__,
        "period_s": T,
        "periods": periods,
        "dt_s": dt,
        "steps_per_period": N,
        "clik_gain_per_s": CLIK_GAIN,
        "q0_rad": np.asarray(q0, dtype=float).tolist(),
        "q_start_rad": traj.info["q_start"].tolist(),
        "closure_first_raw_rad": float(raw[0]),
        "closure_last_raw_rad": float(raw[-1]),
        "closure_first_wrapped_rad": float(wrapped[0]),
        "closure_last_wrapped_rad": float(wrapped[-1]),
        "detect_period": {
            "periodic": per.periodic,
            "multiple": per.multiple,
            "settled_after": per.settled_after,
            "max_multiple": 8,
            "tol_rad": TOL,
            "text": str(per),
        },
        "wrapped_period": {**wper, "max_multiple": periods // 2, "tol_rad": TOL},
        "near_return_wrapped": near,
        "max_tracking_error_m": traj.max_error,
        "min_sigma_J": sigma_min,
        "dt_half_check": check,
        "runtime_s": runtime,
    }


def cycle_outcome(r: dict) -> tuple[str, str]:
    """``(outcome, text)`` for one case: ``"cycle"``, ``"none"`` (no cycle at dt nor dt/2 in
    ≥ DECIDE periods), ``"step-dependent"`` (found at one step only) or ``"short"``."""
    at_dt = r["detect_period"]["periodic"] or r["wrapped_period"]["periodic"]
    half = r["dt_half_check"]
    at_half = None if half is None else half["wrapped_period"]["periodic"]
    text = (
        f"{r['case']} (δ = {r['delta']}): {fmt_period(r['wrapped_period'])} at dt, "
        f"{'not run' if half is None else fmt_period(half['wrapped_period'])} at dt/2 in "
        f"{r['periods']} periods, near return {r['near_return_wrapped']['gap_rad']:.1e} rad"
    )
    if at_half is None:
        return ("short", text)  # --quick: no step check, nothing is decided
    if at_dt and at_half:
        return ("cycle", text)
    if at_dt or at_half:
        return ("step-dependent", text)
    return ("none" if r["periods"] >= DECIDE else "short", text)


def claims(rows: list[dict]) -> list[dict]:
    """Claim rows computed from the cases (Fig 4.7 / Remark 4.4 and Conjecture 4.1)."""
    by = {r["case"]: cycle_outcome(r) for r in rows}
    case = {r["case"]: r for r in rows}

    def apart(name):
        half = case[name]["dt_half_check"]
        first = half and half["first_period_apart"]
        return "never" if first is None else f"from period {first}"

    crit = (
        f"criterion: a cycle is a wrapped return within {TOL:g} rad at some multiple ≤ K/2 "
        f"that repeats (detect_period or the wrapped search); 'no cycle' needs ≥ {DECIDE} "
        "periods at both dt and dt/2; found at one step only is step-dependent"
    )
    short = "; the run is too short or has no dt/2 check (--quick): the full run decides"

    def status(outcomes, want):
        if any(o == "short" for o in outcomes):
            return "inconclusive"
        if any(o == "step-dependent" for o in outcomes):
            return "inconclusive"
        return "reproduced" if all(o == want for o in outcomes) else "differs"

    rows_out = []
    o = [by["spatial_5r"][0]]
    rows_out.append(
        claim(
            "rem4.4-fig4.7-5r-closes",
            "Long J⁺ runs of the 5R3D on the Lissajous close, over a high multiple of T.",
            "Remark 4.4, Fig 4.7: 'the joints trajectory is finally closed but over a very "
            "high multiple of the initial period'",
            by["spatial_5r"][1],
            status(o, "cycle"),
            crit
            + (
                "; this 5R's axes are qpcoord's choice (the thesis gives none); its dt and "
                f"dt/2 sections differ by > {AGREE:g} rad {apart('spatial_5r')}"
                if o[0] == "none"
                else ""
            )
            + (short if o[0] == "short" else "")
            + ("; found at one step only" if o[0] == "step-dependent" else ""),
        )
    )
    for name, clause, want, thesis in (
        ("planar_3r", "δ = 1", "cycle", "Conjecture 4.1: δ = 1 or 2 converges (faster for δ = 1)"),
        ("planar_4r", "δ = 2", "cycle", "Conjecture 4.1: δ = 1 or 2 converges to a limit cycle"),
        ("planar_5r", "δ = 3", "none", "Conjecture 4.1: δ > 2 neither periodic nor converges"),
    ):
        oc, text = by[name]
        note = crit
        if oc == "short":
            note += short
        elif oc == "step-dependent":
            note += (
                f"; the outcome changes with the step (σ_min(J) down to "
                f"{case[name]['min_sigma_J']:.1e} on the run): a step-converged study "
                "would decide"
            )
        elif oc != want:
            note += "; wrapped closure of the last period: " + ", ".join(
                f"{c} {case[c]['closure_last_wrapped_rad']:.2g} rad"
                for c in ("planar_4r", "planar_5r")
            )
        rows_out.append(
            claim(
                f"conj4.1-delta{clause[-1]}",
                f"With q̇ = J⁺Ẏ on a planar arm with {clause}, the joints "
                + ("converge to a limit cycle." if want == "cycle" else "find no cycle."),
                thesis,
                text,
                status([oc], want),
                note,
            )
        )
    return rows_out


def fmt_period(d: dict) -> str:
    return f"{d['multiple']}T@{d['settled_after']}" if d["periodic"] else "no"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument(
        "--quick", action="store_true", help="10 planar / 3 spatial periods, no dt/2 runs (CI)"
    )
    p.add_argument("--out", type=Path, default=Path("out/ch4_long_runs"))
    p.add_argument("--planar-periods", type=int, default=None, help="default 300 (quick: 10)")
    p.add_argument("--spatial-periods", type=int, default=None, help="default 100 (quick: 3)")
    args = p.parse_args(argv)
    planar = args.planar_periods or (10 if args.quick else 300)
    spatial = args.spatial_periods or (3 if args.quick else 100)
    if min(planar, spatial) < 2:
        p.error("each run needs at least 2 periods")

    t0 = time.perf_counter()
    rows = [
        run_case(name, spatial if name == "spatial_5r" else planar, args.out, not args.quick)
        for name in ("planar_3r", "planar_4r", "planar_5r", "spatial_5r")
    ]
    total = time.perf_counter() - t0

    log = TextLog()
    say = log.say

    say(
        f"{'case':<11}{'δ':>2}{'K':>5} {'closure 1st':>11} {'last raw':>9} {'last wrap':>9} "
        f"{'raw≤8T':>7} {'wrapped':>8} {'near return':>13} {'max err m':>9} {'σmin J':>8} "
        f"{'dt/2 apart':>10} {'time s':>6}"
    )
    for r in rows:
        nr = r["near_return_wrapped"]
        apart = (r["dt_half_check"] or {"first_period_apart": "-"})["first_period_apart"]
        say(
            f"{r['case']:<11}{r['delta']:>2}{r['periods']:>5} "
            f"{r['closure_first_raw_rad']:11.2e} {r['closure_last_raw_rad']:9.2e} "
            f"{r['closure_last_wrapped_rad']:9.2e} {fmt_period(r['detect_period']):>7} "
            f"{fmt_period(r['wrapped_period']):>8} {nr['gap_rad']:8.1e}@{nr['multiple']:<4} "
            f"{r['max_tracking_error_m']:9.1e} {r['min_sigma_J']:8.1e} "
            f"{'never' if apart is None else apart:>10} {r['runtime_s']:6.1f}"
        )
    say(f"total {total:.1f} s (including the dt/2 runs)")
    rows_claims = claims(rows)
    for c in rows_claims:
        say(f"{c['id']}: {c['measured']} -> {c['status']}")
    log.write(args.out / "summary.txt")
    write_json(
        args.out / "summary.json", {"cases": rows, "total_runtime_s": total, "claims": rows_claims}
    )
    print(f"wrote {args.out / 'summary.json'} and closure_*.png, joints_*.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
