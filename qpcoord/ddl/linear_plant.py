"""Any linear dual stage: :class:`LinearDualStage` and its disturbances (:class:`Disturbance`).

A coarse and a fine actuator, each a SISO state-space model from its input to its position
(m), continuous or discrete, optionally behind an input filter (a discrete SISO model running
at ``Ts/M`` whose input is held over the sampling period ``Ts``: the held / multirate filters
of hard-disk drives). One sampling period ``Ts`` (s); the controller measures, once per
period, the combined position error::

    e(k) = d_out(k) − y_c(k) − y_f(k)                                          (m)

with ``d_out`` the sum of the output disturbances (a reference to track is one: ``d = r``).
Disturbances enter at the output or at either actuator's input; each is a SISO model driven
by white noise of a given variance, held over ``Ts``.

Every model is in deviations from an operating point: ``y_f = 0`` is the fine stage's
centre. Ranges and rate limits act on the inputs (the simulator clips them), strokes on the
positions (the simulator reports, per step, a position outside its stroke).

:meth:`LinearDualStage.discrete` returns the whole plant as one discrete model at ``Ts``
(:class:`DiscreteDualStage`), the model the controllers are designed on and
:func:`.linear_sim.simulate_linear` steps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

__all__ = ["Disturbance", "DiscreteDualStage", "LinearDualStage", "as_siso"]

_PLACES = ("output", "coarse", "fine")


def _matrix(name: str, value, shape=None) -> np.ndarray:
    try:
        a = np.array(value, dtype=float, ndmin=2)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a numeric matrix, got {value!r}") from exc
    if a.ndim != 2:
        raise ValueError(f"{name} must be 2-D, got shape {a.shape}")
    bad = np.argwhere(~np.isfinite(a))
    if bad.size:
        i, j = bad[0]
        raise ValueError(f"{name} is not finite at [{i}, {j}] (value {a[i, j]!r})")
    if shape is not None and a.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {a.shape}")
    return a


def as_siso(
    name: str, model, dt=None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """``(A, B, C, D, dt)`` of a SISO model, validated; ``dt = 0.0`` for continuous time.

    ``model``: a python-control ``StateSpace`` / ``TransferFunction`` (its ``dt``; ``None``
    or 0 is continuous), or a tuple ``(A, B, C, D)`` (continuous unless ``dt`` is given) or
    ``(A, B, C, D, dt)``. Raises ValueError naming ``name`` for a non-square ``A``,
    inconsistent shapes, a non-SISO model, a non-finite entry or a bad ``dt``.
    """
    if hasattr(model, "A") or hasattr(model, "num"):
        import control

        ss = control.ss(model)
        a, b, c, d = ss.A, ss.B, ss.C, ss.D
        mdt = ss.dt
    elif isinstance(model, (tuple, list)) and len(model) in (4, 5):
        a, b, c, d = model[:4]
        mdt = model[4] if len(model) == 5 else dt
    else:
        raise ValueError(
            f"{name} must be a python-control model or a tuple (A, B, C, D[, dt]), got {model!r}"
        )
    mdt = 0.0 if mdt is None or mdt is False else mdt
    if mdt is True:
        raise ValueError(f"{name}: an unspecified sampling period (dt=True) is not accepted")
    mdt = float(mdt)
    if not math.isfinite(mdt) or mdt < 0.0:
        raise ValueError(f"{name}: sampling period must be finite and >= 0, got {mdt!r}")
    a = _matrix(f"{name}.A", a)
    n = a.shape[0]
    if a.shape != (n, n):
        raise ValueError(f"{name}.A must be square, got shape {a.shape}")
    b = _matrix(f"{name}.B", b, (n, 1)) if n else np.zeros((0, 1))
    c = _matrix(f"{name}.C", c, (1, n)) if n else np.zeros((1, 0))
    d = _matrix(f"{name}.D", d, (1, 1))
    return a, b, c, d, mdt


def _zoh(a: np.ndarray, b: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    n, m = b.shape
    blk = np.zeros((n + m, n + m))
    blk[:n, :n] = a * h
    blk[:n, n:] = b * h
    e = expm(blk)
    return e[:n, :n], e[:n, n:]


def _range(name: str, value, allow_inf: bool) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a pair (low, high), got {value!r}") from exc
    if (
        math.isnan(lo)
        or math.isnan(hi)
        or (not allow_inf and not (math.isfinite(lo) and math.isfinite(hi)))
    ):
        raise ValueError(f"{name} must be finite numbers, got {value!r}")
    if not hi > lo:
        raise ValueError(f"{name} must have high > low (a stroke or range > 0), got {value!r}")
    return lo, hi


def _stroke(name: str, value) -> tuple[float, float]:
    if np.ndim(value) == 0:
        v = float(value)
        if not math.isfinite(v) or v <= 0.0:
            raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        return -0.5 * v, 0.5 * v
    lo, hi = _range(name, value, allow_inf=False)
    if not lo <= 0.0 <= hi:
        raise ValueError(f"{name} must contain the operating point 0, got {value!r}")
    return lo, hi


@dataclass(frozen=True)
class Disturbance:
    """A disturbance: a SISO model driven by white noise, added at ``at``.

    Attributes
    ----------
    model : object
        SISO model (python-control or ``(A, B, C, D[, dt])``), continuous or discrete at the
        plant's ``Ts``; output in m (``at="output"``) or in the actuator's input unit.
    at : {"output", "coarse", "fine"}
        Where it enters: the measured error (``e = d − y``), or an actuator's input.
    variance : float
        Variance of the white noise driving it, held over each period (unit²).
    name : str
        Label.
    """

    model: object
    at: str = "output"
    variance: float = 1.0
    name: str = ""

    def __post_init__(self):
        if self.at not in _PLACES:
            raise ValueError(f"Disturbance.at must be one of {_PLACES}, got {self.at!r}")
        v = float(self.variance)
        if not math.isfinite(v) or v <= 0.0:
            raise ValueError(f"Disturbance.variance must be finite and > 0, got {self.variance!r}")


@dataclass(frozen=True)
class DiscreteDualStage:
    """The whole plant at ``Ts``: ``x⁺ = A x + B u + G w``, ``u = (u_c, u_f)``.

    Attributes
    ----------
    A, B, G : ndarray
        State (n × n), input (n × 2) and disturbance-noise (n × n_w) matrices.
    W : ndarray
        Covariance of ``w`` (n_w × n_w, diagonal).
    c_coarse, c_fine, c_dist : ndarray
        Rows (1 × n) giving ``y_c``, ``y_f`` and ``d_out``; the measured error is
        ``e = c_error x`` with ``c_error = c_dist − c_coarse − c_fine``.
    B_direct : ndarray
        Input matrix (n × 2) of an input added at each actuator after its filter (held over
        ``Ts``): how an input disturbance enters.
    n_coarse : int
        The first ``n_coarse`` states are the coarse channel's (its filter's, then its
        actuator's); the fine channel's follow up to ``n_plant``.
    n_plant : int
        The first ``n_plant`` states are the actuators' (and their filters'); the rest are
        the disturbance models'.
    Ts : float
        Sampling period, s.
    """

    A: np.ndarray
    B: np.ndarray
    G: np.ndarray
    W: np.ndarray
    c_coarse: np.ndarray
    c_fine: np.ndarray
    c_dist: np.ndarray
    n_plant: int
    Ts: float
    B_direct: np.ndarray
    n_coarse: int

    @property
    def c_error(self) -> np.ndarray:
        """Row of the measured error ``e = d_out − y_c − y_f``."""
        return self.c_dist - self.c_coarse - self.c_fine

    @property
    def n(self) -> int:
        """Number of states."""
        return self.A.shape[0]


class LinearDualStage:
    """A linear dual stage: coarse and fine actuators as state-space models (SI units).

    Parameters
    ----------
    coarse, fine : model
        SISO models from each actuator's input (any unit) to its position (m): a
        python-control ``StateSpace`` / ``TransferFunction`` or ``(A, B, C, D[, dt])``;
        continuous, or discrete at ``Ts`` (at ``Ts/M`` behind a filter of that rate). No
        feed-through (``D = 0``): a position does not respond within the instant.
    Ts : float
        Sampling period of the controller, s.
    coarse_range, fine_range : (float, float)
        Input ranges (the simulator clips the commands), input units; ±inf allowed.
    coarse_rate, fine_rate : float
        Input rate limits, input units per second (inf: none).
    coarse_stroke, fine_stroke : float or (float, float)
        Position ranges around the operating point, m (a number: the full stroke, centred).
    coarse_filter, fine_filter : model, optional
        Discrete SISO input filters at ``Ts/M`` (integer ``M ≥ 1``), input held over ``Ts``,
        output held over ``Ts/M`` into the actuator.
    disturbances : sequence of Disturbance
        Disturbance models (their states follow the actuators' in :meth:`discrete`).
    noise_rms : float
        Measurement noise of the error, m rms (≥ 0; used by the estimators' design).
    name : str
        Label.

    Raises
    ------
    ValueError
        Naming the argument: a non-square ``A``, inconsistent or non-SISO matrices, a NaN or
        infinite entry, a sampling period that is not finite and > 0, a discrete model at
        another rate than the one it runs at, a filter rate that is not ``Ts/M``, a stroke or
        range ≤ 0, a feed-through, an unstable disturbance model.
    """

    def __init__(
        self,
        coarse,
        fine,
        Ts: float,
        *,
        coarse_range=(-math.inf, math.inf),
        fine_range=(-math.inf, math.inf),
        coarse_rate: float = math.inf,
        fine_rate: float = math.inf,
        coarse_stroke=1.0,
        fine_stroke=1.0,
        coarse_filter=None,
        fine_filter=None,
        disturbances=(),
        noise_rms: float = 0.0,
        name: str = "",
    ):
        ts = float(Ts)
        if not math.isfinite(ts) or ts <= 0.0:
            raise ValueError(f"Ts must be a finite sampling period > 0 s, got {Ts!r}")
        self.Ts = ts
        self.name = str(name)
        self.coarse = as_siso("coarse", coarse)
        self.fine = as_siso("fine", fine)
        self.coarse_filter = (
            None if coarse_filter is None else as_siso("coarse_filter", coarse_filter)
        )
        self.fine_filter = None if fine_filter is None else as_siso("fine_filter", fine_filter)
        for label, act, filt in (
            ("coarse", self.coarse, self.coarse_filter),
            ("fine", self.fine, self.fine_filter),
        ):
            if np.any(act[3] != 0.0):
                raise ValueError(
                    f"{label}.D must be 0 (no feed-through to a position), got {act[3]!r}"
                )
            rate = ts if filt is None else filt[4]
            if filt is not None:
                m = ts / filt[4] if filt[4] > 0 else 0.0
                if filt[4] <= 0.0 or abs(m - round(m)) > 1e-9 * m or round(m) < 1:
                    raise ValueError(
                        f"{label}_filter must be discrete at Ts/M (integer M >= 1), got dt = "
                        f"{filt[4]!r} s with Ts = {ts!r} s"
                    )
            if act[4] > 0.0 and abs(act[4] - rate) > 1e-9 * rate:
                raise ValueError(
                    f"{label} is discrete at dt = {act[4]!r} s but runs at {rate!r} s "
                    "(Ts, or the filter's rate)"
                )
        self.coarse_range = _range("coarse_range", coarse_range, allow_inf=True)
        self.fine_range = _range("fine_range", fine_range, allow_inf=True)
        for nm, v in (("coarse_rate", coarse_rate), ("fine_rate", fine_rate)):
            v = float(v)
            if math.isnan(v) or v <= 0.0:
                raise ValueError(f"{nm} must be > 0 (inf: no limit), got {v!r}")
        self.coarse_rate = float(coarse_rate)
        self.fine_rate = float(fine_rate)
        self.coarse_stroke = _stroke("coarse_stroke", coarse_stroke)
        self.fine_stroke = _stroke("fine_stroke", fine_stroke)
        dist = tuple(disturbances)
        for i, d in enumerate(dist):
            if not isinstance(d, Disturbance):
                raise ValueError(f"disturbances[{i}] must be a Disturbance, got {d!r}")
        self.disturbances = dist
        self._dist = [as_siso(f"disturbances[{i}].model", d.model) for i, d in enumerate(dist)]
        for i, m in enumerate(self._dist):
            if m[4] > 0.0 and abs(m[4] - ts) > 1e-9 * ts:
                raise ValueError(
                    f"disturbances[{i}].model is discrete at {m[4]!r} s, not Ts = {ts!r} s"
                )
        nr = float(noise_rms)
        if not math.isfinite(nr) or nr < 0.0:
            raise ValueError(f"noise_rms must be finite and >= 0, got {noise_rms!r}")
        self.noise_rms = nr
        self._discrete = None
        self.discrete()  # validates the discretisation (e.g. unstable disturbance models)

    # ------------------------------------------------------------------ discretisation
    def _channel(self, act, filt) -> tuple[np.ndarray, ...]:
        """One actuator (and its filter) at ``Ts``: ``(A, B, C, B_direct)``, input held over
        ``Ts``; ``B_direct`` takes an input added after the filter (at the actuator)."""
        a, b, c, _, dt = act
        if filt is None:
            if dt == 0.0:
                a, b = _zoh(a, b, self.Ts)
            return a, b, c, b
        fa, fb, fc, fd, fdt = filt
        if dt == 0.0:
            a, b = _zoh(a, b, fdt)
        nf, n = fa.shape[0], a.shape[0]
        # one filter period: filter output held into the actuator
        phi = np.zeros((nf + n, nf + n))
        phi[:nf, :nf] = fa
        phi[nf:, :nf] = b @ fc
        phi[nf:, nf:] = a
        gam = np.hstack((np.vstack((fb, b @ fd)), np.vstack((np.zeros((nf, 1)), b))))
        m = int(round(self.Ts / fdt))
        big_a = np.eye(nf + n)
        big_b = np.zeros((nf + n, 2))
        for _ in range(m):  # the input is held over the M filter periods of one Ts
            big_b = phi @ big_b + gam
            big_a = phi @ big_a
        return big_a, big_b[:, :1], np.hstack((np.zeros((1, nf)), c)), big_b[:, 1:]

    def discrete(self) -> DiscreteDualStage:
        """The plant as one discrete model at ``Ts`` (cached): actuators, then disturbances."""
        if self._discrete is not None:
            return self._discrete
        ca, cb, cc, cbd = self._channel(self.coarse, self.coarse_filter)
        fa, fb, fc, fbd = self._channel(self.fine, self.fine_filter)
        nc, nf = ca.shape[0], fa.shape[0]
        blocks_a = [ca, fa]
        dparts = []
        for i, (d, m) in enumerate(zip(self.disturbances, self._dist, strict=True)):
            a, b, c, dd, dt = m
            if dt == 0.0:
                a, b = _zoh(a, b, self.Ts)
            if a.size and np.max(np.abs(np.linalg.eigvals(a))) >= 1.0:
                raise ValueError(
                    f"disturbances[{i}].model must be stable (a pole on or outside the unit "
                    "circle at Ts): replace an integrator by a pole at a low frequency"
                )
            if np.any(dd != 0.0):
                raise ValueError(f"disturbances[{i}].model must have D = 0, got {dd!r}")
            dparts.append((d, a, b, c))
            blocks_a.append(a)
        n = sum(x.shape[0] for x in blocks_a)
        A = np.zeros((n, n))
        B = np.zeros((n, 2))
        G = np.zeros((n, len(dparts)))
        c_c = np.zeros((1, n))
        c_f = np.zeros((1, n))
        c_d = np.zeros((1, n))
        A[:nc, :nc] = ca
        A[nc : nc + nf, nc : nc + nf] = fa
        B[:nc, 0:1] = cb
        B[nc : nc + nf, 1:2] = fb
        b_direct = np.zeros((n, 2))  # an input added after the filter, at the actuator
        b_direct[:nc, 0:1] = cbd
        b_direct[nc : nc + nf, 1:2] = fbd
        c_c[0, :nc] = cc
        c_f[0, nc : nc + nf] = fc
        k = nc + nf
        for j, (d, a, b, c) in enumerate(dparts):
            nd = a.shape[0]
            A[k : k + nd, k : k + nd] = a
            G[k : k + nd, j : j + 1] = b
            if d.at == "output":
                c_d[0, k : k + nd] = c
            else:  # enters an actuator's input (after its filter), held over the period
                col = 0 if d.at == "coarse" else 1
                A[:, k : k + nd] += b_direct[:, col : col + 1] @ c
            k += nd
        W = np.diag([d.variance for d in self.disturbances]) if dparts else np.zeros((0, 0))
        self._discrete = DiscreteDualStage(
            A=A,
            B=B,
            G=G,
            W=W,
            c_coarse=c_c,
            c_fine=c_f,
            c_dist=c_d,
            n_plant=nc + nf,
            Ts=self.Ts,
            B_direct=b_direct,
            n_coarse=nc,
        )
        return self._discrete

    def with_disturbances(self, disturbances) -> LinearDualStage:
        """The same plant with other disturbance models."""
        return LinearDualStage(
            self.coarse,
            self.fine,
            self.Ts,
            coarse_range=self.coarse_range,
            fine_range=self.fine_range,
            coarse_rate=self.coarse_rate,
            fine_rate=self.fine_rate,
            coarse_stroke=self.coarse_stroke,
            fine_stroke=self.fine_stroke,
            coarse_filter=self.coarse_filter,
            fine_filter=self.fine_filter,
            disturbances=disturbances,
            noise_rms=self.noise_rms,
            name=self.name,
        )

    def __repr__(self) -> str:
        d = self.discrete()
        return (
            f"LinearDualStage({self.name!r}, Ts={self.Ts:g} s, {d.n_plant} actuator states, "
            f"{len(self.disturbances)} disturbances)"
        )
