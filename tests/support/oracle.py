"""Reference lexicographic solver for the tests (cvxpy + Clarabel; never used by qpcoord).

``lexicographic(levels, bounds, constraints)`` solves a prioritised stack the slow, obvious
way, one conic solve per level, and returns the per-level residuals with the same
definition as :attr:`qpcoord.Solution.level_residuals`::

    r_k = √( Σ_eq ‖√w (A x − b)‖² + Σ_ineq ‖√w · (C x − clip(C x, lower, upper))‖² )

Formulation (``mode="pin"``, the default)
-----------------------------------------
Level ``k`` is ``minimise ‖A_k x − b_k‖² + ‖s_k ∘ v_k‖²`` over ``(x, v_k)`` subject to
``lower_k ≤ C_k x − v_k ≤ upper_k`` (rows already multiplied by ``√w``, ``s_k = √w``), the
bounds, the hard constraints and everything the levels above fixed. The objective is
strictly convex in ``(A_k x, v_k)`` and the feasible set of ``(A_k x, v_k)`` is convex, so
its optimal value ``(u_k*, v_k*)`` is unique, although the optimal ``x`` need not be. Hence
the optimal set of level ``k`` is exactly

    S_k = S_{k-1} ∩ {A_k x = u_k*} ∩ {C_i x = c_i* for rows with v_i* ≠ 0}
                  ∩ {lower_i ≤ C_i x ≤ upper_i for rows with v_i* = 0}

(a violated row is pinned at its optimal value: any other value of ``C_i x`` would change
``v_i``). The equality parts are imposed as ``E x = E x_k*`` with ``E`` an orthonormal basis of
the row space of every row pinned so far (hard equalities included) and ``x_k*`` the
level-``k`` optimum. Writing ``A_k x == u_k*`` level by level would be just as valid in exact
arithmetic (``u_k*`` is unique, inequalities or not), but it stacks redundant equalities
(duplicate rows, rows shared between levels) whose right-hand sides agree only to the
solver's accuracy, which interior-point solvers handle badly; ``E x = E x_k*`` is consistent
by construction. The kept inequality rows are relaxed by exactly what ``x_k*`` misses them
by (~1e-12), so every later problem is feasible by construction too. Sensitivity to the
solver's error ``ε`` is *linear*: the pinned values move by ``ε`` and the later levels by
``ε`` times the conditioning of the pinned rows (≤ ~1e4 in the tests).

Finally ``‖x‖²`` is minimised over ``S_last``; that point is unique. The final residuals
must reproduce every level's own optimum to ``SELF_CHECK`` or :class:`OracleError` is raised.

``mode="epigraph"``: the textbook alternative, kept to cross-check the pinning logic. Every
level above keeps its slack variables and the constraint ``r_j(x, v_j) ≤ r_j* + τ(1 + r_j*)``
(``r`` the residual norm). It needs no classification of violated rows, but

* its sensitivity is only *square-root*: at an optimum with ``r_j* > 0`` the residual grows
  quadratically away from the optimal set, so ``τ`` lets x move by ``√(2τ r_j*)/σ`` and the
  lower levels gain up to that much (measured: 1e-4 … 3e-3 in x for ``τ = 1e-9 … 1e-8``);
* those constraints touch the optimal set tangentially, and Clarabel often stops short
  (``AlmostSolved``/``InsufficientProgress``) even at ``τ = 1e-9`` and tolerances 1e-9.

Useless as a 1e-6 reference, hence ``"pin"``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import cvxpy as cp
import numpy as np

import qpcoord as qc

__all__ = ["OracleResult", "lexicographic", "level_residuals", "OracleError"]

#: Clarabel settings: far tighter than the 1e-6 the tests ask for (``tol_feas`` 1e-12 is
#: out of reach on the cond-1e4 stacks: Clarabel stalls at ~2e-12 and says AlmostSolved).
CLARABEL = dict(
    tol_gap_abs=1e-12,
    tol_gap_rel=1e-12,
    tol_feas=1e-11,
    tol_ktratio=1e-10,
    max_iter=400,
)
#: ``mode="epigraph"``: its constraints touch the optimal set tangentially; Clarabel
#: cannot certify tight tolerances on them (``optimal_inaccurate`` is accepted there).
CLARABEL_EPI = dict(tol_gap_abs=1e-9, tol_gap_rel=1e-9, tol_feas=1e-9, max_iter=400)
#: A slack ``|v_i*| > VIOL_TOL · max(1, |bound|)`` marks a violated row (pinned). The test
#: stacks keep every violation far above it (≥ 1e-3) and Clarabel's error far below it.
VIOL_TOL = 1e-7
#: Relative singular-value threshold for the orthonormal basis of the pinned rows. The
#: test stacks have no singular value (relative) between ~1e-13 and ~1e-6.
RANK_TOL = 1e-10
#: Default relative slack of ``mode="epigraph"``'s objective-value constraints.
EPI_TOL = 1e-9
#: Internal consistency: the residual of the final x must reproduce each level's optimum.
SELF_CHECK = 1e-8


class OracleError(RuntimeError):
    """The reference solve failed (solver status or self-check)."""


@dataclass
class OracleResult:
    x: np.ndarray
    level_residuals: np.ndarray
    #: √(optimal value) of each level's own solve (equals level_residuals up to ~1e-9).
    level_optima: np.ndarray
    info: dict = field(default_factory=dict)


@dataclass
class _Level:
    Ae: np.ndarray  # √w-scaled equality rows
    be: np.ndarray
    C: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    sw: np.ndarray  # √w of each inequality row


def _as_tasks(level):
    if isinstance(level, (qc.Equality, qc.Inequality)):
        return [level]
    return list(level)


def _stack_level(tasks, n: int) -> _Level:
    eqs = [t for t in tasks if isinstance(t, qc.Equality)]
    ins = [t for t in tasks if isinstance(t, qc.Inequality)]
    Ae = np.vstack([np.sqrt(t.weight)[:, None] * t.A for t in eqs]) if eqs else np.zeros((0, n))
    be = np.concatenate([np.sqrt(t.weight) * t.b for t in eqs]) if eqs else np.zeros(0)
    C = np.vstack([t.C for t in ins]) if ins else np.zeros((0, n))
    lo = np.concatenate([t.lower for t in ins]) if ins else np.zeros(0)
    hi = np.concatenate([t.upper for t in ins]) if ins else np.zeros(0)
    sw = np.concatenate([np.sqrt(t.weight) for t in ins]) if ins else np.zeros(0)
    return _Level(Ae, be, C, lo, hi, sw)


def _residual(L: _Level, x: np.ndarray) -> float:
    r = L.Ae @ x - L.be
    cx = L.C @ x
    v = L.sw * (cx - np.clip(cx, L.lo, L.hi))
    return float(np.sqrt(r @ r + v @ v))


def level_residuals(levels, x) -> np.ndarray:
    """Per-level residual norms of ``x`` (same definition as ``Solution.level_residuals``),
    computed from the tasks' public attributes only."""
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    return np.array([_residual(_stack_level(_as_tasks(lv), n), x) for lv in levels])


def _two_sided(expr, lo, hi):
    """``lo ≤ expr ≤ hi`` for the finite sides only."""
    out = []
    fl, fh = np.isfinite(lo), np.isfinite(hi)
    if fl.any():
        out.append(expr[np.flatnonzero(fl)] >= lo[fl])
    if fh.any():
        out.append(expr[np.flatnonzero(fh)] <= hi[fh])
    return out


def _orth_rows(F: np.ndarray) -> np.ndarray:
    """Orthonormal basis (rows) of the row space of ``F``."""
    if F.shape[0] == 0:
        return F
    _, s, Vt = np.linalg.svd(F, full_matrices=False)
    if s.size == 0 or s[0] == 0.0:
        return np.zeros((0, F.shape[1]))
    rank = int(np.count_nonzero(s > RANK_TOL * s[0]))
    return Vt[:rank]


def _solve(problem: cp.Problem, where: str, settings=CLARABEL, ok=(cp.OPTIMAL,)) -> None:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # cvxpy's "may be inaccurate": status is checked
            problem.solve(solver=cp.CLARABEL, **settings)
    except cp.error.SolverError as exc:
        raise OracleError(f"{where}: Clarabel failed: {exc}") from None
    if problem.status not in ok:
        raise OracleError(f"{where}: Clarabel status {problem.status!r}")


#: Polish: a kept row within this (relative) distance of a limit is taken as active
#: (tried in turn until one verifies).
ACTIVE_TOLS = (1e-7, 1e-5, 1e-9, 1e-3)
#: Polish: the KKT residual (relative to ``‖Aᵀ‖·‖A x − b‖``) that certifies the point.
KKT_TOL = 1e-9


def _polish(A, b, E, e, C, lo, hi, x_guess):
    """:func:`_polish_at` with each of ``ACTIVE_TOLS`` in turn (``None``: none verified)."""
    for tol in ACTIVE_TOLS:
        x = _polish_at(A, b, E, e, C, lo, hi, x_guess, tol)
        if x is not None:
            return x
    return None


def _bvls(A, b, lo, hi):
    """scipy's bounded-variable least squares (an exact active-set method)."""
    from scipy.optimize import lsq_linear

    return lsq_linear(A, b, bounds=(lo, hi), method="bvls", tol=1e-15).x


def _polish_at(A, b, E, e, C, lo, hi, x_guess, active_tol):
    """Exact optimum of ``min ‖A x − b‖ s.t. E x = e, lo ≤ C x ≤ hi`` near ``x_guess``
    (a conic solver's point), or ``None`` if it cannot be verified.

    The rows within ``active_tol`` of a limit at ``x_guess`` are taken as active (equal to
    that limit); the equality-constrained least-squares problem is solved by an
    orthonormal null-space basis (SVD), choosing among its optima the one nearest
    ``x_guess``. It is accepted only if it is primal feasible (to 1e-12 relative) and
    the KKT conditions hold with multipliers of the right signs (an NNLS, to
    ``KKT_TOL``): a convex problem's KKT point is its optimum.
    """
    cx = C @ x_guess
    sc = np.maximum(1.0, np.abs(cx))
    at_lo = np.isfinite(lo) & (cx - lo <= active_tol * sc)
    at_hi = np.isfinite(hi) & (hi - cx <= active_tol * sc) & ~at_lo
    W = at_lo | at_hi
    K = np.vstack([E, C[W]])
    k = np.concatenate([e, np.where(at_lo, lo, hi)[W]])
    n = A.shape[1]
    if K.shape[0]:
        U, s, Vt = np.linalg.svd(K, full_matrices=True)
        rank = int(np.count_nonzero(s > RANK_TOL * s[0])) if s.size and s[0] > 0 else 0
        xp = Vt[:rank].T @ ((U[:, :rank].T @ k) / s[:rank])
        if np.linalg.norm(K @ xp - k) > 1e-12 * max(1.0, np.linalg.norm(k)):
            return None  # the guessed active rows are inconsistent
        N = Vt[rank:].T
    else:
        xp, N = np.zeros(n), np.eye(n)
    if N.shape[1] == 0:
        x = xp
    else:
        M = A @ N
        z, *_ = np.linalg.lstsq(M, b - A @ xp, rcond=None)
        # among the optima (z + null(M)), the one nearest the guess
        _, sm, Vm = np.linalg.svd(M, full_matrices=True)
        rm = int(np.count_nonzero(sm > RANK_TOL * sm[0])) if sm.size and sm[0] > 0 else 0
        Z = Vm[rm:].T
        z = z + Z @ (Z.T @ (N.T @ (x_guess - xp) - z))
        x = xp + N @ z
    # primal feasibility of every kept row
    cx = C @ x
    tol = 1e-12 * np.maximum(1.0, np.abs(cx))
    if np.any(cx < lo - tol) or np.any(cx > hi + tol):
        return None
    # dual: Aᵀr = Eᵀμ + Σ_lo λ Cᵢᵀ − Σ_hi λ Cᵢᵀ,  λ ≥ 0  (rows with lo == hi: either sign)
    from scipy.optimize import nnls

    r = A @ x - b
    g = A.T @ r
    eq_rows = W & (lo == hi)
    cols = [E.T, -E.T, C[at_lo | eq_rows].T, -C[at_hi | eq_rows].T]
    Mk = np.hstack([c for c in cols if c.shape[1]]) if any(c.shape[1] for c in cols) else None
    scale = float(np.linalg.norm(A) * np.linalg.norm(r))
    if scale == 0.0:
        return x
    res = np.linalg.norm(g) if Mk is None else nnls(Mk, g, maxiter=50 * Mk.shape[1])[1]
    return x if res <= KKT_TOL * scale else None


def lexicographic(
    levels,
    bounds=None,
    constraints=None,
    mode: str = "pin",
    epi_tol: float = EPI_TOL,
    polish: bool = False,
) -> OracleResult:
    """Reference strict-hierarchy solution of a stack (same arguments as ``qc.Stack``).

    Returns the minimum-norm point of the lexicographically optimal set and its residuals.
    Raises :class:`OracleError` if Clarabel does not report ``optimal`` or if the final
    point does not reproduce every level's optimum to ``SELF_CHECK`` (relative).

    ``polish=True`` (``mode="pin"``) makes every level without inequality rows exact
    where it can be verified (:func:`_polish`): Clarabel's point is only ~1e-11 off, but
    the next levels are pinned to it and, on near-singular levels, a 1e-13 error in level
    ``k`` buys level ``k+1`` up to ~1e-6 of its scale (measured, campaign near_parallel).
    ``info["polished"]`` lists the levels that were made exact; if the final minimum-norm
    step fails, the last level's point (also lexicographically optimal) is returned as
    ``x`` and ``info["min_norm"]`` is ``False``.
    """
    if mode not in ("pin", "epigraph"):
        raise ValueError(mode)
    settings = CLARABEL if mode == "pin" else CLARABEL_EPI
    ok = (cp.OPTIMAL,) if mode == "pin" else (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)
    levels = [_as_tasks(lv) for lv in levels]
    hard = [] if constraints is None else _as_tasks(constraints)
    n = next(t.shape[1] for t in [*hard, *(t for lv in levels for t in lv)])
    Ls = [_stack_level(lv, n) for lv in levels]
    H = _stack_level(hard, n)
    if H.Ae.shape[0]:  # hard equalities must hold exactly: drop their weights
        H.Ae = np.vstack([t.A for t in hard if isinstance(t, qc.Equality)])
        H.be = np.concatenate([t.b for t in hard if isinstance(t, qc.Equality)])

    # Inequality rows every solve must respect: bounds, hard inequalities and (pin mode)
    # the satisfied rows of the levels above.
    Cin, lin, uin = [np.zeros((0, n))], [np.zeros(0)], [np.zeros(0)]
    if bounds is not None:
        lb, ub = bounds.resolve(n)
        Cin, lin, uin = [np.eye(n)], [lb], [ub]
    Cin.append(H.C)
    lin.append(H.lo)
    uin.append(H.hi)
    # pinned rows (x-space) and the point whose values they keep
    pinned = np.zeros((0, n))
    x_pin = None
    if H.Ae.shape[0]:
        x0 = np.linalg.lstsq(H.Ae, H.be, rcond=None)[0]
        if np.max(np.abs(H.Ae @ x0 - H.be)) > 1e-9 * max(1.0, np.max(np.abs(H.be))):
            raise OracleError("inconsistent hard equalities")
        pinned = H.Ae
    x = cp.Variable(n)

    def common(x_pin):
        """Inequality rows, relaxed by exactly what the pinned point misses them by (the
        previous solve's ~1e-12 error): with ``E x = E x_pin`` the problem then stays
        feasible by construction, and the relaxation is negligible."""
        C, lo, hi = np.vstack(Cin), np.concatenate(lin), np.concatenate(uin)
        if x_pin is not None:
            cx = C @ x_pin
            miss = np.maximum(np.maximum(lo - cx, cx - hi), 0.0)
            if np.any(miss > 1e-8 * np.maximum(1.0, np.abs(cx))):
                raise OracleError(f"the pinned point violates kept rows by {miss.max():.2e}")
            lo, hi = lo - miss, hi + miss
        cons = _two_sided(C @ x, lo, hi)
        E = _orth_rows(pinned)
        if E.shape[0]:
            cons.append(E @ x == E @ (x0 if x_pin is None else x_pin))
        return cons

    epi = []  # objective-value constraints (epigraph mode)
    optima = []
    n_pinned = []
    violated_rows = []
    polished = []
    for k, L in enumerate(Ls):
        mi = L.C.shape[0]
        v = cp.Variable(mi) if mi else None
        parts = []  # the level's weighted residual vector
        cons = common(x_pin) + epi
        if L.Ae.shape[0]:
            parts.append(L.Ae @ x - L.be)
        if mi:
            parts.append(cp.multiply(L.sw, v))
            cons += _two_sided(L.C @ x - v, L.lo, L.hi)
        obj = cp.sum([cp.sum_squares(p) for p in parts])
        prob = cp.Problem(cp.Minimize(obj), cons)
        eligible = polish and mode == "pin" and mi == 0 and L.Ae.shape[0] > 0
        exact = None  # a verified exact optimum found before the conic solve (BVLS)
        if eligible:
            C, lo, hi = np.vstack(Cin), np.concatenate(lin), np.concatenate(uin)
            E = _orth_rows(pinned)
            e = E @ x_pin if x_pin is not None else (E @ x0 if E.shape[0] else np.zeros(0))
            if E.shape[0] == 0 and C.shape[0] == n and np.array_equal(C, np.eye(n)):
                # a bounded least-squares problem: BVLS's active set, verified
                exact = _polish(L.Ae, L.be, E, e, C, lo, hi, _bvls(L.Ae, L.be, lo, hi))
        if exact is not None:
            xk = exact
            r = L.Ae @ xk - L.be
            fk = float(r @ r)
            polished.append(k)
        else:
            _solve(prob, f"level {k}", settings, ok)
            xk = np.array(x.value, dtype=float)
            fk = max(float(prob.value), 0.0)
            if eligible:
                xp = _polish(L.Ae, L.be, E, e, C, lo, hi, xk)
                if xp is not None:
                    r = L.Ae @ xp - L.be
                    if float(r @ r) <= fk * (1 + 1e-6) + 1e-300:
                        xk, fk = xp, float(r @ r)
                        polished.append(k)
        optima.append(np.sqrt(fk))
        if mode == "epigraph":
            rk = np.sqrt(fk)
            if mi:
                epi += _two_sided(L.C @ x - v, L.lo, L.hi)
            epi.append(cp.norm(cp.hstack(parts)) <= rk + epi_tol * (1.0 + rk))
            continue
        # pin: equality rows, violated inequality rows; keep the satisfied ones
        new = [L.Ae]
        if mi:
            vk = np.array(v.value, dtype=float)
            scale = np.maximum(
                1.0,
                np.maximum(
                    np.abs(np.where(np.isfinite(L.lo), L.lo, 0.0)),
                    np.abs(np.where(np.isfinite(L.hi), L.hi, 0.0)),
                ),
            )
            viol = np.abs(vk) > VIOL_TOL * scale
            new.append(L.C[viol])
            Cin.append(L.C[~viol])
            lin.append(L.lo[~viol])
            uin.append(L.hi[~viol])
            violated_rows.append(np.flatnonzero(viol))
        else:
            violated_rows.append(np.zeros(0, dtype=int))
        pinned = np.vstack([pinned, *new])
        x_pin = xk
        n_pinned.append(_orth_rows(pinned).shape[0])
    # minimum-norm point of the lexicographic optimal set
    prob = cp.Problem(cp.Minimize(cp.sum_squares(x)), common(x_pin) + epi)
    min_norm = True
    try:
        _solve(prob, "minimum-norm step", settings, ok)
        xf = np.array(x.value, dtype=float)
    except OracleError:
        if not (polish and x_pin is not None):
            raise
        # the last level's point is in the lexicographic optimal set too (not the
        # minimum-norm one); the self-check below still applies to it
        xf, min_norm = x_pin, False
    res = np.array([_residual(L, xf) for L in Ls])
    optima = np.array(optima)
    if mode == "pin":
        bad = np.abs(res - optima) > SELF_CHECK * np.maximum(1.0, optima)
        if bad.any():
            raise OracleError(
                f"self-check: final residuals {res} do not reproduce the level optima {optima}"
            )
    info = dict(
        mode=mode,
        pinned_rank=n_pinned,
        violated_rows=violated_rows,
        polished=polished,
        min_norm=min_norm,
    )
    return OracleResult(x=xf, level_residuals=res, level_optima=optima, info=info)
