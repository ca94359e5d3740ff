"""Run a coordination scheme along a reference path: :func:`simulate` → :class:`Trajectory`.

A *scheme* is anything with ``velocity(q, t, reference) -> v`` (size ``robot.nv``; ``q̇`` in
rad/s for the thesis arms): an
:class:`~qpcoord.IK` stack, or the thesis schemes of later chapters. A list of levels is
turned into an :class:`~qpcoord.IK` for you.

Integration
-----------
``integrator="rk4"`` (default) integrates the closed-loop ODE ``q̇ = scheme(q, t)`` with the
classical Runge–Kutta method (four scheme evaluations per step): the end-effector error of
the thesis tasks stays within 1e-6 of the path length (see ``tests/test_simulate.py``).
``integrator="euler"`` applies one scheme evaluation per step, ``q ← q + dt q̇``, as a
real control loop at period ``dt`` does.

Every update goes through :meth:`~qpcoord.Robot.integrate`: on a vector-space configuration
(``nq == nv``) it is the plain sum above, bit for bit; on a floating base the quaternion stays
unit. RK4 then takes its stages at ``integrate(q, k_i, c_i dt)`` and its step with the
weighted mean of the four velocities, all in the tangent space at ``q`` (exact for a vector
space, an approximation of order < 4 on a curved configuration space: use ``"euler"`` for a
control loop).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .ik import IK, inverse_kinematics
from .paths import Path
from .robot import Robot
from .tasks import _check_dt

__all__ = ["simulate", "Trajectory", "INTEGRATORS"]

INTEGRATORS = ("rk4", "euler")


@dataclass
class Trajectory:
    """A simulated run.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times (s).
    q : ndarray, shape (N, nq)
        Configurations (rad).
    qdot : ndarray, shape (N, nv)
        Scheme output ``v`` at each sample (rad/s).
    y : ndarray, shape (N, rows)
        End-effector positions (m).
    y_ref : ndarray, shape (N, rows)
        Reference positions (m).
    info : dict
        ``q_start`` (configuration after the start IK), ``q0`` (as given), ``integrator``,
        ``dt``.
    """

    t: np.ndarray
    q: np.ndarray
    qdot: np.ndarray
    y: np.ndarray
    y_ref: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def error(self) -> np.ndarray:
        """End-effector tracking error ``‖y − y_ref‖`` per sample (m)."""
        return np.linalg.norm(self.y - self.y_ref, axis=1)

    @property
    def max_error(self) -> float:
        """Largest tracking error (m)."""
        return float(self.error.max())


def simulate(
    robot: Robot,
    scheme: Any,
    target: Path,
    q0: ArrayLike,
    duration: float,
    dt: float,
    integrator: str = "rk4",
    start: str = "ik",
    solver: str | None = None,
    method: str = "hierarchical",
) -> Trajectory:
    """Simulate ``scheme`` driving ``robot`` along ``target`` for ``duration`` seconds.

    Parameters
    ----------
    robot : Robot
    scheme : object with ``velocity(q, t, reference)``, or a list of levels
        A list is turned into ``IK(robot, levels, dt, solver=solver, method=method)``.
    target : Path
        End-effector reference (m); given to the scheme as ``reference``.
    q0 : array_like, shape (nq,)
        Initial configuration (rad).
    duration : float
        Length of the run (s).
    dt : float
        Integration / control step (s).
    integrator : {"rk4", "euler"}
    start : {"ik", "q0"}
        ``"ik"`` (default): first move ``q0`` to the path's start point with
        :func:`~qpcoord.inverse_kinematics` (minimum-norm change); ``"q0"``: start as given.
    solver, method : str
        For a list of levels.

    Returns
    -------
    Trajectory
        ``N = round(duration/dt) + 1`` samples.

    Raises
    ------
    ValueError
        Bad arguments, or an unreachable start point.
    """
    if not isinstance(robot, Robot):
        raise ValueError(f"robot must be a qpcoord.Robot, got {type(robot).__name__}")
    if not isinstance(target, Path):
        raise ValueError(f"target must be a qpcoord.paths.Path, got {type(target).__name__}")
    if target.dim != robot.m:
        raise ValueError(f"target is {target.dim}-D but the robot has {robot.m} task rows")
    if integrator not in INTEGRATORS:
        raise ValueError(f"integrator must be one of {INTEGRATORS}, got {integrator!r}")
    if start not in ("ik", "q0"):
        raise ValueError(f"start must be 'ik' or 'q0', got {start!r}")
    dt = _check_dt(dt)
    if isinstance(duration, bool) or not np.isfinite(duration) or duration <= 0:
        raise ValueError(f"duration must be > 0 and finite (s), got {duration!r}")
    q_given = robot.check_configuration(q0, "q0").copy()
    if isinstance(scheme, (list, tuple)):
        scheme = IK(robot, scheme, dt, solver=solver, method=method)
    if not callable(getattr(scheme, "velocity", None)):
        raise ValueError(f"scheme must have a velocity(q, t, reference) method, got {scheme!r}")
    q = inverse_kinematics(robot, target.position(0.0), q_given) if start == "ik" else q_given
    steps = int(round(duration / dt))
    N = steps + 1
    t = np.arange(N) * dt
    Q = np.empty((N, robot.nq))
    QD = np.empty((N, robot.nv))
    Y = np.empty((N, robot.m))

    euclidean = robot.euclidean

    def f(qq: np.ndarray, tt: float) -> np.ndarray:
        v = np.asarray(scheme.velocity(qq, tt, target), dtype=float)
        if v.shape != (robot.nv,) or not np.all(np.isfinite(v)):
            raise ValueError(f"scheme returned an invalid velocity at t = {tt:.6g} s: {v!r}")
        return v

    for k in range(N):
        tk = t[k]
        Q[k] = q
        Y[k] = robot.position(q)
        k1 = f(q, tk)
        QD[k] = k1
        if k == steps:
            break
        if euclidean:  # q + v dt: robot.integrate's arithmetic, without its checks
            if integrator == "euler":
                q = q + dt * k1
            else:
                k2 = f(q + 0.5 * dt * k1, tk + 0.5 * dt)
                k3 = f(q + 0.5 * dt * k2, tk + 0.5 * dt)
                k4 = f(q + dt * k3, tk + dt)
                q = q + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        elif integrator == "euler":
            q = robot.integrate(q, k1, dt)
        else:
            k2 = f(robot.integrate(q, k1, 0.5 * dt), tk + 0.5 * dt)
            k3 = f(robot.integrate(q, k2, 0.5 * dt), tk + 0.5 * dt)
            k4 = f(robot.integrate(q, k3, dt), tk + dt)
            q = robot.integrate(q, (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0, dt)
    return Trajectory(
        t=t,
        q=Q,
        qdot=QD,
        y=Y,
        y_ref=np.atleast_2d(target.position(t)),
        info={"q0": q_given, "q_start": Q[0].copy(), "integrator": integrator, "dt": dt},
    )
