"""Closed-loop simulation of a DDL plant with a controller: :func:`simulate` → :class:`Run`."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import numpy as np

from ._check import positive
from .metrics import tracking_metrics

__all__ = ["Run", "simulate", "as_reference"]


@dataclass
class Run:
    """Time series and metrics of one closed-loop run (SI units, one sample per period).

    Attributes
    ----------
    fs : float
        Sampling rate, Hz.
    t, r : ndarray
        Time (s) and reference (m).
    y : ndarray
        Measured output at each sample (before that sample's command), m: the plant's
        metrology reading, *without* the injected faults.
    y_sensor : ndarray
        With ``simulate(..., faults=...)``: the value delivered to the controller at each
        sample (the reading with the faults applied; may hold NaN), m. Else empty.
    y_f, y_c : ndarray
        True fine extension and carriage position at the same instants, m.
    y_c_hat : ndarray
        Controller's carriage estimate (``controller.y_c_hat``; NaN-free: the true y_c is
        *not* substituted — if the controller has no estimate the array is empty).
    v, i_a, i_b : ndarray
        Commands of each period: piezo voltage applied (V), coil currents (A).
    fine_saturated : ndarray of bool
        Fine stage at a stroke limit at the end of the period.
    metrics : dict
        See :func:`.metrics.tracking_metrics`, plus ``rejected_samples`` (int: measurements
        the controller's :class:`.guard.MeasurementGuard` rejected; 0 for a controller
        without ``guard``), ``rejected_references`` (int), ``lost_sync`` (bool),
        ``sync_slip_steps``, ``coarse_stop_steps``, ``saturation_guard_steps`` (int: steps in
        which the controller's saturation guard acted, 0 without one), ``rmse_true`` (m, error
        of the true output), ``fine_excursion`` (max |y_f − mid-stroke|, m), ``wall_time`` (s);
        with ``simulate(..., timing=True)`` also ``step_time_median`` and ``step_time_p99``
        (s per ``controller.step`` call).
    step_times : ndarray
        Wall time of each ``controller.step`` call, s (only with ``timing=True``; else
        empty).
    """

    fs: float
    t: np.ndarray
    r: np.ndarray
    y: np.ndarray
    y_f: np.ndarray
    y_c: np.ndarray
    y_c_hat: np.ndarray
    v: np.ndarray
    i_a: np.ndarray
    i_b: np.ndarray
    fine_saturated: np.ndarray
    metrics: dict = field(default_factory=dict)
    step_times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    y_sensor: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def error(self) -> np.ndarray:
        """Measured tracking error ``r − y``, m."""
        return self.r - self.y


def as_reference(reference, fs: float, plant=None) -> np.ndarray:
    """Validate a reference: 1-D finite array of metres (or an object with ``sample(fs)``).

    Raises ValueError for non-finite samples, fewer than 2 samples (shorter than one step)
    or, if ``plant`` is given, samples outside the plant's reachable output range.
    """
    if hasattr(reference, "sample") and callable(reference.sample):
        reference = reference.sample(fs)
    r = np.asarray(reference, dtype=float)
    if r.ndim != 1:
        raise ValueError(f"reference must be 1-D (metres sampled at fs), got shape {r.shape}")
    if r.size < 2:
        raise ValueError(
            f"reference has {r.size} sample(s): shorter than one control step at fs = {fs} Hz"
        )
    bad = np.flatnonzero(~np.isfinite(r))
    if bad.size:
        raise ValueError(f"reference is not finite at sample {bad[0]} (value {r[bad[0]]!r})")
    if plant is not None:
        lo, hi = plant.output_range
        k = np.flatnonzero((r < lo) | (r > hi))
        if k.size:
            raise ValueError(
                f"reference leaves the stroke [{lo:.6g}, {hi:.6g}] m at sample {k[0]} "
                f"(value {r[k[0]]!r} m)"
            )
    return r


def simulate(
    plant,
    controller,
    reference,
    fs: float = 8000.0,
    *,
    seed: int = 0,
    progress: bool = False,
    timing: bool = False,
    faults=None,
) -> Run:
    """Run ``controller`` on ``plant`` tracking ``reference`` at ``fs`` Hz.

    Parameters
    ----------
    plant : DualStage
        The plant (reset here: output starts at ``reference[0]`` with the fine stage at
        mid-stroke and the carriage at rest).
    controller : object
        ``reset(plant, fs, y0, r0)`` and ``step(y, r) -> (v, i_a, i_b)`` (see
        :mod:`.coordinator`); an attribute ``y_c_hat`` is logged if present.
    reference : array_like or object
        Reference output, m, one sample per period (or an object with ``sample(fs)``).
    fs : float
        Control rate, Hz.
    seed : int
        Seed of the metrology noise.
    progress : bool
        Print a progress line to stderr (off by default in library calls).
    timing : bool
        Time every ``controller.step`` call with ``time.perf_counter`` (adds ≈ 1 µs a
        step outside the timed interval; off by default): ``Run.step_times`` and the metrics
        ``step_time_median``, ``step_time_p99``.

    Returns
    -------
    Run
        Time series and ``.metrics``. Fine-stage saturation and loss of synchronism are
        reported in the metrics, not raised.
    """
    fs = positive("fs", fs)
    r = as_reference(reference, fs, plant)
    n = r.size
    y = plant.reset(fs, y0=float(r[0]), seed=seed)
    controller.reset(plant, fs, y, float(r[0]))
    has_hat = hasattr(controller, "y_c_hat")
    ys = [0.0] * n
    yfs = [0.0] * n
    ycs = [0.0] * n
    hats = [0.0] * n if has_hat else []
    vs = [0.0] * n
    ias = [0.0] * n
    ibs = [0.0] * n
    sats = [False] * n
    stops = 0
    cstep = controller.step
    times = []
    if timing:
        raw_step = cstep
        clock = time.perf_counter
        record = times.append

        def cstep(y_, r_):
            t_ = clock()
            out = raw_step(y_, r_)
            record(clock() - t_)
            return out

    if faults is None:
        fault = None
    elif isinstance(faults, dict):
        table = {int(k): float(v) for k, v in faults.items()}
        bad = [k for k in table if not 0 <= k < n]
        if bad:
            raise ValueError(f"faults: sample index {bad[0]} outside 0..{n - 1}")

        def fault(k_, y_):
            return table.get(k_, y_)

    elif callable(faults):
        fault = faults
    else:
        raise ValueError(f"faults must be a dict or a callable (k, y) -> y, got {faults!r}")
    sensor = [0.0] * n if fault is not None else []
    pstep = plant.step
    rl = r.tolist()
    chunk = max(1, n // 10)
    t0 = time.perf_counter()
    for k in range(n):
        ys[k] = y
        yfs[k] = plant.y_f
        ycs[k] = plant.y_c
        if fault is not None:
            ym = float(fault(k, y))
            sensor[k] = ym
            v, ia, ib = cstep(ym, rl[k])
        else:
            v, ia, ib = cstep(y, rl[k])
        if has_hat:
            hats[k] = controller.y_c_hat
        vs[k] = v
        ias[k] = ia
        ibs[k] = ib
        y = pstep(v, ia, ib)
        if plant.fine_saturated:
            sats[k] = True
        if plant.coarse_at_stop:
            stops += 1
        if progress and (k + 1) % chunk == 0:
            print(f"\rsimulate: {100 * (k + 1) // n:3d} %", end="", file=sys.stderr)
    wall = time.perf_counter() - t0
    if progress:
        print(file=sys.stderr)
    run = Run(
        fs=fs,
        t=np.arange(n) / fs,
        r=r,
        y=np.array(ys),
        y_f=np.array(yfs),
        y_c=np.array(ycs),
        y_c_hat=np.array(hats),
        v=np.array(vs),
        i_a=np.array(ias),
        i_b=np.array(ibs),
        fine_saturated=np.array(sats, dtype=bool),
        y_sensor=np.array(sensor),
    )
    fp = plant.fine
    m = tracking_metrics(
        run.error,
        run.i_a,
        run.i_b,
        run.y_f,
        (fp.stroke_min, fp.stroke_max),
        run.fine_saturated,
        plant.stepper.resistance,
    )
    guard = getattr(controller, "guard", None)
    m["rejected_samples"] = int(getattr(guard, "rejected", 0))
    m["rejected_references"] = int(getattr(guard, "rejected_references", 0))
    m["lost_sync"] = bool(plant.lost_sync)
    m["sync_slip_steps"] = int(plant.sync_slip_steps)
    m["coarse_stop_steps"] = int(stops)
    m["saturation_guard_steps"] = int(getattr(controller, "saturation_guard_steps", 0))
    true_err = r - (run.y_c + run.y_f)
    m["rmse_true"] = float(np.sqrt(np.mean(true_err * true_err)))
    m["fine_excursion"] = float(np.max(np.abs(run.y_f - fp.centre)))
    m["wall_time"] = wall
    if timing:
        run.step_times = np.array(times)
        m["step_time_median"] = float(np.median(run.step_times))
        m["step_time_p99"] = float(np.percentile(run.step_times, 99))
    run.metrics = m
    return run
