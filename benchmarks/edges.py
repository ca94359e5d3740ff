"""At the edges: an unreachable target and a joint driven into its position limit, qpcoord
against Pink on the same scenario, one table each.

Scenarios:

- ``unreachable``: UR10, ``tool0`` pose target 3.7 m from the base (the arm reaches 1.3 m),
  deadbeat frame task (qpcoord gain ``1/dt``, Pink gain 1) over a posture (qpcoord: the
  level below; Pink: cost 1e-3), the robot's position and speed limits, dt = 10 ms, 2 000
  steps. Rows: without damping, and with Levenberg–Marquardt damping ``lm_damping=1``
  (qpcoord: on the task, Pink: the same parameter of its ``FrameTask``).
- ``reachable``: the same with a target 0.24 m from the start pose: steps until the pose
  error is below 1e-6 (does the damping slow a reachable target?).
- ``elbow``: UR10 ``tool0`` position target near its base (reachable with the elbow at
  2.60 rad), deadbeat task over a posture, dt = 10 ms: with the one-step joint-limit box the
  elbow lands on its limit at π, where the folded arm is singular; rows: that box
  (``JointLimits`` gain 1, the IK's default), its damper form (gain 0.5, Pink's default),
  and with ``AccelerationLimits(50)``; Pink with its default limits, and with its
  ``AccelerationLimit(50)``.
- ``limit``: Panda joint 1 pulled 1 rad past its upper limit by a posture (gain 20/s; Pink
  gain 0.02 per step), dt = 1 ms, 2 000 steps, acceleration limit 50 rad/s² (qpcoord:
  ``AccelerationLimits(robot, 50)`` with and without its braking rows; Pink:
  ``AccelerationLimit(model, 50)`` beside its configuration and velocity limits).

Columns: velocity reversals per second over the last 500 steps (a joint's velocity changing
sign between two steps, both above 1e-6 rad/s), the largest step jump ``max |v_k − v_{k−1}|``
(rad/s), the largest acceleration (rad/s²), the largest position-limit violation (rad), the
settle time (s: from then on ``|v| < 1e-3 rad/s``; ``—`` if never), ``|v|`` at the end,
the final task error (UR10: ``log6`` norm of the pose error; Panda: distance of joint 1 to
its limit, rad), the steps until the pose error is below 1e-6, and the step at which a QP
had no solution (the run stops there; the other columns cover the steps before).

Run::

    python benchmarks/edges.py            # all scenarios (a few seconds)
    python benchmarks/edges.py --steps 500
"""

from __future__ import annotations

import argparse
import logging
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

import qpcoord as qc  # noqa: E402
from qpcoord.kinematics.tasks import AccelerationLimits  # noqa: E402

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


def _pose_error(robot, q, T) -> float:
    return float(np.linalg.norm(pin.log6(pin.SE3(T).actInv(pin.SE3(robot.frame_pose(q, FRAME))))))


def reach(target_offset, steps: int, dt: float = 0.01) -> list[tuple[str, dict]]:
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
    return rows


def _steps_to(robot, qs, T) -> int | None:
    for k, q in enumerate(qs):
        if _pose_error(robot, q, T) < 1e-6:
            return k + 1
    return None


def limit(steps: int, dt: float = 1e-3, a_max: float = 50.0) -> list[tuple[str, dict]]:
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
    return rows


ELBOW_TARGET = np.array([-0.118, 0.193, 0.303])  # tool0, m: reached with the elbow at 2.60 rad


def elbow(steps: int, dt: float = 0.01, a_max: float = 50.0) -> list[tuple[str, dict]]:
    """UR10 ``tool0`` position target near the base: a deadbeat task drives the elbow onto
    its limit at π, where the arm is folded (the Jacobian's smallest singular value 0.002)."""
    from pink.limits import AccelerationLimit, ConfigurationLimit, VelocityLimit
    from pink.tasks import FrameTask, PostureTask

    ur10 = qc.robots.load("ur10")
    q0 = np.array([0.0, -1.2, 2.6, -1.9, -1.57, 0.0])

    def error(q):
        return float(np.linalg.norm(ur10.frame_pose(q, FRAME)[:3, 3] - ELBOW_TARGET))

    rows = []
    variants = (
        ("qpcoord JointLimits (gain 1)", [qc.JointLimits(ur10), qc.VelocityLimits(ur10)]),
        ("qpcoord JointLimits(gain=0.5)", [qc.JointLimits(ur10, 0.5), qc.VelocityLimits(ur10)]),
        (
            f"qpcoord + AccelerationLimits({a_max:g})",
            [qc.JointLimits(ur10), qc.VelocityLimits(ur10), AccelerationLimits(ur10, a_max)],
        ),
    )
    for label, limits in variants:
        task = qc.FramePositionTask(ur10, FRAME, ELBOW_TARGET, gain=1 / dt)
        ik = qc.IK(ur10, [task, qc.PostureTask(ur10, q0)], dt=dt, limits=limits)
        vs, qs = _qc_loop(ur10, q0, ik, steps)
        rows.append((label, metrics(vs, dt, ur10, qs, error(qs[-1]))))
        rows[-1][1]["QP failed at step"] = None
    model = ur10.model
    for label, accel in (("pink", None), (f"pink + AccelerationLimit({a_max:g})", a_max)):
        hand = FrameTask(FRAME, position_cost=1.0, orientation_cost=0.0, gain=1.0)
        hand.set_target(pin.SE3(np.eye(3), ELBOW_TARGET))
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
    return rows


COLUMNS = ["reversals/s", "max jump", "max |a|", "violation", "settle (s)", "|v| end", "error",
           "steps to 1e-6", "QP failed at step"]  # fmt: skip


def table(title: str, rows: list[tuple[str, dict]]) -> str:
    cols = [c for c in COLUMNS if any(c in r for _, r in rows)]
    out = [f"### {title}", "", "| solver | " + " | ".join(cols) + " |"]
    out.append("|---|" + "---:|" * len(cols))
    for name, r in rows:
        cells = []
        for c in cols:
            x = r.get(c)
            cells.append("—" if x is None else f"{x:.3g}" if isinstance(x, float) else str(x))
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=2000)
    args = parser.parse_args(argv)
    logging.getLogger().setLevel(logging.ERROR)  # Pink logs configurations past a limit
    print(table(f"UR10, unreachable target 3.7 m away ({args.steps} steps, dt 10 ms)",
                reach(None, args.steps)))  # fmt: skip
    print()
    print(table("UR10, reachable target 0.24 m away (300 steps, dt 10 ms)",
                reach([0.2, -0.1, 0.1], 300)))  # fmt: skip
    print()
    print(table(f"UR10, elbow onto its limit at π, folded ({args.steps} steps, dt 10 ms)",
                elbow(args.steps)))  # fmt: skip
    print()
    print(table(f"Panda joint 1 into its limit, a_max 50 rad/s² ({args.steps} steps, dt 1 ms)",
                limit(args.steps)))  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
