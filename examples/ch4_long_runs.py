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

Conjecture 4.1 is judged on many starts, not one (one start decides nothing: a random 4R
start, q0 = (0.312, −2.968, 1.593, 0.240), closes on a 36·T cycle): 10 seeded random starts per δ
(uniform in (−π, π]ⁿ, seed n, moved onto the circle's start point by the start IK), 300
periods at T/200 and again at T/400, integrated for all starts at once
(:func:`batch_pinv_sections`, the same scheme and RK4 as ``qc.simulate``, agreeing with it to
4e-16 rad). A start converges when, for some m ≤ 60, the wrapped gap
``‖p_k − p_(k−m)‖`` ends at ≤ 1e-9 rad or decays geometrically by ≥ 2 decades over the last
half of the run (ending ≤ 1e-3 rad). Measured (full run)::

    δ = 1 (3R): 100 % converge at T/200 (all on 30·T cycles), 20 % at T/400
    δ = 2 (4R):  10 % at T/200 and at T/400 (one start on a 36·T cycle; nine drift)
    δ = 3 (5R):   0 % at both steps

Fig 4.7 / Remark 4.4 is judged, in the full run, on the general 5R geometries that put the
thesis's q0 on the Lissajous with Thm 4.2's hypothesis (:func:`geometry_search`: 6 of 100
seeded starts) -- not on qpcoord's arm, reported beside them. :func:`found_arms_study` runs
J⁺ (1/s feedback) from q0 on all of them, 300 periods at T/200 and T/400 (333 s); the rule,
fixed before the first run, is in :func:`found_arm_outcome` and :func:`found_arms_status`.
Measured: 4 arms close on a 1·T cycle at both steps, 1 shows no cycle up to 60·T, 1 loses
the path (σ_min(J) 1.2e-4); none closes over a multiple ≥ 2: differs. Full run 826 s on
the loaded 2-core machine (the search 160 s, the found arms 333 s).

Claims (``summary["claims"]``): Fig 4.7 / Remark 4.4 (above) and the
three clauses of Conjecture 4.1 from the multi-start study (criteria in
:func:`conjecture_claims`): δ = 1 inconclusive (step-dependent), δ = 2 differs (a thesis
error: 9 of 10 starts never converge), δ = 3 reproduced. ``--quick`` (3 starts, 10 periods,
no T/400) decides none of them. The single planar runs above are kept for their figures
(no dt/2 check: they decide nothing).

Run: ``python examples/ch4_long_runs.py [--quick] [--out DIR]``
(``--planar-periods`` / ``--spatial-periods`` change the run lengths).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import qpcoord as qc
from qpcoord.studies.claims import QUICK, claim
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


CONJ_STARTS = 10  # seeded random starts per δ
CONJ_MAX_MULTIPLE = 60  # cycles up to 60·T are looked for (a 4R start closes on 36·T)
CONJ_FLOOR = 1e-9  # rad: a gap this small has reached the round-off floor
CONJ_DECADES = 2.0  # decades of geometric decay over the last half of the run
CONJ_BELOW = 1e-3  # rad: ... and a final gap at most this


def batch_pinv_sections(q_start, path, periods: int, steps: int) -> np.ndarray:
    """Poincaré sections of ``q̇ = J⁺(Ẏ_ref + K(Y_ref − Y))`` (K = CLIK_GAIN) for many starts
    at once on planar unit-link arms in absolute angles, classical RK4 with ``steps`` per period.

    The same scheme and integrator as ``qc.simulate(arm, qc.schemes.PseudoInverse(arm,
    gain=CLIK_GAIN), ...)`` (agrees with it to 4e-16 rad after one period), vectorised over the
    starts: ``J = [−sin q; cos q]``, ``J⁺ = Jᵀ(JJᵀ)⁻¹`` with the 2×2 inverse in closed form.

    Returns
    -------
    numpy.ndarray, shape (periods + 1, starts, n)
        Joint angles (rad) at t = kT.
    """
    q = np.array(q_start, dtype=float)
    dt = path.period / steps
    out = np.empty((periods + 1, *q.shape))
    out[0] = q

    def f(q, t):
        yr, vr = path.position(t), path.velocity(t)
        c, s = np.cos(q), np.sin(q)
        e = vr + CLIK_GAIN * (yr - np.stack([c.sum(1), s.sum(1)], axis=1))
        a, b, d = (s * s).sum(1), -(s * c).sum(1), (c * c).sum(1)  # JJᵀ = [[a, b], [b, d]]
        det = a * d - b * b
        u = (d * e[:, 0] - b * e[:, 1]) / det
        v = (a * e[:, 1] - b * e[:, 0]) / det
        return -s * u[:, None] + c * v[:, None]

    for k in range(periods):
        for i in range(steps):
            t = (k * steps + i) * dt
            k1 = f(q, t)
            k2 = f(q + 0.5 * dt * k1, t + 0.5 * dt)
            k3 = f(q + 0.5 * dt * k2, t + 0.5 * dt)
            k4 = f(q + dt * k3, t + dt)
            q = q + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        out[k + 1] = q
    return out


def geometric_convergence(sections: np.ndarray, max_multiple: int) -> dict:
    """Does one start's section sequence converge to a cycle, judged by the decay of its gap?

    For each multiple ``m``, ``g_m(k) = ‖wrap(p_k − p_{k−m})‖``. The start converges to an
    ``m·T`` cycle if ``g_m`` ends at the round-off floor (≤ CONJ_FLOOR), or if a least-squares
    line through ``log10 g_m`` over the last half of the run falls by ≥ CONJ_DECADES decades
    and ``g_m`` ends ≤ CONJ_BELOW (geometric decay under way). The smallest such ``m`` is
    the period. Criteria set before the runs.
    """
    K = len(sections) - 1
    best = None
    for m in range(1, min(max_multiple, K // 2) + 1):
        g = np.linalg.norm(wrap(sections[m:] - sections[:-m]), axis=1)
        tail = g[len(g) // 2 :]
        x = np.arange(tail.size)
        slope = np.polyfit(x, np.log10(np.maximum(tail, 1e-300)), 1)[0]
        decades = float(-slope * (tail.size - 1))
        if g[-1] <= CONJ_FLOOR or (decades >= CONJ_DECADES and g[-1] <= CONJ_BELOW):
            return {"converges": True, "multiple": m, "final_gap_rad": float(g[-1]),
                    "decades_last_half": decades}  # fmt: skip
        if best is None or g[-1] < best["final_gap_rad"]:
            best = {"converges": False, "multiple": m, "final_gap_rad": float(g[-1]),
                    "decades_last_half": decades}  # fmt: skip
    return best


def random_starts(n: int, count: int, path) -> np.ndarray:
    """``count`` seeded random configurations of the planar nR moved onto the path's start by
    ``qc.inverse_kinematics`` (as ``qc.simulate(start="ik")``); seed ``n``."""
    arm = qc.robots.load("planar_nr", n=n)
    rng = np.random.default_rng(n)
    out = []
    while len(out) < count:
        q0 = rng.uniform(-np.pi, np.pi, n)
        try:
            q = qc.inverse_kinematics(arm, path.position(0.0), q0)
        except ValueError:  # unreachable from there: draw again
            continue
        if np.linalg.norm(arm.position(q) - path.position(0.0)) < 1e-9:
            out.append(q)
    return np.array(out)


def conjecture_study(periods: int, starts: int, step_check: bool) -> list[dict]:
    """Conjecture 4.1 on planar 3R, 4R, 5R (δ = 1, 2, 3): the fraction of seeded random starts
    that converge to a cycle at T/200 (and at T/400 with ``step_check``)."""
    path = qc.paths.Circle(center=(1.5, 0.0), radius=0.5, period=np.pi)
    out = []
    for n in (3, 4, 5):
        t0 = time.perf_counter()
        q_start = random_starts(n, starts, path)
        row = {"n": n, "delta": n - 2, "periods": periods, "starts": starts}
        for steps in (200, 400) if step_check else (200,):
            sec = batch_pinv_sections(q_start, path, periods, steps)
            per = [geometric_convergence(sec[:, j], CONJ_MAX_MULTIPLE) for j in range(starts)]
            row[f"T/{steps}"] = {
                "fraction_converging": sum(p["converges"] for p in per) / starts,
                "per_start": per,
            }
        row["q_start_rad"] = q_start.tolist()
        row["runtime_s"] = time.perf_counter() - t0
        out.append(row)
    return out


def conjecture_claims(study: list[dict]) -> list[dict]:
    """Claim rows for Conjecture 4.1's three clauses from :func:`conjecture_study`.

    Criteria (set before the runs): a δ = 1 or 2 clause ("converges") is reproduced if at least
    90 % of the starts converge at both T/200 and T/400, differs if at most 50 % do at both;
    the δ = 3 clause ("neither periodic nor converges") is reproduced if at most 10 % converge
    at both steps, differs if at least 50 % do at both; anything else, or a run without the
    T/400 check or shorter than DECIDE periods, is inconclusive.
    """
    out = []
    thesis = {
        1: "Conjecture 4.1: δ = 1 or 2 converges (faster for δ = 1)",
        2: "Conjecture 4.1: δ = 1 or 2 converges to a limit cycle",
        3: "Conjecture 4.1: δ > 2 neither periodic nor converges",
    }
    for row in study:
        d = row["delta"]
        fr = {k: v["fraction_converging"] for k, v in row.items() if k.startswith("T/")}
        cyc = sorted({p["multiple"] for p in row["T/200"]["per_start"] if p["converges"]})
        want = d <= 2
        decided = "T/400" in fr and row["periods"] >= DECIDE
        vals = list(fr.values())
        if not decided:
            st = QUICK
        elif want:
            st = (
                "reproduced"
                if min(vals) >= 0.9
                else ("differs" if max(vals) <= 0.5 else "inconclusive")
            )
        else:
            st = (
                "reproduced"
                if max(vals) <= 0.1
                else ("differs" if min(vals) >= 0.5 else "inconclusive")
            )
        measured = (
            ", ".join(f"{100 * v:.0f} % at {k}" for k, v in fr.items())
            + f" of {row['starts']} seeded random starts converge in {row['periods']} periods"
            + (f" (cycles of {', '.join(f'{m}T' for m in cyc)})" if cyc else "")
        )
        note = (
            f"criterion: converging = the gap ‖wrap(p_k − p_(k−m))‖ for some m ≤ "
            f"{CONJ_MAX_MULTIPLE} ends ≤ {CONJ_FLOOR:g} rad or decays geometrically by ≥ "
            f"{CONJ_DECADES:g} decades over the last half of the run (ending ≤ {CONJ_BELOW:g} "
            "rad); "
            + (
                "≥ 90 % converging at T/200 and T/400 reproduces the clause, ≤ 50 % refutes it"
                if want
                else "≤ 10 % converging at T/200 and T/400 reproduces the clause, ≥ 50 % refutes it"
            )
            + "; planar unit-link arm in absolute angles on the circle c = (1.5, 0), R = 0.5, "
            "J⁺ with a 1/s position feedback (the thesis gives no planar experiment)"
        )
        if not decided:
            note += (
                f"; this run ({row['periods']} periods"
                + ("" if "T/400" in fr else ", no T/400 check")
                + f") is too short: the full run ({DECIDE}+ periods, both steps) decides"
            )
        elif st == "differs":
            note += (
                "; the conjecture's clause fails on this arm: a counterexample to a general "
                "statement about serial rotary arms"
            )
        elif st == "inconclusive":
            note += "; a mixed outcome: convergence depends on the start (or on the step)"
        out.append(
            claim(
                f"conj4.1-delta{d}",
                f"With q̇ = J⁺Ẏ on a planar arm with δ = {d}, the joints "
                + ("converge to a limit cycle." if want else "find no cycle."),
                thesis[d],
                measured,
                st,
                note,
                cause="thesis error" if st == "differs" else "",
            )
        )
    return out


#: Geometry search for the thesis's 5R: seeded starts and the threshold
#: on σ_min([J; ω₄; ω₅]) along the Thm 4.2 motion (qpcoord's arm keeps 0.18), fixed before
#: the first search run.
GEOMETRY_STARTS = 100
GEOMETRY_SIGMA = 0.05


def geometry_search(starts: int) -> dict:
    """Search general 5R geometries (``qpcoord.robots.spatial_5r_search``) for one with the
    thesis's q0 on the Lissajous start and Thm 4.2's hypothesis along one period."""
    from qpcoord.robots.spatial_5r_search import search

    t0 = time.perf_counter()
    cands = search(starts=starts, seed=0)
    on = [c for c in cands if c.start_gap_m <= 1e-6]
    sig = np.array([c.sigma_min_thm42 for c in on])
    ok = [c for c in on if c.sigma_min_thm42 >= GEOMETRY_SIGMA]
    return {
        "starts": starts,
        "seed": 0,
        "q0_on_path": len(on),
        "sigma_threshold": GEOMETRY_SIGMA,
        "passing": len(ok),
        "sigma_min_thm42_quantiles": (
            np.percentile(sig, [0, 50, 90, 100]).tolist() if sig.size else []
        ),
        "best_params": (max(on, key=lambda c: c.sigma_min_thm42).params.tolist() if on else []),
        "passing_params": [c.params.tolist() for c in ok],
        "passing_sigma_min_thm42": [float(c.sigma_min_thm42) for c in ok],
        "runtime_s": time.perf_counter() - t0,
    }


#: Long J⁺ runs on the found arms: periods, steps per period (the two
#: steps of the step check) and the tracking error beyond which a run has lost the path.
FOUND_PERIODS = 300
FOUND_STEPS = (200, 400)
FOUND_LOST_M = 1e-2


def found_arm_outcome(per: dict[int, dict], max_err_m: float) -> str:
    """One found arm's outcome from :func:`geometric_convergence` at each step of
    :data:`FOUND_STEPS` (rule fixed before the first run):

    ``"path lost"`` if the tracking error exceeds :data:`FOUND_LOST_M` at either step;
    ``"closes mT"`` (m ≥ 2, the thesis's behaviour) if the sections converge to a cycle at
    both steps with the same multiple m ≥ 2; ``"closes 1T"`` likewise with m = 1; ``"no
    cycle"`` if they converge at neither step; ``"step-dependent"`` otherwise.
    """
    if max_err_m > FOUND_LOST_M:
        return "path lost"
    conv = [p["converges"] for p in per.values()]
    mult = {p["multiple"] for p in per.values() if p["converges"]}
    if all(conv) and len(mult) == 1:
        return "closes 1T" if mult == {1} else "closes mT"
    if not any(conv):
        return "no cycle"
    return "step-dependent"


def found_arms_study(geometry: dict, periods: int = FOUND_PERIODS) -> dict:
    """The long J⁺ run of Fig 4.7 / Remark 4.4 (q̇ = J⁺(Ẏ + K(Y − ζ)), K = CLIK_GAIN, from the
    thesis's q0) on every geometry that passed :func:`geometry_search`, at both steps of
    :data:`FOUND_STEPS`, judged per arm by :func:`found_arm_outcome`."""
    from qpcoord.robots.spatial_5r_search import pinv_sections

    params = np.array(geometry["passing_params"], dtype=float).reshape(-1, 27)
    t0 = time.perf_counter()
    runs = {
        s: pinv_sections(params, qc.robots.spatial_5r.Q0_THESIS, periods, s, CLIK_GAIN)
        for s in FOUND_STEPS
    }
    arms = []
    for j in range(params.shape[0]):
        per = {
            f"T/{s}": geometric_convergence(runs[s].sections[:, j], CONJ_MAX_MULTIPLE)
            for s in FOUND_STEPS
        }
        err = max(float(runs[s].max_tracking_m[j]) for s in FOUND_STEPS)
        last = {
            f"T/{s}": float(wrapped_closure_errors(runs[s].sections[:, j])[-1]) for s in FOUND_STEPS
        }
        arms.append(
            {
                "arm": j,
                "sigma_min_thm42": geometry["passing_sigma_min_thm42"][j],
                "per_step": per,
                "closure_last_wrapped_rad": last,
                "max_tracking_error_m": err,
                "min_sigma_J": min(float(runs[s].min_sigma_J[j]) for s in FOUND_STEPS),
                "outcome": found_arm_outcome(per, err),
            }
        )
    return {
        "periods": periods,
        "steps": list(FOUND_STEPS),
        "arms": arms,
        "runtime_s": time.perf_counter() - t0,
    }


def found_arms_status(study: dict | None) -> tuple[str, str]:
    """``(status, text)`` of Fig 4.7 / Remark 4.4 on the found arms. Rule fixed before the
    first run: reproduced if every arm whose run keeps the path
    "closes mT" (m ≥ 2); differs if none of them closes with m ≥ 2 at either step (all
    "no cycle" or "closes 1T"); inconclusive otherwise (the outcome depends on the arm or
    on the step), or with fewer than two arms that keep the path, runs shorter than
    :data:`DECIDE` periods, or without the study."""
    if study is None:
        return "inconclusive", ""
    valid = [a for a in study["arms"] if a["outcome"] != "path lost"]
    counts: dict[str, int] = {}
    for a in study["arms"]:
        counts[a["outcome"]] = counts.get(a["outcome"], 0) + 1
    mults = sorted({p["multiple"] for a in valid for p in a["per_step"].values() if p["converges"]})
    text = (
        f"J⁺ on the {len(study['arms'])} found arms ({study['periods']} periods at "
        + " and ".join(f"T/{s}" for s in study["steps"])
        + "): "
        + ", ".join(f"{v} {k}" for k, v in sorted(counts.items()))
        + (f" (multiples seen: {', '.join(f'{m}T' for m in mults)})" if mults else "")
    )
    if len(valid) < 2 or study["periods"] < DECIDE:
        return "inconclusive", text
    if all(a["outcome"] == "closes mT" for a in valid):
        return "reproduced", text
    high = [
        a
        for a in valid
        if any(p["converges"] and p["multiple"] >= 2 for p in a["per_step"].values())
    ]
    if not high:
        return "differs", text
    return "inconclusive", text


def claims(rows: list[dict], geometry: dict | None = None, found: dict | None = None) -> list[dict]:
    """Claim row of Fig 4.7 / Remark 4.4.

    It is judged on the *found arms* (``found``, :func:`found_arms_study`: the general 5R
    geometries of the full run's :func:`geometry_search` that put the thesis's q0 on the
    Lissajous with Thm 4.2's hypothesis) by :func:`found_arms_status`; qpcoord's own arm
    (``rows``' ``spatial_5r`` case) is reported beside it. Without a passing geometry the
    thesis's arm is unknown and the row is inconclusive; without the search (``--quick``)
    nothing is decided."""
    by = {r["case"]: cycle_outcome(r) for r in rows}
    case = {r["case"]: r for r in rows}
    half = case["spatial_5r"]["dt_half_check"]
    first = half and half["first_period_apart"]
    ours = by["spatial_5r"][1] + (
        f" (dt and dt/2 sections apart by > {AGREE:g} rad "
        + ("never" if first is None else f"from period {first}")
        + ")"
        if half
        else ""
    )
    rule = (
        "rule fixed before the runs on the found arms: per arm, the sections of J⁺ (1/s "
        f"feedback, {FOUND_PERIODS} periods at T/{FOUND_STEPS[0]} and T/{FOUND_STEPS[1]}) "
        "'close mT' if the gap ‖wrap(p_k − p_(k−m))‖ converges (the Conjecture 4.1 "
        f"criterion, m ≤ {CONJ_MAX_MULTIPLE}) at both steps with the same m ≥ 2; reproduced if "
        "every arm that keeps the path closes mT, differs if none closes with m ≥ 2 at either "
        "step, inconclusive if it depends on the arm or the step; cycles longer than "
        f"{CONJ_MAX_MULTIPLE}·T cannot be seen in this run"
    )
    if geometry is None:
        st, measured = QUICK, "qpcoord's arm: " + ours
        note = rule + "; no geometry search in this run (--quick): the full run decides"
    elif geometry["passing"] == 0:
        st, measured = "inconclusive", "qpcoord's arm: " + ours
        note = (
            rule + "; no 5R geometry in the search has the thesis's q0 on the path with Thm "
            "4.2's hypothesis, so the thesis's arm is unknown"
        )
    else:
        st, text = found_arms_status(found)
        q = geometry["sigma_min_thm42_quantiles"]
        measured = (
            f"{text}; search: {geometry['starts']} seeded general 5R geometries (27 "
            f"parameters, thesis link lengths), q0 on the Lissajous start for "
            f"{geometry['q0_on_path']}, σ_min([J; ω₄; ω₅]) ≥ {GEOMETRY_SIGMA:g} over one "
            f"period for {geometry['passing']} (largest {q[-1]:.3f}); qpcoord's arm: {ours}"
        )
        note = rule + (
            "; the thesis gives no axes: the found arms are the candidates for its arm "
            "(q0 on the path, Thm 4.2's hypothesis), not identified with it"
        )
        if st == "inconclusive":
            note += "; the outcome depends on the arm or the step"
    return [
        claim(
            "rem4.4-fig4.7-5r-closes",
            "Long J⁺ runs of the 5R3D on the Lissajous close, over a high multiple of T.",
            "Remark 4.4, Fig 4.7: 'the joints trajectory is finally closed but over a very "
            "high multiple of the initial period'",
            measured,
            st,
            note,
            cause="our model" if st == "differs" else "",
        )
    ]


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
    p.add_argument(
        "--conjecture-periods",
        type=int,
        default=None,
        help="Conjecture 4.1 study, periods per start (default 300; quick: 10)",
    )
    p.add_argument(
        "--found-periods",
        type=int,
        default=None,
        help=f"J⁺ periods on the found 5R arms (default {FOUND_PERIODS}; full run only)",
    )
    args = p.parse_args(argv)
    planar = args.planar_periods or (10 if args.quick else 300)
    spatial = args.spatial_periods or (3 if args.quick else 100)
    if min(planar, spatial) < 2:
        p.error("each run needs at least 2 periods")

    t0 = time.perf_counter()
    # single-start runs (figures, Remark 4.4); the planar ones do not decide Conjecture 4.1
    # (the multi-start study below does), so only the spatial 5R gets the dt/2 check
    rows = [
        run_case(
            name,
            spatial if name == "spatial_5r" else planar,
            args.out,
            name == "spatial_5r" and not args.quick,
        )
        for name in ("planar_3r", "planar_4r", "planar_5r", "spatial_5r")
    ]
    conj_periods = args.conjecture_periods or (10 if args.quick else 300)
    study = conjecture_study(
        conj_periods, 3 if args.quick else CONJ_STARTS, step_check=not args.quick
    )
    geometry = None if args.quick else geometry_search(GEOMETRY_STARTS)
    found = (
        None
        if geometry is None or not geometry["passing"]
        else found_arms_study(geometry, args.found_periods or FOUND_PERIODS)
    )
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
    say(f"\nConjecture 4.1: seeded random starts, J⁺ (K = {CLIK_GAIN:g}/s), {conj_periods} periods")
    for row in study:
        for key in (k for k in row if k.startswith("T/")):
            per = row[key]["per_start"]
            say(
                f"  δ = {row['delta']} ({row['n']}R) at {key}: "
                f"{100 * row[key]['fraction_converging']:.0f} % converge; per start "
                + ", ".join(
                    (f"{p['multiple']}T" if p["converges"] else "no")
                    + f"({p['final_gap_rad']:.0e})"
                    for p in per
                )
            )
    say(f"total {total:.1f} s (including the dt/2 runs)")
    if geometry is not None:
        say(
            f"5R geometry search: {geometry['starts']} starts, q0 on the path for "
            f"{geometry['q0_on_path']}, σ_min([J; ω₄; ω₅]) ≥ {GEOMETRY_SIGMA:g} for "
            f"{geometry['passing']}; quantiles (0, 50, 90, 100 %) "
            f"{np.round(geometry['sigma_min_thm42_quantiles'], 4).tolist()} "
            f"({geometry['runtime_s']:.0f} s)"
        )
    if found is not None:
        say(f"Fig 4.7 on the found arms ({found['periods']} periods, {found['runtime_s']:.0f} s):")
        for a in found["arms"]:
            say(
                f"  arm {a['arm']} (σ_min Thm 4.2 {a['sigma_min_thm42']:.3f}): {a['outcome']}; "
                + ", ".join(
                    f"{k}: "
                    + (f"{p['multiple']}T" if p["converges"] else "no")
                    + f" (gap {p['final_gap_rad']:.1e} rad, {p['decades_last_half']:.1f} dec)"
                    for k, p in a["per_step"].items()
                )
                + f"; last closure {a['closure_last_wrapped_rad']}; max err "
                f"{a['max_tracking_error_m']:.1e} m, σmin J {a['min_sigma_J']:.2e}"
            )
    rows_claims = claims(rows, geometry, found) + conjecture_claims(study)
    for c in rows_claims:
        say(f"{c['id']}: {c['measured']} -> {c['status']}")
    log.write(args.out / "summary.txt")
    write_json(
        args.out / "summary.json",
        {
            "cases": rows,
            "conjecture_4_1": study,
            "geometry_search_5r": geometry,
            "found_arms_5r": found,
            "total_runtime_s": total,
            "claims": rows_claims,
        },
    )
    print(f"wrote {args.out / 'summary.json'} and closure_*.png, joints_*.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
