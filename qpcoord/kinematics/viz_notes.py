"""What held the robot, frame by frame: :func:`annotate` for :func:`qpcoord.viz.animate`.

For each configuration of a run, :func:`annotate` measures the distance of every collision
pair (:meth:`CollisionAvoidance.compute_distances
<qpcoord.CollisionAvoidance.compute_distances>`) with the witness points of the nearest
pairs, and re-evaluates the IK's rows at that configuration to list the constraints the
step's velocity is at (or beyond): joint limits by joint, hard constraints and
inequality tasks by task and row (collision rows by pair). The result, an
:class:`Annotations`, is a sequence of :class:`FrameNote`, one per configuration;
``animate(..., annotations=...)`` draws it: the nearest pairs' witness segments coloured by
their distance, a marker on each joint at a limit, and a text overlay per frame.

A row is *active* when ``C_i v`` is within ``CHECK_TOL · max(1, |bound|, ‖C_i‖ ‖v‖)`` of a
finite bound (:data:`~qpcoord.core.elimination.CHECK_TOL`, the tolerance every solution is
checked to; ``‖C_i‖ ‖v‖`` is the row's rounding scale), *violated* beyond it: the rule of
:mod:`qpcoord.core.explain`, whose row test this module uses.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, overload

import numpy as np

from ..core.explain import _rows
from .collision import CollisionAvoidance
from .ik import IK
from .paths import Path

__all__ = [
    "annotate",
    "between",
    "Annotations",
    "FrameNote",
    "Witness",
    "ActiveRow",
    "NEAREST_PAIRS",
]

#: Pairs whose witness segments a frame shows by default (nearest first).
NEAREST_PAIRS = 3

#: A witness segment's state: ``"inside"`` below ``min_distance``, ``"near"`` within
#: ``influence_distance`` (the pair's damper row is on), ``"clear"`` farther.
SEGMENT_STATES = ("clear", "near", "inside")


@dataclass(frozen=True)
class Witness:
    """One collision pair at one frame.

    Attributes
    ----------
    index : int
        The pair's row in :class:`~qpcoord.CollisionAvoidance` (``pairs[index]``).
    pair : (str, str)
        Its geometry names (robot geometry first).
    distance : float
        Distance (m); negative: penetration depth.
    points : numpy.ndarray, shape (2, 3)
        The witness points on the first and the second geometry (world, m).
    state : str
        ``"inside"`` (``distance < min_distance``), ``"near"`` (below
        ``influence_distance``) or ``"clear"``.
    """

    index: int
    pair: tuple[str, str]
    distance: float
    points: np.ndarray
    state: str


@dataclass(frozen=True)
class ActiveRow:
    """One row at (or beyond) a bound at one frame.

    Attributes
    ----------
    level : str
        ``"limits"`` (the IK's box on ``v``), ``"constraints"`` (hard) or ``"level k"``.
    task : str
        The limit that sets that side of the box (e.g. ``"joint limits"``) or the task's name.
    row : int
        Row within the task; for the box, the index in ``v``.
    name : str
        What the row is: a joint (``"panda_joint4"``), a collision pair (``"a – b"``), or
        ``"row k"``.
    side : str
        ``"lower"`` or ``"upper"``.
    bound, value : float
        The bound and ``C_i v`` (the row's units: rad/s, m/s for the box).
    violation : float
        How far beyond the bound (≥ 0; 0 when the row holds).
    joint : str or None
        The joint (model name) of a box row.
    """

    level: str
    task: str
    row: int
    name: str
    side: str
    bound: float
    value: float
    violation: float
    joint: str | None = None

    def __str__(self) -> str:
        sign = "≥" if self.side == "lower" else "≤"
        tail = f"  violated by {self.violation:.3g}" if self.violation > 0 else ""
        return f"[{self.level}] {self.task}: {self.name} {sign} {self.bound:.4g}{tail}"


@dataclass(frozen=True)
class FrameNote:
    """What a frame shows.

    Attributes
    ----------
    time : float
        Time of the configuration (s).
    distances : numpy.ndarray or None
        Distance of every collision pair (m), as ``compute_distances``; ``None`` without
        ``collision``.
    nearest : tuple of Witness
        The nearest pairs, nearest first (their witness segments are drawn).
    active : tuple of ActiveRow or None
        The rows the step's velocity is at or beyond; ``None`` for a configuration with no
        step (the last one of a run) or without ``solutions``.
    """

    time: float
    distances: np.ndarray | None
    nearest: tuple[Witness, ...]
    active: tuple[ActiveRow, ...] | None

    @property
    def segments(self) -> list[tuple[np.ndarray, np.ndarray, str]]:
        """``(p1, p2, state)`` of each witness segment drawn (m, world)."""
        return [(w.points[0], w.points[1], w.state) for w in self.nearest]

    @property
    def joints(self) -> list[str]:
        """Joints at one of the IK's limits (model names), each once."""
        return list(dict.fromkeys(r.joint for r in self.active or () if r.joint))

    @property
    def text(self) -> str:
        """The frame's overlay text."""
        lines = [f"t = {self.time:.3f} s"]
        if self.nearest:
            lines.append("nearest pairs (m):")
            lines += [
                f"  {w.distance:+.4f}  {w.pair[0]} – {w.pair[1]}  {w.state}" for w in self.nearest
            ]
        if self.active is not None:
            lines.append("active:" if self.active else "active: none")
            lines += [f"  {r}" for r in self.active]
        return "\n".join(lines)


class Annotations(Sequence[FrameNote]):
    """One :class:`FrameNote` per configuration of a run (what :func:`annotate` returns).

    Attributes
    ----------
    frames : tuple of FrameNote
    pairs : tuple of (str, str)
        The collision pairs (empty without ``collision``).
    """

    def __init__(self, frames: Sequence[FrameNote], pairs: Sequence[tuple[str, str]]) -> None:
        self.frames = tuple(frames)
        self.pairs = tuple(pairs)

    def __len__(self) -> int:
        return len(self.frames)

    @overload
    def __getitem__(self, k: int) -> FrameNote: ...
    @overload
    def __getitem__(self, k: slice) -> Sequence[FrameNote]: ...
    def __getitem__(self, k: int | slice) -> FrameNote | Sequence[FrameNote]:
        return self.frames[k]

    def __repr__(self) -> str:
        return f"Annotations(frames={len(self.frames)}, pairs={len(self.pairs)})"


# ---------------------------------------------------------------------- inputs
def trajectory_samples(robot: Any, trajectory: Any, t: Any) -> tuple[np.ndarray, np.ndarray | None]:
    """Validated configurations (N, nq) of ``trajectory`` (a ``qc.Trajectory`` or an array)
    and their times (s, shape (N,)): ``t``, else the trajectory's, else ``None``. Shared by
    :func:`annotate` and :func:`qpcoord.viz.animate`."""
    times = None
    if hasattr(trajectory, "q") and hasattr(trajectory, "t"):
        trajectory, times = trajectory.q, trajectory.t
    try:
        q = np.array(trajectory, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("trajectory must be a qc.Trajectory or an (N, nq) array") from None
    if q.ndim == 1 and q.size == robot.nq:
        q = q[None, :]
    if q.ndim != 2 or q.shape[0] == 0 or q.shape[1] != robot.nq:
        raise ValueError(
            f"trajectory must hold configurations of shape (N, nq) with nq = {robot.nq} "
            f"for robot {robot.name!r}, got shape {q.shape}"
        )
    for k in range(q.shape[0]):
        robot.check_configuration(q[k], f"trajectory[{k}]")
    if t is not None:
        times = t
    if times is None:
        return q, None
    n = q.shape[0]
    times = np.array(times, dtype=float).reshape(-1)
    if times.shape != (n,) or not np.all(np.isfinite(times)):
        raise ValueError(f"t must hold {n} finite sample times (s), got shape {times.shape}")
    return q, times


def _configurations(ik: IK, trajectory: Any, t: Any) -> tuple[np.ndarray, np.ndarray]:
    """Configurations (N, nq) and their times (s): ``t``, the trajectory's, or ``k · dt``."""
    q, times = trajectory_samples(ik.robot, trajectory, t)
    return q, np.arange(q.shape[0]) * ik.dt if times is None else times


def _velocities(ik: IK, solutions: Any, n: int) -> list[np.ndarray]:
    """The step velocities (nv,): one per configuration, or one fewer (no step from the
    last configuration)."""
    if solutions is None:
        return []
    items = list(solutions)
    if len(items) not in (n, n - 1):
        raise ValueError(
            f"solutions: {len(items)} given for {n} configurations (one per step: {n} or {n - 1})"
        )
    out = []
    for k, s in enumerate(items):
        x = getattr(s, "x", s)
        try:
            v = np.array(x, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"solutions[{k}] must be a Solution or a velocity (nv,)") from None
        if v.shape != (ik.robot.nv,) or not np.all(np.isfinite(v)):
            raise ValueError(
                f"solutions[{k}] must be a finite velocity of size nv = {ik.robot.nv}, got "
                f"shape {v.shape}"
            )
        out.append(v)
    return out


# ---------------------------------------------------------------------- rows at a bound
def _at_bound(values, lower, upper, scale) -> list[tuple[int, str, float, float, float]]:
    """``(row, side, bound, value, violation)`` of the rows at or beyond a finite bound: the
    rule of :meth:`Solution.explain() <qpcoord.Solution.explain>` (its tolerance)."""
    return [
        (r.row, r.side, r.bound, r.value, r.violation)
        for r in _rows(values, lower, upper, scale)[0]
    ]


def _joint_of(model: Any, i: int) -> tuple[str, str]:
    """``(model joint name, name of v[i])`` -- ``"name[k]"`` for a joint's k-th of several."""
    for j in range(1, model.njoints):
        first, size = model.joints[j].idx_v, model.joints[j].nv
        if first <= i < first + size:
            name = model.names[j]
            return name, name + (f"[{i - first}]" if size > 1 else "")
    return "", f"v[{i}]"


def _active(
    ik: IK, q: np.ndarray, v: np.ndarray, collision: CollisionAvoidance | None
) -> tuple[ActiveRow, ...]:
    """The IK's rows (refreshed at ``q``) that ``v`` is at or beyond."""
    rows: list[ActiveRow] = []
    vnorm = float(np.linalg.norm(v))
    P = ik.stack.compiled
    groups = [(f"level {k}", L.ineqs) for k, L in enumerate(P.levels)]
    groups.append(("constraints", P.hard.ineqs))
    pair_task = None if collision is None else collision.task
    for level, tasks in groups:
        for task in tasks:
            C = task.C
            scale = np.linalg.norm(C, axis=1) * vnorm
            for i, side, bound, value, miss in _at_bound(C @ v, task.lower, task.upper, scale):
                if task is pair_task:
                    assert collision is not None
                    a, b = collision.pairs[i]
                    name = f"{a} – {b}"
                else:
                    name = f"row {i}"
                rows.append(ActiveRow(level, task.name, i, name, side, bound, value, miss))
    if ik.limits:
        lower, upper = ik.bounds.resolve(ik.robot.nv)
        boxes = [(lim.task.name, *lim.box(q, ik.dt)) for lim in ik.limits]
        for i, side, bound, value, miss in _at_bound(v, lower, upper, np.abs(v)):
            # the limit that sets this side (the nearest side value; the IK keeps the end
            # nearer to 0 where the boxes do not meet, so the other side may set it)
            gap = []
            for limit, a, b in boxes:
                gap.append((abs(a[i] - bound), side != "lower", limit))
                gap.append((abs(b[i] - bound), side != "upper", limit))
            joint, name = _joint_of(ik.robot.model, i)
            rows.append(ActiveRow("limits", min(gap)[2], i, name, side, bound, value, miss, joint))
    return tuple(rows)


# ---------------------------------------------------------------------- the call
def annotate(
    ik: IK,
    trajectory: Any,
    solutions: Sequence[Any] | None = None,
    collision: CollisionAvoidance | None = None,
    *,
    t: Any = None,
    reference: Path | None = None,
    v_prev: Any = None,
    nearest: int = NEAREST_PAIRS,
) -> Annotations:
    """Per-frame notes of a run for :func:`qpcoord.viz.animate`: pair distances, witness
    segments and the constraints each step was held by.

    Parameters
    ----------
    ik : IK
        The IK that made the run; its rows are re-evaluated at each configuration (its
        tasks' refresh, as in a step). Its ``v_prev`` and last solution are restored
        afterwards; its tasks hold the rows of the last configuration.
    trajectory : qpcoord.Trajectory or array_like, shape (N, nq)
        The configurations (rad, m), as given to ``animate``.
    solutions : sequence, optional
        The steps' :class:`~qpcoord.Solution` (or velocities ``v``, (nv,), rad/s, m/s): one
        per configuration, or one fewer (the last configuration has no step). Without them
        no active rows are listed.
    collision : CollisionAvoidance, optional
        Pairs whose distances are measured (``compute_distances``, m) -- the IK's own or
        one only for watching. Its rows in the IK are named by pair.
    t : array_like, shape (N,), optional
        Times (s) of the configurations, for tasks that follow a path (default: the
        trajectory's, or ``k · ik.dt``).
    reference : Path, optional
        The path given to ``ik.step``.
    v_prev : array_like, shape (nv,), optional
        The velocity before the first step (rad/s, m/s; default 0: a run from rest), for
        acceleration limits; the later steps take the previous solution's.
    nearest : int
        Pairs per frame whose witness segments are drawn and listed (nearest first),
        default 3.

    Returns
    -------
    Annotations
        One :class:`FrameNote` per configuration.

    Raises
    ------
    ValueError
        ``ik`` not an IK; configurations of the wrong size (``trajectory[k]``); a number of
        ``solutions`` other than N or N − 1, or a velocity of the wrong size
        (``solutions[k]``); ``collision`` not a CollisionAvoidance on the IK's robot;
        neither ``solutions`` nor ``collision``; bad ``t``, ``v_prev`` or ``nearest``.
    """
    if not isinstance(ik, IK):
        raise ValueError(f"ik must be a qpcoord.IK, got {type(ik).__name__}")
    if collision is not None:
        if not isinstance(collision, CollisionAvoidance):
            raise ValueError(
                f"collision must be a qpcoord.CollisionAvoidance, got {type(collision).__name__}"
            )
        if collision.robot.model is not ik.robot.model:
            raise ValueError("collision: its robot is not the IK's (another Pinocchio model)")
    if solutions is None and collision is None:
        raise ValueError("annotate: give solutions (active rows) and/or collision (distances)")
    if isinstance(nearest, bool) or not isinstance(nearest, (int, np.integer)) or nearest < 0:
        raise ValueError(f"nearest must be an integer ≥ 0, got {nearest!r}")
    q, times = _configurations(ik, trajectory, t)
    vs = _velocities(ik, solutions, q.shape[0])
    v0 = np.zeros(ik.robot.nv) if v_prev is None else ik.robot._check_velocity(v_prev)

    saved_v, saved_last = ik.v_prev.copy(), ik.last
    frames = []
    try:
        for k in range(q.shape[0]):
            distances = None
            witnesses: tuple[Witness, ...] = ()
            if collision is not None:
                distances = collision.compute_distances(q[k])
                witnesses = _witnesses(collision, distances, int(nearest))
            active = None
            if k < len(vs):
                ik.reset(vs[k - 1] if k else v0)  # the acceleration limits' v_prev
                ik.refresh(q[k], float(times[k]), reference)
                active = _active(ik, q[k], vs[k], collision)
            frames.append(FrameNote(float(times[k]), distances, witnesses, active))
    finally:
        ik.reset(saved_v)
        ik.last = saved_last
    return Annotations(frames, collision.pairs if collision is not None else ())


def _witnesses(
    collision: CollisionAvoidance, distances: np.ndarray, count: int
) -> tuple[Witness, ...]:
    """The ``count`` nearest pairs, from the distance results ``compute_distances`` left."""
    results = collision.geometry_data.distanceResults
    d_s, d_i = collision.min_distance, collision.influence_distance
    out = []
    for i in np.argsort(distances, kind="stable")[:count]:
        res = results[int(i)]
        points = np.array([res.getNearestPoint1(), res.getNearestPoint2()], dtype=float)
        d = float(distances[i])
        state = "inside" if d < d_s else "near" if d < d_i else "clear"
        out.append(Witness(int(i), collision.pairs[int(i)], d, points, state))
    return tuple(out)


def between(notes: Sequence[FrameNote], first: int, last: int) -> str:
    """What the configurations strictly between frames ``first`` and ``last`` showed that
    frame ``last`` does not: a nearer pair, and rows active there but not at ``last``
    (with the number of steps). Empty when they add nothing -- the lines a page adds to
    frame ``last``'s text when it skips the frames in between (``fps``)."""
    hidden = notes[first + 1 : last]
    if not hidden:
        return ""
    lines = []
    here = notes[last]
    closest = min(
        (n for n in hidden if n.nearest), key=lambda n: n.nearest[0].distance, default=None
    )
    if closest is not None and (
        not here.nearest or closest.nearest[0].distance < here.nearest[0].distance
    ):
        w = closest.nearest[0]
        lines.append(
            f"  nearest {w.distance:+.4f}  {w.pair[0]} – {w.pair[1]}  {w.state} "
            f"at t = {closest.time:.3f} s"
        )
    now = {(r.level, r.task, r.name, r.side) for r in here.active or ()}
    counts: dict[tuple[str, str, str, str], int] = {}
    for n in hidden:
        for r in n.active or ():
            key = (r.level, r.task, r.name, r.side)
            if key not in now:
                counts[key] = counts.get(key, 0) + 1
    for (level, task, name, side), count in counts.items():
        sign = "≥" if side == "lower" else "≤"
        lines.append(f"  also active: [{level}] {task}: {name} {sign} bound ({count} steps)")
    if not lines:
        return ""
    head = (
        f"between frames (t {hidden[0].time:.3f}–{hidden[-1].time:.3f} s, {len(hidden)} not shown):"
    )
    return "\n".join([head, *lines])
