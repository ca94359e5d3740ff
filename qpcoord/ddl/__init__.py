"""ESO/PRIMA Differential Delay Line (thesis chapter 6, appendix B): a dual-stage plant,
atmospheric references, the thesis's closed-loop coordinator and the two-DDL scheme.

Quick start::

    import qpcoord.ddl as ddl
    plant = ddl.DualStage()
    r = ddl.kolmogorov_opd(10.0, 8000.0, seed=1, preset="paranal_250hz")
    run = ddl.simulate(plant, ddl.SisoCoordinator(), r, fs=8000.0)
    run.metrics["rmse"]   # m

Any linear dual stage: :class:`LinearDualStage` (``DualStage().linear(fs)`` is PRIMA's), its
controllers :class:`LQG`, :class:`FrequencySplit` (the thesis's coordinator) and
:class:`LinearMPC` (a prioritised stack) with ``reset()`` / ``step(e) -> (u_c, u_f)`` and
``state_space()``, chosen against a :class:`Spec` by :func:`choose_controller`, simulated by
:func:`simulate_linear` (or on the nonlinear DualStage through
:class:`OnDualStage`).

Controllers of the DDL plant follow a two-method interface — ``reset(plant, fs, y0, r0)`` and
``step(y, r) -> (v, i_a, i_b)`` — documented in :mod:`qpcoord.ddl.coordinator`. Every
controller passes its measurement through a :class:`MeasurementGuard` (``ctl.guard``);
``simulate(..., faults=...)`` injects metrology faults (:mod:`qpcoord.ddl.faults`).
"""

from . import faults, identify, references, two_ddl
from .choose import Choice, Spec, choose_controller, surrogate
from .compare import compare, format_grid, format_table
from .coordinator import SisoCoordinator
from .design import DesignReport, LqrDesignReport, design_coordinator, design_lqr
from .envelope import ReferenceCheck, check_reference
from .fine import FineParams
from .flatness import FlatnessBased
from .flexure import BladeFlexure
from .guard import MeasurementGuard
from .identify import bandwidth_3db, coarse_frf, fine_frf, peak_frequency
from .linear_mpc import LinearMPC
from .linear_plant import DiscreteDualStage, Disturbance, LinearDualStage
from .linear_sim import LinearRun, simulate_linear
from .lqg import LQG, sensitivity
from .lqr import LQR, DesignModel, design_model
from .lqr_current import LQRCurrent
from .metrics import power, tracking_metrics
from .mpc import MPC
from .on_plant import OnDualStage
from .pi_linearised import PILinearised
from .plant import DualStage
from .pq import PQ
from .pq_current import PQCurrent
from .psd import OpdPsd
from .references import PRESETS, kolmogorov_opd, opd_psd, step_reference
from .simulate import Run, simulate
from .split import FrequencySplit
from .stability import simulated_coarse_margin
from .stepper import StepperParams

__all__ = [
    "BladeFlexure",
    "Choice",
    "DesignModel",
    "DesignReport",
    "DiscreteDualStage",
    "Disturbance",
    "DualStage",
    "FineParams",
    "FlatnessBased",
    "FrequencySplit",
    "LQG",
    "LQR",
    "LQRCurrent",
    "LinearDualStage",
    "LinearMPC",
    "LinearRun",
    "LqrDesignReport",
    "MPC",
    "MeasurementGuard",
    "OnDualStage",
    "OpdPsd",
    "PILinearised",
    "PQ",
    "PQCurrent",
    "PRESETS",
    "ReferenceCheck",
    "Run",
    "SisoCoordinator",
    "Spec",
    "StepperParams",
    "bandwidth_3db",
    "check_reference",
    "choose_controller",
    "coarse_frf",
    "compare",
    "design_coordinator",
    "design_lqr",
    "design_model",
    "faults",
    "fine_frf",
    "format_grid",
    "format_table",
    "identify",
    "kolmogorov_opd",
    "opd_psd",
    "peak_frequency",
    "power",
    "references",
    "sensitivity",
    "simulate",
    "simulate_linear",
    "simulated_coarse_margin",
    "step_reference",
    "surrogate",
    "tracking_metrics",
    "two_ddl",
]
