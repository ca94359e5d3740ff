"""Figures written to files (PNG) for the examples; never shown (matplotlib's Agg backend).

Needs matplotlib (the ``plots`` extra). Each function writes one file atomically
(temporary file + rename) and returns its path.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

__all__ = ["joint_plot", "closure_plot", "save", "animation"]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def save(fig, path) -> Path:
    """Write a matplotlib figure to ``path`` atomically and close it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".tmp" + path.suffix)
    try:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
        _pyplot().close(fig)
    return path


def joint_plot(traj, path, title: str, period: float | None = None) -> Path:
    """Joint angles (rad) over time (s), one line per joint; task periods marked."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 3.6))
    for i in range(traj.q.shape[1]):
        ax.plot(traj.t, traj.q[:, i], lw=1.0, label=f"q{i + 1}")
    if period:
        for k in range(1, int(traj.t[-1] / period) + 1):
            ax.axvline(k * period, color="0.8", lw=0.6, zorder=0)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("joint angle (rad)")
    ax.set_title(title)
    ax.legend(loc="upper right", fontsize=7, ncol=min(5, traj.q.shape[1]))
    return save(fig, path)


def closure_plot(errors: dict, path, title: str, floor: float = 1e-16) -> Path:
    """Closure error per period (rad, log scale), one line per scheme."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 3.6))
    for name, e in errors.items():
        e = np.maximum(np.asarray(e, dtype=float), floor)
        ax.semilogy(np.arange(1, len(e) + 1), e, marker="o", ms=3, lw=1.0, label=name)
    ax.set_xlabel("period k")
    ax.set_ylabel("‖q(kT) − q((k−1)T)‖ (rad)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    return save(fig, path)


def animation(robot, trajectory, path, **options) -> dict:
    """Write ``trajectory`` of ``robot`` as one HTML animation (:func:`qpcoord.viz.animate`,
    ``options`` passed on) for an example's ``summary.json``.

    Returns
    -------
    dict
        ``{"html": file name, "html_mb": size (MB)}``, or ``{"html": None, "html_reason":
        why}`` when meshcat (the ``viz`` extra) is missing or the robot has no visual geometry
        (:class:`~qpcoord.kinematics.viz.NoVisualGeometry`); any other error propagates (a
        bad trajectory or target is the script's bug).
    """
    from ..kinematics import viz  # meshcat itself is imported by animate

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        html = viz.animate(robot, trajectory, path, **options)
    except ImportError as exc:  # meshcat missing
        return {"html": None, "html_reason": f"meshcat not installed: {exc}"}
    except viz.NoVisualGeometry as exc:
        return {"html": None, "html_reason": str(exc)}
    return {"html": html.name, "html_mb": round(html.stat().st_size / 1e6, 2)}
