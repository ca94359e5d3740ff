"""The IEEJ hard-disk-drive dual-stage benchmark: loader, plant cases and its own evaluation.

The numbers come from a data directory (``plant.npz``, ``disturbance.npz``,
``reference_controller.npz``, with its README and licence note; the project keeps a copy in
``shared/data/hdd``): a voice-coil motor (VCM, 16 modes) and a piezo micro-actuator (PZT,
8 modes, 50 nm stroke), controller period ``Ts = 19.841 µs``, multirate filters at ``Ts/2``,
nine plant cases (resonance frequencies ×1.04/1/0.96 of the VCM and ×1.06/1/0.94 of the PZT,
damping ×0.8/1/1.2, PZT gain ×1/1.05/0.95), and the disturbances: repeatable run-out
``d_RRO`` (420 samples per revolution, one per ``Ts``), the RV filter ``d_f`` at the VCM input
and 13 fan-vibration modes ``d_p`` at the output, each driven by uniform noise from its own
seed held over ``Tsc = Ts/20``.

Evaluation (the benchmark's user manual, p. 20), as :func:`evaluate` does it: the plant
emulated at ``Tsc`` with a zero-order hold; the feedback controller ``C_d`` at ``Ts`` on
``e = −y_c(nTs) + d_RRO(n)``, no computation delay; the multirate filters ``F_m`` at ``Ts/2``
with their input held over ``Ts`` and their output held over ``Ts/2`` into the actuators;
``d_f`` added at the VCM input and ``d_p`` at the output at every ``Tsc``; 1.1 s simulated,
the window ``t ≥ 0.1 s`` for 120 revolutions; reported: ``3σ = 3 std(y_c)`` (N − 1) in % of
the track pitch and ``max |y_cp|`` (the PZT's displacement) in m.

Reproduction: the reference controller (:func:`reference_controller` with the benchmark's
``F_m``) gives the published 3σ on every case to within 0.005 %-points (case 9, the worst:
14.544 % against 14.54 %) and max |y_cp| to within 0.005 nm. The RV filter is run as a sum of
exactly discretised first-order modes: its discrete transfer-function polynomials (a pole at
3 Hz, ``1 − 2·10⁻⁵`` from 1 at ``Tsc``) lose ``d_f`` to cancellation (6 % off, which put every
3σ 0.04 %-points high). ``python examples/hdd_benchmark.py`` prints the table.

How it is computed (linearity): the disturbances' response through the open plant is
computed at ``Tsc`` once (``lfilter`` per mode); the loop runs at ``Ts`` with the plant lifted
over one period (its input changes at the two half periods); the control's response at every
``Tsc`` is then filtered through the plant's modes and added.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import signal
from scipy.linalg import expm

__all__ = [
    "HddBenchmark",
    "load",
    "CASES",
    "evaluate",
    "evaluate_cases",
    "reference_controller",
    "PUBLISHED_SIGMA3",
    "design_controller",
    "reduced_controller",
    "REDUCED_ORDER",
    "disturbances",
    "linear_plant",
]

CASES = tuple(range(1, 10))
#: The reference controller's published 3σ per case (% of track pitch; data README).
PUBLISHED_SIGMA3 = (13.51, 13.18, 14.08, 13.17, 12.81, 13.67, 13.88, 13.59, 14.54)


def _arr(d, key: str, path: Path) -> np.ndarray:
    if key not in d.files:
        raise ValueError(f"{path} has no array {key!r}")
    a = np.asarray(d[key])
    if a.dtype.kind in "fc" and not np.all(np.isfinite(a)):
        raise ValueError(f"{path}: {key!r} is not finite")
    return a


@dataclass(frozen=True)
class HddBenchmark:
    """The benchmark's numbers (SI units), see :func:`load`."""

    Ts: float
    mr_filter: int
    mr_plant: int
    track_pitch: float
    pzt_stroke: float
    kp_vcm: float
    vcm_hz: np.ndarray
    vcm_kappa: np.ndarray
    vcm_zeta: np.ndarray
    pzt_hz: np.ndarray
    pzt_kappa: np.ndarray
    pzt_zeta: np.ndarray
    case_freq_vcm: np.ndarray
    case_freq_pzt: np.ndarray
    case_damp: np.ndarray
    case_gain_pzt: np.ndarray
    rro: np.ndarray
    dp_hz: np.ndarray
    dp_zeta: np.ndarray
    dp_gain: np.ndarray
    rv_num: np.ndarray
    rv_den: np.ndarray
    seed_df: int
    seeds_dp: np.ndarray
    t_sim: float
    t_transient: float
    n_rev: int
    reference: dict

    @property
    def Tsc(self) -> float:
        """Plant emulation period ``Ts / mr_plant``, s."""
        return self.Ts / self.mr_plant

    @property
    def samples_per_rev(self) -> int:
        """Controller samples per revolution (servo sectors)."""
        return self.rro.size

    def vcm(self, case: int):
        """Continuous modal model of the VCM for ``case`` (1–9): ``(A, B, C)``, input the VCM
        command, output m; modes ``κ_i K_p / (s² + 2ζ_i ω_i s + ω_i²)`` with the case's
        frequency and damping factors (the numerator is not rescaled, as the benchmark)."""
        i = _case(case)
        w = 2.0 * math.pi * self.vcm_hz * self.case_freq_vcm[i]
        z = self.vcm_zeta * self.case_damp[i]
        return _modal(w, z, self.vcm_kappa * self.kp_vcm)

    def pzt(self, case: int):
        """Continuous modal model of the PZT for ``case``: ``(A, B, C)``, input m, output m;
        normalised to a static gain of ``case_gain_pzt`` (1, 1.05 or 0.95)."""
        i = _case(case)
        w = 2.0 * math.pi * self.pzt_hz * self.case_freq_pzt[i]
        z = self.pzt_zeta * self.case_damp[i]
        g0 = abs(float(np.sum(self.pzt_kappa / (w * w))))
        return _modal(w, z, self.pzt_kappa / g0 * self.case_gain_pzt[i])


def _case(case: int) -> int:
    if int(case) != case or not 1 <= case <= 9:
        raise ValueError(f"case must be an integer 1..9, got {case!r}")
    return int(case) - 1


def _modal(w, z, num):
    """Block-diagonal ``Σ num_i/(s² + 2 z_i w_i s + w_i²)``: states (position, velocity)."""
    n = 2 * w.size
    a = np.zeros((n, n))
    b = np.zeros((n, 1))
    c = np.zeros((1, n))
    for i, (wi, zi, ni) in enumerate(zip(w, z, num, strict=True)):
        a[2 * i, 2 * i + 1] = 1.0
        a[2 * i + 1, 2 * i] = -wi * wi
        a[2 * i + 1, 2 * i + 1] = -2.0 * zi * wi
        b[2 * i + 1, 0] = ni
        c[0, 2 * i] = 1.0
    return a, b, c


def load(data_dir) -> HddBenchmark:
    """Read the benchmark's three ``.npz`` files from ``data_dir``.

    Raises ValueError naming the file and key when one is missing or not finite.
    """
    root = Path(data_dir)
    if not root.is_dir():
        raise ValueError(f"data_dir {str(root)!r} is not a directory")
    files = {}
    for name in ("plant", "disturbance", "reference_controller"):
        path = root / f"{name}.npz"
        if not path.is_file():
            raise ValueError(f"{path} is missing (the HDD benchmark's data directory?)")
        files[name] = (np.load(path, allow_pickle=False), path)
    (p, pp), (d, dp), (r, rp) = files["plant"], files["disturbance"], files["reference_controller"]
    ref = {}
    for nm in ("Cd_vcm", "Cd_pzt", "Fm_vcm", "Fm_pzt"):
        ref[nm] = tuple(_arr(r, f"{nm}_{k}", rp) for k in ("A", "B", "C", "D", "Ts"))
    return HddBenchmark(
        Ts=float(_arr(p, "Ts", pp)),
        mr_filter=int(_arr(p, "Mr_f", pp)),
        mr_plant=int(_arr(p, "Mr_p", pp)),
        track_pitch=float(_arr(p, "track_pitch", pp)),
        pzt_stroke=float(_arr(p, "pzt_stroke", pp)),
        kp_vcm=float(_arr(p, "Kp_vcm", pp)),
        vcm_hz=_arr(p, "omega_vcm_hz", pp).astype(float),
        vcm_kappa=_arr(p, "kappa_vcm", pp).astype(float),
        vcm_zeta=_arr(p, "zeta_vcm", pp).astype(float),
        pzt_hz=_arr(p, "omega_pzt_hz", pp).astype(float),
        pzt_kappa=_arr(p, "kappa_pzt", pp).astype(float),
        pzt_zeta=_arr(p, "zeta_pzt", pp).astype(float),
        case_freq_vcm=_arr(p, "case_freq_vcm", pp).astype(float),
        case_freq_pzt=_arr(p, "case_freq_pzt", pp).astype(float),
        case_damp=_arr(p, "case_damp", pp).astype(float),
        case_gain_pzt=_arr(p, "case_gain_pzt", pp).astype(float),
        rro=_arr(d, "rro", dp).astype(float),
        dp_hz=_arr(d, "dp_freq_hz", dp).astype(float),
        dp_zeta=_arr(d, "dp_zeta", dp).astype(float),
        dp_gain=_arr(d, "dp_gain", dp).astype(float),
        rv_num=_arr(d, "rv_num", dp).astype(float),
        rv_den=_arr(d, "rv_den", dp).astype(float),
        seed_df=int(_arr(d, "seed_df", dp)),
        seeds_dp=_arr(d, "seeds_dp", dp).astype(int),
        t_sim=float(_arr(d, "Tsim", dp)),
        t_transient=float(_arr(d, "t_transient", dp)),
        n_rev=int(_arr(d, "n_rev_eval", dp)),
        reference=ref,
    )


def reference_controller(bench: HddBenchmark):
    """The benchmark's example feedback controller ``C_d`` as one system at ``Ts``:
    ``(A, B, C, D, Ts)`` from ``e`` (m) to ``(u_dv, u_dp)`` (block diagonal)."""
    av, bv, cv, dv, _ = bench.reference["Cd_vcm"]
    ap, bp, cp, dp, _ = bench.reference["Cd_pzt"]
    return _stack_siso((av, bv, cv, dv), (ap, bp, cp, dp)) + (bench.Ts,)


def _stack_siso(s1, s2):
    a1, b1, c1, d1 = (np.atleast_2d(x) for x in s1)
    a2, b2, c2, d2 = (np.atleast_2d(x) for x in s2)
    n1, n2 = a1.shape[0], a2.shape[0]
    a = np.zeros((n1 + n2, n1 + n2))
    a[:n1, :n1] = a1
    a[n1:, n1:] = a2
    b = np.vstack((b1, b2))
    c = np.zeros((2, n1 + n2))
    c[0, :n1] = c1
    c[1, n1:] = c2
    d = np.vstack((d1, d2))
    return a, b, c, d


def _noise(seed: int, n: int) -> np.ndarray:
    """The benchmark's noise: MT19937 ``rand(n) − 0.5`` (numpy's legacy RandomState)."""
    return np.random.RandomState(int(seed)).rand(n) - 0.5


def _zoh_tf(num, den, h: float):
    b, a, _ = signal.cont2discrete((np.atleast_1d(num), np.atleast_1d(den)), h, method="zoh")
    return np.atleast_1d(np.squeeze(b)), np.atleast_1d(np.squeeze(a))


def _modal_filter(w, z, num, x, h: float) -> np.ndarray:
    """Response of ``Σ num_i/(s² + 2 z_i w_i s + w_i²)`` to ``x`` held over ``h``."""
    y = np.zeros_like(x)
    for wi, zi, ni in zip(w, z, num, strict=True):
        b, a = _zoh_tf([ni], [1.0, 2.0 * zi * wi, wi * wi], h)
        y += signal.lfilter(b, a, x)
    return y


def _zoh_modes(num, den, x, h: float) -> np.ndarray:
    """Response of the strictly proper ``num/den`` (distinct poles) to ``x`` held over ``h``,
    as a sum of first-order modes ``r_i/(s − p_i)``, each discretised exactly.

    The RV filter's discrete transfer function has a pole at 3 Hz, ``1 − 2·10⁻⁵`` from 1 at
    ``Tsc``: its polynomial coefficients lose the response to cancellation (``lfilter`` on them
    is 6 % off), while each mode's recursion ``x ← e^{p h} x + (e^{p h} − 1)/p · u`` is exact
    to rounding."""
    r, p, k = signal.residue(num, den)
    if np.size(k) and np.any(np.asarray(k) != 0.0):
        raise ValueError("the filter must be strictly proper")
    y = np.zeros(x.size, dtype=complex)
    for ri, pi in zip(r, p, strict=True):
        lam = np.exp(pi * h)
        y += ri * (lam - 1.0) / pi * signal.lfilter([0.0, 1.0], [1.0, -lam], x.astype(complex))
    return y.real


@dataclass(frozen=True)
class Disturbances:
    """The exogenous signals of one run at ``Tsc`` (m): ``y_dist`` = response of the open
    plant to ``d_f`` plus ``d_p`` (output), and ``rro`` at ``Ts``."""

    y_dist: np.ndarray
    rro: np.ndarray


def disturbances(
    bench: HddBenchmark, case: int, t_sim: float | None = None, *, seeds=None
) -> Disturbances:
    """The disturbances of a run of ``t_sim`` s (default the benchmark's 1.1 s) on ``case``:
    noise length ``round(1.1 s/Tsc) + 1`` cut to the run, from the benchmark's seeds or from
    ``seeds`` (14 integers: ``w_1`` then the 13 fan modes' — fresh references for a design
    that must not see the evaluation's)."""
    i = _case(case)
    tsc = bench.Tsc
    n_full = int(round(bench.t_sim / tsc)) + 1
    t_sim = bench.t_sim if t_sim is None else float(t_sim)
    if not 0.0 < t_sim <= bench.t_sim:
        raise ValueError(f"t_sim must be in (0, {bench.t_sim}] s, got {t_sim!r}")
    n = int(round(t_sim / tsc)) + 1
    # RV: d_f = rv(s) w_1 without its feed-through, at the VCM input
    num, den = bench.rv_num, bench.rv_den
    d0 = num[0] / den[0] if num.size == den.size else 0.0
    num_sp = np.trim_zeros(num - d0 * den, "f") if d0 else num
    if seeds is None:
        seeds = (bench.seed_df, *bench.seeds_dp)
    seeds = [int(x) for x in seeds]
    if len(seeds) != 1 + bench.seeds_dp.size:
        raise ValueError(f"seeds must be {1 + bench.seeds_dp.size} integers, got {len(seeds)}")
    d_f = _zoh_modes(num_sp, den, _noise(seeds[0], n_full)[:n], tsc)
    w = 2.0 * math.pi * bench.vcm_hz * bench.case_freq_vcm[i]
    z = bench.vcm_zeta * bench.case_damp[i]
    y = _modal_filter(w, z, bench.vcm_kappa * bench.kp_vcm, d_f, tsc)
    for g, f, zt, seed in zip(bench.dp_gain, bench.dp_hz, bench.dp_zeta, seeds[1:], strict=True):
        wk = 2.0 * math.pi * f
        bk, ak = _zoh_tf([g], [1.0, 2.0 * zt * wk, wk * wk], tsc)
        y += signal.lfilter(bk, ak, _noise(seed, n_full)[:n])
    n_ts = int(math.ceil(n / bench.mr_plant)) + 1
    rro = np.resize(bench.rro, n_ts)
    return Disturbances(y_dist=y, rro=rro)


def _lift_filter(fm, mr: int):
    """A filter at ``Ts/mr`` with its input held over ``Ts``: matrices giving its ``mr``
    outputs within the period and its state at the next period from (state, input)."""
    a, b, c, d = (np.atleast_2d(np.asarray(x, dtype=float)) for x in fm[:4])
    n = a.shape[0]
    outs_x, outs_u = [], []
    ax, bu = np.eye(n), np.zeros((n, 1))
    for _ in range(mr):
        outs_x.append(c @ ax)
        outs_u.append(c @ bu + d)
        ax, bu = a @ ax, a @ bu + b
    return np.vstack(outs_x), np.vstack(outs_u), ax, bu


def evaluate(
    bench: HddBenchmark,
    controller,
    case: int,
    *,
    filters="reference",
    t_sim: float | None = None,
    t_start: float | None = None,
    n_rev: int | None = None,
    dist: Disturbances | None = None,
) -> dict:
    """The benchmark's evaluation of a linear controller on ``case``.

    Parameters
    ----------
    bench : HddBenchmark
    controller : tuple
        ``(A, B, C, D, Ts)``: discrete at the benchmark's ``Ts`` from ``e`` (m) to
        ``(u_dv, u_dp)`` (``C`` 2 rows, ``D`` 2 × 1) — the feedback controller ``C_d``.
    case : int
        Plant case 1–9.
    filters : "reference" or None or pair
        The multirate filters ``F_m`` between ``C_d`` and the actuators: the benchmark's
        (``"reference"``), none (``None``: ``u_d`` held over ``Ts``), or a pair of
        ``(A, B, C, D, dt)`` at ``Ts/M``.
    t_sim, t_start, n_rev : optional
        Run length and window (defaults: the benchmark's 1.1 s, 0.1 s, 120 revolutions);
        shorter ones for quick checks.
    dist : Disturbances, optional
        Precomputed :func:`disturbances` for this case and run length.

    Returns
    -------
    dict
        ``sigma3_pct`` (3 std(y_c) in % of the track pitch), ``sigma3`` (m), ``pzt_max``
        (max |y_cp| in the window, m), ``pzt_ok`` (``pzt_max < pzt_stroke``), ``e`` (the
        measured error at ``Ts``, whole run), ``y_c`` (head position at every ``Tsc``, whole
        run, m), ``window`` (the slice of ``y_c`` evaluated).
    """
    ak, bk, ck, dk, tk = controller
    ak, bk, ck, dk = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (ak, bk, ck, dk))
    if ck.shape[0] != 2 or dk.shape != (2, 1) or bk.shape[1] != 1:
        raise ValueError(f"controller must map e to 2 outputs (C 2 rows, D 2x1), got C {ck.shape}")
    if abs(float(tk) - bench.Ts) > 1e-9 * bench.Ts:
        raise ValueError(f"controller Ts = {tk!r} s is not the benchmark's {bench.Ts!r} s")
    for nm, x in (("A", ak), ("B", bk), ("C", ck), ("D", dk)):
        if not np.all(np.isfinite(x)):
            raise ValueError(f"controller {nm} is not finite")
    t_sim = bench.t_sim if t_sim is None else float(t_sim)
    t_start = bench.t_transient if t_start is None else float(t_start)
    n_rev = bench.n_rev if n_rev is None else int(n_rev)
    mrp = bench.mr_plant
    tsc = bench.Tsc
    if filters == "reference":
        filters = (bench.reference["Fm_vcm"], bench.reference["Fm_pzt"])
    if filters is None:
        mrf = 1
        flt = [(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.ones((1, 1)))] * 2
    else:
        mrf = int(round(bench.Ts / float(filters[0][4])))
        flt = [tuple(np.atleast_2d(np.asarray(x, dtype=float)) for x in f[:4]) for f in filters]
    if mrp % mrf:
        raise ValueError(f"filter rate Ts/{mrf} does not divide the plant rate Ts/{mrp}")
    hold = mrp // mrf  # plant samples per filter output
    if dist is None:
        dist = disturbances(bench, case, t_sim)
    n_tsc = dist.y_dist.size
    n_ts = (n_tsc - 1) // mrp + 1
    # plant lifted over one filter period and over Ts (input piecewise constant per filter
    # output); VCM and PZT block diagonal
    av, bv, cv = bench.vcm(case)
    ap, bp, cp = bench.pzt(case)
    nv, npz = av.shape[0], ap.shape[0]
    a = np.zeros((nv + npz, nv + npz))
    a[:nv, :nv], a[nv:, nv:] = av, ap
    b = np.zeros((nv + npz, 2))
    b[:nv, 0:1], b[nv:, 1:2] = bv, bp
    c = np.hstack((cv, cp))
    h = tsc * hold
    blk = np.zeros((nv + npz + 2, nv + npz + 2))
    blk[: nv + npz, : nv + npz] = a * h
    blk[: nv + npz, nv + npz :] = b * h
    e = expm(blk)
    phi_h, gam_h = e[: nv + npz, : nv + npz], e[: nv + npz, nv + npz :]
    # filters lifted over Ts: outputs within the period from (x_f, u_d)
    lv = _lift_filter(flt[0], mrf)
    lp = _lift_filter(flt[1], mrf)
    nfv, nfp, nk = flt[0][0].shape[0], flt[1][0].shape[0], ak.shape[0]
    npl = nv + npz
    # closed loop at Ts: z = (x_p, x_fv, x_fp, x_k), inputs w = (y_dist(nTs), rro(n))
    nz = npl + nfv + nfp + nk
    sp, sv, sq, sk = (
        slice(0, npl),
        slice(npl, npl + nfv),
        slice(npl + nfv, npl + nfv + nfp),
        slice(npl + nfv + nfp, nz),
    )
    ez = np.zeros((1, nz))
    ez[0, sp] = -c[0]
    ew = np.array([[-1.0, 1.0]])
    uz = dk @ ez
    uz[:, sk] += ck
    uw = dk @ ew
    # filter outputs (mrf per actuator) as maps of (z, w)
    ov_z = lv[0] @ np.eye(nz)[sv] + lv[1] @ uz[0:1] if nfv else lv[1] @ uz[0:1]
    ov_w = lv[1] @ uw[0:1]
    op_z = lp[0] @ np.eye(nz)[sq] + lp[1] @ uz[1:2] if nfp else lp[1] @ uz[1:2]
    op_w = lp[1] @ uw[1:2]
    acl = np.zeros((nz, nz))
    bcl = np.zeros((nz, 2))
    pz = np.eye(nz)[sp]
    pw = np.zeros((npl, 2))
    for j in range(mrf):
        inp_z = np.vstack((ov_z[j], op_z[j]))
        inp_w = np.vstack((ov_w[j], op_w[j]))
        pz = phi_h @ pz + gam_h @ inp_z
        pw = phi_h @ pw + gam_h @ inp_w
    acl[sp], bcl[sp] = pz, pw
    if nfv:
        acl[sv] = lv[2] @ np.eye(nz)[sv] + lv[3] @ uz[0:1]
        bcl[sv] = lv[3] @ uw[0:1]
    if nfp:
        acl[sq] = lp[2] @ np.eye(nz)[sq] + lp[3] @ uz[1:2]
        bcl[sq] = lp[3] @ uw[1:2]
    acl[sk] = bk @ ez
    acl[sk, sk] += ak
    bcl[sk] = bk @ ew
    outz = np.vstack((ov_z, op_z, ez))
    outw = np.vstack((ov_w, op_w, ew))
    wseq = np.column_stack((dist.y_dist[::mrp][:n_ts], dist.rro[:n_ts]))
    zs = np.zeros((n_ts, nz))
    zk = np.zeros(nz)
    if np.max(np.abs(np.linalg.eigvals(acl))) >= 1.0:
        raise ValueError(
            f"the controller does not stabilise case {case} "
            "(a closed-loop pole on or outside the unit circle)"
        )
    for k in range(n_ts):
        zs[k] = zk
        zk = acl @ zk + bcl @ wseq[k]
    outs = zs @ outz.T + wseq @ outw.T  # (n_ts, 2 mrf + 1)
    e_ts = outs[:, -1]
    u_v = np.repeat(outs[:, :mrf].ravel(), hold)[:n_tsc]
    u_p = np.repeat(outs[:, mrf : 2 * mrf].ravel(), hold)[:n_tsc]
    i = _case(case)
    wv = 2.0 * math.pi * bench.vcm_hz * bench.case_freq_vcm[i]
    zv = bench.vcm_zeta * bench.case_damp[i]
    y_v = _modal_filter(wv, zv, bench.vcm_kappa * bench.kp_vcm, u_v, tsc)
    wp = 2.0 * math.pi * bench.pzt_hz * bench.case_freq_pzt[i]
    zp = bench.pzt_zeta * bench.case_damp[i]
    g0 = abs(float(np.sum(bench.pzt_kappa / (wp * wp))))
    y_p = _modal_filter(wp, zp, bench.pzt_kappa / g0 * bench.case_gain_pzt[i], u_p, tsc)
    y_c = y_v + y_p + dist.y_dist
    k0 = int(round(t_start / tsc))
    k1 = k0 + n_rev * bench.samples_per_rev * mrp
    if k1 > n_tsc:
        raise ValueError(
            f"the window ({t_start} s + {n_rev} revolutions) does not fit in {t_sim} s"
        )
    win = y_c[k0:k1]
    s3 = 3.0 * float(np.std(win, ddof=1))
    pzt_max = float(np.max(np.abs(y_p[k0:k1])))
    return {
        "sigma3": s3,
        "sigma3_pct": 100.0 * s3 / bench.track_pitch,
        "pzt_max": pzt_max,
        "pzt_ok": pzt_max < bench.pzt_stroke,
        "e": e_ts,
        "y_c": y_c,
        "window": slice(k0, k1),
        "loop_check": float(
            np.max(np.abs(y_c[: n_ts * mrp : mrp][: e_ts.size] + e_ts - dist.rro[: e_ts.size]))
        ),
    }


def evaluate_cases(bench: HddBenchmark, controller, cases=CASES, **kwargs) -> list[dict]:
    """:func:`evaluate` on each case (the 9 by default)."""
    return [dict(evaluate(bench, controller, c, **kwargs), case=c) for c in cases]


def linear_plant(bench: HddBenchmark, case: int = 2, *, disturbance_models: bool = True):
    """The benchmark's plant ``case`` as a :class:`~qpcoord.ddl.LinearDualStage` at ``Ts``.

    Coarse: the VCM behind the benchmark's multirate filter ``F_mv`` (at ``Ts/2``, input held
    over ``Ts``); fine: the PZT behind ``F_mp``; PZT stroke ±``pzt_stroke``. With
    ``disturbance_models``, the benchmark's disturbance generators (not its seeds): the RV
    filter at the VCM input (feed-through dropped) and the 13 fan modes at the output, each
    driven by white noise of the benchmark's variance (1/12, held over ``Tsc``) expressed at
    ``Ts`` (same power spectral density: variance ``1/12 · Tsc/Ts``). The repeatable
    run-out is not modelled.
    """
    from ..linear_plant import Disturbance, LinearDualStage

    av, bv, cv = bench.vcm(case)
    ap, bp, cp = bench.pzt(case)
    z = np.zeros((1, 1))
    dist = []
    if disturbance_models:
        var = (1.0 / 12.0) * bench.Tsc / bench.Ts
        num, den = bench.rv_num, bench.rv_den
        d0 = num[0] / den[0] if num.size == den.size else 0.0
        num_sp = np.trim_zeros(num - d0 * den, "f") if d0 else num
        dist.append(Disturbance(_tf_ss(num_sp, den), "coarse", var, "RV"))
        for k, (g, f, zt) in enumerate(zip(bench.dp_gain, bench.dp_hz, bench.dp_zeta, strict=True)):
            w = 2.0 * math.pi * f
            dist.append(
                Disturbance(_tf_ss([g], [1.0, 2.0 * zt * w, w * w]), "output", var, f"fan {k + 1}")
            )
    fv, fp = bench.reference["Fm_vcm"], bench.reference["Fm_pzt"]
    return LinearDualStage(
        (av, bv, cv, z),
        (ap, bp, cp, z),
        bench.Ts,
        coarse_filter=tuple(np.atleast_2d(x) for x in fv[:4]) + (float(fv[4]),),
        fine_filter=tuple(np.atleast_2d(x) for x in fp[:4]) + (float(fp[4]),),
        fine_stroke=(-bench.pzt_stroke, bench.pzt_stroke),
        coarse_stroke=1.0,
        disturbances=dist,
        name=f"HDD case {case}",
    )


def _tf_ss(num, den):
    a, b, c, d = signal.tf2ss(np.atleast_1d(num), np.atleast_1d(den))
    return a, b, c, d


#: Order of :func:`reduced_controller`: the lowest balanced truncation of
#: :func:`design_controller`'s law (111 states) that keeps every spec item on fresh
#: disturbances (seeds 1001–1014, 0.3 s windows, case 7, the worst): 33 states give 6.70 %
#: (the full law 6.75 %), peak |S| 5.08 dB and a stable loop on the nine cases; 32 states give
#: a 24 dB peak, 31 a 7.7 dB one, 28 and fewer an unstable loop.
REDUCED_ORDER = 33


def design_controller(
    bench: HddBenchmark,
    *,
    case: int = 3,
    error_scale: float = 1e-9,
    coarse_input_scale: float = 1e-7,
    fine_input_scale: float = 5e-8,
    fine_scale: float = 5e-8,
    input_noise: float = 1e-4,
):
    """An LQG for the benchmark, designed from its models only (no evaluation seed).

    :class:`~qpcoord.ddl.LQG` on :func:`linear_plant` of ``case`` with the disturbance
    generators; its measurement noise is the fastest keeping the peak sensitivity ≤ 6 dB and
    the loop stable on all nine cases (``robust_plants``). The case and the scales (m, VCM
    input units, m, m) were chosen on fresh disturbances (seeds 1001–1014; 0.3 s windows):
    worst over the nine cases 6.75 % designed on case 3 (high temperature: lowest
    resonances, most damping), 6.79 % on case 9; on cases 3, 8 and 9 only, 6.94 % on the
    nominal case 2 and 7.11 % on case 4; a PZT given more room (``fine_scale`` and
    ``fine_input_scale`` 1e-7: 7.18 %), a cheaper VCM (``coarse_input_scale`` 2e-7:
    7.45 %) and a weaker input noise (1e-5: no change) did not help. Takes about 30 s;
    order: the plant's 111 states (VCM 32, F_mv 24, PZT 16, F_mp 10, RV 3, fan modes 26);
    :func:`reduced_controller` brings it to :data:`REDUCED_ORDER`.
    """
    from ..lqg import LQG

    plant = linear_plant(bench, case)
    others = [linear_plant(bench, c, disturbance_models=False) for c in CASES if c != case]
    return LQG(
        plant,
        error_scale=error_scale,
        coarse_input_scale=coarse_input_scale,
        fine_input_scale=fine_input_scale,
        fine_scale=fine_scale,
        input_noise=input_noise,
        robust_plants=others,
    )


def reduced_controller(law, order: int = REDUCED_ORDER):
    """``law``'s state-space form (:meth:`~qpcoord.ddl.LQG.state_space`) reduced to ``order``
    states by balanced truncation, with the error and the two commands in the units of the
    law's scales (``error``, ``coarse_input``, ``fine_input``): ``(A, B, C, D, Ts)``.

    Check the result on every case (:func:`~qpcoord.ddl.lqg.closed_loop_poles`,
    :func:`~qpcoord.ddl.sensitivity`, :func:`evaluate`): a truncation can lose stability
    (see :data:`REDUCED_ORDER`)."""
    from ..reduce import balanced_truncation

    sc = law.scales
    red, _ = balanced_truncation(
        law.state_space(), order, sc["error"], [sc["coarse_input"], sc["fine_input"]]
    )
    return red
