"""Classical Preisach model on a discretised α–β triangle (thesis appendix C, Eqs C.1–C.8).

The model is stored as the Everett (Preisach) function ``X(α, β)`` of Eq. C.3 on the nodes
of a mesh ``levels[0] < … < levels[n]`` (V) of the limiting triangle ``T₀`` (``α ≥ β``),
plus an output offset (m). Between nodes ``X`` is the bilinear spline of Eq. C.8,
``X = a00 + a10 α + a01 β + a11 α β``, on the rectangular cells; on the diagonal
(triangular) cells of Fig. C.5 it is the linear interpolant ``c (α − β)``, still of the
form C.8 with ``a00 = a11 = 0``, which vanishes on ``α = β`` as ``X`` must.

This module holds the parameters and the Everett function; the memory of extrema (Eqs
C.6–C.7, wipe-out) is :mod:`qpcoord.hysteresis.memory` (:meth:`PreisachModel.evaluate` runs
a fresh stage of it) and the inverse (Eqs C.9–C.11) :mod:`qpcoord.hysteresis.inverse`.
"""

from __future__ import annotations

from bisect import bisect_right

import numpy as np

from .memory import PreisachStage

__all__ = ["PreisachModel"]


def _as_levels(levels) -> np.ndarray:
    lv = np.asarray(levels, dtype=float)
    if lv.ndim != 1 or lv.size < 2:
        raise ValueError(f"levels must be a 1-D array of at least 2 voltages, got shape {lv.shape}")
    if not np.all(np.isfinite(lv)):
        raise ValueError(f"levels must be finite, got {lv[~np.isfinite(lv)][0]!r}")
    d = np.diff(lv)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0))
        raise ValueError(
            f"levels must be strictly increasing: levels[{k}] = {lv[k]!r} V, "
            f"levels[{k + 1}] = {lv[k + 1]!r} V"
        )
    return lv


class PreisachModel:
    """Classical Preisach model identified on a mesh of the α–β triangle.

    Parameters
    ----------
    levels : array_like, shape (n + 1,)
        Mesh voltages ``u_min = levels[0] < … < levels[n] = u_max`` (V); the same mesh is
        used for the switching-up values α and the switching-down values β.
    everett : array_like, shape (n + 1, n + 1)
        ``everett[i, j] = X(levels[i], levels[j])`` (m) for ``i ≥ j`` (Eq. C.3); entries
        above the diagonal are ignored; the diagonal must be zero.
    offset : float
        Output (m) in negative saturation, i.e. at ``u_min`` with every hysteron off.

    Raises
    ------
    ValueError
        Non-finite values, a non-zero diagonal, or a non-monotone Everett function: the
        major loop must rise strictly with the voltage (``X[i, 0]`` increasing in ``i``,
        ``X[n, j]`` decreasing in ``j``) and, so that the inverse of Eqs C.9–C.11 is unique,
        every first-order reversal curve too (``X[i, j]`` strictly increasing in ``i`` and
        strictly decreasing in ``j`` on the triangle). The message names the node.

    Notes
    -----
    The output of a state with stored extrema is given by Eqs C.6–C.7; see
    :class:`qpcoord.hysteresis.memory.PreisachStage` (per sample) and :meth:`evaluate`
    (vectorised over a signal).
    """

    def __init__(self, levels, everett, offset: float = 0.0) -> None:
        lv = _as_levels(levels)
        n1 = lv.size
        E = np.array(everett, dtype=float)
        if E.shape != (n1, n1):
            raise ValueError(f"everett must have shape {(n1, n1)}, got {E.shape}")
        E = np.tril(E)
        if not np.all(np.isfinite(E)):
            i, j = np.argwhere(~np.isfinite(E))[0]
            raise ValueError(f"everett[{i}, {j}] = {E[i, j]!r} is not finite")
        offset = float(offset)
        if not np.isfinite(offset):
            raise ValueError(f"offset = {offset!r} m is not finite")
        scale = max(float(np.abs(E).max()), 1e-300)
        diag = np.abs(np.diag(E))
        if np.any(diag > 1e-12 * scale):
            k = int(np.argmax(diag))
            raise ValueError(f"everett[{k}, {k}] = {E[k, k]!r} m: X(α, α) must be 0 (Eq. C.3)")
        np.fill_diagonal(E, 0.0)
        self._check_monotone(lv, E, offset)
        self.levels = lv
        self.everett = E
        self.offset = offset
        self._build_tables()

    # ------------------------------------------------------------------ construction
    @staticmethod
    def _check_monotone(lv, E, offset) -> None:
        n = lv.size - 1
        asc = offset + E[:, 0]
        d = np.diff(asc)
        if np.any(d <= 0):
            k = int(np.argmax(d <= 0))
            raise ValueError(
                "non-monotone major loop: ascending branch x(u) goes from "
                f"{asc[k]!r} m at u = {lv[k]!r} V to {asc[k + 1]!r} m at u = {lv[k + 1]!r} V"
            )
        desc = offset + E[n, 0] - E[n, :]
        d = np.diff(desc)
        if np.any(d <= 0):
            k = int(np.argmax(d <= 0))
            raise ValueError(
                "non-monotone major loop: descending branch x(u) goes from "
                f"{desc[k]!r} m at u = {lv[k]!r} V to {desc[k + 1]!r} m at u = {lv[k + 1]!r} V"
            )
        for i in range(1, n + 1):
            row = E[i, : i + 1]  # X(l_i, l_j), j = 0..i, must decrease strictly to 0
            bad = np.flatnonzero(np.diff(row) >= 0)
            if bad.size:
                j = int(bad[0])
                raise ValueError(
                    f"non-monotone reversal curve from α = {lv[i]!r} V: X(α, β) = "
                    f"{row[j]!r} m at β = {lv[j]!r} V but {row[j + 1]!r} m at "
                    f"β = {lv[j + 1]!r} V (must decrease)"
                )
        for j in range(n):
            col = E[j:, j]  # X(l_i, l_j), i = j..n, must increase strictly from 0
            bad = np.flatnonzero(np.diff(col) <= 0)
            if bad.size:
                i = j + int(bad[0])
                raise ValueError(
                    f"non-monotone Everett function at β = {lv[j]!r} V: X(α, β) = "
                    f"{E[i, j]!r} m at α = {lv[i]!r} V but {E[i + 1, j]!r} m at "
                    f"α = {lv[i + 1]!r} V (must increase)"
                )

    @classmethod
    def from_forc(cls, levels, x_forc) -> PreisachModel:
        """Identify the model from first-order reversal curves (Eq. C.3, Fig. C.3).

        Parameters
        ----------
        levels : array_like, shape (n + 1,)
            Mesh voltages (V), strictly increasing.
        x_forc : array_like, shape (n + 1, n + 1)
            ``x_forc[i, j]`` (m): output after rising from negative saturation (``u_min``)
            to ``α = levels[i]`` and then falling to ``β = levels[j]`` (``j ≤ i``);
            ``x_forc[i, i]`` is the major ascending branch ``x_α``. Entries above the
            diagonal are ignored.

        Returns
        -------
        PreisachModel
            With ``X(α_i, β_j) = x_forc[i, i] − x_forc[i, j]`` and offset ``x_forc[0, 0]``.
        """
        lv = _as_levels(levels)
        xf = np.asarray(x_forc, dtype=float)
        if xf.shape != (lv.size, lv.size):
            raise ValueError(f"x_forc must have shape {(lv.size, lv.size)}, got {xf.shape}")
        low = np.tril(np.ones_like(xf, dtype=bool))
        if not np.all(np.isfinite(xf[low])):
            i, j = np.argwhere(low & ~np.isfinite(xf))[0]
            raise ValueError(f"x_forc[{i}, {j}] = {xf[i, j]!r} is not finite")
        E = np.tril(np.diag(xf)[:, None] - xf)
        return cls(lv, E, offset=xf[0, 0])

    def _build_tables(self) -> None:
        lv, E = self.levels, self.everett
        n = lv.size - 1
        a00 = np.zeros((n, n))
        a10 = np.zeros((n, n))
        a01 = np.zeros((n, n))
        a11 = np.zeros((n, n))
        for i in range(n):
            al0, al1 = lv[i], lv[i + 1]
            c = E[i + 1, i] / (al1 - al0)  # diagonal (triangular) cell: X = c (α − β)
            a10[i, i], a01[i, i] = c, -c
            for j in range(i):
                b0, b1 = lv[j], lv[j + 1]
                f00, f10, f01, f11 = E[i, j], E[i + 1, j], E[i, j + 1], E[i + 1, j + 1]
                D = (al1 - al0) * (b1 - b0)
                a11[i, j] = (f00 - f10 - f01 + f11) / D
                a10[i, j] = (-f00 * b1 + f10 * b1 + f01 * b0 - f11 * b0) / D
                a01[i, j] = (-f00 * al1 + f10 * al0 + f01 * al1 - f11 * al0) / D
                a00[i, j] = (f00 * al1 * b1 - f10 * al0 * b1 - f01 * al1 * b0 + f11 * al0 * b0) / D
        self._a = np.stack([a00, a10, a01, a11])  # (4, n, n), cell (i: α, j: β)
        # Python copies for the per-sample path (float lists index faster than numpy)
        self._t00, self._t10, self._t01, self._t11 = (t.ravel().tolist() for t in self._a)
        self._lv = lv.tolist()
        self._E = E.tolist()
        self._n = n

    # ------------------------------------------------------------------ properties
    @property
    def u_min(self) -> float:
        """Lowest identified voltage (V)."""
        return float(self.levels[0])

    @property
    def u_max(self) -> float:
        """Highest identified voltage (V)."""
        return float(self.levels[-1])

    @property
    def x_min(self) -> float:
        """Output at ``u_min`` (m), the bottom of the major loop."""
        return self.offset

    @property
    def x_max(self) -> float:
        """Output at ``u_max`` (m), the top of the major loop."""
        return self.offset + float(self.everett[-1, 0])

    # ------------------------------------------------------------------ Everett function
    def _cell(self, v: float) -> int:
        i = bisect_right(self._lv, v) - 1
        n = self._n
        return n - 1 if i >= n else (0 if i < 0 else i)

    def everett_scalar(self, a: float, b: float) -> float:
        """Everett function ``X(a, b)`` (m) of one pair of voltages (V), ``a ≥ b`` in the
        identified range, without checks: the per-sample path of the memory."""
        k = self._cell(a) * self._n + self._cell(b)
        return self._t00[k] + self._t10[k] * a + (self._t01[k] + self._t11[k] * a) * b

    def everett_at(self, alpha, beta) -> np.ndarray:
        """Everett function ``X(α, β)`` (m) by the interpolation of Eq. C.8, vectorised.

        Parameters
        ----------
        alpha, beta : array_like
            Switching-up and switching-down voltages (V), broadcastable, with
            ``u_min ≤ β ≤ α ≤ u_max``.
        """
        a, b = np.broadcast_arrays(np.asarray(alpha, float), np.asarray(beta, float))
        for name, v in (("alpha", a), ("beta", b)):
            self.check_range(v, name)
        if np.any(a < b):
            k = np.argwhere(a < b)[0]
            raise ValueError(
                f"alpha = {a[tuple(k)]!r} V < beta = {b[tuple(k)]!r} V: outside the triangle"
            )
        return self.everett_unchecked(a, b)

    def everett_unchecked(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """:meth:`everett_at` without its checks (``a``, ``b``: float arrays (V) of one shape,
        ``a ≥ b`` in the identified range): the memory's vectorised path."""
        n = self._n
        i = np.clip(np.searchsorted(self.levels, a, side="right") - 1, 0, n - 1)
        j = np.clip(np.searchsorted(self.levels, b, side="right") - 1, 0, n - 1)
        k = i * n + j
        t = self._a.reshape(4, -1)
        return t[0, k] + t[1, k] * a + (t[2, k] + t[3, k] * a) * b

    def check_range(self, v: np.ndarray, name: str) -> None:
        """Raise ``ValueError`` naming ``name``, the index and the value if an entry of ``v``
        (V) is NaN or outside ``[u_min, u_max]``."""
        bad = ~((v >= self.levels[0]) & (v <= self.levels[-1]))  # NaN is bad too
        if np.any(bad):
            k = np.argwhere(bad)[0]
            val = v[tuple(k)]
            what = "NaN" if np.isnan(val) else "outside the identified range"
            raise ValueError(
                f"{name} = {val!r} V at index {tuple(int(e) for e in k)} is {what} "
                f"[{self.u_min!r}, {self.u_max!r}] V"
            )

    # ------------------------------------------------------------------ convenience
    def major_loop(self, num: int = 201) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Major loop of the model.

        Returns
        -------
        u : ndarray, shape (num,)
            Voltages from ``u_min`` to ``u_max`` (V).
        x_up, x_down : ndarray, shape (num,)
            Output (m) on the ascending branch from negative saturation and on the
            descending branch from positive saturation.
        """
        u = np.linspace(self.u_min, self.u_max, int(num))
        up = self.offset + self.everett_unchecked(u, np.full_like(u, self.u_min))
        down = self.x_max - self.everett_unchecked(np.full_like(u, self.u_max), u)
        return u, up, down

    def linear_command(self, x) -> np.ndarray:
        """Uncompensated open-loop command (V): the straight line through the major loop's
        end points, ``u = u_min + (x − x_min)(u_max − u_min)/(x_max − x_min)``.

        Parameters
        ----------
        x : array_like
            Desired output (m).
        """
        x = np.asarray(x, dtype=float)
        if not np.all(np.isfinite(x)):
            raise ValueError(f"x = {x[~np.isfinite(x)].ravel()[0]!r} m is not finite")
        k = (self.u_max - self.u_min) / (self.x_max - self.x_min)
        return self.u_min + (x - self.x_min) * k

    def evaluate(self, u) -> np.ndarray:
        """Output (m) for a voltage signal ``u`` (V), starting from negative saturation.

        Vectorised (see :meth:`qpcoord.hysteresis.memory.PreisachStage.run`); equal to
        stepping a fresh :class:`~qpcoord.hysteresis.memory.PreisachStage` sample by sample.

        Raises
        ------
        ValueError
            If ``u`` holds NaN or leaves ``[u_min, u_max]`` (the value is named).
        """
        return PreisachStage(self).run(u)

    def __repr__(self) -> str:
        return (
            f"PreisachModel({self._n}×{self._n} mesh, u ∈ [{self.u_min:g}, {self.u_max:g}] V, "
            f"x ∈ [{self.x_min:.4g}, {self.x_max:.4g}] m)"
        )
