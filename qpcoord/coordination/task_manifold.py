"""The task manifold of a redundant arm with one degree of redundancy (thesis Def. 5.1).

For a path ``Y(t)`` the task manifold is the union of the *redundancy fibres* (self-motion
curves) ``𝔖(Y) = {q : ζ(q) = Y}`` over the points of the path; for the 3R arm on a circle
it is a torus ``S¹ × S¹`` (§5.2.1, Fig. 5.1). Here:

- :func:`fibre` -- trace the fibre through ``q`` (``nq − rows = 1``) until it closes,
  returning the configurations (rad) and the arc length (rad);
- :func:`fibre_point` -- move a signed arc length ``s`` along the fibre (the choice of
  ``q̄`` in §5.5);
- :func:`self_motion_direction` -- the unit tangent of the fibre at ``q``.

The fibre is followed with RK4 steps of the unit null-space field, each followed by
Gauss–Newton corrections back onto ``ζ(q) = Y`` (to 1e-12 m), so it does not drift off the
fibre over long traces.
"""

from __future__ import annotations

import numpy as np

from ..core.linalg import null_space
from ..kinematics.robot import Robot

__all__ = ["fibre", "fibre_point", "self_motion_direction", "wrap_angles"]


def _check(robot) -> Robot:
    if not isinstance(robot, Robot):
        raise ValueError(f"robot must be a qpcoord.Robot, got {type(robot).__name__}")
    if robot.nq - robot.m != 1:
        raise ValueError(
            f"fibres are traced for one degree of redundancy; robot {robot.name!r} has "
            f"nq − rows = {robot.nq - robot.m}"
        )
    return robot


def wrap_angles(q) -> np.ndarray:
    """Angles wrapped to ``(−π, π]`` (rad)."""
    q = np.asarray(q, dtype=float)
    return np.pi - np.mod(np.pi - q, 2 * np.pi)


def self_motion_direction(robot, q, previous=None) -> np.ndarray:
    """Unit tangent of the fibre through ``q`` (``J n = 0``, ``‖n‖ = 1``).

    The sign is chosen to agree with ``previous`` if given, else so that the largest
    entry is positive.

    Raises
    ------
    ValueError
        ``q`` singular (the null space is not one-dimensional there).
    """
    robot = _check(robot)
    q = robot.check_configuration(q)
    N = null_space(robot.jacobian(q))
    if N.shape[1] != 1:
        raise ValueError(f"singular configuration q = {q.tolist()}: the fibre is not a curve")
    n = N[:, 0]
    if previous is not None:
        if n @ previous < 0:
            n = -n
    elif n[np.argmax(np.abs(n))] < 0:
        n = -n
    return n


def _project(robot: Robot, q: np.ndarray, y0: np.ndarray) -> np.ndarray:
    for _ in range(8):
        y, J = robot._kinematics(q)
        e = y0 - y
        if np.linalg.norm(e) <= 1e-12:
            break
        q = q + np.linalg.lstsq(J, e, rcond=None)[0]
    return q


def _advance(robot, q, h, y0, n_prev):
    def f(x, prev):
        return self_motion_direction(robot, x, prev)

    k1 = f(q, n_prev)
    k2 = f(q + 0.5 * h * k1, k1)
    k3 = f(q + 0.5 * h * k2, k1)
    k4 = f(q + h * k3, k1)
    q_new = _project(robot, q + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4), y0)
    return q_new, k1


def fibre(
    robot, q, step: float = 0.02, max_length: float = 100.0, periodic_angles: bool = True
) -> tuple[np.ndarray, float]:
    """Trace the redundancy fibre through ``q`` until it closes.

    Parameters
    ----------
    robot : Robot
        One degree of redundancy (``nq − rows = 1``).
    q : array_like, shape (nq,)
        Start configuration (rad), not singular.
    step : float
        Arc-length step (rad), default 0.02.
    max_length : float
        Give up after this arc length (rad).
    periodic_angles : bool
        Count a return modulo 2π in every coordinate as closing (revolute joints).

    Returns
    -------
    points : ndarray, shape (N, nq)
        Configurations along the fibre (rad), first = ``q``; the closing point is not
        repeated.
    length : float
        Arc length of the closed fibre (rad).

    Raises
    ------
    ValueError
        Bad arguments, an exactly singular configuration met on the way, or no closure
        within ``max_length``.

    Notes
    -----
    Where the task manifold is pinched (the unit 3R at ``|y| = 1``, fibre through the
    singular ``(π, 0, 0)``) the trace passes close to the singularity without stopping and
    may continue on the other branch (measured: σ_min 4.4e-3 on the way, one winding in
    q₂ and q₃; ``examples/ch5_task_manifold.py``).
    """
    robot = _check(robot)
    q = robot.check_configuration(q).copy()
    if isinstance(step, bool) or not np.isfinite(step) or step <= 0:
        raise ValueError(f"step must be > 0 and finite (rad), got {step!r}")
    if isinstance(max_length, bool) or not np.isfinite(max_length) or max_length <= step:
        raise ValueError(f"max_length must be finite and > step (rad), got {max_length!r}")
    y0 = robot.position(q)
    start = q.copy()
    pts = [q.copy()]
    n_prev = None
    length = 0.0
    while length < max_length:
        q_new, n_prev = _advance(robot, q, step, y0, n_prev)
        length += float(np.linalg.norm(q_new - q))
        q = q_new
        d = q - start
        if periodic_angles:
            d = wrap_angles(d)
        gap = float(np.linalg.norm(d))
        if length > 3 * step and gap < 0.75 * step:
            # replace the last step by the chord from the last kept point to the start
            # (its copy shifted by whole turns, q − d)
            last = float(np.linalg.norm(q - pts[-1]))
            chord = float(np.linalg.norm((q - d) - pts[-1]))
            return np.array(pts), length - last + chord
        pts.append(q.copy())
    raise ValueError(
        f"the fibre through q = {start.tolist()} did not close within {max_length} rad"
    )


def fibre_point(robot, q, s: float, step: float = 0.01) -> np.ndarray:
    """The configuration at signed arc length ``s`` (rad) along the fibre from ``q``.

    The positive direction is :func:`self_motion_direction` at ``q``. The end-effector
    position is kept to 1e-12 m.
    """
    robot = _check(robot)
    q = robot.check_configuration(q).copy()
    if isinstance(s, bool) or not np.isfinite(s):
        raise ValueError(f"s must be a finite arc length (rad), got {s!r}")
    if s == 0:
        return q
    y0 = robot.position(q)
    n_prev = self_motion_direction(robot, q)
    sign = 1.0 if s > 0 else -1.0
    if sign < 0:
        n_prev = -n_prev
    steps = max(1, int(np.ceil(abs(s) / step)))
    h = abs(s) / steps
    for _ in range(steps):
        # march with h along the direction that continues n_prev
        q, n_prev = _advance(robot, q, h, y0, n_prev)
    return q
