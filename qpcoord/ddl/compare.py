"""Run several DDL controllers on the same cases and tabulate them (thesis Tables 6.1–6.2).

``compare(controllers)`` runs every controller (a dict name → factory: each run gets a fresh
controller) on the same cases:

* ``kolmogorov``: the ``paranal_250hz`` preset OPD (:func:`.references.kolmogorov_opd`), one
  run per seed;
* ``step_centre``, ``step_extremity``: the 5 mm steps of Fig 6.19
  (:func:`.references.fig619_steps`), deterministic (run once, with the first seed);
* ``mismatch+``, ``mismatch-``: the Kolmogorov reference on a plant whose piezo gain, flexure
  stiffness and friction (Coulomb and static) are all +20 % / −20 % off, while the controller
  is designed on (and initialised from) the nominal plant — see :class:`DesignedOn`;
* ``latency2``: the Kolmogorov reference on the nominal plant with two periods (250 µs at
  8 kHz) of extra command latency (:class:`DelayedPlant`: computation, DAC and amplifier
  delays the ideal ``simulate`` loop does not have). Not one of the thesis's cases: a probe
  of the latency tolerance that the linear ``delay_margin_samples`` reports predict.

Each row holds the Table 6.1 metrics (RMSE, max, mean |e|, power), the fine stage's closest
approach to a stop, saturated steps, lost synchronism (steps with the rotor > π from the
field), the settling time of steps (last time |e| > 100 nm, after the step), and the
per-step controller time (median and 99th percentile of ``controller.step``, from
``simulate(..., timing=True)``). A controller whose construction, reset or step raises does
not stop the comparison: its row records the error.
"""

from __future__ import annotations

import dataclasses
import math
import traceback
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ._check import positive
from .plant import DualStage
from .references import fig619_steps, kolmogorov_opd
from .simulate import simulate

__all__ = [
    "default_controllers",
    "Case",
    "DelayedPlant",
    "DesignedOn",
    "compare",
    "default_cases",
    "format_table",
    "format_grid",
    "qualitative_grid",
    "mismatched_plant",
    "METRICS",
]

#: Metric keys of a row, in table order (SI units: m, W, s).
METRICS = (
    "rmse",
    "max_abs",
    "mean_abs",
    "power",
    "fine_margin_min",
    "saturated_steps",
    "sync_slip_steps",
    "settle_time",
    "step_time_median",
    "step_time_p99",
)

SETTLE_BAND = 100e-9  # m: "within 100 nm" for step settling (as docs/ch6.md part 1)
WARMUP = 0.5  # s: start-up window excluded from ``max_abs_after_warmup``
HOLD = 1.0  # s: final window of step runs for ``hold_*`` metrics


@dataclass(frozen=True)
class Case:
    """One comparison case.

    Attributes
    ----------
    name : str
    reference : callable
        ``reference(seed) -> ndarray`` of metres at ``fs``.
    plant : callable
        ``plant() -> DualStage``: the simulated (true) plant.
    design_plant : callable, optional
        ``design_plant() -> DualStage``: the plant the controller is given (nominal model);
        None = the true plant (no mismatch).
    seeded : bool
        Whether the reference depends on the seed (else the case runs once).
    step_time : float, optional
        Time of the step (s), for the settling time.
    """

    name: str
    reference: Callable
    plant: Callable = DualStage
    design_plant: Callable | None = None
    seeded: bool = True
    step_time: float | None = None


def default_controllers() -> dict:
    """Name → factory of every DDL controller of the library, with default arguments: the
    thesis coordinator; the thesis's current-driven LQR (no rate limit) and PQ (coarse stage
    as main actuator), ``LQRCurrent`` and ``PQCurrent``; qpcoord's field-phase variants
    ``LQR`` and ``PQ`` (3 mm/s rate limit, fixed amplitude); the prioritised-stack MPC
    (weighted, persistent QP); and the PI-linearised and flatness-based coarse controls of
    Table 6.1 (dither + friction feed-forward)."""
    from .coordinator import SisoCoordinator
    from .flatness import FlatnessBased
    from .lqr import LQR
    from .lqr_current import LQRCurrent
    from .mpc import MPC
    from .pi_linearised import PILinearised
    from .pq import PQ
    from .pq_current import PQCurrent

    return {
        "coordinator": SisoCoordinator,
        "LQRCurrent": LQRCurrent,
        "PQCurrent": PQCurrent,
        "LQR": LQR,
        "PQ": PQ,
        "MPC": MPC,
        "PILinearised": PILinearised,
        "FlatnessBased": FlatnessBased,
    }


def mismatched_plant(factor: float) -> DualStage:
    """Default plant with piezo gain, flexure stiffness and friction multiplied by ``factor``."""
    factor = positive("factor", factor)
    base = DualStage()
    fine = dataclasses.replace(base.fine, gain=base.fine.gain * factor)
    flex = dataclasses.replace(base.flexure, stiffness_sum=base.flexure.stiffness_sum * factor)
    st = dataclasses.replace(
        base.stepper,
        coulomb_torque=base.stepper.coulomb_torque * factor,
        static_torque=base.stepper.static_torque * factor,
    )
    return DualStage(fine, st, flex)


class DelayedPlant:
    """A plant whose commands take effect ``delay`` periods late (pure transport delay).

    Wraps a :class:`DualStage`: ``step(v, i_a, i_b)`` applies the command given ``delay``
    calls earlier (the first command is repeated until then); every other attribute is the
    wrapped plant's.
    """

    def __init__(self, plant: DualStage, delay: int = 1):
        if int(delay) != delay or delay < 0:
            raise ValueError(f"delay must be a non-negative integer, got {delay!r}")
        self.__dict__["plant"] = plant
        self.__dict__["delay"] = int(delay)
        self.__dict__["_buf"] = deque()

    def __getattr__(self, name):
        return getattr(self.__dict__["plant"], name)

    def reset(self, fs, *args, **kwargs):
        self._buf.clear()
        return self.plant.reset(fs, *args, **kwargs)

    def step(self, v, i_a, i_b):
        buf = self._buf
        cmd = (v, i_a, i_b)
        if not buf:
            buf.extend([cmd] * self.delay)
        buf.append(cmd)
        return self.plant.step(*buf.popleft())


def default_cases(
    duration: float = 10.0,
    step_duration: float = 6.0,
    fs: float = 8000.0,
    mismatch: float = 0.2,
    latency: int = 2,
) -> list[Case]:
    """The cases of the module docstring (durations in s, ``mismatch`` a fraction,
    ``latency`` in periods; ``latency=0`` leaves the latency case out)."""
    duration = positive("duration", duration)
    step_duration = positive("step_duration", step_duration)
    fs = positive("fs", fs)
    mismatch = float(mismatch)
    if not 0.0 < mismatch < 1.0:
        raise ValueError(f"mismatch must lie in (0, 1), got {mismatch!r}")
    if int(latency) != latency or latency < 0:
        raise ValueError(f"latency must be a non-negative integer, got {latency!r}")
    latency = int(latency)

    def kolmo(seed):
        return kolmogorov_opd(duration, fs, seed=seed, preset="paranal_250hz")

    steps = fig619_steps(step_duration, fs)
    cases = [
        Case("kolmogorov", kolmo),
        Case("step_centre", lambda seed: steps["centre"], seeded=False, step_time=0.1),
        Case("step_extremity", lambda seed: steps["extremity"], seeded=False, step_time=0.1),
        Case(
            "mismatch+",
            kolmo,
            plant=lambda: mismatched_plant(1.0 + mismatch),
            design_plant=DualStage,
        ),
        Case(
            "mismatch-",
            kolmo,
            plant=lambda: mismatched_plant(1.0 - mismatch),
            design_plant=DualStage,
        ),
    ]
    if latency:
        cases.append(
            Case(f"latency{latency}", kolmo, plant=lambda: DelayedPlant(DualStage(), latency))
        )
    return cases


class DesignedOn:
    """Wrap a controller so that it is reset on a *nominal* plant while another one runs.

    ``reset(plant, …)`` resets ``nominal`` with the true plant's carriage position and applied
    voltage (what the hardware would read back at start-up) and passes ``nominal`` to the
    wrapped controller: its design and initial estimates use the nominal parameters. ``step``
    is the wrapped controller's own bound method (no extra call layer).
    """

    def __init__(self, inner, nominal: DualStage):
        self.inner = inner
        self.nominal = nominal

    def reset(self, plant, fs, y0, r0):
        self.nominal.reset(fs, coarse0=plant.y_c, v0=plant.v_applied)
        self.inner.reset(self.nominal, fs, y0, r0)
        self.step = self.inner.step

    def step(self, y, r):  # replaced by the inner bound method in reset
        return self.inner.step(y, r)

    @property
    def y_c_hat(self):
        return self.inner.y_c_hat

    @property
    def guard(self):
        """The wrapped controller's measurement guard (read by :func:`.simulate`)."""
        return getattr(self.inner, "guard", None)


def _settle_time(err: np.ndarray, fs: float, t_step: float) -> float:
    """Time after ``t_step`` (s) from which |err| stays within SETTLE_BAND; NaN if never."""
    bad = np.flatnonzero(np.abs(err) > SETTLE_BAND)
    if bad.size == 0:
        return 0.0
    if bad[-1] == err.size - 1:
        return math.nan
    return max(0.0, (bad[-1] + 1) / fs - t_step)


def _empty_row(name: str, case: str, seed: int) -> dict:
    row = {"controller": name, "case": case, "seed": seed, "error": None}
    for k in METRICS:
        row[k] = math.nan
    row["lost_sync"] = None
    for k in ("hold_rmse", "hold_max", "hold_mean", "max_abs_after_warmup"):
        row[k] = math.nan
    return row


def compare(
    controllers: dict,
    references=None,
    seeds=(0,),
    duration: float = 10.0,
    fs: float = 8000.0,
    progress: bool = False,
    *,
    step_duration: float = 6.0,
    mismatch: float = 0.2,
    latency: int = 2,
    keep_runs: bool = False,
) -> list[dict]:
    """Run every controller on every case; one row per (controller, case, seed).

    Parameters
    ----------
    controllers : dict
        Name → factory (a zero-argument callable returning a fresh controller with
        ``reset``/``step``, see :mod:`.coordinator`).
    references : list of Case or dict, optional
        The cases (default :func:`default_cases`); a dict name → array (m, at ``fs``) or
        name → :class:`Case` is accepted too (arrays run on the default plant, once).
    seeds : sequence of int
        Seeds of the seeded cases (reference realisations); unseeded cases run once with
        ``seeds[0]``.
    duration, step_duration : float
        Length of the Kolmogorov / step references, s (default cases only).
    fs : float
        Control rate, Hz.
    progress : bool
        Print one line per run to stderr.
    mismatch : float
        Relative parameter error of the mismatch cases (0.2 = ±20 %).
    latency : int
        Extra command delay of the latency case, periods (0: no latency case).
    keep_runs : bool
        Store the :class:`.simulate.Run` of each row under ``"run"``.

    Returns
    -------
    list of dict
        Keys ``controller``, ``case``, ``seed``, ``error`` (None, or ``"Type: message"`` if
        the controller failed), ``lost_sync`` (bool), and :data:`METRICS` (NaN when failed
        or not applicable; ``settle_time`` only for step cases), ``max_abs_after_warmup``
        (max |e| for t ≥ 0.5 s, tracking cases), ``hold_rmse``, ``hold_max``, ``hold_mean``
        (errors over the last 1 s, step cases), ``wall_time`` (s).
    """
    import sys

    if not isinstance(controllers, dict) or not controllers:
        raise ValueError(
            f"controllers must be a non-empty dict name -> factory, got {controllers!r}"
        )
    for name, fac in controllers.items():
        if not callable(fac):
            raise ValueError(f"controllers[{name!r}] must be a factory (callable), got {fac!r}")
    fs = positive("fs", fs)
    seeds = tuple(int(s) for s in seeds)
    if not seeds:
        raise ValueError(f"seeds must not be empty, got {seeds!r}")
    if references is None:
        cases = default_cases(duration, step_duration, fs, mismatch, latency)
    elif isinstance(references, dict):
        cases = []
        for k, v in references.items():
            if isinstance(v, Case):
                cases.append(v)
            else:
                arr = np.asarray(v, dtype=float)
                cases.append(Case(str(k), lambda seed, a=arr: a, seeded=False))
    else:
        cases = list(references)
        for c in cases:
            if not isinstance(c, Case):
                raise ValueError(f"references must be Case objects or a dict, got {c!r}")
    rows = []
    for case in cases:
        for seed in seeds if case.seeded else seeds[:1]:
            ref = case.reference(seed)
            for name, fac in controllers.items():
                row = _empty_row(name, case.name, seed)
                try:
                    ctl = fac()
                    plant = case.plant()
                    if case.design_plant is not None:
                        ctl = DesignedOn(ctl, case.design_plant())
                    run = simulate(plant, ctl, ref, fs, seed=seed, timing=True)
                except Exception as exc:  # noqa: BLE001 - recorded in the row by design
                    row["error"] = f"{type(exc).__name__}: {exc}"
                    row["traceback"] = traceback.format_exc(limit=4)
                    rows.append(row)
                    if progress:
                        print(
                            f"compare: {name} / {case.name}: FAILED {row['error']}",
                            file=sys.stderr,
                        )
                    continue
                m = run.metrics
                for k in METRICS:
                    if k in m:
                        row[k] = m[k]
                row["lost_sync"] = bool(m["lost_sync"])
                row["wall_time"] = m["wall_time"]
                err = run.error
                if case.step_time is not None:
                    row["settle_time"] = _settle_time(err, fs, case.step_time)
                    tail = err[-max(1, int(HOLD * fs)) :]
                    row["hold_rmse"] = float(np.sqrt(np.mean(tail * tail)))
                    row["hold_max"] = float(np.max(np.abs(tail)))
                    row["hold_mean"] = float(np.mean(np.abs(tail)))
                else:
                    late = err[int(WARMUP * fs) :]
                    row["max_abs_after_warmup"] = (
                        float(np.max(np.abs(late))) if late.size else math.nan
                    )
                if keep_runs:
                    row["run"] = run
                rows.append(row)
                if progress:
                    print(
                        f"compare: {name:>12s} / {case.name:<15s} seed {seed}: "
                        f"rmse {row['rmse'] * 1e9:7.1f} nm, wall {m['wall_time']:.2f} s",
                        file=sys.stderr,
                    )
    return rows


# ---------------------------------------------------------------------------- formatting
def _agg(rows, controller, case, key):
    vals = [r[key] for r in rows if r["controller"] == controller and r["case"] == case]
    vals = [v for v in vals if v is not None and not (isinstance(v, float) and math.isnan(v))]
    if not vals:
        return math.nan
    return float(np.median(vals))


def _names(rows, key):
    out = []
    for r in rows:
        if r[key] not in out:
            out.append(r[key])
    return out


def format_table(rows: list[dict]) -> str:
    """Markdown table in the form of thesis Table 6.1, one line per (controller, case).

    Units: nm (RMSE, max, mean |e|), W (power), µm (fine margin), s (settling), µs (per-step
    controller time). Values are medians over seeds; failed runs show the error. Tracking
    cases: "max" is the whole-run max with, in parentheses, the max after the first 0.5 s
    (start-up). Step cases (†): RMSE, max and mean are over the last 1 s (holding error);
    the settling time is that to stay within 100 nm after the step.
    """
    head = (
        "| controller | case | RMSE [nm] | max [nm] | mean [nm] | P [W] | fine margin [µm] "
        "| sat. steps | lost sync | settle [s] | step µs med / p99 |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for c in _names(rows, "controller"):
        for case in _names(rows, "case"):
            sel = [r for r in rows if r["controller"] == c and r["case"] == case]
            if not sel:
                continue
            errs = [r["error"] for r in sel if r["error"]]
            if len(errs) == len(sel):
                msg = errs[0].replace("|", "/")[:80]
                lines.append(f"| {c} | {case} | failed: {msg} |" + " |" * 8)
                continue

            def g(k, scale=1.0, fmt="{:.1f}", c=c, case=case):
                v = _agg(rows, c, case, k)
                return "–" if math.isnan(v) else fmt.format(v * scale)

            lost = sum(1 for r in sel if r["lost_sync"])
            step_case = not math.isnan(_agg(rows, c, case, "hold_rmse"))
            if step_case:
                err_cells = (
                    f"{g('hold_rmse', 1e9)}† | {g('hold_max', 1e9)}† | {g('hold_mean', 1e9)}†"
                )
            else:
                err_cells = (
                    f"{g('rmse', 1e9)} | {g('max_abs', 1e9)} ({g('max_abs_after_warmup', 1e9)}) | "
                    f"{g('mean_abs', 1e9)}"
                )
            lines.append(
                f"| {c} | {case} | {err_cells} | {g('power', 1.0, '{:.3g}')} | "
                f"{g('fine_margin_min', 1e6, '{:.2f}')} | {g('saturated_steps', 1, '{:.0f}')} | "
                f"{lost}/{len(sel)} | {g('settle_time', 1, '{:.2f}')} | "
                f"{g('step_time_median', 1e6, '{:.1f}')} / {g('step_time_p99', 1e6, '{:.1f}')} |"
            )
    return head + "\n".join(lines) + "\n"


def _band(ratio: float, bands=(1.25, 2.0, 4.0, 8.0)) -> str:
    marks = ("++++", "+++", "++", "+")
    for b, m in zip(bands, marks, strict=True):
        if ratio <= b:
            return m
    return "-"


def qualitative_grid(rows: list[dict]) -> dict:
    """Table 6.2-style ratings computed from the measured rows by fixed rules.

    Rules (``best`` = the best controller's value on that criterion):

    * RMS error, e_max: median over seeds on ``kolmogorov``; ratio to best ≤ 1.25 → ``++++``,
      ≤ 2 → ``+++``, ≤ 4 → ``++``, ≤ 8 → ``+``, else ``-``;
    * power: absolute bands against the 5 W spec: ≤ 0.1 W ``++++``, ≤ 0.5 W ``+++``, ≤ 2 W
      ``++``, ≤ 5 W ``+``, else ``-``;
    * step response: worst settling time (within 100 nm) of the step cases, ratio to best as
      above; ``---`` if a step run lost synchronism or never settled;
    * robustness: worst RMSE of the mismatch cases divided by the nominal RMSE: ≤ 1.1
      ``++++``, ≤ 1.5 ``+++``, ≤ 2 ``++``, ≤ 4 ``+``, else ``-``; ``---`` if a mismatch run
      saturated the fine stage or lost synchronism;
    * latency tolerance (not in the thesis; only with a ``latency…`` case): RMSE with the
      extra latency divided by the nominal RMSE, same bands and ``---`` rule as robustness.

    A controller whose runs failed gets ``n/a``. Returns {criterion: {controller: mark}}.
    """
    ctls = _names(rows, "controller")
    cases = set(_names(rows, "case"))
    crit = {}

    def ok(c, case):
        return any(r["controller"] == c and r["case"] == case and not r["error"] for r in rows)

    def relative(values):
        good = {c: v for c, v in values.items() if not math.isnan(v)}
        best = min(good.values()) if good else math.nan
        out = {}
        for c in ctls:
            v = values.get(c, math.nan)
            out[c] = "n/a" if math.isnan(v) or not best > 0 else _band(v / best)
        return out

    if "kolmogorov" in cases:
        for key, label in (("rmse", "RMS error"), ("max_abs", "e_max")):
            crit[label] = relative(
                {
                    c: _agg(rows, c, "kolmogorov", key) if ok(c, "kolmogorov") else math.nan
                    for c in ctls
                }
            )
        pw = {}
        for c in ctls:
            p = _agg(rows, c, "kolmogorov", "power") if ok(c, "kolmogorov") else math.nan
            pw[c] = "n/a" if math.isnan(p) else _band(p, (0.1, 0.5, 2.0, 5.0))
        crit["Power dissipation"] = pw
    step_cases = [c for c in ("step_centre", "step_extremity") if c in cases]
    if step_cases:
        worst = {}
        broken = set()
        for c in ctls:
            sel = [r for r in rows if r["controller"] == c and r["case"] in step_cases]
            if not sel or any(r["error"] for r in sel):
                worst[c] = math.nan
                continue
            ts = [r["settle_time"] for r in sel]
            if any(r["lost_sync"] for r in sel) or any(math.isnan(t) for t in ts):
                broken.add(c)
                worst[c] = math.nan
            else:
                worst[c] = max(ts)
        marks = relative(worst)
        for c in broken:
            marks[c] = "---"
        crit["Step response"] = marks
    mm = [c for c in ("mismatch+", "mismatch-") if c in cases]
    if mm and "kolmogorov" in cases:
        rob = {}
        for c in ctls:
            sel = [r for r in rows if r["controller"] == c and r["case"] in mm]
            nominal = _agg(rows, c, "kolmogorov", "rmse")
            if not sel or any(r["error"] for r in sel) or math.isnan(nominal):
                rob[c] = "n/a"
                continue
            if any(r["lost_sync"] or r["saturated_steps"] > 0 for r in sel):
                rob[c] = "---"
                continue
            worst = max(_agg(rows, c, case, "rmse") for case in mm)
            rob[c] = _band(worst / nominal, (1.1, 1.5, 2.0, 4.0))
        crit["Robustness"] = rob
    lat = [c for c in cases if c.startswith("latency")]
    if lat and "kolmogorov" in cases:
        marks = {}
        for c in ctls:
            sel = [r for r in rows if r["controller"] == c and r["case"] in lat]
            nominal = _agg(rows, c, "kolmogorov", "rmse")
            if not sel or any(r["error"] for r in sel) or math.isnan(nominal):
                marks[c] = "n/a"
            elif any(r["lost_sync"] or r["saturated_steps"] > 0 for r in sel):
                marks[c] = "---"
            else:
                worst = max(_agg(rows, c, case, "rmse") for case in lat)
                marks[c] = _band(worst / nominal, (1.1, 1.5, 2.0, 4.0))
        crit["Latency tolerance"] = marks
    return crit


def format_grid(rows: list[dict]) -> str:
    """Markdown rendering of :func:`qualitative_grid` (criteria × controllers)."""
    grid = qualitative_grid(rows)
    ctls = _names(rows, "controller")
    out = "| | " + " | ".join(ctls) + " |\n|---|" + "---|" * len(ctls) + "\n"
    for crit, marks in grid.items():
        out += f"| {crit} | " + " | ".join(marks.get(c, "n/a") for c in ctls) + " |\n"
    return out
