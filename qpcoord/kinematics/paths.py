"""End-effector reference paths of the thesis, as functions of time.

Every path gives ``position(t)`` (m), ``velocity(t)`` (m/s) and ``acceleration(t)``
(m/s²) for a scalar time ``t`` (s) or an array of times (then one row per time), its
``period`` (s) and ``length()`` (m, arc length over one period).

- :class:`LissajousSphere` -- thesis Eq. 3.3: a Lissajous curve mapped onto a sphere
  (Example 4.1 parameters by default), tracked by the 5R arm in chapter 4;
- :class:`Circle` -- the circle of Eq. 5.1 (Fig. 5.9 parameters by default), tracked by the
  3R arm in chapter 5.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "Path",
    "LissajousSphere",
    "Circle",
    "HorizontalCircle",
    "rotation_x",
    "rotation_y",
    "rotation_z",
]


def rotation_x(a: float) -> np.ndarray:
    """Rotation matrix about x by ``a`` rad."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation_y(b: float) -> np.ndarray:
    """Rotation matrix about y by ``b`` rad."""
    c, s = np.cos(b), np.sin(b)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_z(c_: float) -> np.ndarray:
    """Rotation matrix about z by ``c_`` rad."""
    c, s = np.cos(c_), np.sin(c_)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _finite(value: Any, what: str, positive: bool = False) -> float:
    if isinstance(value, bool):
        raise ValueError(f"{what} must be a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be a number, got {value!r}") from None
    if not np.isfinite(v) or (positive and v <= 0):
        raise ValueError(f"{what} must be {'> 0 and ' if positive else ''}finite, got {value!r}")
    return v


def _times(t: ArrayLike) -> tuple[np.ndarray, bool]:
    arr = np.asarray(t, dtype=float)
    if arr.ndim > 1:
        raise ValueError(f"t must be a scalar or a 1-D array of seconds, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("t contains a non-finite time")
    return np.atleast_1d(arr), arr.ndim == 0


class Path(ABC):
    """Base class: subclasses implement ``_eval(t) -> (p, v, a)`` for a 1-D array ``t``."""

    period: float = np.inf
    dim: int = 3

    @abstractmethod
    def _eval(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration (each ``(len(t), dim)``) at the times ``t`` (s)."""

    def _pick(self, t: ArrayLike, k: int) -> np.ndarray:
        ts, scalar = _times(t)
        out = self._eval(ts)[k]
        return out[0] if scalar else out

    def position(self, t: ArrayLike) -> np.ndarray:
        """Position (m) at time ``t`` (s): shape (dim,) or (len(t), dim)."""
        return self._pick(t, 0)

    def velocity(self, t: ArrayLike) -> np.ndarray:
        """Velocity (m/s) at time ``t`` (s)."""
        return self._pick(t, 1)

    def position_velocity(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """``(position(t), velocity(t))`` for a scalar time ``t`` (s) from one evaluation."""
        p, v, _ = self._eval(np.array([float(t)]))
        return p[0], v[0]

    def acceleration(self, t: ArrayLike) -> np.ndarray:
        """Acceleration (m/s²) at time ``t`` (s)."""
        return self._pick(t, 2)

    def length(self, samples: int = 20001) -> float:
        """Arc length (m) over one period (trapezoidal rule on ``samples`` points)."""
        t = np.linspace(0.0, self.period, samples)
        speed = np.linalg.norm(self._eval(t)[1], axis=1)
        return float(np.sum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t)))


class LissajousSphere(Path):
    """Thesis Eq. 3.3: a Lissajous curve on a sphere (defaults: Example 4.1).

    ``x_p = A cos(ωt + φ)``, ``y_p = A cos(2ωt + φ)`` (rad) are mapped to
    ``Y = Rx(a) Ry(b) Rz(c) r (cos x_p cos y_p, cos x_p sin y_p, sin x_p) + centre``.

    Parameters
    ----------
    radius : float
        Sphere radius ``r`` (m), default 1.5.
    center : array_like, shape (3,)
        Sphere centre (m), default ``(0, -0.5, 0.2)``.
    omega : float
        ``ω`` (rad/s), default 0.4; period ``2π/ω``.
    amplitude : float
        ``A`` (rad), default 0.6.
    phase : float
        ``φ`` (rad), default π/2.
    angles : array_like, shape (3,)
        ``(a, b, c)`` (rad), default ``(π/4, π/4, 0)``.
    """

    dim = 3

    def __init__(
        self,
        radius: float = 1.5,
        center: ArrayLike = (0.0, -0.5, 0.2),
        omega: float = 0.4,
        amplitude: float = 0.6,
        phase: float = np.pi / 2,
        angles: ArrayLike = (np.pi / 4, np.pi / 4, 0.0),
    ) -> None:
        self.radius = _finite(radius, "radius", positive=True)
        self.omega = _finite(omega, "omega", positive=True)
        self.amplitude = _finite(amplitude, "amplitude")
        self.phase = _finite(phase, "phase")
        self.center = np.array(center, dtype=float).reshape(-1)
        if self.center.shape != (3,) or not np.all(np.isfinite(self.center)):
            raise ValueError(f"center must be 3 finite numbers (m), got {center!r}")
        ang = np.asarray(angles, dtype=float).reshape(-1)
        if ang.shape != (3,):
            raise ValueError(f"angles must be 3 numbers (a, b, c) in rad, got {angles!r}")
        a, b, c = (_finite(v, "angles") for v in ang)
        self.angles = (a, b, c)
        self.rotation = rotation_x(a) @ rotation_y(b) @ rotation_z(c)
        self.period = 2 * np.pi / self.omega

    def _eval(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        A, w, ph, r = self.amplitude, self.omega, self.phase, self.radius
        xp = A * np.cos(w * t + ph)
        yp = A * np.cos(2 * w * t + ph)
        dxp = -A * w * np.sin(w * t + ph)
        dyp = -2 * A * w * np.sin(2 * w * t + ph)
        ddxp = -A * w**2 * np.cos(w * t + ph)
        ddyp = -4 * A * w**2 * np.cos(2 * w * t + ph)
        cx, sx, cy, sy = np.cos(xp), np.sin(xp), np.cos(yp), np.sin(yp)
        s = r * np.stack([cx * cy, cx * sy, sx], axis=1)
        # first derivatives of s with respect to (xp, yp)
        s_x = r * np.stack([-sx * cy, -sx * sy, cx], axis=1)
        s_y = r * np.stack([-cx * sy, cx * cy, np.zeros_like(cx)], axis=1)
        # second derivatives
        s_xx = -s
        s_yy = r * np.stack([-cx * cy, -cx * sy, np.zeros_like(cx)], axis=1)
        s_xy = r * np.stack([sx * sy, -sx * cy, np.zeros_like(cx)], axis=1)
        ds = s_x * dxp[:, None] + s_y * dyp[:, None]
        dds = (
            s_xx * (dxp**2)[:, None]
            + 2 * s_xy * (dxp * dyp)[:, None]
            + s_yy * (dyp**2)[:, None]
            + s_x * ddxp[:, None]
            + s_y * ddyp[:, None]
        )
        R = self.rotation
        return s @ R.T + self.center, ds @ R.T, dds @ R.T


class Circle(Path):
    """Circle ``h(y) = ‖y − c‖² − R² = 0`` run at constant speed (defaults: thesis Fig. 5.9).

    ``y(t) = c + R (cos(2πt/T + φ), sin(2πt/T + φ))``.

    Parameters
    ----------
    center : array_like, shape (2,)
        ``(c_x, c_y)`` (m), default ``(1.5, 0)``.
    radius : float
        ``R`` (m), default 0.5.
    period : float
        ``T`` (s), default π.
    phase : float
        ``φ`` (rad), default 0 (start at ``c + (R, 0)``, where the thesis q0
        ``(0, π/3, −π/3)`` puts the 3R end effector).
    """

    dim = 2

    def __init__(
        self,
        center: ArrayLike = (1.5, 0.0),
        radius: float = 0.5,
        period: float = np.pi,
        phase: float = 0.0,
    ) -> None:
        self.center = np.array(center, dtype=float).reshape(-1)
        if self.center.shape != (2,) or not np.all(np.isfinite(self.center)):
            raise ValueError(
                f"center must be 2 finite numbers (m), got {center!r}: Circle is the planar "
                "circle of Eq. 5.1; for a 3-D end effector use "
                "qc.paths.HorizontalCircle(start, radius, period)"
            )
        self.radius = _finite(radius, "radius", positive=True)
        self.period = _finite(period, "period", positive=True)
        self.phase = _finite(phase, "phase")

    def _eval(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        w = 2 * np.pi / self.period
        ang = w * t + self.phase
        u = np.stack([np.cos(ang), np.sin(ang)], axis=1)
        du = np.stack([-np.sin(ang), np.cos(ang)], axis=1)
        R = self.radius
        return self.center + R * u, R * w * du, -R * w**2 * u


class HorizontalCircle(Path):
    """A 3-D circle in the horizontal plane that starts at a given point (IK demos).

    ``y(t) = start + R (cos ωt − 1, sin ωt, 0)``, ``ω = 2π/T``: it passes through ``start``
    at ``t = 0`` (so a robot standing there needs no initial jump), centre ``start − (R, 0, 0)``.

    Parameters
    ----------
    start : array_like, shape (3,)
        Point at ``t = 0`` (m).
    radius : float
        ``R`` (m), > 0.
    period : float
        ``T`` (s), > 0.
    """

    dim = 3

    def __init__(self, start: ArrayLike, radius: float, period: float) -> None:
        self.start = np.array(start, dtype=float).reshape(-1)
        if self.start.shape != (3,) or not np.all(np.isfinite(self.start)):
            raise ValueError(f"start must be 3 finite numbers (m), got {start!r}")
        self.radius = _finite(radius, "radius", positive=True)
        self.period = _finite(period, "period", positive=True)
        self.center = self.start - np.array([self.radius, 0.0, 0.0])

    def _eval(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        w = 2 * np.pi / self.period
        c, s, z = np.cos(w * t), np.sin(w * t), np.zeros_like(t)
        r = self.radius
        p = self.start + r * np.stack([c - 1.0, s, z], axis=1)
        v = r * w * np.stack([-s, c, z], axis=1)
        return p, v, -r * w * w * np.stack([c, s, z], axis=1)
