"""Franka Panda: a hand pose reached past a sphere, self-collision on, 100 Hz.

A 6 cm sphere (centre (0.47, 0.03, 0.52) m) sits between the hand (``panda_hand_tcp``,
start (0.31, 0, 0.49) m, pointing down) and its targets. The strict stack: level 0
collision avoidance (``CollisionAvoidance``: the sphere against every link, and the 44
self-collision pairs the SRDF leaves; convex hulls; ``d_s`` = 2 cm, ``d_i`` = 10 cm, gain
0.5 m/s: velocity dampers, inequalities), level 1 the hand's full pose (``FrameTask``, gain
5/s), level 2 posture toward the start (1/s); the robot's joint position and speed limits
are hard. dt = 0.01 s. Three phases, the orientation kept:

- ``around``: the target 0.35 m ahead, *behind* the sphere (the straight path crosses it
  3 cm from its centre): the hand slides around the sphere and reaches the pose;
- ``into``: the target at the sphere's centre (unreachable): the hand stops at ``d_s``;
- ``tuck``: the target low, near the robot's base (0.2, 0.1, 0.15) m: link 5 comes onto
  link 1 and the self-collision rows stop it at ``d_s``. A control run without the self
  pairs (``self_collision=False``) shows what they prevent.

Every distance is measured after every step over every pair (coal on the same hulls, the
monitor is a second ``CollisionAvoidance`` whose rows are not used).

The same scenario runs with Pink 4.4 (``pink.solve_ik``, default configuration and speed
limits, same model and hulls, same dt): the sphere is added to Pink's collision model on the
universe joint and the 61 pairs (44 self + 17 sphere) go to one ``SelfCollisionBarrier``
(``h = d − d_s``, ``ḣ ≥ −γ h`` with γ = ξ/(d_i − d_s) = 6.25/s, our damper's rate; its
default safe-displacement cost); the hand a ``FrameTask`` (costs 1, gain ``K dt``), the
posture a ``PostureTask`` (cost 1e-3). Pink has no sphere barrier of its own
(``BodySphericalBarrier`` is between two frame origins) and no priorities.

Measured (full run, 3 s a phase, 2 shared cores, Python engine): the smallest link–sphere
distance over every step is ``d_s`` + 3e-10 m (never below it); the smallest self-pair
distance ``d_s`` + 7e-8 m (without the self pairs −5.7 cm: link 5 inside link 1); pose
error after ``around`` 5.7e-7 (reached around the sphere), ``into`` stops with the hand
0.089 from the sphere's centre (its fingers at ``d_s``), ``tuck`` ends 4.5e-2 from its target
(held off by self-collision; 2.0e-2 without the self pairs). Pink with its default
barrier: the same distances kept (``d_s`` − 3e-8 m), but its safe-displacement cost (gain
1, a ``‖Δq‖²`` term weighted by ``1/‖J_h‖²``) slows it near the sphere: pose error after
``around`` 3.0e-2, and in ``tuck`` it stops 6.4 cm from self-contact; with that cost off
(``safe_displacement_gain=0``) Pink moves like ours (pose error after ``around`` 3.5e-6,
self pairs stopped at ``d_s``). Median step (IK + integrate): qpcoord ≈ 0.27 ms free,
≈ 0.65–0.9 ms with the dampers active (overall ≈ 0.63 ms), Pink ≈ 2.2 ms (it computes
every pair's distance every step; ≈ 3.4×). ``--quick`` (2 s a phase): the same distances,
pose error after ``around`` 9.6e-5 (Pink 5.0e-2). A run prints its numbers.

Claims (``summary["claims"]``, all ``"not in thesis"``, acceptance criteria; each
criterion stated in its note, status computed from the run): the hand and links never come
closer than ``d_s`` to the sphere (tolerance 0.1 mm, the docs' stated tolerance); the self
pairs never closer than ``d_s`` (same tolerance), and without them they collide; the pose
behind the sphere is reached; Pink side by side. Figure: ``distance.png`` (smallest sphere
and self distances and the pose error over time, qpcoord and Pink). Animation:
``panda_obstacle.html`` (one self-contained page, ≈ 15 MB: the Panda's meshes and the
viewer dominate; its size is printed).

Needs the ``robots`` extra (example-robot-data), ``viz`` (meshcat) for the HTML; Pink
(``pip install pin-pink``) for the comparison.

Run: ``python examples/panda_obstacle.py [--quick] [--out DIR]`` (writes ``summary.json``).
"""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

import qpcoord as qc
from qpcoord.studies.claims import claim
from qpcoord.studies.figures import animation as write_animation
from qpcoord.studies.files import write_json

DT = 0.01  # s, control period (100 Hz)
FRAME = "panda_hand_tcp"
SPHERE_CENTRE = (0.47, 0.03, 0.52)  # m
SPHERE_RADIUS = 0.06  # m
GOALS = {  # m, hand target positions (the start orientation is kept)
    "around": (0.65, 0.0, 0.50),
    "into": SPHERE_CENTRE,
    "tuck": (0.20, 0.10, 0.15),
}
D_S, D_I, XI = 0.02, 0.10, 0.5  # m, m, m/s: safety and influence distances, damper gain
HAND_GAIN = 5.0  # 1/s
POSTURE_GAIN = 1.0  # 1/s
PINK_POSTURE_COST = 1e-3
DIST_TOL = 1e-4  # m: a distance "below d_s" beyond this fails (docs/collision.md)
REACH_TOL = {False: 1e-6, True: 1e-3}  # pose error (log6 norm) counted as reached: full, quick


def setup():
    """The robot, its start configuration and the hand targets (4×4, m)."""
    arm = qc.robots.load("panda")
    q0 = arm.reference_configuration("default")
    T0 = arm.frame_pose(q0, FRAME)
    goals = {}
    for name, p in GOALS.items():
        T = T0.copy()
        T[:3, 3] = p
        goals[name] = T
    return arm, q0, goals


def pose_error(arm, q, T) -> float:
    """‖log₆(T*⁻¹ T)‖ of the hand (m and rad mixed, as Pink's FrameTask error)."""
    H = pin.SE3(arm.frame_pose(q, FRAME))
    return float(np.linalg.norm(pin.log6(pin.SE3(T).actInv(H)).vector))


def avoidance(arm, self_collision: bool = True) -> qc.CollisionAvoidance:
    sphere = qc.Sphere(SPHERE_CENTRE, SPHERE_RADIUS)
    return qc.CollisionAvoidance(
        arm,
        obstacles=[sphere],
        self_collision=self_collision,
        min_distance=D_S,
        influence_distance=D_I,
        gain=XI,
    )


def run(solver: str, phases: list[tuple[str, int]]) -> dict:
    """One closed loop: ``solver`` "qpcoord", "qpcoord (no self pairs)", "pink" or "pink
    (no safe displ.)" (its barrier's safe-displacement cost off)."""
    arm, q0, goals = setup()
    monitor = avoidance(arm)  # measures every pair, its rows unused
    on_sphere = np.array(["obstacle" in b for _, b in monitor.pairs])
    if solver.startswith("qpcoord"):
        avoid = avoidance(arm, self_collision=solver == "qpcoord")
        hand = qc.FrameTask(arm, FRAME, goals[phases[0][0]], gain=HAND_GAIN)
        posture = qc.PostureTask(arm, q0, gain=POSTURE_GAIN)
        ik = qc.IK(arm, [avoid, hand, posture], DT, limits="robot")

        def step(q):
            v, _ = ik.step(q)
            return v, arm.integrate(q, v, DT)

        def retarget(T):
            hand.set_target(T)

    else:
        import pink
        from pink.barriers import SelfCollisionBarrier

        logging.getLogger().setLevel(logging.ERROR)  # Pink logs limits it is off by 1e-6
        # the same hulls, sphere (on the universe joint) and pairs as ours
        gm = monitor.geometry_model.copy()
        config = pink.Configuration(
            arm.model, arm.model.createData(), q0.copy(), collision_model=gm
        )
        barrier = SelfCollisionBarrier(
            n_collision_pairs=len(gm.collisionPairs),
            gain=XI / (D_I - D_S),
            d_min=D_S,
            safe_displacement_gain=0.0 if "safe" in solver else 1.0,  # 1.0: Pink's default
        )
        hand = pink.tasks.FrameTask(
            FRAME, position_cost=1.0, orientation_cost=1.0, gain=HAND_GAIN * DT
        )
        posture = pink.tasks.PostureTask(cost=PINK_POSTURE_COST, gain=POSTURE_GAIN * DT)
        posture.set_target(q0)

        def step(q):
            v = pink.solve_ik(
                config,
                [hand, posture],
                DT,
                solver="daqp",
                barriers=[barrier],
                safety_break=False,
            )
            config.integrate_inplace(v, DT)
            return v, config.q.copy()

        def retarget(T):
            hand.set_target(pin.SE3(T))

    q = q0.copy()
    qs, times, d_sphere, d_self, err, phase_end = [q0.copy()], [], [], [], [], {}
    for name, steps in phases:
        T = goals[name]
        retarget(T)
        first = len(times)
        for _ in range(steps):
            t0 = time.perf_counter()
            _, q = step(q)
            times.append(time.perf_counter() - t0)
            d = monitor.compute_distances(q)
            d_sphere.append(float(d[on_sphere].min()))
            d_self.append(float(d[~on_sphere].min()))
            err.append(pose_error(arm, q, T))
            qs.append(q.copy())
        phase_end[name] = {
            "pose_error": err[-1],
            "min_sphere_distance_m": min(d_sphere[first:]),
            "min_self_distance_m": min(d_self[first:]),
            "steps": steps,
            "step_median_us": 1e6 * float(np.median(times[first:])),
        }
    t_us = 1e6 * np.array(times)
    return {
        "solver": solver,
        "steps": len(times),
        "phases": phase_end,
        "min_sphere_distance_m": min(d_sphere),
        "min_self_distance_m": min(d_self),
        "step_median_us": float(np.median(t_us)),
        "step_p99_us": float(np.percentile(t_us, 99)),
        "pairs": len(monitor.pairs),
        # per step; plotted / animated, not written to summary.json
        "series": {"sphere_m": d_sphere, "self_m": d_self, "pose_error": err},
        "q": np.array(qs),
    }


def claims(by: dict[str, dict], quick: bool = False) -> list[dict]:
    """Claim rows computed from the runs (see the module docstring)."""
    reach_tol = REACH_TOL[quick]
    ours, free = by["qpcoord"], by["qpcoord (no self pairs)"]
    s, c = ours["min_sphere_distance_m"], ours["min_self_distance_m"]
    around = ours["phases"]["around"]["pose_error"]
    rows = [
        claim(
            "sphere-kept-at-ds",
            "A hand driven past and into a sphere never comes closer than d_s to it, at any step.",
            "not in thesis (acceptance criterion)",
            f"smallest link–sphere distance {s:.6f} m (d_s = {D_S:g} m, d_s − min = "
            f"{D_S - s:.1e} m) over {ours['steps']} steps of {DT:g} s; the 'into' phase "
            f"ends {ours['phases']['into']['pose_error']:.3f} from the sphere's centre",
            "not in thesis",
            f"criterion: ≥ d_s − {DIST_TOL:g} m at every step (level-0 velocity dampers, "
            f"first-order Euler steps); {'holds' if s >= D_S - DIST_TOL else 'does not hold'}"
            " in this run",
        ),
        claim(
            "self-pairs-kept-at-ds",
            "The Panda's self-collision pairs never come closer than d_s.",
            "not in thesis (acceptance criterion)",
            f"smallest self-pair distance {c:.6f} m with the self pairs, "
            f"{free['min_self_distance_m']:.4f} m without them (same targets)",
            "not in thesis",
            f"criterion: ≥ d_s − {DIST_TOL:g} m at every step, and < d_s without the rows "
            "(the scenario makes them bind); "
            + (
                "holds"
                if c >= D_S - DIST_TOL and free["min_self_distance_m"] < D_S
                else "does not hold"
            )
            + " in this run",
        ),
        claim(
            "pose-reached-around",
            "The pose behind the sphere is reached by going around it (level 1 under level 0).",
            "not in thesis (our scenario)",
            f"pose error after 'around' ({DT * ours['phases']['around']['steps']:g} s) "
            f"{around:.1e} (log6 norm, m and rad)",
            "not in thesis",
            f"our check: ≤ {reach_tol:g}; {'holds' if around <= reach_tol else 'does not hold'}"
            " in this run",
        ),
    ]
    pk = by.get("pink")
    if pk is None:
        rows.append(
            claim(
                "pink-side-by-side",
                "The same scenario with Pink (SelfCollisionBarrier over the same pairs).",
                "not in thesis (peer comparison)",
                "Pink not installed: skipped",
                "not in thesis",
                "pip install pin-pink to run it",
            )
        )
        return rows
    ratio = pk["step_median_us"] / ours["step_median_us"]
    pa = pk["phases"]["around"]["pose_error"]
    p0 = by["pink (no safe displ.)"]
    rows.append(
        claim(
            "pink-side-by-side",
            "The same scenario with Pink (SelfCollisionBarrier over the same pairs).",
            "not in thesis (peer comparison)",
            f"smallest sphere distance: qpcoord {s:.5f} m, Pink {pk['min_sphere_distance_m']:.5f}"
            f" m (safe-displacement cost off: {p0['min_sphere_distance_m']:.5f} m); self: "
            f"qpcoord {c:.5f} m, Pink {pk['min_self_distance_m']:.5f} m "
            f"({p0['min_self_distance_m']:.5f} m); pose error after 'around': qpcoord "
            f"{around:.1e}, Pink {pa:.1e} ({p0['phases']['around']['pose_error']:.1e}); median "
            f"step qpcoord {ours['step_median_us']:.0f} µs, Pink {pk['step_median_us']:.0f} µs "
            f"(Pink / qpcoord {ratio:.2f})",
            "not in thesis",
            "our check: qpcoord keeps d_s (as above) and its pose error after 'around' ≤ "
            f"Pink's (default barrier); "
            f"{'holds' if around <= pa and s >= D_S - DIST_TOL else 'does not hold'} in this "
            "run. Pink's default safe-displacement cost (gain 1) damps the motion near the "
            "sphere: the hand creeps around it",
        )
    )
    return rows


def figure(rows: list[dict], phases: list[tuple[str, int]], path: Path) -> Path:
    """Smallest sphere / self distances and the pose error over time, one style per run."""
    from qpcoord.studies.figures import _pyplot, save

    plt = _pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    styles = {
        "qpcoord": "-",
        "pink": "--",
        "qpcoord (no self pairs)": ":",
        "pink (no safe displ.)": "-.",
    }
    for r in rows:
        t = DT * np.arange(1, r["steps"] + 1)
        ls = styles[r["solver"]]
        axes[0].plot(t, 100 * np.array(r["series"]["sphere_m"]), ls=ls, lw=1, label=r["solver"])
        axes[1].plot(t, 100 * np.array(r["series"]["self_m"]), ls=ls, lw=1, label=r["solver"])
        axes[2].semilogy(
            t, np.maximum(r["series"]["pose_error"], 1e-12), ls=ls, lw=1, label=r["solver"]
        )
    for ax in axes[:2]:
        ax.axhline(100 * D_S, color="k", lw=0.6, ls=":")
        ax.set_ylim(-7, 30)
    t_phase = 0.0
    for name, steps in phases:
        for ax in axes:
            ax.axvline(t_phase, color="grey", lw=0.5)
        axes[0].text(
            t_phase, 0.97, f" {name}", fontsize=7, va="top", transform=axes[0].get_xaxis_transform()
        )
        t_phase += DT * steps
    axes[0].set_ylabel("links–sphere (cm)")
    axes[1].set_ylabel("self pairs (cm)")
    axes[2].set_ylabel("hand pose error")
    axes[2].set_xlabel("t (s)")
    axes[0].set_title("Panda: collision (0) > hand pose (1) > posture (2); dotted: d_s")
    axes[0].legend(fontsize=7)
    return save(fig, path)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="2 s a phase, few frames (CI)")
    p.add_argument("--out", type=Path, default=Path("out/panda_obstacle"))
    args = p.parse_args(argv)
    try:
        qc.robots.load("panda")
    except ValueError as exc:  # example-robot-data missing
        print(f"skipped: {exc}")
        return 0
    n = 200 if args.quick else 300
    phases = [("around", n), ("into", n), ("tuck", n)]
    solvers = ["qpcoord", "qpcoord (no self pairs)"]
    try:
        import pink  # noqa: F401

        solvers += ["pink", "pink (no safe displ.)"]
    except ImportError:
        print("Pink not installed (pip install pin-pink): comparison skipped")
    by = {s: run(s, phases) for s in solvers}
    print(f"{by['qpcoord']['pairs']} pairs (44 self + 17 sphere); d_s = {D_S} m")
    print(
        f"{'solver':<24} {'phase':<6} {'pose err':>9} {'sphere (m)':>10} {'self (m)':>9} "
        f"{'median µs':>9}"
    )
    for r in by.values():
        for name, e in r["phases"].items():
            print(
                f"{r['solver']:<24} {name:<6} {e['pose_error']:9.1e} "
                f"{e['min_sphere_distance_m']:10.6f} {e['min_self_distance_m']:9.5f} "
                f"{e['step_median_us']:9.0f}"
            )
    print(
        f"{'solver':<24} {'min sphere (m)':>14} {'penetration':>11} {'min self (m)':>12} "
        f"{'median µs':>9} {'p99 µs':>7}"
    )
    for r in by.values():
        pen = max(0.0, -r["min_sphere_distance_m"], -r["min_self_distance_m"])
        print(
            f"{r['solver']:<24} {r['min_sphere_distance_m']:14.6f} {pen:11.1e} "
            f"{r['min_self_distance_m']:12.6f} {r['step_median_us']:9.0f} {r['step_p99_us']:7.0f}"
        )
    if "pink" in by:
        ratio = by["pink"]["step_median_us"] / by["qpcoord"]["step_median_us"]
        print(f"median step time Pink / qpcoord: {ratio:.2f}")
    rows_claims = claims(by, args.quick)
    for c in rows_claims:
        print(f"{c['id']}: {c['measured']} -> {c['status']}")
    try:
        figure(list(by.values()), phases, args.out / "distance.png")
    except ImportError:  # matplotlib missing (the ``plots`` extra)
        print("matplotlib not installed: figure skipped")
    arm, _, goals = setup()
    html = write_animation(
        arm,
        by["qpcoord"]["q"],
        args.out / "panda_obstacle.html",
        dt=DT,
        targets=list(goals.values()),
        obstacles=[qc.Sphere(SPHERE_CENTRE, SPHERE_RADIUS)],
        fps=5 if args.quick else 25,
    )
    done = f"wrote {html['html']} ({html['html_mb']} MB)" if html["html"] else None
    print(done or f"animation skipped: {html['html_reason']}")
    rows = [{k: v for k, v in r.items() if k not in ("series", "q")} for r in by.values()]
    write_json(
        args.out / "summary.json",
        {
            "phases": phases,
            "rows": rows,
            "pink": "pink" in by,
            **html,
            "claims": rows_claims,
        },
    )
    print(f"wrote {args.out / 'summary.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
