"""Per-step cost of the stacks a robot cell adds to a pose step: bands, collision, polygons.

Scenarios (1 kHz, the targets of ``ik_peers.py``, one BLAS thread):

- Panda (7 DoF, fingers locked), the hand's pose on a 0.1 m horizontal circle above a posture
  task, hard joint position and speed limits (``ik_peers.py``'s ``panda-pose``), then the same
  with, at level 0:

  - ``+ table band``: a :class:`~qpcoord.PositionBand` keeping the hand 5 cm above a table
    (``z ≥ z₀ − 0.05`` m; the other sides free);
  - ``+ sphere``: the band and a :class:`~qpcoord.kinematics.collision.CollisionAvoidance`
    against one 5 cm sphere 20 cm in front of the hand (17 robot-vs-sphere pairs);
  - ``+ self-collision + sphere``: the band and ``CollisionAvoidance(self_collision=True)``
    with the sphere (the SRDF's pairs removed).

- Talos (free flyer, nv = 38): feet, the CoM in the support polygon, the right gripper on a
  minimum-jerk path, posture (``ik_peers.py``'s ``talos``), and the same without the polygon.

A timed step is ``set_target`` and :meth:`IK.step_integrate <qpcoord.IK.step_integrate>`
(the tasks' refresh, the limit box, the strict hierarchy and the integration of ``q``).
Median and 99th percentile of the per-step wall time over the run, the range over
``--runs`` runs of every stack in turn; ratio: the median over the scenario's first row.
Nothing here is asserted (tests never time).

Run: ``python benchmarks/cell_stacks.py [--steps 1400] [--runs 2] [--scenario panda|talos]``
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from _table import markdown, preamble, span  # noqa: E402
from ik_peers import (  # noqa: E402
    ALPHA,
    DT,
    HAND_ALPHA,
    TALOS_CORNERS,
    TALOS_MARGIN,
    TALOS_SOLES,
    scenario,
)

import qpcoord as qc  # noqa: E402
from qpcoord.kinematics.collision import CollisionAvoidance, Sphere  # noqa: E402

PANDA_STACKS = ("pose + posture", "+ table band", "+ sphere", "+ self-collision + sphere")
TALOS_STACKS = ("feet, hand, posture", "+ CoM in the support polygon")
TABLE_DROP = 0.05  # m below the start: the table band's face
SPHERE_AHEAD, SPHERE_RADIUS = 0.2, 0.05  # m


class Loop:
    """One IK on a scenario with the cell's additions ``extra`` (a name of the tuples above);
    ``sphere``: the sphere's centre (m, default ``SPHERE_AHEAD`` in front of the hand)."""

    def __init__(self, sc: dict, extra: str, sphere=None) -> None:
        robot = sc["robot"]
        self.q = sc["q0"].copy()
        self.targets = sc["targets"]
        hand_gain, posture_gain = HAND_ALPHA / DT, ALPHA / DT
        if sc["name"] == "talos":
            feet = [qc.FrameTask(robot, s, gain=1.0 / DT) for s in TALOS_SOLES]
            for foot in feet:
                foot.set_target_from_configuration(self.q)
            self.hand = qc.FramePositionTask(robot, sc["frame"], self.targets[0], gain=hand_gain)
            posture = qc.PostureTask(robot, self.q, gain=posture_gain)
            levels: list = [feet, self.hand, posture]
            if extra == TALOS_STACKS[1]:
                polygon = qc.SupportPolygon(
                    robot,
                    list(TALOS_SOLES),
                    margin=TALOS_MARGIN,
                    gain=1.0 / DT,
                    contact_points=TALOS_CORNERS,
                )
                levels.insert(1, polygon)
            self.ik = qc.IK(robot, levels, DT, limits="robot")
            self._T = None
            return
        T0 = robot.frame_pose(self.q, sc["frame"])
        self._T = T0.copy()
        self.hand = qc.FrameTask(robot, sc["frame"], self._pose(0), gain=hand_gain)
        posture = qc.PostureTask(robot, self.q, gain=posture_gain)
        top: list = []
        if extra != PANDA_STACKS[0]:
            lower = np.array([-np.inf, -np.inf, T0[2, 3] - TABLE_DROP])
            top.append(qc.PositionBand(robot, lower=lower, gain=1.0 / DT, name="table"))
        if extra in PANDA_STACKS[2:]:
            centre = T0[:3, 3] + [SPHERE_AHEAD, 0.0, 0.0] if sphere is None else sphere
            top.append(
                CollisionAvoidance(
                    robot,
                    obstacles=[Sphere(centre, SPHERE_RADIUS)],
                    self_collision=extra == PANDA_STACKS[3],
                )
            )
        levels = ([top] if top else []) + [self.hand, posture]
        limits = [qc.JointLimits(robot, gain=0.5), qc.VelocityLimits(robot, sc["speed"])]
        self.ik = qc.IK(robot, levels, DT, limits=limits)

    def _pose(self, k: int):
        T = self._T
        T[:3, 3] = self.targets[k]
        return T

    def step(self, k: int) -> float:
        t0 = time.perf_counter()
        self.hand.set_target(self.targets[k] if self._T is None else self._pose(k))
        self.q, _, _ = self.ik.step_integrate(self.q)
        return time.perf_counter() - t0


def run(name: str, steps: int, runs: int) -> list[list[str]]:
    """Rows of the table: every stack of the scenario, ``runs`` runs each, in turn."""
    stacks = PANDA_STACKS if name == "panda" else TALOS_STACKS
    sc = scenario("panda-pose" if name == "panda" else "talos", steps, 0.8)
    med: dict[str, list[float]] = {s: [] for s in stacks}
    p99: dict[str, list[float]] = {s: [] for s in stacks}
    for _ in range(runs):
        for s in stacks:
            loop = Loop(sc, s)
            times = np.array([loop.step(k) for k in range(steps)]) * 1e6
            med[s].append(float(np.median(times)))
            p99[s].append(float(np.percentile(times, 99)))
    base = np.median(med[stacks[0]])
    label = "Panda" if name == "panda" else "Talos"
    return [
        [
            f"{label}: {s}",
            span(med[s]),
            span(p99[s]),
            f"{np.median(med[s]) / base:.2f}×",
        ]
        for s in stacks
    ]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=1400, help="steps per run (default 1400)")
    p.add_argument("--runs", type=int, default=2, help="runs of every stack (default 2)")
    p.add_argument(
        "--scenario",
        choices=("panda", "talos"),
        action="append",
        help="panda and/or talos (default both)",
    )
    a = p.parse_args(argv)
    if a.steps < 10 or a.runs < 1:
        p.error("--steps must be at least 10 and --runs at least 1")
    rows = []
    for name in a.scenario or ("panda", "talos"):
        rows += run(name, a.steps, a.runs)
    print(preamble())
    print(
        f"µs per step, {a.steps} steps, the range over {a.runs} run(s); ratio: median over "
        "the scenario's first row:\n"
    )
    print(markdown(["stack", "median µs", "p99 µs", "ratio"], rows, "lrrr"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
