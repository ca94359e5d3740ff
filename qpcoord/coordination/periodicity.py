"""Periodicity of joint motions under a periodic task (thesis §3.2–3.3, chapter 4).

A redundant arm tracking a closed end-effector path of period ``T`` is *repeatable* when
its joints come back too. With the trajectory sampled stroboscopically at ``t₀ + kT`` (the
Poincaré section of a periodically forced system, thesis Def. 3.5 and Remark 3.2):

- :func:`poincare_section` -- the section points ``p_k = q(t₀ + kT)`` (rad);
- :func:`closure_errors` -- ``‖p_k − p_{k−1}‖`` per period (rad): the joint drift;
- :func:`periods_to_closure` -- the period from which that drift stays below a threshold
  (the convergence figure of the chapter 5 limit cycles);
- :func:`joint_path_lengths` -- ``∫‖q̇‖ dt`` per period (rad), the §5.4 comparison;
- :func:`detect_period` -- "periodic with period m·T from period k on", or "not periodic
  within K periods", with the evidence.

Section points fall on samples when ``T`` is a whole number of steps (choose
``dt = T/N``); otherwise they are interpolated with cubic Hermite polynomials on ``q`` and
``q̇`` (error O(dt⁴)), never linearly.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "poincare_section",
    "closure_errors",
    "periods_to_closure",
    "joint_path_lengths",
    "detect_period",
    "Periodicity",
]


def _check_period(traj, period, t0: float | None) -> tuple[float, float]:
    if isinstance(period, bool) or not isinstance(period, (int, float, np.integer, np.floating)):
        raise ValueError(f"period must be a number of seconds, got {period!r}")
    if not np.isfinite(period) or period <= 0:
        raise ValueError(f"period must be > 0 and finite (s), got {period!r}")
    for name in ("t", "q", "qdot"):
        if not hasattr(traj, name):
            raise ValueError(f"traj must be a qpcoord.Trajectory (no attribute {name!r})")
    if t0 is None:
        t0 = float(traj.t[0])
    if not np.isfinite(t0) or t0 < traj.t[0] or t0 > traj.t[-1]:
        raise ValueError(
            f"t0 = {t0!r} s is outside the trajectory's time span "
            f"[{traj.t[0]:.6g}, {traj.t[-1]:.6g}] s"
        )
    return float(period), float(t0)


def _sample(traj, times: np.ndarray) -> np.ndarray:
    """``q`` at ``times`` (s): exact at samples, cubic Hermite between them."""
    t = traj.t
    dt = t[1] - t[0]
    u = (times - t[0]) / dt
    k = np.clip(np.floor(u + 1e-9).astype(int), 0, len(t) - 1)
    s = u - k
    on_sample = np.abs(s) <= 1e-9
    out = traj.q[k].copy()
    mid = ~on_sample & (k < len(t) - 1)
    if mid.any():
        km = k[mid]
        sm = s[mid][:, None]
        h00 = 2 * sm**3 - 3 * sm**2 + 1
        h10 = sm**3 - 2 * sm**2 + sm
        h01 = -2 * sm**3 + 3 * sm**2
        h11 = sm**3 - sm**2
        out[mid] = (
            h00 * traj.q[km]
            + h10 * dt * traj.qdot[km]
            + h01 * traj.q[km + 1]
            + h11 * dt * traj.qdot[km + 1]
        )
    return out


def poincare_section(traj, period: float, t0: float | None = None) -> np.ndarray:
    """Section points ``q(t₀ + kT)``, ``k = 0, 1, …`` while inside the run (rad).

    Parameters
    ----------
    traj : Trajectory
    period : float
        Task period ``T`` (s).
    t0 : float, optional
        Phase of the section (s); default the trajectory's first time.

    Returns
    -------
    ndarray, shape (K + 1, nq)

    Raises
    ------
    ValueError
        Non-positive period, ``t0`` outside the run, or a run shorter than one period.
    """
    period, t0 = _check_period(traj, period, t0)
    count = int(np.floor((traj.t[-1] - t0) / period + 1e-9)) + 1
    if count < 2:
        raise ValueError(
            f"the trajectory ({traj.t[-1] - traj.t[0]:.6g} s) does not contain one period "
            f"({period:.6g} s) after t0"
        )
    return _sample(traj, t0 + period * np.arange(count))


def closure_errors(traj, period: float, t0: float | None = None) -> np.ndarray:
    """Joint drift per period ``‖q(t₀ + kT) − q(t₀ + (k−1)T)‖`` (rad), ``k = 1 … K``."""
    p = poincare_section(traj, period, t0)
    return np.linalg.norm(np.diff(p, axis=0), axis=1)


def periods_to_closure(errors, threshold: float = 1e-6) -> int | None:
    """The first period ``k`` (1-based) whose closure error, and every later one, is below
    ``threshold`` (rad); ``None`` if the run never settles below it.

    ``errors`` are :func:`closure_errors` (entry ``k−1`` compares periods ``k−1`` and ``k``).
    A run periodic from the start gives 1.
    """
    e = np.asarray(errors, dtype=float).reshape(-1)
    if e.size == 0:
        raise ValueError("errors is empty: the run holds no whole period")
    if not np.isfinite(threshold) or threshold <= 0:
        raise ValueError(f"threshold must be > 0 (rad), got {threshold!r}")
    above = np.flatnonzero(~(e < threshold))
    if above.size == 0:
        return 1
    k = int(above[-1]) + 1  # index of the first entry after the last one above
    return None if k >= e.size else k + 1


def joint_path_lengths(traj, period: float, t0: float | None = None) -> np.ndarray:
    """Joint-space path length ``∫ ‖q̇‖ dt`` over each whole period (rad).

    Trapezoidal rule on the samples' ``‖q̇‖``; requires ``T`` to be a whole number of
    steps (choose ``dt = T/N``).
    """
    period, t0 = _check_period(traj, period, t0)
    dt = float(traj.t[1] - traj.t[0])
    n = period / dt
    if abs(n - round(n)) > 1e-6:
        raise ValueError(f"period {period:.6g} s is not a whole number of steps dt = {dt:.6g} s")
    n = int(round(n))
    k0 = int(round((t0 - traj.t[0]) / dt))
    speed = np.linalg.norm(traj.qdot, axis=1)
    out = []
    while k0 + n < len(speed):
        s = speed[k0 : k0 + n + 1]
        out.append(dt * (s.sum() - 0.5 * (s[0] + s[-1])))
        k0 += n
    return np.array(out)


@dataclass
class Periodicity:
    """Result of :func:`detect_period`.

    Attributes
    ----------
    periodic : bool
        A period ``m·T`` (``m ≤ max_multiple``) was found.
    multiple : int or None
        The smallest such ``m``.
    settled_after : int or None
        First section index ``k`` from which ``‖p_{j+m} − p_j‖ ≤ tol`` for every later ``j``.
    periods : int
        Number of whole periods in the run.
    gaps : dict
        For each tested ``m``: ``‖p_{j+m} − p_j‖`` over ``j`` (rad) -- the evidence.
    tol : float
        Tolerance used (rad).
    """

    periodic: bool
    multiple: int | None
    settled_after: int | None
    periods: int
    tol: float
    gaps: dict = field(default_factory=dict)

    def __str__(self) -> str:
        if self.periodic:
            return (
                f"periodic with period {self.multiple}·T from period {self.settled_after} on "
                f"(gap ≤ {self.tol:.1e} rad over {self.periods} periods)"
            )
        best = min((float(g[-1]) for g in self.gaps.values() if len(g)), default=float("nan"))
        return (
            f"not periodic within {self.periods} periods (smallest final gap "
            f"{best:.3e} rad > {self.tol:.1e} rad)"
        )


def detect_period(
    traj,
    period: float,
    max_multiple: int = 8,
    tol: float = 1e-6,
    t0: float | None = None,
    min_repeats: int = 3,
) -> Periodicity:
    """Is the joint motion periodic with a multiple of the task period?

    The section points ``p_k`` are compared with ``p_{k+m}`` for ``m = 1 … max_multiple``;
    the motion is periodic with period ``m·T`` when, from some ``k`` on, every gap is
    below ``tol`` and at least ``min_repeats`` such gaps were seen (so a chance near-return
    is not taken for a cycle). The smallest such ``m`` is reported.

    Parameters
    ----------
    traj : Trajectory
    period : float
        Task period ``T`` (s).
    max_multiple : int
        Largest period multiple tried.
    tol : float
        Gap tolerance (rad), e.g. a few times the integration error.
    t0 : float, optional
        Phase of the section (s).
    min_repeats : int
        Gaps under ``tol`` needed at the end of the run.
    """
    if isinstance(max_multiple, bool) or not isinstance(max_multiple, int) or max_multiple < 1:
        raise ValueError(f"max_multiple must be an integer >= 1, got {max_multiple!r}")
    if not np.isfinite(tol) or tol <= 0:
        raise ValueError(f"tol must be > 0 (rad), got {tol!r}")
    p = poincare_section(traj, period, t0)
    periods = len(p) - 1
    gaps: dict = {}
    for m in range(1, max_multiple + 1):
        if len(p) <= m:
            break
        g = np.linalg.norm(p[m:] - p[:-m], axis=1)
        gaps[m] = g
        above = np.flatnonzero(g > tol)
        first_ok = 0 if above.size == 0 else int(above[-1]) + 1
        if len(g) - first_ok >= min_repeats:
            return Periodicity(True, m, first_ok, periods, float(tol), gaps)
    return Periodicity(False, None, None, periods, float(tol), gaps)
