"""Identification of a Preisach model from first-order reversal curves (Eq. C.3, Fig. C.3).

For each mesh voltage ``α = levels[i]`` the actuator is driven from negative saturation
(``u_min``) up to ``α``, giving the major ascending branch ``x_α``, then down to ``u_min``,
passing every ``β = levels[j] ≤ α`` and giving the reversal curve ``x_αβ``. Then
``X(α, β) = x_α − x_αβ`` (Eq. C.3). Going back down to ``u_min`` also returns the actuator
to negative saturation before the next curve.
"""

from __future__ import annotations

import math

import numpy as np

from .preisach import PreisachModel, _as_levels

__all__ = ["forc_program", "identify"]


def _ramp(a: float, b: float, du: float) -> np.ndarray:
    """Samples from a (excluded) to b (included), steps of at most du (V)."""
    k = max(1, math.ceil(abs(b - a) / du - 1e-9))
    return np.linspace(a, b, k + 1)[1:]


def forc_program(levels, du: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Voltage program of the first-order reversal curves on a mesh.

    Parameters
    ----------
    levels : array_like, shape (n + 1,)
        Mesh voltages (V), strictly increasing; ``levels[0]`` is negative saturation.
    du : float
        Largest voltage step between samples (V). A rate-independent plant does not care;
        a real stage is driven slowly so that its dynamics do not show.

    Returns
    -------
    u : ndarray
        The voltage program (V), starting at ``levels[0]``.
    index : ndarray of int, shape (n + 1, n + 1)
        ``u[index[i, j]]`` is the sample where ``x_forc[i, j]`` is read (``j ≤ i``);
        ``-1`` above the diagonal.
    """
    lv = _as_levels(levels)
    du = float(du)
    if not (du > 0 and math.isfinite(du)):
        raise ValueError(f"du = {du!r} V must be positive and finite")
    n1 = lv.size
    index = np.full((n1, n1), -1, dtype=int)
    pieces = [lv[:1]]
    count = 1
    index[0, 0] = 0
    for i in range(1, n1):
        for k in range(i):  # up to α = levels[i]
            r = _ramp(lv[k], lv[k + 1], du)
            pieces.append(r)
            count += r.size
        index[i, i] = count - 1
        for j in range(i - 1, -1, -1):  # down through every β = levels[j]
            r = _ramp(lv[j + 1], lv[j], du)
            pieces.append(r)
            count += r.size
            index[i, j] = count - 1
    return np.concatenate(pieces), index


def identify(plant, levels, du: float = 0.01, resolution: float = 0.0) -> PreisachModel:
    """Identify a :class:`PreisachModel` on ``levels`` from a plant's reversal curves.

    Parameters
    ----------
    plant : object
        Anything with ``reset()`` and ``step(volts) -> metres`` (e.g.
        :class:`~qpcoord.hysteresis.piezo.BoucWenPiezo`, or a driver for a real stage).
        After ``reset()`` one major cycle ``u_min → u_max → u_min`` is applied to put it
        in negative saturation, then :func:`forc_program`.
    levels : array_like
        Mesh voltages (V) within the plant's range.
    du : float
        Largest voltage step (V) of the program.
    resolution : float
        Metrology resolution (m): the readings are rounded to multiples of it (the DDL
        interferometer: 1.25e-9 m). 0 keeps them exact.

    Returns
    -------
    PreisachModel

    Raises
    ------
    ValueError
        If the readings give a non-monotone major loop or reversal curve (see
        :class:`PreisachModel`), or ``resolution`` is negative or not finite.
    """
    resolution = float(resolution)
    if not (resolution >= 0 and math.isfinite(resolution)):
        raise ValueError(f"resolution = {resolution!r} m must be ≥ 0 and finite")
    lv = _as_levels(levels)
    u, index = forc_program(lv, du)
    pre = np.concatenate([_ramp(lv[0], lv[-1], du), _ramp(lv[-1], lv[0], du)])
    plant.reset()
    for v in pre.tolist():
        plant.step(v)
    x = np.fromiter((plant.step(v) for v in u.tolist()), dtype=float, count=u.size)
    if not np.all(np.isfinite(x)):
        k = int(np.argmax(~np.isfinite(x)))
        raise ValueError(f"plant output {x[k]!r} m at u = {u[k]!r} V is not finite")
    if resolution > 0:
        x = np.round(x / resolution) * resolution
    low = index >= 0
    x_forc = np.zeros(index.shape)
    x_forc[low] = x[index[low]]
    return PreisachModel.from_forc(lv, x_forc)
