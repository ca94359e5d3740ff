"""Memory of extrema of the Preisach model and its evaluation (Eqs C.5–C.7, wipe-out).

The state is the alternating list of dominant extrema ``m = [m₀, m₁, m₂, …, m_K]`` (V) with
``m₀ = u_min`` (negative saturation), minima at even and maxima at odd positions,
``m₀ < m₂ < m₄ < … < m₅ < m₃ < m₁`` (the thesis's ``β'₀, α'₁, β'₁, …``). If the last
stored extremum is a minimum (K even) the input is on an ascending branch, otherwise on a
descending one. With ``S_K`` the finished sum of Eq. C.6, the output is::

    ascending  (K even):  x = offset + S_K + X(u, m_K)                        (C.6)
    descending (K odd):   x = offset + S_{K−1} + X(m_K, m_{K−1}) − X(m_K, u)   (C.7)

``acc[K]`` caches ``offset + S_K`` (K even) or ``offset + S_{K−1} + X(m_K, m_{K−1})`` (K
odd), so a sample costs one Everett evaluation plus one per reversal or wipe-out. The
wipe-out property removes the pair ``(m_{K−1}, m_K)`` as soon as the input passes
``m_{K−1}`` (a stored maximum going up, a stored minimum going down); going down to
``u_min`` returns the model to negative saturation.

The inverse (Eqs C.9–C.11) is :class:`qpcoord.hysteresis.inverse.PreisachCompensator`.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["PreisachStage", "EverettModel"]


@runtime_checkable
class EverettModel(Protocol):
    """What the memory reads of its model (a :class:`~qpcoord.hysteresis.PreisachModel`,
    whose :meth:`~qpcoord.hysteresis.PreisachModel.evaluate` runs a stage of this module):
    the identified range (V), the major loop's end points and offset (m), and the Everett
    function ``X(α, β)`` (m) per pair and vectorised, unchecked."""

    offset: float

    @property
    def u_min(self) -> float: ...

    @property
    def u_max(self) -> float: ...

    @property
    def x_min(self) -> float: ...

    @property
    def x_max(self) -> float: ...

    def everett_scalar(self, a: float, b: float) -> float: ...

    def everett_unchecked(self, a: np.ndarray, b: np.ndarray) -> np.ndarray: ...

    def check_range(self, v: np.ndarray, name: str) -> None: ...


class _Memory:
    """State machine (extrema stack) shared by :class:`PreisachStage` and the compensator."""

    def __init__(self, model: EverettModel, clip: bool = False) -> None:
        if not isinstance(model, EverettModel):
            raise ValueError(f"model must be a PreisachModel, got {type(model).__name__}")
        self.model = model
        self.clip = bool(clip)
        self._X = model.everett_scalar
        self._lo = model.u_min
        self._hi = model.u_max
        self._xlo = model.x_min
        self._xhi = model.x_max
        self.reset()

    def reset(self) -> None:
        """Return to negative saturation: input ``u_min`` (V), output ``x_min`` (m)."""
        self._m = [self._lo]
        self._acc = [self.model.offset]
        self._u = self._lo
        self._x = self.model.offset

    @property
    def u(self) -> float:
        """Current input voltage (V)."""
        return self._u

    @property
    def x(self) -> float:
        """Current output (m)."""
        return self._x

    @property
    def extrema(self) -> list[float]:
        """Stored dominant extrema ``[u_min, max₁, min₁, max₂, …]`` (V), a copy."""
        return list(self._m)

    # ------------------------------------------------------------------ forward, per sample
    def _forward(self, u: float) -> float:
        m, acc, X = self._m, self._acc, self._X
        uc = self._u
        K = len(m) - 1
        if u > uc:
            if K & 1:  # reversal: uc was a minimum
                acc.append(acc[K] - X(m[K], uc))
                m.append(uc)
                K += 1
            while K >= 2 and u >= m[K - 1]:  # wipe-out of (max, min)
                del m[-2:], acc[-2:]
                K -= 2
            x = acc[K] + X(u, m[K])
        elif u < uc:
            if not K & 1:  # reversal: uc was a maximum
                acc.append(acc[K] + X(uc, m[K]))
                m.append(uc)
                K += 1
            while K >= 3 and u <= m[K - 1]:  # wipe-out of (min, max)
                del m[-2:], acc[-2:]
                K -= 2
            if K == 1 and u <= m[0]:  # back to negative saturation
                del m[1:], acc[1:]
                x = acc[0]
            else:
                x = acc[K] - X(m[K], u)
        else:
            return self._x
        self._u = u
        self._x = x
        return x

    # ------------------------------------------------------------------ inverse, per sample


def _bad(name: str, value: float, unit: str, lo: float, hi: float) -> ValueError:
    what = "NaN" if value != value else "outside the identified range"
    return ValueError(f"{name} = {value!r} {unit} is {what} [{lo!r}, {hi!r}] {unit}")


class PreisachStage(_Memory):
    """Stateful hysteretic stage: voltage in, displacement (or effective voltage) out.

    Parameters
    ----------
    model : PreisachModel
        The identified model.
    output : {"metres", "volts"}
        What :meth:`step` returns. ``"metres"``: the displacement ``x`` (m).
        ``"volts"``: the *effective voltage* (V), ``u_min + (x − x_min)(u_max − u_min)/
        (x_max − x_min)``, i.e. the voltage a hysteresis-free actuator with the same major
        loop end points would need for the same ``x``; use it to put the hysteresis in
        front of a linear plant model whose static gain already maps volts to metres
        (e.g. the DDL fine stage, 3 µm/V).
    clip : bool
        If true, an input outside ``[u_min, u_max]`` is saturated to the range instead of
        raising (NaN always raises).

    Notes
    -----
    :meth:`reset` puts the stage in negative saturation (input ``u_min``). :meth:`step`
    does no numpy work and allocates nothing but the Python floats of its result and the
    list slots of a new extremum: 0.9–2.6 µs a sample (medians over runs, 21-level mesh,
    stochastic input; measured by ``examples/appC_preisach.py``, see ``docs/appC.md``).
    """

    def __init__(self, model: EverettModel, output: str = "metres", clip: bool = False) -> None:
        if output not in ("metres", "volts"):
            raise ValueError(f"output must be 'metres' or 'volts', got {output!r}")
        super().__init__(model, clip)
        self.output = output
        self._gain = (model.x_max - model.x_min) / (model.u_max - model.u_min)  # m/V

    def step(self, volts: float) -> float:
        """Advance one sample with input ``volts`` (V); return the output (m or V, see
        ``output``).

        Raises
        ------
        ValueError
            ``volts`` is NaN, or outside ``[u_min, u_max]`` and ``clip`` is false.
        """
        u = float(volts)
        if not (self._lo <= u <= self._hi):
            if self.clip and u == u:
                u = self._lo if u < self._lo else self._hi
            else:
                raise _bad("volts", u, "V", self._lo, self._hi)
        x = self._forward(u)
        if self.output == "volts":
            return self._lo + (x - self._xlo) / self._gain
        return x

    def run(self, u) -> np.ndarray:
        """Outputs for a voltage signal ``u`` (V), continuing from the current state and
        leaving the state at the last sample. Returns metres or volts as ``output`` says.

        Vectorised: a Python loop runs over the monotone segments of ``u`` (one per
        reversal) and the wipe-outs inside them, the Everett function is evaluated once
        over the whole signal with numpy. Equal to calling :meth:`step` per sample;
        0.6–1.0 µs a sample with a reversal every ≈ 12 samples, 0.07–0.27 µs on a 1 Hz sine at
        5 kHz (measured by ``examples/appC_preisach.py``).
        """
        u = np.array(u, dtype=float, ndmin=1)
        if u.ndim != 1:
            raise ValueError(f"u must be 1-D, got shape {u.shape}")
        if self.clip:
            if np.any(np.isnan(u)):
                raise _bad("u", float(u[np.isnan(u)][0]), "V", self._lo, self._hi)
            u = np.clip(u, self._lo, self._hi)
        else:
            self.model.check_range(u, "u")
        N = u.size
        if N == 0:
            return u.copy()
        prev = np.empty(N)
        prev[0] = self._u
        prev[1:] = u[:-1]
        d = np.sign(u - prev)
        nz = np.flatnonzero(d)
        # pieces: (start, anchor, base, sign); x = base + sign·X(·) on [start, next start)
        starts, anchors, bases, signs = [0], [self._u], [self._x], [0.0]
        if nz.size:
            dn = d[nz]
            seg = nz[np.r_[True, dn[1:] != dn[:-1]]].tolist()
            seg.append(N)
            ul = u.tolist()
            m, acc, X = self._m, self._acc, self._X
            for a, b, up in zip(seg[:-1], seg[1:], (d[seg[:-1]] > 0).tolist(), strict=True):
                uc = ul[a - 1] if a else self._u
                K = len(m) - 1
                start = a
                if up:
                    if K & 1:
                        acc.append(acc[K] - X(m[K], uc))
                        m.append(uc)
                        K += 1
                    end = ul[b - 1]
                    while K >= 2 and end >= m[K - 1]:
                        p = a + int(np.searchsorted(u[a:b], m[K - 1], side="left"))
                        starts.append(start), anchors.append(m[K]), bases.append(acc[K])
                        signs.append(1.0)
                        del m[-2:], acc[-2:]
                        K -= 2
                        start = p
                else:
                    if not K & 1:
                        acc.append(acc[K] + X(uc, m[K]))
                        m.append(uc)
                        K += 1
                    end = ul[b - 1]
                    while K >= 1 and end <= m[K - 1]:
                        p = a + int(np.searchsorted(-u[a:b], -m[K - 1], side="left"))
                        starts.append(start), anchors.append(m[K]), bases.append(acc[K])
                        signs.append(-1.0)
                        if K == 1:
                            del m[1:], acc[1:]
                            K = 0
                        else:
                            del m[-2:], acc[-2:]
                            K -= 2
                        start = p
                starts.append(start), anchors.append(m[K]), bases.append(acc[K])
                signs.append(-1.0 if K & 1 else 1.0)
        st = np.asarray(starts)
        lengths = np.diff(np.r_[st, N])
        anc = np.repeat(np.asarray(anchors), lengths)
        base = np.repeat(np.asarray(bases), lengths)
        sg = np.repeat(np.asarray(signs), lengths)
        alpha = np.where(sg < 0, anc, u)
        beta = np.where(sg > 0, anc, u)
        x = base + sg * self.model.everett_unchecked(alpha, beta)
        self._u = float(u[-1])
        self._x = float(x[-1])
        if self.output == "volts":
            return self._lo + (x - self._xlo) / self._gain
        return x
