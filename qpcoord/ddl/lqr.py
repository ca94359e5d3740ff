"""Discrete LQR with integral action and a steady-state Kalman observer for the DDL: `LQR`.

The design model is shared with the MPC (:func:`design_model`): the dual stage linearised
about rest at a carriage position with the fine stage at mid-stroke
(:meth:`.plant.DualStage.linearise`, ``inputs="phase"``) and discretised with a zero-order
hold at the control rate.

Discrete design model (all deviations from the operating point, SI units)::

    x(k+1) = A x(k) + B u(k),     y(k) = C x(k)
    x = (y_f [m], ẏ_f [m/s], y_c [m], ẏ_c [m/s])      (fine, then coarse)
    u = (v − v_op [V], α − α_op [rad electrical])      (piezo voltage, field phase)
    y = y_f + y_c [m]                                  (metrology output)

``v_op`` is the voltage that holds the fine stage at mid-stroke, ``α_op`` the field phase that
holds the carriage at rest at ``y_c_op`` with the field amplitude ``current``. Augmented with
the integral of the output error, ``x_i(k+1) = x_i(k) + h (y(k) − r(k))`` (m·s, ``h = 1/fs``),
the LQR state is ``x_a = (x − x_ss, x_i)`` (5 states) with input ``u − u_ss``, where the
**command matrix** ``(N_x, N_u)`` gives the steady state that realises a constant reference
with the fine stage centred (the coarse stage takes the whole static reference — the
reference split of the hard-disk-drive literature, thesis §6.1.4)::

    x_ss = N_x (r − y_op),  u_ss = N_u (r − y_op),   y_op = y_c_op + y_f,mid
    [A − I  B] [N_x]   [0]
    [  C    0] [N_u] = [1]     and   C_f N_x = 0   (C_f picks y_f)

Control law (per period, measured y, reference r)::

    x̂ = x̄ + M (y − y_op − C x̄)                   (current-estimator Kalman update)
    u = u_ss − K_x (x̂ − x_ss) − k_i x_i,          then clipped as the hardware would:
        v ∈ [0, 10] V, |Δα| ≤ max_speed/fs (rad per step, keeps the rotor synchronised)
    x_i ← x_i + h (y − r)                          (frozen while an input is clipped)
    x̄ ← A x̂ + B u_applied                          (the observer sees the clipped input)

and the coils get ``i_a = I sin α``, ``i_b = I cos α`` (direct-coil phase command at fixed
amplitude ``I``, the interface of the thesis coordinator).

Default weights (design rules, Bryson's rule ``1/max²`` with the maxima stated):

* output error ``y − r``: ``error_max`` = 1.3 µm on ``Cᵀ C`` — not a tolerance but the
  robustness rule: the smallest value (most aggressive design) for which the LQG loop
  broken at the measurement keeps peak |S| ≤ 1.6, the constraint the coordinator's fine PI
  was designed under (:func:`tune_error_max` gives 1.23 µm at 8 kHz, rounded up to 1.3 µm;
  Bryson's 10 nm would give peak |S| = 9.6 and a 3 kHz loop crossover);
* fine stage off-centre: 10 µm (one third of the 30 µm stroke, leaving 5 µm to a stop) →
  ``1/(10 µm)²`` on ``C_fᵀ C_f``;
* integral of the output error: ``1/(error_max · T_i)²`` with ``T_i = 1/(2π·20 Hz)``: an error
  of ``error_max`` held for one integral time of a 20 Hz corner weighs as much as
  ``error_max`` itself;
* velocities: no weight;
* inputs: 5 V on the voltage (half its range) and π/4 rad electrical on the field phase
  deviation (the load angle beyond which the linearisation of the stepper torque loses
  ≈ 10 % of its slope) → ``R = diag(1/25, 16/π²)``.

Kalman observer (steady state, same model): process noise entering as a force on the
carriage with σ = the Coulomb friction force (the main unmodelled force, 31.4 N by default)
and as a voltage on the piezo with σ = 0.05 V (amplifier noise and residual hysteresis,
0.5 % of the range); measurement noise the quantisation ``q²/12`` (q = 1.25 nm).

Sharing with an MPC: ``ctl = LQR().design(plant, fs)`` (no simulation needed) gives
``ctl.model`` (:class:`DesignModel`), ``ctl.Q``, ``ctl.R``, ``ctl.K`` and ``ctl.P``; the cost the
LQR minimises is ``Σ_{k≥0} x_a(k)ᵀ Q x_a(k) + Δu(k)ᵀ R Δu(k)`` with ``x_a = (x − x_ss, x_i)``
on ``(model.Aa, model.Ba)`` and ``Δu = u − u_ss``, so an MPC with stage cost ``(Q, R)`` and
terminal cost ``x_a(N)ᵀ P x_a(N)`` on the same model has ``−K x_a`` as its unconstrained first
move.

The Riccati equations are solved in scaled coordinates (states in µm, mm/s, µm, mm/s, nm·s)
to keep them well conditioned; :attr:`LQR.K` and :attr:`LQR.P` are returned in SI units and satisfy
the SI DARE (tested against python-control ``dlqr`` and scipy).

Measured design at 8 kHz (:meth:`LQR.report`): loop crossover 1053 Hz, PM 50.0°, GM 9.5 dB,
peak |S| 1.575, slowest closed-loop pole 19.8 Hz (integral), observer 130.8 Hz; it tolerates
one extra period of latency (``delay_margin_samples = 1``) — with two it oscillates (2.6 µm
rms on a 2 s Kolmogorov run, measured; the ``latency2`` case of :mod:`.compare`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import scipy.linalg as sla

from ._check import finite, nonnegative, positive
from .guard import MeasurementGuard, guard_arg

__all__ = [
    "DesignModel",
    "design_model",
    "discretise_model",
    "default_weights",
    "solve_dare",
    "kalman_gain",
    "LQR",
]

STATES = ("y_f", "yd_f", "y_c", "yd_c")
INPUTS = ("v", "alpha")


@dataclass(frozen=True)
class DesignModel:
    """Discrete linear design model of the DDL at one operating point (see module docstring).

    Attributes
    ----------
    fs : float
        Sampling rate of the discretisation, Hz (ZOH).
    A : ndarray, shape (4, 4)
        State matrix, states ``STATES = (y_f, ẏ_f, y_c, ẏ_c)`` in m, m/s.
    B : ndarray, shape (4, 2)
        Input matrix, inputs ``INPUTS = (v, α)`` in V and rad electrical (deviations).
    C : ndarray, shape (1, 4)
        Output ``y = y_f + y_c`` (m).
    C_all : ndarray, shape (3, 4)
        Outputs ``(y, y_f, y_c)``.
    Aa, Ba, Ca : ndarray, shapes (5, 5), (5, 2), (1, 5)
        Augmented with the integral state ``x_i(k+1) = x_i(k) + h (y(k) − r(k))`` (m·s) as
        fifth state; ``Ca = [C, 0]``. The reference enters ``x_i`` with ``−h``.
    Nx, Nu : ndarray, shapes (4,), (2,)
        Command matrix: steady state and input per metre of ``r − y_op`` with the fine stage
        centred.
    y_c_op, y_f_op, y_op : float
        Operating carriage position, fine position (mid-stroke) and output, m.
    v_op, alpha_op : float
        Operating voltage (V) and absolute field phase (rad electrical, unwrapped as
        ``y_c_op · p/r_screw + load angle``).
    current : float
        Field amplitude I of the linearisation, A.
    continuous : control.StateSpace
        The continuous model from :meth:`DualStage.linearise` (outputs y, y_f, y_c).
    """

    fs: float
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    C_all: np.ndarray
    Aa: np.ndarray
    Ba: np.ndarray
    Ca: np.ndarray
    Nx: np.ndarray
    Nu: np.ndarray
    y_c_op: float
    y_f_op: float
    y_op: float
    v_op: float
    alpha_op: float
    current: float
    continuous: object = field(repr=False)
    states: tuple = STATES
    inputs: tuple = INPUTS
    #: the plant the model was linearised from (its parameters: friction, mass, resolution)
    plant: Any = field(default=None, repr=False, compare=False)

    @property
    def h(self) -> float:
        """Sampling period, s."""
        return 1.0 / self.fs


def _operating_phase(plant, y_c: float, current: float) -> float:
    """Absolute field phase holding the carriage at rest at ``y_c`` (as in ``linearise``)."""
    s = plant.stepper
    r = s.screw_radius
    th = y_c * s.pole_pairs / r
    load = -float(plant.flexure.force(y_c)) * r + s.detent_torque * math.sin(4.0 * th)
    return th + math.asin(load / (s.torque_constant * current))


def design_model(
    plant, fs: float, y_c: float = 0.0, current: float = 1.5, detent: str = "average"
) -> DesignModel:
    """Discrete design model of ``plant`` at ``fs`` Hz about rest at carriage position ``y_c``.

    Parameters
    ----------
    plant : DualStage
        Plant whose parameters (``fine``, ``stepper``, ``flexure``) define the model; its
        state is not used (it need not be reset).
    fs : float
        Sampling rate, Hz (zero-order hold).
    y_c : float
        Operating carriage position, m (within the coarse stroke).
    current : float
        Field amplitude I, A (must hold the flexure load at ``y_c``).
    detent : {"average", "local"}
        ``"local"``: the exact linearisation at ``y_c`` (:meth:`DualStage.linearise`),
        including the detent torque's local stiffness ``4 T_d p cos(4θe)/r²`` (+7.6 % at a
        full-step position with the default stepper). ``"average"`` (default): that term
        averaged over one full step (zero). The carriage crosses a full step every 10 µm, so
        over any move longer than that the detent averages out; with ``"local"`` the static
        gain α → y_c is 7 % low and the LQR's observer built on it misplaced the carriage by
        0.19 mm after a 5 mm step, which then stopped 0.39 mm short (measured). The mode is
        at 115.7 Hz with ``"average"``, between the 111–120 Hz it takes within one full step.

    Returns
    -------
    DesignModel
        Matrices ``A, B, C`` (4 states, 2 inputs), the integral-augmented ``Aa, Ba, Ca``, the
        command matrix ``Nx, Nu`` and the operating point. State order ``(y_f, ẏ_f, y_c,
        ẏ_c)``, input order ``(v, α)``.

    Raises
    ------
    ValueError
        Non-positive ``fs``, ``y_c`` outside the stroke, ``current`` unable to hold the load.
    """
    import control

    fs = positive("fs", fs)
    y_c = finite("y_c", y_c)
    current = positive("current", current)
    if detent not in ("average", "local"):
        raise ValueError(f"detent must be 'average' or 'local', got {detent!r}")
    sysc = plant.linearise(y_c, current, inputs="phase")  # validates y_c and current
    if detent == "average":
        st = plant.stepper
        rs = st.screw_radius
        th = y_c * st.pole_pairs / rs
        k_det = 4.0 * st.detent_torque * st.pole_pairs * math.cos(4.0 * th) / (rs * rs)
        ac = np.array(sysc.A, dtype=float)
        ac[3, 2] += k_det / plant.carriage_mass(y_c)
        sysc = control.ss(
            ac,
            sysc.B,
            sysc.C,
            sysc.D,
            states=list(STATES),
            inputs=list(INPUTS),
            outputs=["y", "y_f", "y_c"],
        )
    model = discretise_model(
        sysc,
        dp_fine=plant.fine,
        fs=fs,
        y_c=y_c,
        current=current,
        alpha_op=_operating_phase(plant, y_c, current),
    )
    return replace(model, plant=plant)


def discretise_model(
    sysc, dp_fine, fs: float, y_c: float, current: float, alpha_op: float, inputs=INPUTS
) -> DesignModel:
    """ZOH discretisation, integral augmentation and command matrix of a continuous model.

    ``sysc``: 4 states ``STATES``, 2 inputs (piezo voltage first), outputs ``(y, y_f, y_c)``;
    ``dp_fine`` the :class:`.fine.FineParams` giving the mid-stroke operating point. Shared by
    :func:`design_model` (field-phase input) and :func:`.lqr_current.design_model_force`
    (carriage-force input).
    """
    import control

    sysd = control.c2d(sysc, 1.0 / fs, method="zoh")
    a = np.asarray(sysd.A, dtype=float)
    b = np.asarray(sysd.B, dtype=float)
    c_all = np.asarray(sysd.C, dtype=float)
    c = c_all[:1].copy()
    h = 1.0 / fs
    aa = np.zeros((5, 5))
    aa[:4, :4] = a
    aa[4, :4] = h * c[0]
    aa[4, 4] = 1.0
    ba = np.zeros((5, 2))
    ba[:4] = b
    ca = np.zeros((1, 5))
    ca[0, :4] = c[0]
    # command matrix: equilibrium with y = 1 and y_f = 0 (6 equations, 6 unknowns)
    m = np.zeros((6, 6))
    m[:4, :4] = a - np.eye(4)
    m[:4, 4:] = b
    m[4, :4] = c[0]
    m[5, :4] = c_all[1]
    rhs = np.zeros(6)
    rhs[4] = 1.0
    sol = np.linalg.solve(m, rhs)
    fine = dp_fine
    for arr in (a, b, c, c_all, aa, ba, ca):
        arr.setflags(write=False)
    nx = sol[:4].copy()
    nu = sol[4:].copy()
    nx.setflags(write=False)
    nu.setflags(write=False)
    return DesignModel(
        fs=fs,
        A=a,
        B=b,
        C=c,
        C_all=c_all,
        Aa=aa,
        Ba=ba,
        Ca=ca,
        Nx=nx,
        Nu=nu,
        y_c_op=y_c,
        y_f_op=fine.centre,
        y_op=y_c + fine.centre,
        v_op=fine.v_centre,
        alpha_op=alpha_op,
        current=current,
        continuous=sysc,
        inputs=tuple(inputs),
    )


# ---------------------------------------------------------------------------- weights
def default_weights(
    model: DesignModel,
    error_max: float = 1.3e-6,
    centre_max: float = 10e-6,
    integral_corner: float = 20.0,
    v_max: float = 5.0,
    alpha_max: float = math.pi / 4.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Bryson's-rule weights ``(Q, R)`` for the augmented 5-state model (module docstring).

    Parameters
    ----------
    model : DesignModel
        Gives the output rows ``C`` and ``C_f``.
    error_max : float
        Acceptable output error, m.
    centre_max : float
        Acceptable fine-stage deviation from mid-stroke, m.
    integral_corner : float
        Integral corner frequency f_i, Hz: the integral state is weighted as an error of
        ``error_max`` held for ``1/(2π f_i)`` seconds.
    v_max : float
        Acceptable voltage deviation, V.
    alpha_max : float
        Acceptable field-phase deviation, rad electrical.

    Returns
    -------
    Q : ndarray, shape (5, 5)
        SI units (1/m², …, 1/(m·s)²).
    R : ndarray, shape (2, 2)
        1/V², 1/rad².
    """
    error_max = positive("error_max", error_max)
    centre_max = positive("centre_max", centre_max)
    integral_corner = positive("integral_corner", integral_corner)
    v_max = positive("v_max", v_max)
    alpha_max = positive("alpha_max", alpha_max)
    c = np.zeros((1, 5))
    c[0, :4] = model.C[0]
    cf = np.zeros((1, 5))
    cf[0, :4] = model.C_all[1]
    ti = 1.0 / (2.0 * math.pi * integral_corner)
    q = c.T @ c / error_max**2 + cf.T @ cf / centre_max**2
    q[4, 4] = 1.0 / (error_max * ti) ** 2
    r = np.diag([1.0 / v_max**2, 1.0 / alpha_max**2])
    return q, r


def check_weights(q, r, n: int = 5, m: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Validate ``Q`` (n×n, symmetric PSD) and ``R`` (m×m, symmetric PD); ValueError names them."""
    q = np.asarray(q, dtype=float)
    r = np.asarray(r, dtype=float)
    if q.shape != (n, n):
        raise ValueError(f"Q must have shape ({n}, {n}), got {q.shape}")
    if r.shape != (m, m):
        raise ValueError(f"R must have shape ({m}, {m}), got {r.shape}")
    for name, w in (("Q", q), ("R", r)):
        if not np.all(np.isfinite(w)):
            raise ValueError(f"{name} must be finite, got {w.tolist()!r}")
        if not np.allclose(w, w.T, rtol=1e-12, atol=0.0):
            raise ValueError(f"{name} must be symmetric, got {w.tolist()!r}")
    sq = np.sqrt(np.maximum(np.abs(np.diag(q)), 1e-300))
    ev = np.linalg.eigvalsh(q / np.outer(sq, sq))
    if np.any(np.diag(q) < 0) or ev.min() < -1e-9:
        raise ValueError(f"Q must be positive semidefinite, got diagonal {np.diag(q).tolist()!r}")
    if np.any(np.diag(r) <= 0) or np.linalg.eigvalsh(r).min() <= 0:
        raise ValueError(f"R must be positive definite, got {r.tolist()!r}")
    return q, r


# ---------------------------------------------------------------------------- Riccati
def _state_scale(n: int) -> np.ndarray:
    """Typical magnitudes of (y_f, ẏ_f, y_c, ẏ_c[, x_i]) for the scaled Riccati solves."""
    s = np.array([1e-6, 1e-3, 1e-6, 1e-3, 1e-9])
    return s[:n]


def solve_dare(a, b, q, r, method: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """Stabilising DARE solution ``P`` and LQR gain ``K = (R + BᵀPB)⁻¹ BᵀPA`` (SI in, SI out).

    Parameters
    ----------
    a, b : array_like
        Discrete model (n×n, n×m).
    q, r : array_like
        Weights (n×n PSD, m×m PD).
    method : {"auto", "control", "scipy"}
        ``"control"``: python-control ``dlqr`` (slycot if installed, else scipy inside);
        ``"scipy"``: ``scipy.linalg.solve_discrete_are``; ``"auto"``: python-control if
        importable, else scipy. The equation is solved in scaled coordinates (states in µm,
        mm/s, nm·s) and transformed back.

    Returns
    -------
    P : ndarray (n, n)
    K : ndarray (m, n)
        ``u = −K x`` minimises ``Σ xᵀQx + uᵀRu``.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    n, m = b.shape
    q, r = check_weights(q, r, n, m)
    if method not in ("auto", "control", "scipy"):
        raise ValueError(f"method must be 'auto', 'control' or 'scipy', got {method!r}")
    s = _state_scale(n) if n in (4, 5) else np.ones(n)
    si = 1.0 / s
    a_s = si[:, None] * a * s[None, :]
    b_s = si[:, None] * b
    q_s = s[:, None] * q * s[None, :]
    if method in ("auto", "control"):
        try:
            import control
        except ImportError:  # pragma: no cover - python-control is a dependency
            if method == "control":
                raise
            method = "scipy"
    if method in ("auto", "control"):
        k_s, p_s, _ = control.dlqr(a_s, b_s, q_s, r)
        k_s = np.asarray(k_s)
        p_s = np.asarray(p_s)
    else:
        p_s = sla.solve_discrete_are(a_s, b_s, q_s, r)
        k_s = np.linalg.solve(r + b_s.T @ p_s @ b_s, b_s.T @ p_s @ a_s)
    p = si[:, None] * p_s * si[None, :]
    p = 0.5 * (p + p.T)
    k = k_s * si[None, :]
    return p, k


def kalman_gain(
    model: DesignModel,
    sigma_force: float | None = None,
    sigma_v: float = 0.05,
    sigma_meas: float | None = None,
    plant=None,
) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state Kalman gain of the current estimator for ``model`` (4 states).

    Parameters
    ----------
    model : DesignModel
    sigma_force : float, optional
        Std of the force disturbance on the carriage, N (default: the Coulomb friction force
        of ``plant``, or 31.4 N for the default stepper).
    sigma_v : float
        Std of the input-referred voltage disturbance on the piezo, V.
    sigma_meas : float, optional
        Measurement noise std, m (default: quantisation ``q/√12`` of ``plant``, q = 1.25 nm).
    plant : DualStage, optional
        Source of the defaults (default: the plant ``model`` was designed from).

    Returns
    -------
    M : ndarray, shape (4,)
        Current-estimator gain: ``x̂ = x̄ + M (y − C x̄)``.
    Pk : ndarray, shape (4, 4)
        A-priori error covariance (solution of the filter DARE).
    """
    plant = model.plant if plant is None else plant
    if plant is None:
        raise ValueError("plant: kalman_gain needs the plant (model.plant is None)")
    st = plant.stepper
    if sigma_force is None:
        sigma_force = st.coulomb_torque / st.screw_radius
    sigma_force = positive("sigma_force", sigma_force)
    sigma_v = nonnegative("sigma_v", sigma_v)
    if sigma_meas is None:
        q = plant.resolution if plant.resolution > 0 else 1.25e-9
        sigma_meas = math.sqrt(q * q / 12.0 + plant.noise_rms**2)
    sigma_meas = positive("sigma_meas", sigma_meas)
    h = model.h
    mass = plant.carriage_mass(model.y_c_op)
    g = np.zeros((4, 2))
    g[:, 0] = model.B[:, 0]
    g[2, 1] = 0.5 * h * h / mass
    g[3, 1] = h / mass
    w = g @ np.diag([sigma_v**2, sigma_force**2]) @ g.T
    s = _state_scale(4)
    si = 1.0 / s
    a_s = si[:, None] * model.A * s[None, :]
    c_s = model.C * s[None, :]
    w_s = si[:, None] * w * si[None, :] + 1e-30 * np.eye(4)
    v_s = np.array([[sigma_meas**2]])
    pk_s = sla.solve_discrete_are(a_s.T, c_s.T, w_s, v_s)
    m_s = pk_s @ c_s.T / (c_s @ pk_s @ c_s.T + v_s)[0, 0]
    pk = s[:, None] * pk_s * s[None, :]
    return s * m_s[:, 0], pk


def peak_sensitivity(loop, fs: float, n: int = 3000) -> tuple[float, float]:
    """Peak of ``|1/(1 + L(e^{jωh}))|`` for a discrete SISO loop ``loop`` and its frequency (Hz).

    Evaluated on ``n`` log-spaced frequencies from 0.1 Hz to 0.499 fs (Nyquist).
    """
    f = np.logspace(-1, math.log10(0.499 * fs), int(n))
    resp = loop.frequency_response(2.0 * math.pi * f)
    lz = np.asarray(resp.complex).reshape(-1)
    s = 1.0 / np.abs(1.0 + lz)
    k = int(np.argmax(s))
    return float(s[k]), float(f[k])


def loop_margins(loop, fs: float, n: int = 6000) -> dict:
    """Margins of a discrete SISO loop ``L`` from its frequency response (negative feedback).

    Evaluated on ``n`` log-spaced frequencies from 0.01 Hz to 0.499 fs; crossings are located
    by linear interpolation between grid points.

    Returns
    -------
    dict
        ``crossover_hz`` (first |L| = 1 crossing from below 0.499 fs downwards, i.e. the
        highest), ``phase_margin_deg`` (smallest 180° + ∠L over all |L| = 1 crossings),
        ``gain_margin_db`` (smallest −20 log|L| over phase crossovers with |L| < 1: allowed
        gain increase; ``inf`` if none), ``gain_reduction_margin_db`` (smallest 20 log|L|
        over phase crossovers with |L| > 1: allowed gain decrease, conditionally stable
        loops; ``inf`` if none), ``peak_sensitivity`` (max |1/(1 + L)|) and
        ``peak_sensitivity_hz``.
    """
    f = np.logspace(-2, math.log10(0.499 * fs), int(n))
    lz = np.asarray(loop.frequency_response(2.0 * math.pi * f).complex).reshape(-1)
    mag = np.abs(lz)
    ph = np.unwrap(np.angle(lz))
    out = {}
    lm = np.log(mag)
    idx = np.flatnonzero(np.sign(lm[:-1]) != np.sign(lm[1:]))
    pms = []
    fc = []
    for k in idx:
        t = lm[k] / (lm[k] - lm[k + 1])
        p = ph[k] + t * (ph[k + 1] - ph[k])
        pm = math.degrees((p + math.pi) % (2.0 * math.pi))
        pms.append(pm if pm <= 180.0 else pm - 360.0)
        fc.append(f[k] * (f[k + 1] / f[k]) ** t)
    out["crossover_hz"] = float(max(fc)) if fc else math.nan
    out["phase_margin_deg"] = float(min(pms, key=abs)) if pms else math.inf
    # phase crossovers: ∠L = −180° (mod 360°)
    w = (ph + math.pi) / (2.0 * math.pi)
    cross = np.flatnonzero(np.floor(w[:-1]) != np.floor(w[1:]))
    up, down = [], []
    for k in cross:
        g = -20.0 * math.log10(0.5 * (mag[k] + mag[k + 1]))
        (up if g > 0 else down).append(abs(g))
    out["gain_margin_db"] = float(min(up)) if up else math.inf
    out["gain_reduction_margin_db"] = float(min(down)) if down else math.inf
    s = 1.0 / np.abs(1.0 + lz)
    k = int(np.argmax(s))
    out["peak_sensitivity"] = float(s[k])
    out["peak_sensitivity_hz"] = float(f[k])
    return out


def delay_margin(loop, max_samples: int = 16) -> int:
    """Largest number of extra one-sample delays ``z⁻ᵏ`` the discrete loop tolerates.

    Returns the largest ``k ≤ max_samples`` such that ``L z⁻ʲ/(1 + L z⁻ʲ)`` is stable for every
    ``j ≤ k`` (all closed-loop poles inside the unit circle), −1 if the nominal loop is
    unstable. Models a computation/actuation latency of whole sampling periods.
    """
    import control

    z1 = control.tf([1.0], [1.0, 0.0], dt=loop.dt)
    lk = loop
    out = -1
    for k in range(int(max_samples) + 1):
        if k:
            lk = lk * z1
        if np.max(np.abs(control.poles(control.feedback(lk, 1)))) >= 1.0:
            break
        out = k
    return out


def tune_error_max(
    plant, fs: float, peak_s: float = 1.6, lo: float = 1e-8, hi: float = 1e-4, iters: int = 30
) -> float:
    """Smallest Bryson output-error scale (m) whose LQG loop keeps peak |S| ≤ ``peak_s``.

    Bisection in log scale on ``error_max`` of :func:`default_weights` (the other weights at
    their defaults, observer :func:`kalman_gain` defaults), at the stroke centre. The
    default ``error_max`` of :class:`LQR` was chosen with this function (``peak_s = 1.6``,
    the coordinator's fine-loop robustness constraint, at 8 kHz) — see ``docs/ch6.md``.
    """
    fs = positive("fs", fs)
    peak_s = positive("peak_s", peak_s)
    model = design_model(plant, fs)

    def ok(em):
        ctl = LQR(*default_weights(model, error_max=em))
        ctl.design(plant, fs)
        return ctl.peak_sensitivity()[0] <= peak_s

    if not ok(hi):
        raise ValueError(f"peak_s = {peak_s!r} is not reachable even with error_max = {hi!r} m")
    if ok(lo):
        return lo
    a, b = math.log(lo), math.log(hi)
    for _ in range(int(iters)):
        mid = 0.5 * (a + b)
        if ok(math.exp(mid)):
            b = mid
        else:
            a = mid
    return math.exp(b)


# ---------------------------------------------------------------------------- controller
class LQR:
    """Discrete LQR + integral action + steady-state Kalman observer for the DDL.

    Parameters
    ----------
    Q : array_like, shape (5, 5), optional
        State weight on ``(y_f, ẏ_f, y_c, ẏ_c, x_i)`` in error coordinates (SI). Default:
        :func:`default_weights`.
    R : array_like, shape (2, 2), optional
        Input weight on ``(v, α)`` deviations (1/V², 1/rad²). Default: :func:`default_weights`.
    current : float
        Field amplitude I, A (``i_a = I sin α``, ``i_b = I cos α``).
    max_speed : float
        Rate limit of the field phase as a carriage speed, m/s (as the coordinator: 3 mm/s).
    sigma_force, sigma_v : float, optional
        Kalman process noise (see :func:`kalman_gain`).
    design_plant : DualStage, optional
        Plant whose parameters the design uses (default: the plant given to :meth:`reset`).
    y_c_op : float, optional
        Linearisation carriage position, m (default: the carriage position at reset).
    guard : MeasurementGuard, optional
        Measurement guard (default: a new :class:`.guard.MeasurementGuard` with the plant's
        physical bounds). A rejected measurement is replaced by the observer's
        predicted output (the measurement update is skipped).

    Attributes (after :meth:`reset`)
    --------------------------------
    model : DesignModel
    Q, R : ndarray
        Weights actually used.
    P : ndarray, shape (5, 5)
        Stabilising DARE solution (SI), the terminal cost an MPC with the same weights uses.
    K : ndarray, shape (2, 5)
        ``u − u_ss = −K x_a``.
    M : ndarray, shape (4,)
        Kalman current-estimator gain.
    y_c_hat : float
        Carriage estimate, m (absolute).
    clipped_steps : int
        Steps in which the voltage clipped or the phase was rate-limited.
    guard : MeasurementGuard
        The measurement guard (``guard.rejected``: measurements rejected).
    """

    def __init__(
        self,
        Q=None,
        R=None,
        current: float = 1.5,
        max_speed: float = 3.0e-3,
        sigma_force: float | None = None,
        sigma_v: float = 0.05,
        design_plant=None,
        y_c_op: float | None = None,
        guard: MeasurementGuard | None = None,
    ):
        if (Q is None) != (R is None):
            raise ValueError("give both Q and R, or neither (defaults from default_weights)")
        if Q is not None:
            self._q_in, self._r_in = check_weights(Q, R)
        else:
            self._q_in = self._r_in = None
        self.current = positive("current", current)
        self.max_speed = positive("max_speed", max_speed)
        self.sigma_force = None if sigma_force is None else positive("sigma_force", sigma_force)
        self.sigma_v = nonnegative("sigma_v", sigma_v)
        self.design_plant = design_plant
        self.y_c_op = None if y_c_op is None else finite("y_c_op", y_c_op)
        self.guard = guard_arg(guard)
        self.y_c_hat = 0.0
        self.model = None

    # ------------------------------------------------------------------ design
    def design(self, plant, fs: float, y_c_op: float = 0.0) -> LQR:
        """Compute ``model``, ``Q``, ``R``, ``P``, ``K``, ``M`` for ``plant`` at ``fs`` Hz."""
        dp = plant if self.design_plant is None else self.design_plant
        self.model = model = design_model(dp, fs, y_c_op, self.current)
        if self._q_in is None:
            self.Q, self.R = default_weights(model)
        else:
            self.Q, self.R = self._q_in.copy(), self._r_in.copy()
        self.P, self.K = solve_dare(model.Aa, model.Ba, self.Q, self.R)
        self.M, self.P_kalman = kalman_gain(model, self.sigma_force, self.sigma_v, plant=dp)
        return self

    def closed_loop_matrix(self) -> np.ndarray:
        """Linear closed loop (plant 4 + estimate 4 + integral 1 states) without clipping.

        State ``(x, x̄, x_i)`` with ``x̄`` the a-priori estimate, reference 0. Its eigenvalues
        are those of ``Aa − Ba K`` and of the estimator ``A − A M C`` (separation).
        """
        mo = self.model
        a, b, c = mo.A, mo.B, mo.C
        kx, ki = self.K[:, :4], self.K[:, 4:]
        m = self.M[:, None]
        # x̂ = x̄ + M C (x − x̄);  u = −Kx x̂ − ki x_i
        # x⁺ = A x + B u; x̄⁺ = A x̂ + B u; x_i⁺ = x_i + h C x
        ux = -kx @ (m @ c)  # u coefficient on x
        uxb = -kx @ (np.eye(4) - m @ c)  # on x̄
        uxi = -ki
        big = np.zeros((9, 9))
        big[:4, :4] = a + b @ ux
        big[:4, 4:8] = b @ uxb
        big[:4, 8:] = b @ uxi
        big[4:8, :4] = a @ m @ c + b @ ux
        big[4:8, 4:8] = a @ (np.eye(4) - m @ c) + b @ uxb
        big[4:8, 8:] = b @ uxi
        big[8, :4] = mo.h * c[0]
        big[8, 8] = 1.0
        return big

    def peak_sensitivity(self, n: int = 3000) -> tuple[float, float]:
        """Peak of |S| = 1/|1 + L| over 0.1 Hz – fs/2 (log grid of ``n`` points) and where, Hz."""
        return peak_sensitivity(self.loop_transfer(), self.model.fs, n)

    def report(self) -> dict:
        """Closed-loop stability and loop margins of the design (requires :meth:`design`).

        Returns
        -------
        dict
            :func:`loop_margins` of :meth:`loop_transfer` plus ``delay_margin_samples``
            (:func:`delay_margin`), ``max_pole_modulus`` (largest
            |eigenvalue| of :meth:`closed_loop_matrix`, < 1 = stable),
            ``regulator_poles_hz`` / ``observer_poles_hz`` (slowest equivalent continuous
            pole magnitude ``|ln z|·fs/2π`` of ``Aa − Ba K`` and of the estimator ``A − AMC``).
        """
        if self.model is None:
            raise RuntimeError("call design(plant, fs) or reset(...) before report()")
        mo = self.model
        loop = self.loop_transfer()
        out = loop_margins(loop, mo.fs)
        out["delay_margin_samples"] = delay_margin(loop)
        out["max_pole_modulus"] = float(
            np.max(np.abs(np.linalg.eigvals(self.closed_loop_matrix())))
        )
        reg = np.linalg.eigvals(mo.Aa - mo.Ba @ self.K)
        obs = np.linalg.eigvals(mo.A - mo.A @ self.M[:, None] @ mo.C)

        def slowest(z):
            z = z[np.abs(z) > 1e-12]
            return float(np.min(np.abs(np.log(z))) * mo.fs / (2.0 * math.pi))

        out["regulator_slowest_hz"] = slowest(reg)
        out["observer_slowest_hz"] = slowest(obs)
        return out

    def loop_transfer(self):
        """Discrete loop transfer ``L(z)`` broken at the measurement (python-control TF).

        The controller (observer + gains + integrator, r = 0) maps y to u; the plant maps u to
        y; ``L = −P·C`` so that the closed loop is ``L/(1+L)`` with negative feedback.
        """
        import control

        mo = self.model
        a, b, c = mo.A, mo.B, mo.C
        kx, ki = self.K[:, :4], self.K[:, 4:]
        m = self.M[:, None]
        # controller state (x̄, x_i), input y: x̂ = (I − M C) x̄ + M y
        ac = np.zeros((5, 5))
        bc = np.zeros((5, 1))
        cc = np.zeros((2, 5))
        dc = np.zeros((2, 1))
        imc = np.eye(4) - m @ c
        cc[:, :4] = -kx @ imc
        cc[:, 4:] = -ki
        dc[:, 0] = (-kx @ m)[:, 0]
        ac[:4, :4] = a @ imc + b @ cc[:, :4]
        ac[:4, 4:] = b @ cc[:, 4:]
        bc[:4] = a @ m + b @ dc
        ac[4, 4] = 1.0
        bc[4, 0] = mo.h
        ctrl = control.ss(ac, bc, cc, dc, dt=mo.h)
        plant = control.ss(a, b, c, np.zeros((1, 2)), dt=mo.h)
        return -(plant * ctrl)

    # ------------------------------------------------------------------ interface
    def reset(self, plant, fs: float, y0: float, r0: float) -> None:
        """Design at the carriage position (or ``y_c_op``) and start at rest (see module)."""
        fs = positive("fs", fs)
        y0 = finite("y0", y0)
        r0 = finite("r0", r0)
        y_op = plant.y_c if self.y_c_op is None else self.y_c_op
        self.design(plant, fs, y_op)
        mo = self.model
        fp = plant.fine
        self._vmin = fp.v_min
        self._vmax = fp.v_max
        self._h = mo.h
        self._a = tuple(tuple(float(v) for v in row) for row in mo.A)
        self._b = tuple(tuple(float(v) for v in row) for row in mo.B)
        self._m = tuple(float(v) for v in self.M)
        self._kx = tuple(tuple(float(v) for v in row[:4]) for row in self.K)
        self._ki = tuple(float(row[4]) for row in self.K)
        self._nx = tuple(float(v) for v in mo.Nx)
        self._nu = tuple(float(v) for v in mo.Nu)
        self._y_op = mo.y_op
        self._v_op = mo.v_op
        st = plant.stepper
        self._dmax = self.max_speed / fs * st.pole_pairs / st.screw_radius
        # the field starts where it holds the carriage (plant at rest): α(0) = equilibrium
        self._alpha = plant.equilibrium_phase(self.current)
        self._alpha_op = mo.alpha_op
        # a-priori estimate: at rest where the plant is (deviation from the operating point)
        yf0 = fp.gain * plant.v_applied
        self._xbar = [yf0 - mo.y_f_op, 0.0, y0 - yf0 - mo.y_c_op, 0.0]
        self._xi = 0.0
        self.clipped_steps = 0
        self.y_c_hat = y0 - yf0
        self.guard.reset(plant, fs, y0, r0)

    def _feedback(self, y: float, r: float):
        """Observer update and state feedback of one period (shared with the current-driven
        variant): returns the guarded ``y, r`` (m), the corrected estimate ``x`` (4 values),
        the voltage ``v`` (V, clipped to its range), the coarse input deviation ``u2`` (the
        variant's unit: rad of field phase, or N) and whether ``v`` was clipped."""
        mg = self._m
        x0, x1, x2, x3 = self._xbar
        y, r = self.guard.filter(y, r, self._y_op + x0 + x2)
        innov = (y - self._y_op) - (x0 + x2)
        x0 += mg[0] * innov
        x1 += mg[1] * innov
        x2 += mg[2] * innov
        x3 += mg[3] * innov
        rd = r - self._y_op
        nx = self._nx
        e0 = x0 - nx[0] * rd
        e1 = x1 - nx[1] * rd
        e2 = x2 - nx[2] * rd
        e3 = x3 - nx[3] * rd
        xi = self._xi
        kv, k2 = self._kx
        ki = self._ki
        uv = self._nu[0] * rd - (kv[0] * e0 + kv[1] * e1 + kv[2] * e2 + kv[3] * e3 + ki[0] * xi)
        u2 = self._nu[1] * rd - (k2[0] * e0 + k2[1] * e1 + k2[2] * e2 + k2[3] * e3 + ki[1] * xi)
        # hardware limit: voltage range
        clipped = False
        v = self._v_op + uv
        if v > self._vmax:
            v = self._vmax
            clipped = True
        elif v < self._vmin:
            v = self._vmin
            clipped = True
        return y, r, (x0, x1, x2, x3), v, u2, clipped

    def _predict(self, y: float, r: float, x, v: float, u2: float, clipped: bool) -> None:
        """Integrator (held while an input is clipped) and the observer's prediction with
        the applied inputs ``v`` (V) and ``u2`` (the coarse input deviation)."""
        if clipped:
            self.clipped_steps += 1
        else:
            self._xi = self._xi + self._h * (y - r)
        x0, x1, x2, x3 = x
        uv = v - self._v_op
        a = self._a
        b = self._b
        xb = self._xbar
        xb[0] = a[0][0] * x0 + a[0][1] * x1 + b[0][0] * uv
        xb[1] = a[1][0] * x0 + a[1][1] * x1 + b[1][0] * uv
        xb[2] = a[2][2] * x2 + a[2][3] * x3 + b[2][1] * u2
        xb[3] = a[3][2] * x2 + a[3][3] * x3 + b[3][1] * u2
        self.y_c_hat = x2 + self.model.y_c_op

    def step(self, y: float, r: float) -> tuple[float, float, float]:
        """One period: measured output ``y`` (m), reference ``r`` (m) → (V, A, A)."""
        y, r, x, v, ua, clipped = self._feedback(y, r)
        # hardware limit: phase rate
        alpha = self._alpha_op + ua
        d = alpha - self._alpha
        dmax = self._dmax
        if d > dmax:
            alpha = self._alpha + dmax
            clipped = True
        elif d < -dmax:
            alpha = self._alpha - dmax
            clipped = True
        self._alpha = alpha
        self._predict(y, r, x, v, alpha - self._alpha_op, clipped)
        cur = self.current
        return v, cur * math.sin(alpha), cur * math.cos(alpha)
