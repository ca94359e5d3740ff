"""At the edges: an unreachable target, a joint driven into its position limit and an elbow
on its limit at a singular configuration, qpcoord against Pink and mink on the same scenario,
one table each.

Scenarios:

- ``unreachable``: UR10, ``tool0`` pose target 3.7 m from the base (the arm reaches 1.3 m),
  deadbeat frame task (qpcoord gain ``1/dt``, Pink and mink gain 1) over a posture (qpcoord:
  the level below; Pink and mink: cost 1e-3), the robot's position and speed limits,
  dt = 10 ms, 2 000 steps. Rows: without damping, and with Levenberg–Marquardt damping
  ``lm_damping=1`` (qpcoord: on the task, Pink and mink: the same parameter of their
  ``FrameTask``).
- ``reachable``: the same with a target 0.24 m from the start pose: steps until the pose
  error is below 1e-6 (does the damping slow a reachable target?).
- ``elbow``: UR10 ``tool0`` position target near its base (reachable with the elbow at
  2.60 rad), deadbeat task over a posture, dt = 10 ms: a one-step joint-limit box lands the
  elbow on its limit at π, where the folded arm is singular; rows: the IK's default limits
  (``JointLimits`` gain 0.5 within its band of 0.2 ``v_max dt``, full speed outside), the
  one-step box (gain 1), the damper at every distance (``band=inf``), the default with
  ``AccelerationLimits(50)``, and the default beside ``VelocityLimits(robot, 0.5 v_max)``,
  alone and with ``AccelerationLimits(20)`` (:data:`SLOW_A_MAX`); Pink with its default
  limits (``ConfigurationLimit`` gain 0.5) and with its ``AccelerationLimit(50)``; mink with
  its ``ConfigurationLimit`` (gain 0.95) and with gain 0.5, both beside its
  ``VelocityLimit`` (the robot's speed limits).
- ``held``: UR10 from ``HELD_Q0`` toward ``HELD_TARGET``: the deadbeat task rests the elbow
  on its limit at −π, 0.19 m from the target; rows with and without ``lm_damping=1``, and
  with ``AccelerationLimits(50)``.
- ``limit``: Panda joint 1 pulled 1 rad past its upper limit by a posture (gain 20/s; Pink
  gain 0.02 per step), dt = 1 ms, 2 000 steps, acceleration limit 50 rad/s² (qpcoord:
  ``AccelerationLimits(robot, 50)`` beside the default limits, with and without its braking
  rows; Pink: ``AccelerationLimit(model, 50)`` beside its configuration and velocity limits;
  mink has no acceleration limit).

mink runs in its own environment (``benchmarks/mink_side.py`` under
``benchmarks/.mink-venv``, see ``_mink.MINK_SETUP``) on a MuJoCo model built from the same
URDF, ``tool0`` a site; the notes under the table give its version and how far its
``tool0`` pose is from qpcoord's, or why it did not run.

Columns: velocity reversals per second over the last 500 steps (a joint's velocity changing
sign between two steps, both above 1e-6 rad/s), the largest step jump ``max |v_k − v_{k−1}|``
(rad/s), the largest acceleration (rad/s²), the largest position-limit violation (rad), the
settle time (s: from then on ``|v| < 1e-3 rad/s``; ``—`` if never), ``|v|`` at the end,
the final task error (UR10: ``log6`` norm of the pose error, or the position error in m;
Panda: distance of joint 1 to its limit, rad) and the step at which a QP had no solution
(the run stops there; the other columns cover the steps before).

Run::

    python benchmarks/edges.py            # all scenarios (a few seconds)
    python benchmarks/edges.py --steps 500
    python benchmarks/edges.py --pairs 300   # and the random elbow-limit pairs (a minute)
    python benchmarks/edges.py --pairs 60 --pairs-steps 600 --pairs-speed 0.5  # half speed
"""

from __future__ import annotations

import argparse
import logging
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
from _mink import call_mink_side  # noqa: E402
from _table import markdown, preamble  # noqa: E402

import qpcoord as qc  # noqa: E402
from qpcoord.kinematics.tasks import LIMIT_BAND, AccelerationLimits  # noqa: E402

Q_UR = np.array([0.0, -1.2, 1.6, -1.9, -1.57, 0.0])
FRAME = "tool0"


def metrics(vs: np.ndarray, dt: float, robot, qs: np.ndarray, error: float) -> dict:
    """The table's numbers for velocities ``vs`` (steps+1, nv; the first row the rest before
    the start) and configurations ``qs`` (steps, nq)."""
    last = vs[-500:]
    big = np.abs(last) > 1e-6
    flips = (np.sign(last[1:]) * np.sign(last[:-1]) < 0) & big[1:] & big[:-1]
    jumps = np.abs(np.diff(vs, axis=0))
    speed = np.linalg.norm(vs, axis=1)
    moving = np.flatnonzero(speed >= 1e-3)
    settle = (
        None
        if moving.size and moving[-1] == len(vs) - 1
        else (0.0 if not moving.size else (moving[-1] + 1) * dt)
    )
    over = np.maximum(qs - robot.upper, robot.lower - qs)
    finite = np.isfinite(robot.upper) & np.isfinite(robot.lower)
    return {
        "reversals/s": flips.sum() / (len(last) * dt),
        "max jump": jumps.max(),
        "max |a|": jumps.max() / dt,
        "violation": max(0.0, over[:, finite].max()),
        "settle (s)": settle,
        "|v| end": speed[-1],
        "error": error,
    }


def _pink_loop(robot, q0, tasks, dt, steps, limits=None, accel=None):
    import pink
    from pink.exceptions import NoSolutionFound

    conf = pink.Configuration(robot.model, robot.model.createData(), q0.copy())
    vs, qs, failed = [np.zeros(robot.nv)], [], None
    for k in range(steps):
        if accel is not None:
            accel.set_last_integration(vs[-1], dt)
        try:
            v = pink.solve_ik(conf, tasks, dt, solver="daqp", limits=limits, safety_break=False)
        except NoSolutionFound:
            failed = k + 1  # the QP has no solution: the run stops here
            break
        conf.integrate_inplace(v, dt)
        vs.append(v)
        qs.append(conf.q.copy())
    return np.array(vs), np.array(qs), failed


def _qc_loop(robot, q0, ik, steps):
    q, vs, qs = q0.copy(), [np.zeros(robot.nv)], []
    for _ in range(steps):
        q, v, _ = ik.step_integrate(q)
        vs.append(v)
        qs.append(q)
    return np.array(vs), np.array(qs)


def mink_runs(robot, runs: list[dict], dt: float) -> tuple[dict, str]:
    """mink's runs (``benchmarks/mink_side.py`` in ``benchmarks/.mink-venv``) on a MuJoCo
    model of the same URDF, ``FRAME`` as a site: (label -> (vs, qs, failed), a note).

    Each run: ``label``, ``q0``, ``steps``, ``target`` (4 × 4), ``position_only``, ``gain``
    (per step), ``lm_damping``, ``posture_cost``, ``config_gain`` (``None``: mink's default);
    mink's ``ConfigurationLimit`` and ``VelocityLimit`` (the robot's speed limits)."""
    check = [np.asarray(r["q0"], dtype=float) for r in runs]
    check.append(robot.random_configuration(0))
    out, why = call_mink_side(robot, FRAME, runs, dt, check, robot.velocity_limit)
    if out is None:
        return {}, why
    same = max(
        float(np.abs(np.array(T) - robot.frame_pose(q, FRAME)).max())
        for q, T in zip(check, out["poses"], strict=True)
    )
    results = {}
    for r in out["runs"]:
        vs = np.vstack([np.zeros(robot.nv), np.array(r["v"]).reshape(-1, robot.nv)])
        results[r["label"]] = (vs, np.array(r["q"]).reshape(-1, robot.nq), r["failed"])
    note = (
        f"mink {out['mink']} (MuJoCo {out['mujoco']}) on a MuJoCo model of the same URDF: "
        f"{FRAME}'s pose agrees with qpcoord's to {same:.1g} at {len(check)} configurations."
    )
    return results, note


def _pose_error(robot, q, T) -> float:
    return float(np.linalg.norm(pin.log6(pin.SE3(T).actInv(pin.SE3(robot.frame_pose(q, FRAME))))))


Rows = list[tuple[str, dict]]


def _mink_rows(robot, runs: list[dict], dt: float, error, steps_to=None) -> tuple[Rows, str]:
    """mink's rows of a table: ``error(q)`` the final task error, ``steps_to(qs)`` the
    "steps to 1e-6" column (if given)."""
    results, note = mink_runs(robot, runs, dt)
    rows = []
    for r in runs:
        if r["label"] not in results:
            continue
        vs, qs, failed = results[r["label"]]
        rows.append((r["label"], metrics(vs, dt, robot, qs, error(qs[-1]))))
        if steps_to is not None:
            rows[-1][1]["steps to 1e-6"] = steps_to(qs)
        rows[-1][1]["QP failed at step"] = failed
    return rows, note


def reach(target_offset, steps: int, dt: float = 0.01) -> tuple[Rows, list[str]]:
    from pink.tasks import FrameTask, PostureTask

    ur10 = qc.robots.load("ur10")
    T = ur10.frame_pose(Q_UR, FRAME).copy()
    if target_offset is None:
        T[:3, 3] = [3.7, 0.0, 0.5]
    else:
        T[:3, 3] += target_offset
    rows = []
    for lm in (0.0, 1.0):
        task = qc.FrameTask(ur10, FRAME, T, gain=1 / dt, lm_damping=lm)
        ik = qc.IK(ur10, [task, qc.PostureTask(ur10, Q_UR)], dt=dt)
        vs, qs = _qc_loop(ur10, Q_UR, ik, steps)
        rows.append(
            (f"qpcoord lm_damping={lm:g}", metrics(vs, dt, ur10, qs, _pose_error(ur10, qs[-1], T)))
        )
        rows[-1][1]["steps to 1e-6"] = _steps_to(ur10, qs, T)
        rows[-1][1]["QP failed at step"] = None
    for lm in (0.0, 1.0):
        hand = FrameTask(FRAME, position_cost=1.0, orientation_cost=1.0, gain=1.0, lm_damping=lm)
        hand.set_target(pin.SE3(T))
        posture = PostureTask(cost=1e-3)
        posture.set_target(Q_UR.copy())
        vs, qs, failed = _pink_loop(ur10, Q_UR, [hand, posture], dt, steps)
        rows.append(
            (f"pink lm_damping={lm:g}", metrics(vs, dt, ur10, qs, _pose_error(ur10, qs[-1], T)))
        )
        rows[-1][1]["steps to 1e-6"] = _steps_to(ur10, qs, T)
        rows[-1][1]["QP failed at step"] = failed
    runs = [
        _mink_run(f"mink lm_damping={lm:g}", Q_UR, steps, T, False, lm_damping=lm)
        for lm in (0.0, 1.0)
    ]
    more, note = _mink_rows(
        ur10, runs, dt, lambda q: _pose_error(ur10, q, T), lambda qs: _steps_to(ur10, qs, T)
    )
    return rows + more, [note]


def _mink_run(label, q0, steps, target, position_only, lm_damping=0.0, config_gain=None):
    """One mink run: deadbeat frame task (gain 1 per step) over a posture at cost 1e-3, as
    Pink's rows."""
    return {
        "label": label,
        "q0": q0,
        "steps": steps,
        "target": target,
        "position_only": position_only,
        "gain": 1.0,
        "lm_damping": lm_damping,
        "posture_cost": 1e-3,
        "config_gain": config_gain,
    }


def _steps_to(robot, qs, T) -> int | None:
    for k, q in enumerate(qs):
        if _pose_error(robot, q, T) < 1e-6:
            return k + 1
    return None


def limit(steps: int, dt: float = 1e-3, a_max: float = 50.0) -> tuple[Rows, list[str]]:
    from pink.limits import AccelerationLimit, ConfigurationLimit, VelocityLimit
    from pink.tasks import PostureTask

    panda = qc.robots.load("panda")
    q0 = np.clip(np.zeros(panda.nq), panda.lower + 0.1, panda.upper - 0.1)
    q_ref = q0.copy()
    q_ref[0] = panda.upper[0] + 1.0
    rows = []
    for label, brake in (("qpcoord braking", "robot"), ("qpcoord no braking", None)):
        post = qc.PostureTask(panda, q0, gain=20.0)
        post.q_ref = q_ref
        limits = [
            qc.JointLimits(panda),
            qc.VelocityLimits(panda),
            AccelerationLimits(panda, a_max, position_limits=brake),
        ]
        ik = qc.IK(panda, [post], dt=dt, limits=limits)
        vs, qs = _qc_loop(panda, q0, ik, steps)
        rows.append((label, metrics(vs, dt, panda, qs, abs(qs[-1, 0] - panda.upper[0]))))
        rows[-1][1]["QP failed at step"] = None
    model = panda.model
    accel = AccelerationLimit(model, np.full(model.nv, a_max))
    posture = PostureTask(cost=1.0, gain=20.0 * dt)
    posture.set_target(q_ref)
    limits = [ConfigurationLimit(model), VelocityLimit(model), accel]
    vs, qs, failed = _pink_loop(panda, q0, [posture], dt, steps, limits=limits, accel=accel)
    rows.append(
        ("pink AccelerationLimit", metrics(vs, dt, panda, qs, abs(qs[-1, 0] - panda.upper[0])))
    )
    rows[-1][1]["QP failed at step"] = failed
    return rows, ["mink: no row (mink 1.3 has no acceleration limit)."]


ELBOW_TARGET = np.array([-0.118, 0.193, 0.303])  # tool0, m: reached with the elbow at 2.60 rad
#: rad/s²: the acceleration limit of the elbow case's half-speed row with acceleration limits
SLOW_A_MAX = 20.0
#: UR10 start and tool0 target (m) from which a deadbeat task rests the elbow on its limit at
#: -π with the target 0.19 m away: reached (elbow at -2.29 rad) by a task of gain ≤ 50/s
HELD_Q0 = np.array([-0.83, -3.04, -2.46, -2.84, -1.6, -1.77])
HELD_TARGET = np.array([0.087, -0.028, 0.494])


def _position_rows(q0, target, steps, dt, variants, pink_variants, mink_variants):
    """A deadbeat ``tool0`` position task over a posture on the UR10, one row per variant:
    qpcoord ``(label, limits, lm_damping)``, Pink ``(label, acceleration limit or None,
    lm_damping)``, mink ``(label, ConfigurationLimit gain or None, lm_damping)``."""
    from pink.limits import AccelerationLimit, ConfigurationLimit, VelocityLimit
    from pink.tasks import FrameTask, PostureTask

    ur10 = qc.robots.load("ur10")

    def error(q):
        return float(np.linalg.norm(ur10.frame_pose(q, FRAME)[:3, 3] - target))

    rows = []
    for label, limits_of, lm in variants:
        task = qc.FramePositionTask(ur10, FRAME, target, gain=1 / dt, lm_damping=lm)
        ik = qc.IK(ur10, [task, qc.PostureTask(ur10, q0)], dt=dt, limits=limits_of(ur10))
        vs, qs = _qc_loop(ur10, q0, ik, steps)
        rows.append((label, metrics(vs, dt, ur10, qs, error(qs[-1]))))
        rows[-1][1]["QP failed at step"] = None
    model = ur10.model
    for label, accel, lm in pink_variants:
        hand = FrameTask(FRAME, position_cost=1.0, orientation_cost=0.0, gain=1.0, lm_damping=lm)
        hand.set_target(pin.SE3(np.eye(3), target))
        posture = PostureTask(cost=1e-3)
        posture.set_target(q0.copy())
        limits = [ConfigurationLimit(model), VelocityLimit(model)]
        acc = None
        if accel is not None:
            acc = AccelerationLimit(model, np.full(model.nv, accel))
            limits.append(acc)
        vs, qs, failed = _pink_loop(ur10, q0, [hand, posture], dt, steps, limits=limits, accel=acc)
        rows.append((label, metrics(vs, dt, ur10, qs, error(qs[-1]))))
        rows[-1][1]["QP failed at step"] = failed
    T = np.eye(4)
    T[:3, 3] = target
    runs = [
        _mink_run(label, q0, steps, T, True, lm_damping=lm, config_gain=gain)
        for label, gain, lm in mink_variants
    ]
    more, note = _mink_rows(ur10, runs, dt, error)
    return rows + more, [note]


def _robot_limits(robot):
    return "robot"


def elbow(steps: int, dt: float = 0.01, a_max: float = 50.0) -> tuple[Rows, list[str]]:
    """UR10 ``tool0`` position target near the base: a deadbeat task drives the elbow onto
    its limit at π, where the arm is folded (the Jacobian's smallest singular value 0.002)."""
    variants = (
        ('qpcoord limits="robot" (JointLimits gain 0.5, band 0.2)', _robot_limits, 0.0),
        (
            "qpcoord JointLimits(gain=1)",
            lambda r: [qc.JointLimits(r, gain=1.0), qc.VelocityLimits(r)],
            0.0,
        ),
        (
            "qpcoord JointLimits(band=inf)",
            lambda r: [qc.JointLimits(r, band=np.inf), qc.VelocityLimits(r)],
            0.0,
        ),
        (
            f"qpcoord + AccelerationLimits({a_max:g})",
            lambda r: [qc.JointLimits(r), qc.VelocityLimits(r), AccelerationLimits(r, a_max)],
            0.0,
        ),
        (
            "qpcoord VelocityLimits(0.5 v_max)",
            lambda r: [qc.JointLimits(r), qc.VelocityLimits(r, 0.5 * r.velocity_limit)],
            0.0,
        ),
        (
            f"qpcoord VelocityLimits(0.5 v_max) + AccelerationLimits({SLOW_A_MAX:g})",
            lambda r: [
                qc.JointLimits(r),
                qc.VelocityLimits(r, 0.5 * r.velocity_limit),
                AccelerationLimits(r, SLOW_A_MAX),
            ],
            0.0,
        ),
    )
    pink = (("pink (ConfigurationLimit gain 0.5)", None, 0.0),
            (f"pink + AccelerationLimit({a_max:g})", a_max, 0.0))  # fmt: skip
    mink = (("mink (ConfigurationLimit gain 0.95)", None, 0.0),
            ("mink ConfigurationLimit(gain=0.5)", 0.5, 0.0))  # fmt: skip
    q0 = np.array([0.0, -1.2, 2.6, -1.9, -1.57, 0.0])
    return _position_rows(q0, ELBOW_TARGET, steps, dt, variants, pink, mink)


def held(steps: int, dt: float = 0.01, a_max: float = 50.0) -> tuple[Rows, list[str]]:
    """UR10 ``tool0`` position target 0.19 m from where a deadbeat task rests the elbow on
    its limit at −π: the other joints alternate at their speed limits whatever the
    position-limit gain or band (the same numbers); the task's ``lm_damping`` settles them
    there, acceleration limits let the arm reach the target."""
    variants = (
        ('qpcoord limits="robot"', _robot_limits, 0.0),  # the same with JointLimits(gain=1)
        ('qpcoord limits="robot", lm_damping=1', _robot_limits, 1.0),
        (
            f"qpcoord + AccelerationLimits({a_max:g})",
            lambda r: [qc.JointLimits(r), qc.VelocityLimits(r), AccelerationLimits(r, a_max)],
            0.0,
        ),
    )
    pink = (("pink", None, 0.0), ("pink lm_damping=1", None, 1.0))
    mink = (("mink", None, 0.0), ("mink lm_damping=1", None, 1.0))
    return _position_rows(HELD_Q0, HELD_TARGET, steps, dt, variants, pink, mink)


def pairs(
    count: int, steps: int = 1500, dt: float = 0.01, seed: int = 1, speed: float = 1.0
) -> str:
    """``count`` random UR10 start/target pairs whose deadbeat-ish ``tool0`` task drives the
    elbow toward its limit at ±π (start elbow ±[2.2, 3.0] rad, target reached with the elbow
    at ±[2.4, 3.12] rad, the same sign), per position-limit gain ``K``, task gain and task
    ``lm_damping``: how many runs still reverse more than 10 times a second over the last
    500 steps, and how many reach the target to 1e-6 m. ``JointLimits`` rows: the one-step
    box (gain 1), the damper at every distance (gain 0.5, ``band=inf``) and the default (gain
    0.5 within a band of 0.2 ``v_max dt``); the last rows add ``AccelerationLimits(r,
    SLOW_A_MAX)`` to the default. The speed box is ``VelocityLimits(r, speed · v_max)``."""
    ur10 = qc.robots.load("ur10")
    rng = np.random.default_rng(seed)
    cases = []
    for _ in range(count):
        q0 = rng.uniform(-np.pi, np.pi, 6)
        q0[2] = rng.uniform(2.2, 3.0) * rng.choice([-1, 1])
        goal = rng.uniform(-np.pi, np.pi, 6)
        goal[2] = np.sign(q0[2]) * rng.uniform(2.4, 3.12)
        cases.append((q0, ur10.frame_pose(goal, FRAME)[:3, 3].copy()))
    out = [
        f"### UR10, {count} random elbow-limit pairs ({steps} steps, dt 10 ms, seed {seed}, "
        f"speed limits {speed:g} v_max)",
        "",
        "| JointLimits gain | band | AccelerationLimits (rad/s²) | task gain (1/s) "
        "| task lm_damping | runs reversing > 10/s | runs reaching 1e-6 m |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    limit_rows = ((1.0, LIMIT_BAND), (0.5, np.inf), (0.5, LIMIT_BAND))
    variants = [(g, K, band, 0.0, None) for g in (100.0, 50.0, 30.0) for K, band in limit_rows]
    variants.append((100.0, 0.5, LIMIT_BAND, 1.0, None))
    variants += [(g, 0.5, LIMIT_BAND, 0.0, SLOW_A_MAX) for g in (100.0, 50.0)]
    for task_gain, K, band, lm, a_max in variants:
        chatter = reached = 0
        for q0, target in cases:
            task = qc.FramePositionTask(ur10, FRAME, target, gain=task_gain, lm_damping=lm)
            limits = [
                qc.JointLimits(ur10, gain=K, band=band),
                qc.VelocityLimits(ur10, speed * ur10.velocity_limit),
            ]
            if a_max is not None:
                limits.append(AccelerationLimits(ur10, a_max))
            ik = qc.IK(ur10, [task, qc.PostureTask(ur10, q0)], dt=dt, limits=limits)
            vs, qs = _qc_loop(ur10, q0, ik, steps)
            err = float(np.linalg.norm(task.compute_error(qs[-1])))
            chatter += metrics(vs, dt, ur10, qs, err)["reversals/s"] > 10
            reached += err < 1e-6
        acc = "—" if a_max is None else f"{a_max:g}"
        out.append(f"| {K:g} | {band:g} | {acc} | {task_gain:g} | {lm:g} | {chatter} | {reached} |")
    return "\n".join(out)


COLUMNS = ["reversals/s", "max jump", "max |a|", "violation", "settle (s)", "|v| end", "error",
           "QP failed at step"]  # fmt: skip


def table(cases: list[tuple[str, tuple[Rows, list[str]]]]) -> str:
    """One markdown table: a row per case and solver; the cases' notes below it, once each."""
    rows: list[list[str]] = []
    notes: list[str] = []
    for case, (case_rows, case_notes) in cases:
        for name, r in case_rows:
            cells = []
            for c in COLUMNS:
                x = r.get(c)
                cells.append("—" if x is None else f"{x:.3g}" if isinstance(x, float) else str(x))
            rows.append([case, name, *cells])
        notes += [n for n in case_notes if n not in notes]
    out = markdown(["case", "solver", *COLUMNS], rows, "ll" + "r" * len(COLUMNS))
    return "\n".join([out, *([""] + notes if notes else [])])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument(
        "--pairs",
        type=int,
        default=0,
        help="also run this many random UR10 elbow-limit pairs per gain (300: ~1 min)",
    )
    parser.add_argument(
        "--pairs-steps", type=int, default=1500, help="steps of each random pair (default 1500)"
    )
    parser.add_argument(
        "--pairs-speed",
        type=float,
        default=1.0,
        help="the random pairs' speed limits as a fraction c of the robot's (default 1)",
    )
    args = parser.parse_args(argv)
    logging.getLogger().setLevel(logging.ERROR)  # Pink logs configurations past a limit
    n = args.steps
    cases = [
        ("UR10 unreachable, 3.7 m", reach(None, n)),
        ("UR10 reachable, 0.24 m", reach([0.2, -0.1, 0.1], 300)),
        ("UR10 elbow onto its limit at π", elbow(n)),
        ("UR10 elbow held on −π", held(n)),
        ("Panda joint 1 into its limit", limit(n)),
    ]
    print(preamble())
    print(
        f"UR10 at dt 10 ms ({n} steps; the reachable target 300), Panda at dt 1 ms ({n} "
        "steps); jumps in rad/s per step, |a| in rad/s², settle: time until |v| stays below "
        "1e-3 rad/s ('—': never), error: the final task error (UR10: m or log6 norm; Panda: "
        "joint 1's distance to its limit, rad):\n"
    )
    print(table(cases))
    if args.pairs > 0:
        print()
        print(pairs(args.pairs, steps=args.pairs_steps, speed=args.pairs_speed))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
