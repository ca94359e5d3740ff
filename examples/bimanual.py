"""Talos carries a box between its hands: feet fixed, relative hand pose held, hands apart.

From the SRDF's ``half_sitting`` (free-flyer root, nq 39 / nv 38), a strict four-level
stack at 100 Hz (dt = 0.01 s, Euler steps on the configuration manifold): level 0 holds
each sole's full pose (``FrameTask``, deadbeat gain 1/dt) **and** keeps the hands apart
(``CollisionAvoidance`` restricted to the wrists and grippers, ``frames=`` arm links 5–7 and
the gripper bases of both arms: 16 pairs, convex hulls, ``d_s`` = 5 cm, ``d_i`` = 15 cm,
gain 0.5 m/s); level 1 the right gripper's pose *in the left gripper's frame*
(``RelativeFrameTask``: the box); level 2 the left gripper's pose in the world
(``FrameTask``: moves the pair); level 3 posture toward ``half_sitting``. Joint position
and speed limits are hard. Three phases:

- ``grasp``: the hands come in front of the robot, 0.30 m apart, facing each other;
- ``carry``: the left hand moves 5 cm forward, 10 cm left, 10 cm up and turns 0.3 rad about
  the vertical, the relative pose held: the right hand follows (the box is carried);
- ``squeeze`` (the relative target asks the hands 3 cm apart, a crushed box): level 0 stops
  the wrists at ``d_s`` and level 1 does what is left.

Two Talos arms rather than two Panda arms: the humanoid makes the feet a real level-0
constraint (the floating base moves), and one robot model carries both arms, so the
relative task and the hand pairs are within one model.

The same scenario runs with Pink 4.4 where it can be expressed: the feet, the
``RelativeFrameTask`` (``pink.tasks.RelativeFrameTask(frame, root)``), the left hand and
the posture as costs (feet 10, relative 1, hand 1, posture 1e-3; gains ``K dt``), the
hands kept apart by ``SelfCollisionBarrier`` over the same 16 pairs and hulls
(``γ = ξ/(d_i − d_s)`` = 5/s, its default safe-displacement cost).

Measured (full run, 2 s a phase, 2 shared cores, Python engine; a run prints its own):
relative pose error in the second half of ``carry`` ≤ 5.5e-5 (6.3e-6 at its end; log6
norm, m and rad) while the left hand moves (5.9e-3 from its target at the end, gain 2/s);
the hands' hulls never closer than ``d_s`` (``squeeze`` ends at ``d_s`` + 2e-5 m, the
relative error left at 0.14); feet drift 1.1e-3 m during ``grasp`` (the arms swing at their
speed limits: a first-order Euler step at dt = 0.01 s, corrected at the next step by the
deadbeat level 0), 7e-6 m in ``carry``, 8e-4 m in ``squeeze``. Pink (costs): relative error
in ``carry`` 1.0e-2, left hand 8.1e-2 (the two tasks trade against each other), hands at
``d_s`` + 7e-6 m, feet 4.2e-5 m (it moves slower). Median step: qpcoord 1.1 ms, 3.4 ms
with the hands' dampers active (``squeeze``), p99 ≈ 50 ms (a few slow hierarchical solves
on the loaded machine); Pink ≈ 0.97 ms. ``--quick`` (1.5 s a phase): relative error in
``carry`` ≤ 9e-5 (Pink 1.1e-2), hands ≥ ``d_s``, feet 1.1e-3 m.

Claims (``summary["claims"]``, all ``"not in thesis"``, acceptance criteria; criteria
in the notes, statuses computed from the run): the relative pose is held while the pair
moves; the hands never closer than ``d_s``; the feet stay put; Pink side by side.
Figure: ``bimanual.png`` (relative pose error, hands' distance, feet drift over time).
Animation: ``bimanual.html`` (self-contained, ≈ 12 MB: Talos's meshes dominate).

Needs the ``robots`` extra (example-robot-data), ``viz`` (meshcat) for the HTML; Pink
(``pip install pin-pink``) for the comparison.

Run: ``python examples/bimanual.py [--quick] [--out DIR]`` (writes ``summary.json``).
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
SOLES = ("left_sole_link", "right_sole_link")
LEFT, RIGHT = "gripper_left_base_link", "gripper_right_base_link"
#: links taking part in "hands apart": wrists and gripper bases of both arms
LINKS = [f"arm_{s}_{i}_link" for s in ("left", "right") for i in (5, 6, 7)] + [LEFT, RIGHT]
GRASP_LEFT = (0.40, 0.15, 0.85)  # m, left gripper in front; the right one mirrored in y
CARRY = (0.05, 0.10, 0.10)  # m, left gripper moved by this in "carry" ...
CARRY_YAW = 0.3  # rad, ... and turned by this about the vertical
SQUEEZE = 0.1  # the relative target's translation scaled by this in "squeeze" (3 cm)
D_S, D_I, XI = 0.05, 0.15, 0.5  # m, m, m/s: hands-apart safety / influence, damper gain
REL_GAIN = 10.0  # 1/s, relative task (the box)
HAND_GAIN = 2.0  # 1/s, left-hand task
POSTURE_GAIN = 1.0  # 1/s
PINK_COSTS = {"feet": 10.0, "relative": 1.0, "hand": 1.0, "posture": 1e-3}
REL_TOL = 1e-4  # relative pose error (log6 norm) during "carry" counted as held
DIST_TOL = 1e-4  # m: a hands' distance "below d_s" beyond this fails
FEET_TOL = 2e-3  # m, feet drift (Euler step at dt = 0.01 s)


def setup():
    """Talos, ``half_sitting`` and the phases: (name, left-hand target, relative target)."""
    robot = qc.robots.load("talos")
    q0 = robot.reference_configuration("half_sitting")
    TL, TR = robot.frame_pose(q0, LEFT).copy(), robot.frame_pose(q0, RIGHT).copy()
    TL[:3, 3] = GRASP_LEFT
    TR[:3, 3] = np.multiply(GRASP_LEFT, (1, -1, 1))
    rel = np.linalg.inv(TL) @ TR  # right gripper in the left gripper's frame (0.30 m apart)
    carry = TL.copy()
    carry[:3, 3] += CARRY
    carry[:3, :3] = pin.rpy.rpyToMatrix(0.0, 0.0, CARRY_YAW) @ TL[:3, :3]
    squeeze = rel.copy()
    squeeze[:3, 3] *= SQUEEZE
    phases = [("grasp", TL, rel), ("carry", carry, rel), ("squeeze", carry, squeeze)]
    return robot, q0, phases


def apart_task(robot) -> qc.CollisionAvoidance:
    return qc.CollisionAvoidance(
        robot,
        self_collision=True,
        frames=LINKS,
        min_distance=D_S,
        influence_distance=D_I,
        gain=XI,
    )


def log6(A: np.ndarray, B: np.ndarray) -> float:
    """‖log₆(A⁻¹ B)‖ (m and rad mixed, as Pink's errors)."""
    return float(np.linalg.norm(pin.log6(pin.SE3(A).actInv(pin.SE3(B))).vector))


def run(solver: str, steps: int) -> dict:
    """One closed loop, ``solver`` "qpcoord" or "pink"; ``steps`` per phase."""
    robot, q0, phases = setup()
    monitor = apart_task(robot)  # measures the 16 pairs, its rows unused
    feet0 = [robot.frame_pose(q0, s)[:3, 3].copy() for s in SOLES]
    if solver == "qpcoord":
        feet = [qc.FrameTask(robot, s, gain=1.0 / DT) for s in SOLES]
        for foot in feet:
            foot.set_target_from_configuration(q0)
        rel = qc.RelativeFrameTask(robot, RIGHT, LEFT, phases[0][2], gain=REL_GAIN)
        hand = qc.FrameTask(robot, LEFT, phases[0][1], gain=HAND_GAIN)
        posture = qc.PostureTask(robot, q0, gain=POSTURE_GAIN)
        levels = [[*feet, apart_task(robot)], rel, hand, posture]
        ik = qc.IK(robot, levels, DT)  # limits="robot": position and speed, hard

        def step(q):
            v, _ = ik.step(q)
            return robot.integrate(q, v, DT)

        def retarget(TL, Trel):
            hand.set_target(TL)
            rel.set_target(Trel)

    else:
        import pink
        from pink.barriers import SelfCollisionBarrier
        from pink.tasks import FrameTask, PostureTask, RelativeFrameTask

        logging.getLogger().setLevel(logging.ERROR)  # Pink logs limits it is off by 1e-6
        gm = monitor.geometry_model.copy()  # same hulls and pairs
        config = pink.Configuration(
            robot.model, robot.model.createData(), q0.copy(), collision_model=gm
        )
        c = PINK_COSTS
        feet = [FrameTask(s, c["feet"], c["feet"], gain=1.0) for s in SOLES]
        for foot in feet:
            foot.set_target_from_configuration(config)
        rel = RelativeFrameTask(RIGHT, LEFT, c["relative"], c["relative"], gain=REL_GAIN * DT)
        hand = FrameTask(LEFT, c["hand"], c["hand"], gain=HAND_GAIN * DT)
        posture = PostureTask(cost=c["posture"], gain=POSTURE_GAIN * DT)
        posture.set_target(q0)
        barrier = SelfCollisionBarrier(
            n_collision_pairs=len(gm.collisionPairs), gain=XI / (D_I - D_S), d_min=D_S
        )
        tasks = [*feet, rel, hand, posture]

        def step(q):
            v = pink.solve_ik(
                config, tasks, DT, solver="daqp", barriers=[barrier], safety_break=False
            )
            config.integrate_inplace(v, DT)
            return config.q.copy()

        def retarget(TL, Trel):
            hand.set_target(pin.SE3(TL))
            rel.set_target(pin.SE3(Trel))

    q = q0.copy()
    qs, times, phase_end = [q0.copy()], [], {}
    series = {k: [] for k in ("relative", "hand", "hands_m", "feet_m")}
    for name, TL, Trel in phases:
        retarget(TL, Trel)
        first = len(times)
        for _ in range(steps):
            t0 = time.perf_counter()
            q = step(q)
            times.append(time.perf_counter() - t0)
            HL, HR = robot.frame_pose(q, LEFT), robot.frame_pose(q, RIGHT)
            series["relative"].append(log6(Trel, np.linalg.inv(HL) @ HR))
            series["hand"].append(log6(TL, HL))
            series["hands_m"].append(float(monitor.compute_distances(q).min()))
            series["feet_m"].append(
                max(
                    float(np.linalg.norm(robot.frame_pose(q, s)[:3, 3] - p0))
                    for s, p0 in zip(SOLES, feet0, strict=True)
                )
            )
            qs.append(q.copy())
        seg = slice(first, len(times))
        phase_end[name] = {
            "relative_error": series["relative"][-1],
            "relative_error_max_last_half": max(series["relative"][first + steps // 2 :]),
            "hand_error": series["hand"][-1],
            "min_hands_distance_m": min(series["hands_m"][seg]),
            "feet_drift_m": max(series["feet_m"][seg]),
            "step_median_us": 1e6 * float(np.median(times[seg])),
        }
    t_us = 1e6 * np.array(times)
    return {
        "solver": solver,
        "steps": len(times),
        "phases": phase_end,
        "min_hands_distance_m": min(series["hands_m"]),
        "feet_drift_m": max(series["feet_m"]),
        "step_median_us": float(np.median(t_us)),
        "step_p99_us": float(np.percentile(t_us, 99)),
        "pairs": len(monitor.pairs),
        "series": series,  # plotted / animated, not written to summary.json
        "q": np.array(qs),
    }


def claims(by: dict[str, dict]) -> list[dict]:
    """Claim rows computed from the runs (see the module docstring)."""
    ours = by["qpcoord"]
    carry = ours["phases"]["carry"]
    held = carry["relative_error_max_last_half"]
    d, feet = ours["min_hands_distance_m"], ours["feet_drift_m"]
    rows = [
        claim(
            "relative-pose-held",
            "The hands' relative pose (level 1) is held while the left hand moves the pair "
            "(level 2).",
            "not in thesis (acceptance criterion)",
            f"relative pose error during 'carry' (its second half) ≤ {held:.1e}, at its end "
            f"{carry['relative_error']:.1e}; left-hand error at its end "
            f"{carry['hand_error']:.1e} (log6 norms, m and rad)",
            "not in thesis",
            f"criterion: ≤ {REL_TOL:g}; {'holds' if held <= REL_TOL else 'does not hold'} in "
            "this run",
        ),
        claim(
            "hands-kept-apart",
            "The wrists and grippers never come closer than d_s, even when the relative task "
            "asks them to.",
            "not in thesis (acceptance criterion)",
            f"smallest distance between the two arms' wrist/gripper hulls {d:.6f} m "
            f"(d_s = {D_S:g} m); 'squeeze' leaves the relative error at "
            f"{ours['phases']['squeeze']['relative_error']:.3f}",
            "not in thesis",
            f"criterion: ≥ d_s − {DIST_TOL:g} m at every step; "
            f"{'holds' if d >= D_S - DIST_TOL else 'does not hold'} in this run",
        ),
        claim(
            "feet-fixed",
            "Both soles stay put (level 0) while the arms move.",
            "not in thesis (acceptance criterion)",
            f"max sole displacement {feet:.1e} m over {ours['steps']} steps of {DT:g} s "
            f"(grasp {ours['phases']['grasp']['feet_drift_m']:.1e} m, carry "
            f"{carry['feet_drift_m']:.1e} m)",
            "not in thesis",
            f"criterion: ≤ {FEET_TOL:g} m (first-order Euler steps at dt = {DT:g} s: the "
            "drift is second order in the step); "
            f"{'holds' if feet <= FEET_TOL else 'does not hold'} in this run",
        ),
    ]
    pk = by.get("pink")
    if pk is None:
        rows.append(
            claim(
                "pink-side-by-side",
                "The same scenario with Pink (costs, RelativeFrameTask, SelfCollisionBarrier).",
                "not in thesis (peer comparison)",
                "Pink not installed: skipped",
                "not in thesis",
                "pip install pin-pink to run it",
            )
        )
        return rows
    pc = pk["phases"]["carry"]
    ratio = pk["step_median_us"] / ours["step_median_us"]
    rows.append(
        claim(
            "pink-side-by-side",
            "The same scenario with Pink (costs, RelativeFrameTask, SelfCollisionBarrier).",
            "not in thesis (peer comparison)",
            f"relative error in 'carry' (second half): qpcoord {held:.1e}, Pink "
            f"{pc['relative_error_max_last_half']:.1e}; left hand at its end: qpcoord "
            f"{carry['hand_error']:.1e}, Pink {pc['hand_error']:.1e}; hands' min distance: "
            f"qpcoord {d:.5f} m, Pink {pk['min_hands_distance_m']:.5f} m; feet drift: qpcoord "
            f"{feet:.1e} m, Pink {pk['feet_drift_m']:.1e} m; median step qpcoord "
            f"{ours['step_median_us']:.0f} µs, Pink {pk['step_median_us']:.0f} µs "
            f"(Pink / qpcoord {ratio:.2f})",
            "not in thesis",
            "our check: qpcoord's relative error in 'carry' ≤ Pink's; "
            f"{'holds' if held <= pc['relative_error_max_last_half'] else 'does not hold'} "
            "in this run",
        )
    )
    return rows


def figure(rows: list[dict], steps: int, path: Path) -> Path:
    """Relative pose error, hands' distance and feet drift over time, one style per run."""
    from qpcoord.studies.figures import _pyplot, save

    plt = _pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    for r in rows:
        t = DT * np.arange(1, r["steps"] + 1)
        ls = "-" if r["solver"] == "qpcoord" else "--"
        s = r["series"]
        axes[0].semilogy(t, np.maximum(s["relative"], 1e-12), ls=ls, lw=1, label=r["solver"])
        axes[1].plot(t, 100 * np.array(s["hands_m"]), ls=ls, lw=1, label=r["solver"])
        axes[2].semilogy(t, np.maximum(s["feet_m"], 1e-12), ls=ls, lw=1, label=r["solver"])
    axes[1].axhline(100 * D_S, color="k", lw=0.6, ls=":")
    for k, name in enumerate(("grasp", "carry", "squeeze")):
        for ax in axes:
            ax.axvline(k * steps * DT, color="grey", lw=0.5)
        axes[0].text(
            k * steps * DT,
            0.97,
            f" {name}",
            fontsize=7,
            va="top",
            transform=axes[0].get_xaxis_transform(),
        )
    axes[0].set_ylabel("relative pose error")
    axes[1].set_ylabel("hands' distance (cm)")
    axes[2].set_ylabel("feet drift (m)")
    axes[2].set_xlabel("t (s)")
    axes[0].set_title("Talos: feet + hands apart (0) > relative (1) > left hand (2) > posture")
    axes[0].legend(fontsize=7)
    return save(fig, path)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="1.5 s a phase, few frames (CI)")
    p.add_argument("--out", type=Path, default=Path("out/bimanual"))
    args = p.parse_args(argv)
    try:
        qc.robots.load("talos")
    except ValueError as exc:  # example-robot-data missing
        print(f"skipped: {exc}")
        return 0
    steps = 150 if args.quick else 200
    solvers = ["qpcoord"]
    try:
        import pink  # noqa: F401

        solvers.append("pink")
    except ImportError:
        print("Pink not installed (pip install pin-pink): comparison skipped")
    by = {s: run(s, steps) for s in solvers}
    print(f"{by['qpcoord']['pairs']} hand pairs; d_s = {D_S} m; {steps} steps of {DT} s a phase")
    print(
        f"{'solver':<8} {'phase':<8} {'rel err':>8} {'rel 2nd half':>12} {'hand err':>8} "
        f"{'hands (m)':>9} {'feet (m)':>8} {'median µs':>9}"
    )
    for r in by.values():
        for name, e in r["phases"].items():
            print(
                f"{r['solver']:<8} {name:<8} {e['relative_error']:8.1e} "
                f"{e['relative_error_max_last_half']:12.1e} {e['hand_error']:8.1e} "
                f"{e['min_hands_distance_m']:9.5f} {e['feet_drift_m']:8.1e} "
                f"{e['step_median_us']:9.0f}"
            )
    print(f"{'solver':<8} {'hands min (m)':>13} {'feet (m)':>8} {'median µs':>9} {'p99 µs':>7}")
    for r in by.values():
        print(
            f"{r['solver']:<8} {r['min_hands_distance_m']:13.6f} {r['feet_drift_m']:8.1e} "
            f"{r['step_median_us']:9.0f} {r['step_p99_us']:7.0f}"
        )
    rows_claims = claims(by)
    for c in rows_claims:
        print(f"{c['id']}: {c['measured']} -> {c['status']}")
    try:
        figure(list(by.values()), steps, args.out / "bimanual.png")
    except ImportError:  # matplotlib missing (the ``plots`` extra)
        print("matplotlib not installed: figure skipped")
    robot, _, phases = setup()
    html = write_animation(
        robot,
        by["qpcoord"]["q"],
        args.out / "bimanual.html",
        dt=DT,
        targets=[phases[0][1], phases[1][1]],
        fps=5 if args.quick else 25,
    )
    done = f"wrote {html['html']} ({html['html_mb']} MB)" if html["html"] else None
    print(done or f"animation skipped: {html['html_reason']}")
    rows = [{k: v for k, v in r.items() if k not in ("series", "q")} for r in by.values()]
    write_json(
        args.out / "summary.json",
        {
            "steps_per_phase": steps,
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
