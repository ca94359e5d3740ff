"""Per-step differential IK: qpcoord vs Pink vs PlaCo.

Scenarios (same targets, same start, same hard limits for every solver, 1 kHz):

- ``panda-position``: Franka Panda (7 DoF, fingers locked), hand (``panda_hand_tcp``)
  position on a 0.1 m horizontal circle run in 2 s through its start, plus a posture task
  toward the start ``q0``; hard joint position limits and joint speed limits
  (``--speed`` rad/s on every joint, default 0.8: they bind part of the time).
- ``panda-pose``: the same with the hand's full pose (the start orientation held).
- ``talos``: Talos whole body (free-flyer, nv = 38): both soles fixed, the CoM ground
  projection inside the support polygon (an inequality), the right gripper moving 0.4 m
  forward, 0.1 m left, 0.3 m down along a minimum-jerk path (2 s, then held), posture toward
  ``half_sitting``; the robot's joint position and speed limits hard.

Solvers, stepped in lockstep (one step of each in turn, the order rotating every step):

- ``qpcoord strict native``: :class:`qpcoord.IK`, ``method="hierarchical"``, default
  engine: one native call per step (task rows, limit box, strict hierarchy and the
  integration of ``q``: ``IK.step_integrate``);
- with ``--engines``, ``qpcoord strict python``: the same IK with ``engine="python"`` (Python
  task refresh, the Python engine on daqp, ``robot.integrate``), and ``qpcoord weighted
  native`` (Panda only): the same stack as one weighted QP (``weight_ratio`` 1e-3), its
  default engine: one native call per step as the strict one (task rows, limit box, the native
  weighted QP and the integration of ``q``: ``IK.step_integrate``);
- ``pink``: ``pink.solve_ik`` with ``solver="daqp"`` (the same backend), then
  ``Configuration.integrate_inplace``;
- ``placo``: PlaCo 0.10 ``KinematicsSolver`` (its own QP, C++), run by
  ``benchmarks/placo_side.py`` in ``benchmarks/.placo-venv`` (PlaCo pins ``pin==3.8``), one
  subprocess step per lockstep slot, timed by the subprocess's own clock.

A timed step is what a control loop does: set the target, kinematics, task updates, the
QP(s) and the integration (qpcoord: ``set_target`` + ``IK.step_integrate``, or ``IK.step`` +
``robot.integrate``). A pose target is one 4×4 array whose translation is rewritten in place
at every step, by both qpcoord's loop and PlaCo's side.
BLAS is limited to one thread. Errors and limit violations are measured in this process with
qpcoord's Pinocchio model on every solver's configurations.

Gains: PlaCo's tasks have no gain (each soft task asks for its whole error in one step), so
the hand task is deadbeat for everyone (Pink ``gain=1``, qpcoord ``1/dt``); the posture
task removes ``α = 0.05`` of its error per step in qpcoord (``α/dt`` = 50/s) and Pink, the
whole of it in PlaCo. Weights: hand 1, posture 1e-3 (Pink cost, PlaCo weight); qpcoord's
weighted method uses its ``weight_ratio`` 1e-3 between the two levels. No task gets a
feed-forward velocity. Talos: feet deadbeat (qpcoord level 0, Pink cost 1, PlaCo hard), the
CoM polygon an inequality (qpcoord level 1, PlaCo a hard ``CoMPolygonConstraint``; Pink has
none: a CoM cost 1e-2 toward its start). PlaCo's Panda keeps its two finger joints (9
variables, out of every task but its posture); qpcoord and Pink lock them (7).

Run::

    python benchmarks/ik_peers.py                     # all scenarios, 2000 steps (Talos 1000)
    python benchmarks/ik_peers.py --quick             # 60 steps, smoke run (CI)
    python benchmarks/ik_peers.py --scenario panda-position --steps 4000
    python benchmarks/ik_peers.py --make-placo-venv   # create benchmarks/.placo-venv first
    python benchmarks/ik_peers.py --profile           # cProfile of the native Panda IK step
    python benchmarks/ik_peers.py --no-back-to-back   # the lockstep columns only
    python benchmarks/ik_peers.py --engines           # also qpcoord's other engine and method

One table, two kinds of run. **Lockstep**: the solvers stepped in turn as above (the order
rotating every step), so load falls on all alike, but each solver's caches are cold at its
step and PlaCo's subprocess wakes from a pipe wait at every step. **Alone** (back to back):
then each solver runs the whole trajectory alone, one after the other (fresh solver, same
scenario, same per-step timer, same meters; PlaCo gets all its step requests at once). Median
and p99 of each, the alone median over PlaCo's, and the errors and violations (the worse of
the two runs, which follow the same trajectory); ``--json`` keeps every row with its p90.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from _table import markdown, preamble  # noqa: E402

import qpcoord as qc  # noqa: E402

HERE = Path(__file__).resolve().parent
PLACO_VENV = HERE / ".placo-venv"
PLACO_REQUIREMENTS = HERE / "placo-requirements.txt"
DT = 1e-3  # s
HAND_ALPHA = 1.0  # fraction of the hand error removed per step (deadbeat, as PlaCo's tasks)
ALPHA = 0.05  # fraction of the posture error removed per step (qpcoord, Pink)
POSTURE_WEIGHT = 1e-3
PANDA_Q0 = np.array([0.0, -0.4, 0.0, -2.2, 0.0, 1.9, 0.8])  # rad
RADIUS, PERIOD = 0.1, 2.0  # m, s: the Panda's circle
TALOS_SOLES = ("left_sole_link", "right_sole_link")
TALOS_CORNERS = [[x, y, 0.0] for x in (-0.1, 0.1) for y in (-0.05, 0.05)]
TALOS_HAND = "gripper_right_base_link"
TALOS_OFFSET = np.array([0.4, 0.1, -0.3])  # m
TALOS_MARGIN = 0.02  # m
SCENARIOS = ("panda-position", "panda-pose", "talos")
#: The URDFs of ``qc.robots.load("panda" / "talos")`` inside example-robot-data, given to PlaCo.
URDFS = {
    "panda": "panda_description/urdf/panda.urdf",
    "talos": "talos_data/robots/talos_reduced.urdf",
}


def _threads_one():
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl is a qpcoord dependency
        return None
    return threadpool_limits(1)


# --------------------------------------------------------------------------- scenarios


def _min_jerk(p0: np.ndarray, p1: np.ndarray, t: float, duration: float) -> np.ndarray:
    s = min(max(t / duration, 0.0), 1.0)
    return p0 + s**3 * (10 - 15 * s + 6 * s**2) * (p1 - p0)


def scenario(name: str, steps: int, speed: float) -> dict:
    """The data every solver gets: robot, start, targets per step (m), limits."""
    if name not in SCENARIOS:
        raise ValueError(f"scenario must be one of {', '.join(SCENARIOS)}, got {name!r}")
    if name.startswith("panda"):
        robot = qc.robots.load("panda")
        q0 = PANDA_Q0.copy()
        T0 = robot.frame_pose(q0, "panda_hand_tcp")
        circle = qc.paths.HorizontalCircle(T0[:3, 3], radius=RADIUS, period=PERIOD)
        targets = np.array([circle.position((k + 1) * DT) for k in range(steps)])
        return {
            "name": name,
            "robot": robot,
            "frame": "panda_hand_tcp",
            "q0": q0,
            "targets": targets,
            "rotation": T0[:3, :3] if name == "panda-pose" else None,
            "speed": np.full(robot.nv, speed),
        }
    robot = qc.robots.load("talos")
    q0 = robot.reference_configuration("half_sitting")
    p0 = robot.frame_pose(q0, TALOS_HAND)[:3, 3]
    targets = np.array([_min_jerk(p0, p0 + TALOS_OFFSET, (k + 1) * DT, 2.0) for k in range(steps)])
    return {
        "name": name,
        "robot": robot,
        "frame": TALOS_HAND,
        "q0": q0,
        "targets": targets,
        "rotation": None,
        "speed": robot.velocity_limit.copy(),
    }


# --------------------------------------------------------------------------- solvers


class QpcoordLoop:
    """qpcoord's IK on the scenario: ``method`` and ``engine`` as in :meth:`Stack.solve`."""

    def __init__(self, sc: dict, method: str, engine: str | None, label: str) -> None:
        self.name = label
        robot = sc["robot"]
        self.robot, self.q = robot, sc["q0"].copy()
        self.engine, self.targets = engine, sc["targets"]
        self.rotation = sc["rotation"]
        self._T = np.eye(4)
        if self.rotation is not None:
            self._T[:3, :3] = self.rotation
        gain = ALPHA / DT
        if sc["name"] == "talos":
            feet = [qc.FrameTask(robot, s, gain=1.0 / DT) for s in TALOS_SOLES]
            for foot in feet:
                foot.set_target_from_configuration(self.q)
            support = qc.SupportPolygon(
                robot,
                list(TALOS_SOLES),
                margin=TALOS_MARGIN,
                gain=1.0 / DT,
                contact_points=TALOS_CORNERS,
            )
            self.hand = qc.FramePositionTask(
                robot, sc["frame"], self.targets[0], gain=HAND_ALPHA / DT
            )
            posture = qc.PostureTask(robot, self.q, gain=gain)
            levels = [feet, support, self.hand, posture]
            limits = "robot"
        else:
            hg = HAND_ALPHA / DT
            if self.rotation is None:
                self.hand = qc.FramePositionTask(robot, sc["frame"], self.targets[0], gain=hg)
            else:
                self.hand = qc.FrameTask(robot, sc["frame"], self._pose(0), gain=hg)
            posture = qc.PostureTask(robot, self.q, gain=gain)
            levels = [self.hand, posture]
            # Pink's ConfigurationLimit(model, 0.5): the damper at every distance
            limits = [
                qc.JointLimits(robot, gain=0.5, band=np.inf),
                qc.VelocityLimits(robot, sc["speed"]),
            ]
        solver = "daqp" if engine == "python" else None
        self.ik = qc.IK(
            robot, levels, DT, limits=limits, method=method, solver=solver, engine=engine
        )
        # the native IK step (strict or weighted) integrates q in its one native call
        # (IK.step_integrate)
        native_step = self.ik._native is not None and self.ik._native.integrates
        self.step_fn = self._step_native if native_step else self._step_python

    def _pose(self, k: int) -> np.ndarray:
        """The hand's target pose at step ``k``: one 4×4 array rewritten in place (as PlaCo's
        side does; ``FrameTask.set_target`` copies it)."""
        T = self._T
        T[:3, 3] = self.targets[k]
        return T

    def _set_target(self, k: int) -> None:
        self.hand.set_target(self.targets[k] if self.rotation is None else self._pose(k))

    def _step_native(self, k: int) -> float:
        t0 = time.perf_counter()
        self._set_target(k)
        self.q, _, _ = self.ik.step_integrate(self.q)
        return time.perf_counter() - t0

    def _step_python(self, k: int) -> float:
        t0 = time.perf_counter()
        self._set_target(k)
        v, _ = self.ik.step(self.q)
        self.q = self.robot.integrate(self.q, v, DT)
        return time.perf_counter() - t0

    def step(self, k: int) -> float:
        return self.step_fn(k)

    def close(self) -> None:
        pass


class PinkLoop:
    """Pink 4.x on the scenario (daqp). Talos: feet and hand as costs, the CoM as a cost
    toward its start (Pink has no inequality task: the support polygon cannot be posed).
    ``collision_model`` (a ``pinocchio.GeometryModel`` with its pairs) and ``barriers`` (Pink
    barriers) add Pink's barrier constraints."""

    name = "pink"

    def __init__(self, sc: dict, collision_model=None, barriers: tuple = ()) -> None:
        import pink
        import pinocchio as pin
        from pink.limits import ConfigurationLimit, VelocityLimit
        from pink.tasks import ComTask, FrameTask, PostureTask

        # Pink logs (root logger) every configuration 1e-6 past a limit: keep the table readable
        logging.getLogger().setLevel(logging.ERROR)
        self.pink, self.pin = pink, pin
        robot = sc["robot"]
        model = robot.model.copy()
        model.velocityLimit[:] = sc["speed"]
        self.conf = pink.Configuration(
            model, model.createData(), sc["q0"].copy(), collision_model=collision_model
        )
        self.barriers = list(barriers) or None
        self.targets, self.rotation = sc["targets"], sc["rotation"]
        oc = 0.0 if self.rotation is None else 1.0
        self.hand = FrameTask(sc["frame"], position_cost=1.0, orientation_cost=oc, gain=HAND_ALPHA)
        self.goal = self.conf.get_transform_frame_to_world(sc["frame"]).copy()
        if self.rotation is not None:
            self.goal.rotation = self.rotation
        posture = PostureTask(cost=POSTURE_WEIGHT, gain=ALPHA)
        posture.set_target(sc["q0"].copy())
        self.tasks = [self.hand, posture]
        if sc["name"] == "talos":
            feet = [
                FrameTask(s, position_cost=1.0, orientation_cost=1.0, gain=1.0) for s in TALOS_SOLES
            ]
            for foot in feet:
                foot.set_target_from_configuration(self.conf)
            com = ComTask(cost=[1e-2, 1e-2, 0.0])
            com.set_target_from_configuration(self.conf)
            self.tasks += [*feet, com]
        self.limits = [ConfigurationLimit(model, 0.5), VelocityLimit(model)]
        self.q = self.conf.q

    def step(self, k: int) -> float:
        t0 = time.perf_counter()
        self.goal.translation = self.targets[k]
        self.hand.set_target(self.goal)
        v = self.pink.solve_ik(
            self.conf,
            self.tasks,
            DT,
            solver="daqp",
            limits=self.limits,
            barriers=self.barriers,
            safety_break=False,
        )
        self.conf.integrate_inplace(v, DT)
        t = time.perf_counter() - t0
        self.q = self.conf.q
        return t

    def close(self) -> None:
        pass


class PlacoLoop:
    """PlaCo in its own environment (``benchmarks/placo_side.py`` over a pipe); ``extra``:
    more items of the scenario it is sent (``placo_side.py``'s ``self_collision``)."""

    name = "placo"

    def __init__(self, sc: dict, python: Path, extra: dict | None = None) -> None:
        robot = sc["robot"]
        self.robot = robot
        names = [robot.model.names[j] for j in range(1, robot.model.njoints)]
        free = sc["name"] == "talos"
        joints = names[1:] if free else names
        if free:  # qpcoord's model: free-flyer first
            qj = sc["q0"][7:]
        else:
            qj = sc["q0"]
        from qpcoord.robots.external import example_robot_data_urdf

        urdf = URDFS["talos" if free else "panda"]
        data = {
            "robot": "talos" if free else "panda",
            "urdf": str(example_robot_data_urdf(urdf)),
            "frame": sc["frame"],
            "dt": DT,
            "targets": sc["targets"].tolist(),
            "rotation": None if sc["rotation"] is None else sc["rotation"].tolist(),
            "q0": dict(zip(joints, qj.tolist(), strict=True)),
            "speed": dict(zip(joints, sc["speed"][6:] if free else sc["speed"], strict=True)),
            "posture_weight": POSTURE_WEIGHT,
            **(extra or {}),
        }
        if free:
            data["soles"] = list(TALOS_SOLES)
            data["sole_poses"] = [robot.frame_pose(sc["q0"], s).tolist() for s in TALOS_SOLES]
            poly = qc.SupportPolygon(robot, list(TALOS_SOLES), contact_points=TALOS_CORNERS)
            data["polygon"] = _hull(poly, sc["q0"], robot).tolist()
            data["margin"] = TALOS_MARGIN
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
        env.pop("PYTHONPATH", None)
        # the URDFs' package:// meshes, resolved by PlaCo's Pinocchio through this path
        from qpcoord.robots.external import example_robot_data_package_dir

        env["ROS_PACKAGE_PATH"] = str(example_robot_data_package_dir())
        # stderr to a file, not a pipe: nobody reads it while the steps run, and a pipe
        # the child fills (PlaCo's or Pinocchio's warnings) would block it for good
        self._err = tempfile.TemporaryFile(mode="w+")
        self.proc = subprocess.Popen(
            [str(python), str(HERE / "placo_side.py")],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self._err,
            text=True,
            env=env,
        )
        self.proc.stdin.write(json.dumps(data) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"placo_side.py failed: {self._last_error()}")
        hello = json.loads(line)
        self.version = hello["placo"]
        index = {n: i for i, n in enumerate(hello["joints"])}
        off = 7 if free else 0
        self.order = np.array([off + index[n] for n in joints])
        self.free = free
        self.q = sc["q0"].copy()

    def step(self, k: int) -> float:
        self.proc.stdin.write(json.dumps({"k": k}) + "\n")
        self.proc.stdin.flush()
        return self._answer()

    def _last_error(self) -> str:
        """The child's last stderr line (after it died), or ``"no output"``."""
        self.proc.wait(timeout=10)
        self._err.seek(0)
        err = self._err.read().strip().splitlines()
        return err[-1] if err else "no output"

    def _answer(self) -> float:
        """Read one step's answer: its time (s); ``self.q`` becomes its configuration."""
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"placo_side.py died: {self._last_error()}")
        ans = json.loads(line)
        q = np.array(ans["q"])
        self.q = np.concatenate([q[:7], q[self.order]]) if self.free else q[self.order]
        return ans["t"]

    def request_all(self, steps: int) -> None:
        """Ask for steps ``0 … steps−1`` back to back, in one request (the subprocess never
        waits on the pipe between steps); then each :meth:`_answer` reads the next step's
        result. (One request line per step, written at once, hung from ~5 000 steps on:
        once they pass the pipe's 64 KiB the write blocks while the subprocess blocks on its
        full stdout, which nobody reads until the write returns.)"""
        self.proc.stdin.write(json.dumps({"run": steps}) + "\n")
        self.proc.stdin.flush()

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.stdin.write("\n")
            self.proc.stdin.flush()
            self.proc.wait(timeout=10)
        self._err.close()


def _row(name: str, loop, meter: Meter, ts: np.ndarray, mode: str) -> dict:
    """One table row: per-step times (the first 10 % dropped: caches and warm starts settle)
    and the solver's errors and limit violations."""
    us = ts[len(ts) // 10 :] * 1e6
    return {
        "scenario": name,
        "solver": loop.name,
        "mode": mode,
        "steps": len(ts),
        "median_us": float(np.median(us)),
        "p90_us": float(np.percentile(us, 90)),
        "p99_us": float(np.percentile(us, 99)),
        **meter.final(loop.q),
    }


def _makers(sc: dict, placo: Path | None, pink: bool, engines: bool) -> list:
    """Constructors of the scenario's solvers, in the lockstep's order (PlaCo last); qpcoord's
    Python engine and weighted method only with ``engines``."""
    makers = [lambda: QpcoordLoop(sc, "hierarchical", "native", "qpcoord strict native")]
    if engines:
        makers.append(lambda: QpcoordLoop(sc, "hierarchical", "python", "qpcoord strict python"))
    if engines and sc["name"] != "talos":
        makers.append(lambda: QpcoordLoop(sc, "weighted", None, "qpcoord weighted native"))
    if pink:
        makers.append(lambda: PinkLoop(sc))
    if placo is not None:
        makers.append(lambda: PlacoLoop(sc, placo))
    return makers


def _build(make, name: str, notes: list[str]):
    """``make()``, or ``None`` with a note if PlaCo's side does not start."""
    try:
        return make()
    except (RuntimeError, OSError, json.JSONDecodeError) as exc:
        notes.append(f"placo skipped on {name}: {exc}")
        return None


def run_back_to_back(
    name: str, steps: int, speed: float, placo: Path | None, pink: bool, engines: bool
) -> list[dict]:
    """Each solver runs the whole trajectory alone, one solver after the other (same scenario,
    same per-step timer, same meters as :func:`run`), built fresh: no other solver's steps
    between its own. PlaCo's step requests are all written at once, so its process never
    waits on the pipe between steps either."""
    sc = scenario(name, steps, speed)
    notes: list[str] = []
    rows = []
    for make in _makers(sc, placo, pink, engines):
        loop = _build(make, name, notes)
        if loop is None:
            continue
        meter = Meter(sc)
        ts = np.full(steps, np.nan)
        placo_side = isinstance(loop, PlacoLoop)
        try:
            with _threads_one() or _nothing():
                if placo_side:
                    loop.request_all(steps)
                for k in range(steps):
                    q_prev = loop.q.copy()
                    ts[k] = loop._answer() if placo_side else loop.step(k)
                    meter(q_prev, loop.q)
        except RuntimeError as exc:  # PlaCo's QPError, through the pipe
            notes.append(f"{loop.name} failed on {name} (back to back) at step {k}: {exc}")
            continue
        finally:
            loop.close()
        rows.append(_row(name, loop, meter, ts, "back to back"))
    return rows + [{"scenario": name, "note": n} for n in notes]


def _hull(poly, q0: np.ndarray, robot) -> np.ndarray:
    """The support polygon's corners in the world (m), **clockwise** (x, y): PlaCo's
    ``CoMPolygonConstraint`` reads them so (counter-clockwise makes its QP infeasible)."""
    pts = []
    for s in TALOS_SOLES:
        T = robot.frame_pose(q0, s)
        pts += [T[:3, :3] @ np.array(c) + T[:3, 3] for c in TALOS_CORNERS]
    pts = np.array(pts)[:, :2]
    c = pts.mean(axis=0)
    order = np.argsort(np.arctan2(pts[:, 1] - c[1], pts[:, 0] - c[0]))
    from scipy.spatial import ConvexHull

    hull = ConvexHull(pts[order])
    return pts[order][hull.vertices][::-1]


# --------------------------------------------------------------------------- measures


class Meter:
    """Per-solver errors and limit violations, measured on the configurations."""

    def __init__(self, sc: dict) -> None:
        self.sc, self.robot = sc, sc["robot"]
        r = self.robot
        self.free = sc["name"] == "talos"
        self.iq = np.arange(7, r.nq) if self.free else np.arange(r.nq)
        self.iv = np.arange(6, r.nv) if self.free else np.arange(r.nv)
        self.lower, self.upper = r.lower[self.iq], r.upper[self.iq]
        self.speed = sc["speed"][self.iv]
        self.pos_viol = self.speed_viol = 0.0
        self.feet = 0.0
        self.com = -np.inf
        if self.free:
            self.feet0 = [r.frame_pose(sc["q0"], s)[:3, 3] for s in TALOS_SOLES]
            self.polygon = qc.SupportPolygon(r, list(TALOS_SOLES), contact_points=TALOS_CORNERS)

    def __call__(self, q_prev: np.ndarray, q: np.ndarray) -> None:
        r = self.robot
        qj = q[self.iq]
        self.pos_viol = max(
            self.pos_viol, float(np.max(qj - self.upper)), float(np.max(self.lower - qj))
        )
        v = r.difference(q_prev, q)[self.iv] / DT
        self.speed_viol = max(self.speed_viol, float(np.max(np.abs(v) - self.speed)))
        if self.free:
            for s, p0 in zip(TALOS_SOLES, self.feet0, strict=True):
                self.feet = max(self.feet, float(np.linalg.norm(r.frame_pose(q, s)[:3, 3] - p0)))
            e = self.polygon.compute_error(q)[: self.polygon.edges]
            self.com = max(self.com, float(e.max()))

    def final(self, q: np.ndarray) -> dict:
        sc = self.sc
        T = self.robot.frame_pose(q, sc["frame"])
        out = {
            "position_error_m": float(np.linalg.norm(T[:3, 3] - sc["targets"][-1])),
            "joint_limit_violation_rad": max(self.pos_viol, 0.0),
            "speed_limit_violation_rad_s": max(self.speed_viol, 0.0),
        }
        if sc["rotation"] is not None:
            R = sc["rotation"].T @ T[:3, :3]
            out["orientation_error_rad"] = float(
                np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))
            )
        if self.free:
            out["feet_drift_m"] = self.feet
            out["com_beyond_sole_polygon_m"] = self.com
        return out


# --------------------------------------------------------------------------- run


def placo_python(path: str | None) -> Path | None:
    """PlaCo's interpreter: ``path``, or ``benchmarks/.placo-venv``'s if it exists."""
    p = Path(path) if path else PLACO_VENV / "bin" / "python"
    return p if p.exists() else None


def make_placo_venv() -> Path:
    """Create ``benchmarks/.placo-venv`` with ``placo-requirements.txt`` (needs the index)."""
    subprocess.run([sys.executable, "-m", "venv", str(PLACO_VENV)], check=True)
    pip = PLACO_VENV / "bin" / "pip"
    subprocess.run([str(pip), "install", "-q", "-r", str(PLACO_REQUIREMENTS)], check=True)
    return PLACO_VENV / "bin" / "python"


def run(
    name: str, steps: int, speed: float, placo: Path | None, pink: bool, engines: bool
) -> list[dict]:
    """Run one scenario with every available solver in lockstep; one row per solver."""
    sc = scenario(name, steps, speed)
    notes: list[str] = []
    loops = [
        loop
        for make in _makers(sc, placo, pink, engines)
        if (loop := _build(make, name, notes)) is not None
    ]
    meters = [Meter(sc) for _ in loops]
    times = np.full((len(loops), steps), np.nan)
    failed: set[int] = set()
    try:
        with _threads_one() or _nothing():
            for k in range(steps):
                for j in range(len(loops)):
                    i = (j + k) % len(loops)
                    if i in failed:
                        continue
                    q_prev = loops[i].q.copy()
                    try:
                        times[i, k] = loops[i].step(k)
                    except RuntimeError as exc:  # PlaCo's QPError, through the pipe
                        failed.add(i)
                        notes.append(f"{loops[i].name} failed on {name} at step {k}: {exc}")
                        continue
                    meters[i](q_prev, loops[i].q)
    finally:
        for loop in loops:
            loop.close()
    rows = [
        _row(name, loop, meter, ts, "lockstep")
        for i, (loop, meter, ts) in enumerate(zip(loops, meters, times, strict=True))
        if i not in failed
    ]
    for n in notes:
        rows.append({"scenario": name, "note": n})
    return rows


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


#: The error and limit columns of :func:`format_rows`: (row key, header).
ERRORS = (
    ("position_error_m", "hand error (m)"),
    ("orientation_error_rad", "orient. (rad)"),
    ("joint_limit_violation_rad", "joint-limit viol. (rad)"),
    ("speed_limit_violation_rad_s", "speed viol. (rad/s)"),
    ("feet_drift_m", "feet drift (m)"),
    ("com_beyond_sole_polygon_m", "CoM beyond soles (m)"),
)


def format_rows(rows: list[dict]) -> str:
    """One markdown table of :func:`run` and :func:`run_back_to_back` rows: per scenario and
    solver, the lockstep and the back-to-back times, the back-to-back median over PlaCo's
    (``–`` without PlaCo), and the errors and violations, the worse of the two modes (both
    follow the same trajectory); notes as lines under it."""
    by: dict[tuple[str, str], dict[str, dict]] = {}
    for r in rows:
        if "solver" in r:
            by.setdefault((r["scenario"], r["solver"]), {})[r["mode"]] = r
    placo = {sc: m.get("back to back") for (sc, s), m in by.items() if s == "placo"}

    def us(m: dict, mode: str, key: str) -> str:
        return f"{m[mode][key]:.1f}" if mode in m else "–"

    body = []
    for (sc, solver), m in by.items():
        alone, ref = m.get("back to back"), placo.get(sc)
        ratio = f"{alone['median_us'] / ref['median_us']:.1f}" if alone and ref else "–"
        errors = [
            f"{max(r[key] for r in m.values()):.2e}" if key in next(iter(m.values())) else "–"
            for key, _ in ERRORS
        ]
        body.append(
            (sc, solver, us(m, "lockstep", "median_us"), us(m, "lockstep", "p99_us"),
             us(m, "back to back", "median_us"), us(m, "back to back", "p99_us"), ratio, *errors)
        )  # fmt: skip
    head = ("scenario", "solver", "lockstep median µs", "lockstep p99 µs", "alone median µs")
    head += ("alone p99 µs", "alone median / PlaCo", *(h for _, h in ERRORS))
    notes = [r["note"] for r in rows if "note" in r]
    return "\n".join([markdown(head, body, "ll" + "r" * (len(head) - 2)), *notes])


def profile(steps: int) -> str:
    """cProfile of the native strict IK step on ``panda-position`` (top 25 by own time)."""
    import cProfile
    import io
    import pstats

    sc = scenario("panda-position", steps, 0.8)
    loop = QpcoordLoop(sc, "hierarchical", "native", "qpcoord strict native")
    for k in range(50):
        loop.step(k)
    pr = cProfile.Profile()
    with _threads_one() or _nothing():
        pr.enable()
        for k in range(50, steps):
            loop.step(k)
        pr.disable()
    out = io.StringIO()
    pstats.Stats(pr, stream=out).sort_stats("tottime").print_stats(25)
    return out.getvalue()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="60 steps per scenario (smoke run)")
    p.add_argument("--steps", type=int, default=None, help="steps (default 2000, Talos 1000)")
    p.add_argument("--scenario", action="append", choices=SCENARIOS)
    p.add_argument("--speed", type=float, default=0.8, help="Panda speed limit (rad/s)")
    p.add_argument("--placo-python", default=None, help="PlaCo's interpreter")
    p.add_argument("--no-placo", action="store_true")
    p.add_argument("--no-pink", action="store_true")
    p.add_argument("--make-placo-venv", action="store_true")
    p.add_argument("--profile", action="store_true")
    p.add_argument(
        "--no-back-to-back",
        action="store_true",
        help="skip the back-to-back runs (each solver's whole trajectory alone)",
    )
    p.add_argument(
        "--engines",
        action="store_true",
        help="also qpcoord's Python engine and its weighted method (rows 'qpcoord strict "
        "python', 'qpcoord weighted native'; the Panda only for the weighted one)",
    )
    p.add_argument("--json", type=Path, default=None, help="also write the rows here")
    args = p.parse_args(argv)
    if args.steps is not None and args.steps < 20:
        raise SystemExit(f"--steps must be >= 20, got {args.steps}")
    if args.profile:
        print(profile(args.steps or 2000))
        return 0
    if args.make_placo_venv:
        print(f"PlaCo interpreter: {make_placo_venv()}")
        return 0
    print(preamble())
    placo = None if args.no_placo else placo_python(args.placo_python)
    if placo is None and not args.no_placo:
        print(
            f"PlaCo skipped: no interpreter at {args.placo_python or PLACO_VENV / 'bin/python'} "
            "(python benchmarks/ik_peers.py --make-placo-venv creates it)"
        )
    pink = False
    if not args.no_pink:
        import importlib.util

        pink = importlib.util.find_spec("pink") is not None
        if not pink:
            print("Pink skipped: pin-pink not installed (the bench extra)")
    rows = []
    for name in args.scenario or SCENARIOS:
        steps = args.steps or (2000 if name != "talos" else 1000)
        if args.quick:
            steps = 60
        try:
            rows += run(name, steps, args.speed, placo, pink, args.engines)
            if not args.no_back_to_back:
                rows += run_back_to_back(name, steps, args.speed, placo, pink, args.engines)
        except ValueError as exc:  # example-robot-data missing
            rows.append({"scenario": name, "note": f"{name} skipped: {exc}"})
    print(
        "Lockstep: one step of each solver in turn, the order rotating every step; alone: "
        "each solver's whole trajectory alone, one after the other"
        + (" (not run)" if args.no_back_to_back else "")
        + ":\n"
    )
    print(format_rows(rows))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
