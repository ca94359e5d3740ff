"""Inverse Preisach model as a feed-forward compensator (thesis Eqs C.9–C.11).

The inverse (Eqs C.9–C.11 and the descending case) walks the same memory with the desired
output instead of the voltage: pass the wiped-out pairs, then solve ``X(u, β'_N) =
x − x(t₀)`` on the vertical line ``β = β'_N`` (ascending) or ``X(α'_N, u) = x(t₀) − x`` on
the horizontal line ``α = α'_N`` (descending): a binary search over the mesh nodes on that
line finds the cell, and Eq. C.11 (or its β twin) gives ``u`` in closed form.
"""

from __future__ import annotations

import numpy as np

from .memory import _bad, _Memory
from .preisach import PreisachModel

__all__ = ["PreisachCompensator"]


class PreisachCompensator(_Memory):
    """Stateful inverse Preisach model: desired displacement in, voltage out (Eqs C.9–C.11).

    Feed-forward compensator: apply ``step(x_desired)`` to the actuator instead of the
    linear command. Its internal memory is the model's memory under the voltages it
    outputs, so ``model`` driven by those voltages reproduces ``x_desired`` exactly
    (to rounding) on ``[x_min, x_max]``.

    Parameters
    ----------
    model : PreisachModel
        The identified model.
    input : {"metres", "volts"}
        What :meth:`step` takes: the desired displacement (m), or the desired *effective
        voltage* (V) of :class:`PreisachStage` with ``output="volts"``.
    clip : bool
        If true, a target outside ``[x_min, x_max]`` is saturated instead of raising.
    """

    def __init__(self, model: PreisachModel, input: str = "metres", clip: bool = False):
        if input not in ("metres", "volts"):
            raise ValueError(f"input must be 'metres' or 'volts', got {input!r}")
        super().__init__(model, clip)
        self.input = input
        self._gain = (model.x_max - model.x_min) / (model.u_max - model.u_min)  # m/V

    def step(self, target: float) -> float:
        """Voltage (V) to apply now so that the modelled output equals ``target``.

        Parameters
        ----------
        target : float
            Desired displacement (m), or effective voltage (V) if ``input="volts"``.

        Raises
        ------
        ValueError
            ``target`` is NaN, or outside the major loop's output range and ``clip`` is
            false.
        """
        x = float(target)
        if self.input == "volts":
            x = self._xlo + (x - self._lo) * self._gain
        if not (self._xlo <= x <= self._xhi):
            tol = 1e-12 * (self._xhi - self._xlo)  # rounding of x_max vs the model's output
            if self.clip and x == x or self._xlo - tol <= x <= self._xhi + tol:
                x = self._xlo if x < self._xlo else self._xhi
            else:
                name, unit = ("target", "m") if self.input == "metres" else ("target", "V")
                if self.input == "volts":
                    raise _bad(name, float(target), unit, self._lo, self._hi)
                raise _bad(name, x, unit, self._xlo, self._xhi)
        return self._inverse(x)

    def run(self, target) -> np.ndarray:
        """Voltages (V) for a desired signal (m, or V if ``input="volts"``), continuing from
        the current state. A Python loop over :meth:`step` (the inverse is sequential;
        1.9–4.1 µs a sample measured by ``examples/appC_preisach.py``)."""
        t = np.array(target, dtype=float, ndmin=1)
        if t.ndim != 1:
            raise ValueError(f"target must be 1-D, got shape {t.shape}")
        step = self.step
        return np.fromiter((step(v) for v in t.tolist()), dtype=float, count=t.size)

    def _inverse(self, x: float) -> float:
        m, acc, X = self._m, self._acc, self._X
        uc = self._u
        K = len(m) - 1
        pushed = False
        if x > self._x:
            if K & 1:  # reversal at uc (a minimum)
                acc.append(acc[K] - X(m[K], uc))
                m.append(uc)
                K += 1
                pushed = True
            low = m[K]
            while K >= 2 and x >= acc[K - 1]:  # acc[K−1]: output at u = m[K−1]
                low = m[K - 1]  # the wiped-out maximum: u ≥ it, as in the forward model
                del m[-2:], acc[-2:]
                K -= 2
            top = m[K - 1] if K >= 2 else self._hi
            u = self._solve_alpha(m[K], x - acc[K], low, top)
            while K >= 2 and u >= m[K - 1]:  # rounding put u on a stored maximum
                del m[-2:], acc[-2:]
                K -= 2
        elif x < self._x:
            if not K & 1:  # reversal at uc (a maximum)
                acc.append(acc[K] + X(uc, m[K]))
                m.append(uc)
                K += 1
                pushed = True
            high = m[K]
            while K >= 3 and x <= acc[K - 1]:
                high = m[K - 1]  # the wiped-out minimum: u ≤ it
                del m[-2:], acc[-2:]
                K -= 2
            u = (
                self._lo
                if K == 1 and x <= acc[0]
                else self._solve_beta(m[K], acc[K] - x, m[K - 1], high)
            )
            while K >= 3 and u <= m[K - 1]:
                del m[-2:], acc[-2:]
                K -= 2
            if K == 1 and u <= m[0]:  # back to negative saturation
                del m[1:], acc[1:]
        else:
            return uc
        if pushed and u == uc and len(m) == K + 1 and m[-1] == uc:  # no motion: no reversal
            del m[-1], acc[-1]
        self._u = u
        self._x = x
        return u

    def _solve_alpha(self, beta: float, y: float, low: float, top: float) -> float:
        """α ≥ β with X(α, β) = y on the vertical line β (Eq. C.11), clamped to [low, top]."""
        md = self.model
        lv, E, n = md._lv, md._E, md._n
        j = md._cell(beta)
        t = (beta - lv[j]) / (lv[j + 1] - lv[j])
        # nodes α = l_i, i = j+1..n, on the line: X(l_i, β) = (1−t) E[i][j] + t E[i][j+1]
        lo, hi = j + 1, n
        if (1.0 - t) * E[j + 1][j] >= y:
            i = j  # the diagonal (triangular) cell
        elif (1.0 - t) * E[n][j] + t * E[n][j + 1] < y:
            return top
        else:
            while lo < hi:  # first node with X(l_i, β) ≥ y
                mid = (lo + hi) // 2
                if (1.0 - t) * E[mid][j] + t * E[mid][j + 1] >= y:
                    hi = mid
                else:
                    lo = mid + 1
            i = lo - 1
        k = i * n + j
        den = md._t10[k] + md._t11[k] * beta
        u = (y - md._t00[k] - md._t01[k] * beta) / den  # Eq. C.11
        return low if u < low else (top if u > top else u)

    def _solve_beta(self, alpha: float, y: float, bottom: float, high: float) -> float:
        """β ≤ α with X(α, β) = y on the horizontal line α, clamped to [bottom, high]."""
        md = self.model
        lv, E, n = md._lv, md._E, md._n
        i = md._cell(alpha)
        s = (alpha - lv[i]) / (lv[i + 1] - lv[i])
        # nodes β = l_j, j = 0..i, on the line: X(α, l_j) = (1−s) E[i][j] + s E[i+1][j],
        # decreasing in j; find the last node with X ≥ y
        if s * E[i + 1][i] >= y:
            j = i
        else:
            lo, hi = 0, i  # invariant: X(α, l_lo) ≥ y > X(α, l_hi)
            if (1.0 - s) * E[i][0] + s * E[i + 1][0] < y:
                return bottom
            while hi - lo > 1:
                mid = (lo + hi) // 2
                if (1.0 - s) * E[i][mid] + s * E[i + 1][mid] >= y:
                    lo = mid
                else:
                    hi = mid
            j = lo
        k = i * n + j
        den = md._t01[k] + md._t11[k] * alpha
        u = (y - md._t00[k] - md._t10[k] * alpha) / den
        return bottom if u < bottom else (high if u > high else u)
