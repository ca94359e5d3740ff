"""Variable elimination state shared by the stack methods.

The decision variable is parameterised as ``x = x̄ + Z z`` where ``Z`` (n × r, orthonormal
columns, ``None`` meaning the identity) spans the freedom left by everything fixed so far,
and ``x̄`` is the current solution. Inequality rows that must keep holding (bounds, hard
inequalities, satisfied rows of higher levels) are *inherited*: every later QP sees them as
constraints on ``z``. Because ``x̄`` satisfies all of them, ``z = 0`` is always feasible for a
later level, so a strict hierarchy cannot become spuriously infeasible.
"""

from __future__ import annotations

import numpy as np

from .backends import INFEASIBLE, OK, solve_dense_qp
from .errors import InfeasibleError, SolverError
from .linalg import null_space

__all__ = ["Reduced", "FEAS_TOL", "CHECK_TOL"]

#: Relative tolerance under which a closed-form candidate counts as feasible
#: (``row ≤ hi + FEAS_TOL·max(1, |hi|)``).
FEAS_TOL = 1e-9
#: Relative tolerance of the final check of every returned ``x`` against the hard
#: constraints and inherited rows; beyond it a :class:`SolverError` is raised.
CHECK_TOL = 1e-6


def _slack(bound: np.ndarray, tol: float) -> np.ndarray:
    return tol * np.maximum(1.0, np.abs(np.where(np.isfinite(bound), bound, 0.0)))


def within(values: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: float) -> bool:
    """True if ``lo − tol·max(1,|lo|) ≤ values ≤ hi + tol·max(1,|hi|)`` (±inf bounds allowed)."""
    if values.size == 0:
        return True
    # with hi = +inf the right side is +inf; with lo = -inf, lo - values = -inf: both pass
    return bool(
        (values - hi <= tol * np.maximum(1.0, np.abs(hi))).all()
        and (lo - values <= tol * np.maximum(1.0, np.abs(lo))).all()
    )


class Reduced:
    """Current solution ``x̄``, null-space basis ``Z`` and inherited inequality rows."""

    def __init__(self, n: int, lb: np.ndarray | None, ub: np.ndarray | None, solver: str):
        self.n = n
        self.x = np.zeros(n)
        self.Z: np.ndarray | None = None
        self.lb, self.ub = lb, ub
        self.solver = solver
        self.Cin = np.zeros((0, n))
        self.lin = np.zeros(0)
        self.uin = np.zeros(0)
        self.qp_calls = 0

    # -- parameterisation -------------------------------------------------------------
    @property
    def r(self) -> int:
        """Remaining degrees of freedom."""
        return self.n if self.Z is None else self.Z.shape[1]

    def reduce(self, M: np.ndarray) -> np.ndarray:
        """``M Z`` (rows in x-space to rows in z-space)."""
        return M if self.Z is None else M @ self.Z

    def lift(self, z: np.ndarray) -> np.ndarray:
        """``Z z`` (a z-space step to x-space)."""
        return z if self.Z is None else self.Z @ z

    def move_to(self, x: np.ndarray) -> None:
        """Set ``x̄``, snapped into the bounds (removes a backend's ~1e-12 overshoot, which
        would otherwise make ``z = 0`` infeasible for the next level)."""
        self.x = x if self.lb is None else np.clip(x, self.lb, self.ub)

    def restrict(self, basis: np.ndarray) -> None:
        """Keep only the z-directions spanned by ``basis`` (r × r', orthonormal columns)."""
        self.Z = basis if self.Z is None else self.Z @ basis

    def freeze(self, F: np.ndarray) -> None:
        """Fix the z-space rows ``F z`` at their current values (restrict to null(F))."""
        if F.shape[0]:
            self.restrict(null_space(F))

    def inherit(self, C: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
        """Add inequality rows (x-space) that every later level must keep satisfied."""
        if C.shape[0] == 0:
            return
        self.Cin = np.vstack((self.Cin, C))
        self.lin = np.concatenate((self.lin, lo))
        self.uin = np.concatenate((self.uin, hi))

    # -- checks ---------------------------------------------------------------------
    def feasible(self, x: np.ndarray, tol: float = FEAS_TOL) -> bool:
        """Does ``x`` satisfy the bounds and inherited rows (to ``tol``, relative)?"""
        if self.lb is not None and not within(x, self.lb, self.ub, tol):
            return False
        return within(self.Cin @ x, self.lin, self.uin, tol) if self.Cin.shape[0] else True

    # -- QP in z (plus optional slack block) -------------------------------------------
    def _assemble(self, k: int, D, dlo, dhi):
        """Constraint rows of a QP in ``y = (z, w)`` (``k`` entries, ``w`` unbounded)."""
        r = self.r
        x = self.x
        blocks, los, his = [], [], []
        if D is not None and D.shape[0]:
            blocks.append(D)
            los.append(dlo)
            his.append(dhi)
        if self.Cin.shape[0]:
            Cz = self.reduce(self.Cin)
            cx = self.Cin @ x
            if k > r:
                Cz = np.hstack((Cz, np.zeros((Cz.shape[0], k - r))))
            blocks.append(Cz)
            # x̄ meets these rows up to the previous solve's tolerance; never ask for more
            # than z = 0 already gives, so the QP stays feasible by construction
            los.append(np.minimum(self.lin - cx, 0.0))
            his.append(np.maximum(self.uin - cx, 0.0))
        lb = ub = None
        if self.lb is not None:
            if self.Z is None:
                lb = np.full(k, -np.inf)
                ub = np.full(k, np.inf)
                lb[:r] = self.lb - x
                ub[:r] = self.ub - x
            else:
                Zr = self.Z if k == r else np.hstack((self.Z, np.zeros((self.n, k - r))))
                blocks.append(Zr)
                los.append(self.lb - x)
                his.append(self.ub - x)
        if not blocks:
            return np.zeros((0, k)), np.zeros(0), np.zeros(0), lb, ub
        if len(blocks) == 1:
            return blocks[0], los[0], his[0], lb, ub
        return np.vstack(blocks), np.concatenate(los), np.concatenate(his), lb, ub

    def solve_qp(
        self,
        H: np.ndarray,
        f: np.ndarray,
        D: np.ndarray | None = None,
        dlo: np.ndarray | None = None,
        dhi: np.ndarray | None = None,
        y0: np.ndarray | None = None,
        where: str = "",
    ) -> np.ndarray:
        """Solve ``min ½yᵀHy + fᵀy`` over ``y = (z, w)`` with the inherited rows and bounds
        on ``x̄ + Z z`` and the extra rows ``dlo ≤ D y ≤ dhi``; ``w`` (``len(y) − r`` slack
        entries) is unbounded. Returns ``y``; raises :class:`SolverError` on failure."""
        G, lo, hi, lb, ub = self._assemble(H.shape[0], D, dlo, dhi)
        self.qp_calls += 1
        res = solve_dense_qp(self.solver, H, f, G, lo, hi, lb, ub, y0)
        if res.code == INFEASIBLE and (self.Cin.shape[0] or self.lb is not None):
            # z = 0 is feasible by construction, up to the previous solve's tolerance:
            # relax the inherited rows by a hair and try once more.
            t = CHECK_TOL * 1e-2
            self.qp_calls += 1
            res = solve_dense_qp(
                self.solver, H, f, G, lo - _slack(lo, t), hi + _slack(hi, t),
                None if lb is None else lb - _slack(lb, t),
                None if ub is None else ub + _slack(ub, t),
                None,
            )
        if res.code != OK:
            raise SolverError(f"{where}: backend {self.solver!r} failed: {res.message}")
        return res.y

    def hard_phase(self, hard, where: str = "constraints") -> None:
        """Satisfy the hard constraints and bounds; start at the min-norm feasible point.

        Raises
        ------
        InfeasibleError
            Inconsistent hard equalities, or no point satisfies hard rows and bounds.
        """
        if hard.m_eq:
            Ae, be = hard.Ae, hard.be
            U, s, Vt = np.linalg.svd(Ae, full_matrices=True)
            rank = 0
            if s.size and s[0] > 0:
                rank = int(np.count_nonzero(s > max(Ae.shape) * np.finfo(float).eps * s[0]))
            self.x = Vt[:rank].T @ ((U[:, :rank].T @ be) / s[:rank])
            res = Ae @ self.x - be
            scale = max(1.0, float(np.max(np.abs(be))) if be.size else 1.0)
            if float(np.max(np.abs(res))) > CHECK_TOL * scale:
                names = ", ".join(t.label for t in hard.eqs)
                raise InfeasibleError(
                    f"hard equality constraints are inconsistent ({names}): "
                    f"least-squares residual {np.linalg.norm(res):.3g}"
                )
            self.restrict(Vt[rank:].T)
        self.inherit(hard.C, hard.lo, hard.hi)
        if self.lb is None and not self.Cin.shape[0]:
            return
        if self.feasible(self.x):
            return
        if self.lb is not None and self.Z is None and not self.Cin.shape[0]:
            self.x = np.clip(self.x, self.lb, self.ub)
            return
        r = self.r
        if r == 0:
            raise InfeasibleError(
                f"{where}: the hard equalities fix x completely and it violates the bounds "
                "or hard inequalities"
            )
        H = np.eye(r)
        f = self.x.copy() if self.Z is None else self.Z.T @ self.x
        x = self.x
        G, lo, hi, lb, ub = self._assemble(r, None, None, None)
        self.qp_calls += 1
        res = solve_dense_qp(self.solver, H, f, G, lo, hi, lb, ub, None)
        if res.code == INFEASIBLE:
            raise InfeasibleError(
                f"{where}: bounds and hard constraints are inconsistent "
                f"({self.solver}: {res.message})"
            )
        if res.code != OK:
            raise SolverError(f"{where}: backend {self.solver!r} failed: {res.message}")
        xn = x + self.lift(res.y)
        if not self.feasible(xn, CHECK_TOL):
            raise InfeasibleError(
                f"{where}: bounds and hard constraints appear inconsistent "
                f"({self.solver} returned a point violating them)"
            )
        self.x = xn
