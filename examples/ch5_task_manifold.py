"""Chapter 5, Def. 5.1 / Figs 5.1 and 5.3: the task manifold of the 3R arm on the circle.

The task manifold is the union of the redundancy fibres (self-motion curves) over the
points of the path. For the planar 3R arm (absolute angles) on the circle of Fig. 5.9
(``qc.paths.Circle()``: c = (1.5, 0) m, R = 0.5 m, T = π s) it is a torus S¹ × S¹ (§5.2.1).
This script traces it with :func:`qpcoord.coordination.task_manifold.fibre` through N points of the
path
(at ``t = (k + ½) T/N``, each configuration moved exactly onto the path point by
``inverse_kinematics``), and draws in the joint space (angles wrapped to (−π, π], lines
broken at the wraps):

- blue: the fibres (self-motions: same end-effector point, Fig. 5.1's blue curves);
- red: 2.5 periods of ``J⁺`` (``qc.schemes.PseudoInverse``, open loop, from
  ``q0 = (0, π/3, −π/3)``: Fig. 5.1's red curve);
- black: the limit cycle of the soft extension ``g = 3(q₁ − π/2)²`` (Thm 5.1, gain 10/s,
  last of 8 periods: Fig. 5.3's periodic trajectory on the torus).

It reports the fibre lengths (rad, arc length in joint space) along the path, how many
fibres close without winding (every joint back to its start, not by ±2π), and the fibre
at the one point of the path with ``|y| = 1`` (``y = (1, 0)``, ``t = T/2``).

Measured (full run, N = 40 fibres, step 0.02 rad):

- fibre length from 9.63 rad (next to the start y = (2, 0), ``|y| = 2``) to 25.56 rad (next
  to y = (1, 0)); all 40 close without winding;
- at ``y = (1, 0)`` (``|y| = 1``, t = T/2) the torus is pinched: besides the ordinary
  branch, the folded family ``q₁ = 0, q₃ = q₂ + π`` (links 2 and 3 cancel) reaches the
  point, and the two meet at the singular configuration ``q = (π, 0, 0)``. The fibre
  traced from the exact point (``inverse_kinematics`` to 1e-12 m), and from the open-loop
  ``J⁺`` configuration there (``|y| = 1 − 5e-10``), comes out as a closed 8.886 rad curve
  that winds once in q₂ and q₃ (smallest σ(J) met on it: 4.4e-3): the tracer crosses
  the pinch onto the folded branch (green dashed in the figure);
- ``J⁺`` (max tracking error 6.5e-9 m) does not close: ``‖q(2T) − q(0)‖ = 0.611`` rad;
  the limit cycle of ``g = 3(q₁ − π/2)²`` closes to < 1e-6 rad from period 5 (5.2e-12 in
  period 8).

Claims (``summary["claims"]``, computed from the run): §5.2.1's torus (differs: every
traced fibre closes, but the singular configuration (π, 0, 0) lies on the task manifold at
y = (1, 0), where the fibre changes winding: a pinched torus); Fig 5.1's red J⁺ curve does
not close; Fig 5.3's limit cycle closes (``--quick``: 3 periods, inconclusive).

Figures: ``task_manifold.png`` (3-D, wrapped angles), ``fibre_lengths.png``.

Run: ``python examples/ch5_task_manifold.py [--quick] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import qpcoord as qc
from qpcoord.coordination.extensions import SoftExtension
from qpcoord.coordination.periodicity import closure_errors, periods_to_closure
from qpcoord.coordination.potentials import JointCentring
from qpcoord.coordination.task_manifold import fibre, wrap_angles
from qpcoord.studies.claims import QUICK, claim
from qpcoord.studies.files import TextLog, write_json

Q0 = np.array([0.0, np.pi / 3, -np.pi / 3])  # thesis Fig. 5.9
Q_FOLDED = np.array([np.pi, 0.0, 0.0])  # rad: the arm folded flat, |y| = 1
SINGULAR_TOL = 1e-12  # σ_min(J) and distance to the circle (m) counted as zero
OPEN_MIN = 1e-3  # rad: J⁺ gap after 2 periods counted as "not closed"
CLOSED = 1e-6  # rad per period: closed
CLOSED_PERIODS = 3  # the last ≥ 3 periods below CLOSED


def winding(points: np.ndarray) -> list[int]:
    """Whole turns per joint accumulated around a closed fibre."""
    total = points[-1] - points[0] + wrap_angles(points[0] - points[-1])
    return [int(v) for v in np.round(total / (2 * np.pi))]


def broken(q: np.ndarray) -> np.ndarray:
    """Wrapped angles with NaN rows inserted where a coordinate jumps by a wrap."""
    w = wrap_angles(q)
    jump = np.any(np.abs(np.diff(w, axis=0)) > np.pi, axis=1)
    out = []
    for i, row in enumerate(w):
        out.append(row)
        if i < len(jump) and jump[i]:
            out.append(np.full(w.shape[1], np.nan))
    return np.array(out)


def run(n_fibres: int, step: float, cycle_periods: int, spp: int) -> tuple[dict, dict]:
    arm = qc.robots.load("planar_3r")
    path = qc.paths.Circle()
    T = path.period
    t0 = time.perf_counter()
    pinv = qc.simulate(arm, qc.schemes.PseudoInverse(arm), path, Q0, 2.5 * T, T / spp, start="q0")
    scheme = SoftExtension(arm, JointCentring(np.pi / 2, 3.0, joints=[0]), "nullspace", gain=10.0)
    soft = qc.simulate(arm, scheme, path, Q0, cycle_periods * T, T / spp, start="q0")
    soft_closure = closure_errors(soft, T)
    t_sim = time.perf_counter() - t0

    t0 = time.perf_counter()
    fibres, rows = [], []
    for k in range(n_fibres):
        t = (k + 0.5) * T / n_fibres
        y = path.position(t)
        q = qc.inverse_kinematics(arm, y, pinv.q[int(round(t / (T / spp)))])
        pts, length = fibre(arm, q, step=step)
        fibres.append(pts)
        rows.append(
            {
                "t_s": t,
                "y_m": y.tolist(),
                "norm_y_m": float(np.linalg.norm(y)),
                "length_rad": length,
                "winding": winding(pts),
            }
        )
    t_fib = time.perf_counter() - t0

    # the pinch of the torus: y = (1, 0) exactly, and the open-loop J⁺ point there
    def sigma_min(pts) -> float:
        return float(min(np.linalg.svd(arm.jacobian(q), compute_uv=False)[-1] for q in pts))

    pinch: dict = {}
    fibres_extra = []
    q_half = qc.inverse_kinematics(arm, path.position(T / 2), pinv.q[spp // 2])
    q_in = pinv.q[spp // 2]
    for tag, q in (("exact_y_1_0", q_half), ("pinv_point_at_half_period", q_in)):
        entry = {"norm_y_m": float(np.linalg.norm(arm.position(q)))}
        try:
            pts, length = fibre(arm, q, step=step)
        except ValueError as exc:
            entry["error"] = str(exc)
        else:
            entry.update(length_rad=length, winding=winding(pts), min_sigma_J=sigma_min(pts))
            fibres_extra.append(pts)
        pinch[tag] = entry
    lengths = np.array([r["length_rad"] for r in rows])
    y_f = arm.position(Q_FOLDED)
    folded = {
        "q_rad": Q_FOLDED.tolist(),
        "y_m": y_f.tolist(),
        "distance_to_circle_m": float(abs(np.linalg.norm(y_f - path.center) - path.radius)),
        "sigma_min_J": float(np.linalg.svd(arm.jacobian(Q_FOLDED), compute_uv=False)[-1]),
    }
    p_sec = qc.analysis.poincare_section(pinv, T)
    result = {
        "robot": "planar_3r",
        "path": "Circle c=(1.5,0) R=0.5 T=π (Fig 5.9)",
        "n_fibres": n_fibres,
        "fibre_step_rad": step,
        "fibre_length_min_rad": float(lengths.min()),
        "fibre_length_max_rad": float(lengths.max()),
        "fibres_closing_without_winding": int(sum(not any(r["winding"]) for r in rows)),
        "fibres": rows,
        "pinch": pinch,
        "folded_configuration": folded,
        "cycle_periods": cycle_periods,
        "pinv_gap_after_2_periods_rad": float(np.linalg.norm(p_sec[2] - p_sec[0])),
        "pinv_max_tracking_error_m": pinv.max_error,
        "soft_alpha": 3.0,
        "soft_closure_error_per_period_rad": soft_closure.tolist(),
        "soft_periods_to_closure_1e-6": periods_to_closure(soft_closure),
        "pinv_periods_to_closure_1e-6": periods_to_closure(closure_errors(pinv, T)),
        "runtime_simulations_s": t_sim,
        "runtime_fibres_s": t_fib,
    }
    return result, {
        "fibres": fibres,
        "extra": fibres_extra,
        "pinv": pinv,
        "cycle": soft.q[-spp - 1 :],
    }


def claims(result: dict) -> list[dict]:
    """Claim rows computed from the run (see the module docstring)."""
    n = result["n_fibres"]
    windings = [tuple(r["winding"]) for r in result["fibres"]]
    windings += [tuple(e["winding"]) for e in result["pinch"].values() if "winding" in e]
    same = len(set(windings)) == 1
    f = result["folded_configuration"]
    singular_on = f["sigma_min_J"] < SINGULAR_TOL and f["distance_to_circle_m"] < SINGULAR_TOL
    gap = result["pinv_gap_after_2_periods_rad"]
    c = np.asarray(result["soft_closure_error_per_period_rad"])
    k = result["soft_periods_to_closure_1e-6"]
    closed = k is not None and len(c) - k + 1 >= CLOSED_PERIODS
    return [
        claim(
            "sec5.2.1-torus",
            "The 3R task manifold of a circle is homeomorphic to a torus S¹ × S¹.",
            "§5.2.1, Def 5.1, Fig 5.1 (circle of Fig 5.9: c = (1.5, 0), R = 0.5)",
            f"{result['fibres_closing_without_winding']}/{n} fibres along the path close "
            f"without winding ({result['fibre_length_min_rad']:.2f}–"
            f"{result['fibre_length_max_rad']:.2f} rad); windings met {sorted(set(windings))}; "
            f"(π, 0, 0) is {f['distance_to_circle_m']:.0e} m from the circle with σ_min(J) = "
            f"{f['sigma_min_J']:.0e}",
            "reproduced" if same and not singular_on else "differs",
            "criterion: every fibre closed with one winding and no singular configuration on "
            "the task manifold"
            + (
                "; at y = (1, 0) the arm can fold flat: the singular (π, 0, 0) lies on the "
                "task manifold, where the ordinary fibres meet the folded branch "
                "q₁ = 0, q₃ = q₂ + π (the fibre traced there has another winding): a "
                "pinched torus, not a torus"
                if not (same and not singular_on)
                else ""
            ),
        ),
        claim(
            "fig5.1-pinv-not-closed",
            "J⁺ alone (Fig 5.1's red curve, 2.5 periods) does not close on the torus.",
            "Fig 5.1, Remark 5.2",
            f"‖q(2T) − q(0)‖ = {gap:.3f} rad (max tracking error "
            f"{result['pinv_max_tracking_error_m']:.1e} m)",
            "reproduced" if gap > OPEN_MIN else "differs",
            f"criterion: gap > {OPEN_MIN:g} rad",
        ),
        claim(
            "fig5.3-limit-cycle",
            "With g = 3(q₁ − π/2)² the joints settle on a closed cycle on the torus.",
            "Fig 5.3, Thm 5.1",
            f"closure per period {', '.join(f'{e:.1e}' for e in c)} rad; "
            + (f"closed from period {k}" if k is not None else f"not closed in {len(c)} periods"),
            "reproduced" if closed else (QUICK if result["cycle_periods"] < 8 else "differs"),
            f"criterion: closure < {CLOSED:g} rad over the last ≥ {CLOSED_PERIODS} periods"
            + (
                f"; {result['cycle_periods']} periods: the full run (8) decides"
                if not closed and result["cycle_periods"] < 8
                else ""
            ),
        ),
    ]


def figures(result, data, out: Path, say) -> None:
    try:
        from qpcoord.studies.figures import _pyplot, save
    except ImportError:  # pragma: no cover - matplotlib missing
        say("matplotlib not installed: figures skipped")
        return
    plt = _pyplot()
    fig = plt.figure(figsize=(7.5, 6.5))
    ax = fig.add_subplot(projection="3d")
    for i, pts in enumerate(data["fibres"]):
        w = broken(np.vstack((pts, pts[:1])))
        ax.plot(*w.T, color="tab:blue", lw=0.6, alpha=0.7, label="fibres" if i == 0 else None)
    for pts in data["extra"][:1]:
        w = broken(np.vstack((pts, pts[:1])))
        ax.plot(*w.T, color="tab:green", lw=1.2, ls="--", label="fibre at y = (1, 0)")
    w = broken(data["pinv"].q)
    ax.plot(*w.T, color="tab:red", lw=1.6, label="J⁺, 2.5 periods")
    w = broken(data["cycle"])
    ax.plot(*w.T, color="k", lw=2.0, label="limit cycle, g = 3(q1 − π/2)²")
    ax.set_xlabel("q1 (rad)")
    ax.set_ylabel("q2 (rad)")
    ax.set_zlabel("q3 (rad)")
    ax.set_title("Fig 5.1 / 5.3: task manifold of the 3R on the circle", fontsize=10)
    ax.legend(fontsize=8, loc="upper left")
    save(fig, out / "task_manifold.png")

    fig, ax = plt.subplots(figsize=(6.5, 3.4))
    t = [r["t_s"] for r in result["fibres"]]
    ax.plot(t, [r["length_rad"] for r in result["fibres"]], "o-", ms=3)
    ax.set_xlabel("path time t (s) of the fibre's end-effector point")
    ax.set_ylabel("fibre length (rad)")
    ax.set_title("Self-motion fibre length along the circle (|y| = 1 at t = T/2)", fontsize=9)
    save(fig, out / "fibre_lengths.png")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="10 fibres, coarse steps (CI)")
    p.add_argument("--out", type=Path, default=Path("out/ch5_task_manifold"))
    args = p.parse_args(argv)
    log = TextLog()
    say = log.say

    if args.quick:
        result, data = run(n_fibres=10, step=0.05, cycle_periods=3, spp=100)
    else:
        result, data = run(n_fibres=40, step=0.02, cycle_periods=8, spp=200)
    say(
        f"{result['n_fibres']} fibres: length {result['fibre_length_min_rad']:.3f} … "
        f"{result['fibre_length_max_rad']:.3f} rad; "
        f"{result['fibres_closing_without_winding']} close without winding"
    )
    for r in result["fibres"]:
        say(
            f"  t = {r['t_s']:6.3f} s  |y| = {r['norm_y_m']:.4f} m  length "
            f"{r['length_rad']:7.3f} rad  winding {r['winding']}"
        )
    for key, e in result["pinch"].items():
        if "error" in e:
            say(f"fibre through {key} (|y| = {e['norm_y_m']:.10f} m): {e['error']}")
        else:
            say(
                f"fibre through {key} (|y| = {e['norm_y_m']:.10f} m): length "
                f"{e['length_rad']:.4f} rad, winding {e['winding']}, min σ(J) on it "
                f"{e['min_sigma_J']:.1e}"
            )
    say(
        f"J⁺: gap q(2T) − q(0) = {result['pinv_gap_after_2_periods_rad']:.3f} rad, "
        f"max tracking error {result['pinv_max_tracking_error_m']:.1e} m"
    )
    c = result["soft_closure_error_per_period_rad"]
    say(
        f"soft extension α = 3: closure per period {', '.join(f'{e:.1e}' for e in c)}; "
        f"closed (< 1e-6) from period {result['soft_periods_to_closure_1e-6']}"
    )
    figures(result, data, args.out, say)
    result["claims"] = claims(result)
    for c in result["claims"]:
        say(f"{c['id']}: {c['measured']} -> {c['status']}")
    log.write(args.out / "summary.txt")
    write_json(args.out / "summary.json", result)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
