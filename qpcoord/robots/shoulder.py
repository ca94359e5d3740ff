"""Appendix A: the 11-muscle glenohumeral model (thesis Eqs A.1–A.19, Fig A.1).

The glenohumeral (GH) joint is a spherical joint (three rotations, no translation) driven
by eleven muscles, each reduced to one resultant line of action. Data: the public DAS3
model (Chadwick et al. 2014, built on the Klein Breteler et al. 1999 cadaver the thesis
uses), lumped per muscle in ``robots/shoulder_muscles.json`` (transcribed from
``shared/data/shoulder-muscles.md``); see ``docs/appA.md``.

Frames and coordinates
----------------------
ISB axes, metres: X anterior, Y superior, Z lateral (right arm). Muscle origins are fixed in
the thorax frame (scapula fixed on the thorax, as in the thesis), centred on the GH centre.
Insertions are fixed in the humerus frame, centred on the GH centre and parallel to the
thorax frame with the arm hanging (``q = 0``).

``q = (θ, ϕ, ψ)`` (rad) are the thesis's Euler angles in the XZY sequence (text of
Sec. A.1, Eqs A.1–A.2, A.10): ``R(q) = Rx(θ) Rz(ϕ) Ry(ψ)`` maps humerus to thorax
coordinates. With these axes a positive right-handed rotation about X moves the hanging
arm medially, so **abduction is θ < 0**; ϕ > 0 is flexion (forward); ψ > 0 internal
rotation. The order of ``q``, ``Q`` and the rows of ``W`` is (θ, ϕ, ψ), the rotation order
of Eq. A.11 (Eq. A.6 numbers them ϕ, θ, ψ and the printed matrix of Eq. A.12 lists its
rows as ϕ, θ, ψ: see ``docs/appA.md``, "Notes on the thesis").

Lines of action
---------------
Straight lines between origin and insertion pass through the humeral head for four
muscles (data note). Each deltoid part and each rotator-cuff muscle therefore wraps, when
its straight line would cut it, around a sphere centred on the GH centre (radius 27.2 mm
for the deltoid, 23.1 mm for the rotator cuff, DAS3's values); the sphere is part of the
humeral head. The wrapped path is the shortest path around the sphere (tangent, great
circle arc, tangent); its length is continuous and once differentiable in ``q`` (the
line of action turns continuously as the wrap engages). The wrap contact force passes
through the sphere's centre, so a muscle's moment about the GH centre is
``r_origin × d F`` with ``d`` the unit direction of the path's free segment at the
origin, pointing to the origin (Eq. A.16), and the moment arms equal ``−∂ℓ/∂q`` (tested).
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

__all__ = ["ShoulderModel", "MusclePaths", "build", "rotation", "COORDINATES", "GRAVITY"]

#: Names of the generalised coordinates, in the order of ``q``, ``Q`` and the rows of W.
COORDINATES = ("theta", "phi", "psi")
#: Gravitational acceleration (m/s²), along −Y.
GRAVITY = 9.81
#: Model range (rad), a choice of this model (not anatomical data): abduction up to 100°
#: (θ ≥ −100°), adduction 30°; flexion 80° and extension 60° (ϕ = ±90° is the XZY gimbal
#: lock, where e_θ and e_ψ align and W loses rank); rotation ±90°.
RANGE_DEG = ((-100.0, 30.0), (-60.0, 80.0), (-90.0, 90.0))


def _rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation(q) -> np.ndarray:
    """Humerus-to-thorax rotation ``R = Rx(θ) Rz(ϕ) Ry(ψ)`` (XZY Euler angles, rad)."""
    th, ph, ps = (float(v) for v in q)
    return _rx(th) @ _rz(ph) @ _ry(ps)


def _body_jacobian(q: np.ndarray) -> np.ndarray:
    """Eq. A.2: ``ω_body = Jb q̇``; columns are e_θ, e_ϕ, e_ψ in humerus coordinates."""
    _, ph, ps = q
    cph, sph, cps, sps = np.cos(ph), np.sin(ph), np.cos(ps), np.sin(ps)
    return np.array(
        [
            [cps * cph, -sps, 0.0],
            [-sph, 0.0, 1.0],
            [sps * cph, cps, 0.0],
        ]
    )


def _body_jacobian_rate(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Time derivative of :func:`_body_jacobian` along ``q̇``."""
    _, ph, ps = q
    _, dph, dps = qd
    cph, sph, cps, sps = np.cos(ph), np.sin(ph), np.cos(ps), np.sin(ps)
    return np.array(
        [
            [-sps * cph * dps - cps * sph * dph, -cps * dps, 0.0],
            [-cph * dph, 0.0, 0.0],
            [cps * cph * dps - sps * sph * dph, -sps * dps, 0.0],
        ]
    )


@dataclass(frozen=True)
class MusclePaths:
    """Muscle paths at one posture (thorax frame, m).

    Per muscle (:meth:`ShoulderModel.paths`) or per line of action
    (:meth:`ShoulderModel.line_paths`). For a muscle on several lines (``lines="elements"``)
    the per-muscle values are the lines' values weighted by their share of the muscle's
    force (the elements' ``f_max`` fractions), so ``W = −∂ℓ/∂q`` still holds.

    Attributes
    ----------
    lengths : numpy.ndarray, shape (n,)
        Path lengths origin → insertion, wrap arc included (m).
    directions : numpy.ndarray, shape (n, 3)
        Per line: unit direction of the path's free segment at the origin, pointing to the
        origin (the direction of its net force on the humerus). Per muscle on several
        lines: the net force on the humerus per newton of muscle force (norm ≤ 1).
    insertions : numpy.ndarray, shape (n, 3)
        Insertion points in thorax coordinates (m).
    tangent_points : numpy.ndarray, shape (n, 3)
        Where the path leaves the line from the origin: the wrap's first tangent point,
        or the insertion for a straight path (m).
    wrapped : numpy.ndarray of bool, shape (n,)
        Whether the path (any of the muscle's lines) wraps around its sphere.
    """

    lengths: np.ndarray
    directions: np.ndarray
    insertions: np.ndarray
    tangent_points: np.ndarray
    wrapped: np.ndarray


class ShoulderModel:
    """Glenohumeral joint with 11 muscles and a rigid arm (thesis appendix A).

    Build it with :func:`build` or ``qpcoord.robots.load("shoulder")``.

    Attributes
    ----------
    names : tuple of str
        Muscle names, in the order of the columns of ``W`` and of force vectors.
    f_max : numpy.ndarray, shape (11,)
        Maximal isometric forces (N).
    f_min : numpy.ndarray, shape (11,)
        Minimal forces, zero (N): a muscle cannot push (Eq. A.24 with a = 0).
    stress : float
        Muscle stress σ with ``F_max = PCSA · σ`` (Pa; Eq. A.14: 40 N/cm² = 4e5 Pa).
    pcsa : numpy.ndarray, shape (11,)
        Physiological cross-sectional areas ``F_max / σ`` (m²).
    origins : numpy.ndarray, shape (11, 3)
        Lumped origins in the thorax frame (m): the lines of a lumped model.
    insertions : numpy.ndarray, shape (11, 3)
        Lumped insertions in the humerus frame (m).
    lines : {"elements", "lumped"}
        Whether some muscles act along several lines (their DAS3 elements) or every muscle
        along its lumped line.
    n_lines : int
        Number of lines of action.
    line_share : numpy.ndarray, shape (11, n_lines)
        Share of each muscle's force carried by each line (rows sum to 1).
    line_origins, line_insertions : numpy.ndarray, shape (n_lines, 3)
        Origin (thorax frame) and insertion (humerus frame) of each line (m).
    line_wrap_radii : numpy.ndarray, shape (n_lines,)
        Wrap-sphere radius of each line (its muscle's), 0 = straight (m).
    wrap_radii : numpy.ndarray, shape (11,)
        Radius of each muscle's wrap sphere, centred on the GH centre; 0 = straight line (m).
    mass : float
        Arm mass (kg).
    com_distance : float
        Distance GH centre → arm centre of mass, along the humeral long axis (m).
    inertia_transverse, inertia_longitudinal : float
        Moments of inertia **about the GH centre** (kg·m²): ``I_t = I_t,com + m L²``,
        ``I_l = I_l,com`` (Eq. A.3's ``I_arm^t``, ``I_arm^l``).
    lower, upper : numpy.ndarray, shape (3,)
        Model range of ``q`` (rad).
    gravity : float
        Gravitational acceleration (m/s²), along −Y.
    """

    n_muscles = 11
    coordinates = COORDINATES

    def __init__(
        self,
        names,
        f_max,
        origins,
        insertions,
        wrap_radii,
        *,
        mass: float,
        com_distance: float,
        inertia_transverse_com: float,
        inertia_longitudinal_com: float,
        stress: float = 4e5,
        lower=None,
        upper=None,
        gravity: float = GRAVITY,
        elements=None,
    ) -> None:
        self.names = tuple(str(n) for n in names)
        m = len(self.names)
        if m < 4:
            raise ValueError(f"names: a shoulder model needs at least 4 muscles, got {m}")
        self.n_muscles = m
        self.f_max = _array(f_max, (m,), "f_max")
        for name, f in zip(self.names, self.f_max, strict=True):
            if not f > 0.0:
                raise ValueError(f"f_max of {name!r} must be > 0 N, got {float(f)!r}")
        self.f_min = np.zeros(m)
        self.origins = _array(origins, (m, 3), "origins")
        self.insertions = _array(insertions, (m, 3), "insertions")
        self.wrap_radii = _array(wrap_radii, (m,), "wrap_radii")
        self._set_lines(elements)
        for j, (o, i, r) in enumerate(zip(self._lo, self._li, self._lr, strict=True)):
            name = self.names[self._lm[j]]
            if r < 0.0:
                raise ValueError(f"wrap radius of {name!r} must be >= 0 m, got {float(r)!r}")
            for what, p in (("origin", o), ("insertion", i)):
                if np.linalg.norm(p) <= r:
                    raise ValueError(
                        f"{what} of {name!r} at {p.tolist()} m lies inside its wrap sphere "
                        f"(radius {r} m)"
                    )
        for what, v in (
            ("mass", mass),
            ("com_distance", com_distance),
            ("inertia_transverse_com", inertia_transverse_com),
            ("inertia_longitudinal_com", inertia_longitudinal_com),
            ("stress", stress),
            ("gravity", gravity),
        ):
            if not (np.isfinite(v) and v >= 0.0) or (what in ("mass", "stress") and v == 0.0):
                raise ValueError(f"{what} must be a finite positive number, got {v!r}")
        self.stress = float(stress)
        self.pcsa = self.f_max / self.stress
        self.mass = float(mass)
        self.com_distance = float(com_distance)
        self.inertia_transverse = float(inertia_transverse_com) + self.mass * com_distance**2
        self.inertia_longitudinal = float(inertia_longitudinal_com)
        self.gravity = float(gravity)
        rng = np.radians(RANGE_DEG)
        self.lower = rng[:, 0].copy() if lower is None else _array(lower, (3,), "lower")
        self.upper = rng[:, 1].copy() if upper is None else _array(upper, (3,), "upper")
        if np.any(self.lower >= self.upper):
            raise ValueError(f"lower {self.lower} must be < upper {self.upper} (rad)")
        if self.lower[1] <= -np.pi / 2 or self.upper[1] >= np.pi / 2:
            raise ValueError(
                f"the phi range [{self.lower[1]}, {self.upper[1]}] rad must stay inside "
                "(-pi/2, pi/2): phi = ±pi/2 is the XZY gimbal lock"
            )
        self._inertia = np.array(
            [self.inertia_transverse, self.inertia_longitudinal, self.inertia_transverse]
        )

    def _set_lines(self, elements) -> None:
        """Lines of action: one per muscle (its lumped line) or, for a muscle given
        ``elements``, one per element, the muscle's force shared in proportion to the
        elements' ``f_max`` (so its moment arm is their force-weighted mean at every q)."""
        m = self.n_muscles
        if elements is None:
            elements = [None] * m
        if len(elements) != m:
            raise ValueError(f"elements must have one entry per muscle ({m}), got {len(elements)}")
        lo, li, lr, lw, lm = [], [], [], [], []
        for j, el in enumerate(elements):
            if el is None:
                lo.append(self.origins[j][None])
                li.append(self.insertions[j][None])
                w = np.ones(1)
            else:
                f = np.asarray(el["f_max"], dtype=float)
                if f.ndim != 1 or f.size < 1 or not np.all(np.isfinite(f) & (f > 0)):
                    raise ValueError(
                        f"elements of {self.names[j]!r}: f_max must be positive forces (N), "
                        f"got {el['f_max']!r}"
                    )
                lo.append(_array(el["origins"], (f.size, 3), f"origins of {self.names[j]!r}"))
                li.append(_array(el["insertions"], (f.size, 3), f"insertions of {self.names[j]!r}"))
                w = f / f.sum()
            lw.append(w)
            lr.append(np.full(w.size, self.wrap_radii[j]))
            lm.append(np.full(w.size, j))
        self._lo, self._li = np.vstack(lo), np.vstack(li)
        self._lr, self._lw = np.concatenate(lr), np.concatenate(lw)
        self._lm = np.concatenate(lm)
        self.line_origins, self.line_insertions, self.line_wrap_radii = self._lo, self._li, self._lr
        self.n_lines = self._lw.size
        self.lines = "lumped" if self.n_lines == m else "elements"
        #: (muscles × lines) sharing matrix: line forces = ``line_share.T @ F``.
        self.line_share = np.zeros((m, self.n_lines))
        self.line_share[self._lm, np.arange(self.n_lines)] = self._lw

    def __repr__(self) -> str:
        return (
            f"ShoulderModel({self.n_muscles} muscles on {self.n_lines} lines, arm {self.mass} kg, "
            f"com {self.com_distance} m, I_t {self.inertia_transverse:.4g} kg·m² about GH)"
        )

    # ------------------------------------------------------------------ inputs
    def check_posture(self, q) -> np.ndarray:
        """``q`` as a float array (3,), checked: finite and inside ``[lower, upper]`` (rad).

        Raises
        ------
        ValueError
            Wrong shape, non-finite value, or an angle outside the model's range (the
            message names the coordinate and its value).
        """
        q = _array(q, (3,), "q")
        for k, name in enumerate(COORDINATES):
            if not self.lower[k] - 1e-12 <= q[k] <= self.upper[k] + 1e-12:
                raise ValueError(
                    f"q[{k}] ({name}) = {float(q[k])!r} rad ({np.degrees(q[k]):.1f}°) is "
                    "outside the "
                    f"model's range [{np.degrees(self.lower[k]):.0f}°, "
                    f"{np.degrees(self.upper[k]):.0f}°]"
                )
        return q

    # ------------------------------------------------------------------ kinematics
    def axes(self, q) -> np.ndarray:
        """Rows e_θ, e_ϕ, e_ψ = ∂ω/∂q̇ in the thorax frame (Eq. A.10): the projection P of
        Eq. A.19, ``Q = P M`` with M a moment about the GH centre (N·m). Shape (3, 3)."""
        q = self.check_posture(q)
        return self._axes(q)

    @staticmethod
    def _axes(q: np.ndarray) -> np.ndarray:
        rx = _rx(q[0])
        return np.vstack((np.array([1.0, 0.0, 0.0]), rx[:, 2], (rx @ _rz(q[1]))[:, 1]))

    def paths(self, q) -> MusclePaths:
        """Muscle paths at posture ``q`` (rad), with the spherical wraps (thorax frame, m)."""
        q = self.check_posture(q)
        return self._paths(q)

    def line_paths(self, q) -> MusclePaths:
        """Paths of the lines of action at ``q`` (rad), one per line (``n_lines``; one per
        muscle for a lumped model, one per DAS3 element with ``lines="elements"``)."""
        q = self.check_posture(q)
        return self._line_paths(q)

    def _paths(self, q: np.ndarray) -> MusclePaths:
        lp = self._line_paths(q)
        if self.lines == "lumped":
            return lp
        A = self.line_share
        wrapped = np.zeros(self.n_muscles, dtype=bool)
        np.logical_or.at(wrapped, self._lm, lp.wrapped)
        return MusclePaths(
            A @ lp.lengths, A @ lp.directions, A @ lp.insertions, A @ lp.tangent_points, wrapped
        )

    def _line_paths(self, q: np.ndarray) -> MusclePaths:
        """All lines at once (vectorised over the lines; the geometry of the class
        docstring: tangent, great-circle arc, tangent when the straight line cuts the
        sphere)."""
        R = rotation(q)
        ins = self._li @ R.T
        o, r = self._lo, self._lr
        seg = o - ins
        straight = np.linalg.norm(seg, axis=1)
        lengths = straight.copy()
        dirs = seg / straight[:, None]
        tang = ins.copy()
        wrapped = np.zeros(self.n_lines, dtype=bool)
        w = np.flatnonzero(r > 0.0)
        if w.size:
            o, i, r = o[w], ins[w], r[w]
            a, b = np.linalg.norm(o, axis=1), np.linalg.norm(i, axis=1)
            e1 = o / a[:, None]
            proj = np.einsum("kj,kj->k", e1, i)
            gamma = np.arccos(np.clip(proj / b, -1.0, 1.0))
            alpha, beta = np.arccos(r / a), np.arccos(r / b)
            cut = gamma > alpha + beta  # otherwise the straight line clears the sphere
            perp = i - proj[:, None] * e1
            norm_perp = np.linalg.norm(perp, axis=1)
            for k in np.flatnonzero(cut & (norm_perp < 1e-12 * b)):  # aligned: any plane
                helper = np.eye(3)[np.argmin(np.abs(e1[k]))]
                perp[k] = helper - (helper @ e1[k]) * e1[k]
                norm_perp[k] = np.linalg.norm(perp[k])
            e2 = perp / np.where(norm_perp > 0.0, norm_perp, 1.0)[:, None]
            t = r[:, None] * (np.cos(alpha)[:, None] * e1 + np.sin(alpha)[:, None] * e2)
            d = o - t
            wl = np.sqrt(a * a - r * r) + r * (gamma - alpha - beta) + np.sqrt(b * b - r * r)
            idx = w[cut]
            lengths[idx] = wl[cut]
            dirs[idx] = d[cut] / np.linalg.norm(d[cut], axis=1)[:, None]
            tang[idx] = t[cut]
            wrapped[idx] = True
        return MusclePaths(lengths, dirs, ins, tang, wrapped)

    def lengths(self, q) -> np.ndarray:
        """Muscle path lengths at ``q`` (m), shape (11,)."""
        return self.paths(q).lengths

    def moment_matrix(self, q) -> np.ndarray:
        """Eq. A.18: columns ``r_j × d_j`` about the GH centre, thorax frame (m), (3, 11);
        ``M = B F`` is the muscles' moment (N·m) for forces F (N)."""
        q = self.check_posture(q)
        return self._moment_matrix(q)

    def _moment_matrix(self, q: np.ndarray) -> np.ndarray:
        B = np.cross(self._lo, self._line_paths(q).directions).T
        return B if self.lines == "lumped" else B @ self.line_share.T

    def moment_arms(self, q) -> np.ndarray:
        """Eq. A.19: the moment-arm matrix ``W = P B`` (m), shape (3, 11).

        ``Q = W F`` maps muscle forces F (N) to the generalised forces Q (N·m) of
        ``(θ, ϕ, ψ)``. Equals ``−∂ℓ/∂q`` (tendon-excursion moment arms).
        """
        q = self.check_posture(q)
        return self._moment_arms(q)

    def _moment_arms(self, q: np.ndarray) -> np.ndarray:
        return self._axes(q) @ self._moment_matrix(q)

    # ------------------------------------------------------------------ dynamics
    def _state(self, q, qd, qdd):
        q = self.check_posture(q)
        qd = _array(qd, (3,), "qd")
        qdd = _array(qdd, (3,), "qdd")
        return q, qd, qdd

    def mass_matrix(self, q) -> np.ndarray:
        """Generalised inertia ``Jbᵀ diag(I_t, I_l, I_t) Jb`` of Eq. A.3 (kg·m²), (3, 3)."""
        q = self.check_posture(q)
        Jb = _body_jacobian(q)
        return Jb.T @ (self._inertia[:, None] * Jb)

    def kinetic_energy(self, q, qd) -> float:
        """Eq. A.3 (J)."""
        q = self.check_posture(q)
        w = _body_jacobian(q) @ _array(qd, (3,), "qd")
        return 0.5 * float(w @ (self._inertia * w))

    def potential_energy(self, q) -> float:
        """Eq. A.4: ``m g L (1 − cos ϕ cos θ)`` (J), zero with the arm hanging."""
        q = self.check_posture(q)
        return self.mass * self.gravity * self.com_distance * (1.0 - np.cos(q[1]) * np.cos(q[0]))

    def gravity_forces(self, q) -> np.ndarray:
        """``∂V/∂q`` of Eq. A.4 (N·m), shape (3,)."""
        q = self.check_posture(q)
        return self._gravity(q)

    def _gravity(self, q: np.ndarray) -> np.ndarray:
        mgl = self.mass * self.gravity * self.com_distance
        th, ph = q[0], q[1]
        return mgl * np.array([np.cos(ph) * np.sin(th), np.sin(ph) * np.cos(th), 0.0])

    def generalised_forces(self, q, qd, qdd, external_moment=None) -> np.ndarray:
        """Generalised forces the muscles must produce for a motion (Eqs A.1–A.6), N·m.

        ``Q = d/dt(∂T/∂q̇) − ∂T/∂q + ∂V/∂q − P M_ext``, computed as
        ``Jbᵀ (I ω̇ + ω × I ω) + ∂V/∂q − P M_ext`` (body frame, Euler's equations about the
        fixed GH centre; equal to the Lagrangian form, tested).

        Parameters
        ----------
        q : array_like, shape (3,)
            Posture ``(θ, ϕ, ψ)`` (rad), inside the model range.
        qd : array_like, shape (3,)
            Angle rates (rad/s).
        qdd : array_like, shape (3,)
            Angle accelerations (rad/s²).
        external_moment : array_like, shape (3,), optional
            Moment about the GH centre of other external loads (e.g. a hand-held weight,
            :meth:`point_load_moment`), thorax frame (N·m).

        Returns
        -------
        numpy.ndarray, shape (3,)
            ``(Q_θ, Q_ϕ, Q_ψ)`` (N·m).
        """
        q, qd, qdd = self._state(q, qd, qdd)
        Jb = _body_jacobian(q)
        w = Jb @ qd
        wd = Jb @ qdd + _body_jacobian_rate(q, qd) @ qd
        Iw = self._inertia * w
        tau = self._inertia * wd + np.cross(w, Iw)
        Q = Jb.T @ tau + self._gravity(q)
        if external_moment is not None:
            Q = Q - self._axes(q) @ _array(external_moment, (3,), "external_moment")
        return Q

    def point_load_moment(self, q, mass: float, distance: float) -> np.ndarray:
        """Moment about the GH centre of a point mass hanging on the humeral long axis
        (a weight in the hand of the straight arm), thorax frame (N·m).

        Parameters
        ----------
        q : array_like, shape (3,)
            Posture (rad).
        mass : float
            Load mass (kg), ≥ 0.
        distance : float
            Distance from the GH centre along the arm (m), ≥ 0.
        """
        q = self.check_posture(q)
        for what, v in (("mass", mass), ("distance", distance)):
            if not (np.isfinite(v) and v >= 0.0):
                raise ValueError(f"point load {what} must be finite and >= 0, got {v!r}")
        r = rotation(q) @ np.array([0.0, -distance, 0.0])
        return np.cross(r, np.array([0.0, -mass * self.gravity, 0.0]))

    def com_acceleration(self, q, qd, qdd) -> np.ndarray:
        """Acceleration of the arm's centre of mass, thorax frame (m/s²)."""
        q, qd, qdd = self._state(q, qd, qdd)
        R = rotation(q)
        Jb = _body_jacobian(q)
        w = R @ (Jb @ qd)
        wd = R @ (Jb @ qdd + _body_jacobian_rate(q, qd) @ qd)
        c = R @ np.array([0.0, -self.com_distance, 0.0])
        return np.cross(wd, c) + np.cross(w, np.cross(w, c))

    def contact_force(self, q, qd, qdd, forces, external_force=None) -> np.ndarray:
        """Glenohumeral contact force: the force of the humerus on the glenoid (N),
        thorax frame, shape (3,).

        Newton's law for the arm: ``m a_c = m g + Σ F_j d_j + F_joint + F_ext``; the glenoid
        receives ``−F_joint``. A negative Z component presses the head into the glenoid.

        Parameters
        ----------
        q, qd, qdd : array_like, shape (3,)
            Posture (rad), rates (rad/s), accelerations (rad/s²).
        forces : array_like, shape (11,)
            Muscle forces (N).
        external_force : array_like, shape (3,), optional
            Other external force on the arm, e.g. a hand-held weight (N).
        """
        q, qd, qdd = self._state(q, qd, qdd)
        F = _array(forces, (self.n_muscles,), "forces")
        a_c = self.com_acceleration(q, qd, qdd)
        g = np.array([0.0, -self.gravity, 0.0])
        total = self._paths(q).directions.T @ F + self.mass * (g - a_c)
        if external_force is not None:
            total = total + _array(external_force, (3,), "external_force")
        return total


def _array(value, shape, what: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(
            f"{what} must be a numeric array of shape {shape}, got {value!r}"
        ) from None
    if arr.shape != shape:
        raise ValueError(f"{what} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(
            f"{what} contains a non-finite value {float(arr[tuple(bad)])!r} at {bad.tolist()}"
        )
    return arr


def _load_table() -> dict:
    from .files import description_path  # package data: works from a non-editable install

    return json.loads(description_path("shoulder_muscles.json").read_text())


def _load_elements() -> dict:
    from .files import description_path

    return json.loads(description_path("shoulder_elements.json").read_text())["muscles"]


def build(
    arm: str = "straight", wrap: bool = True, lines: str = "elements", **overrides
) -> ShoulderModel:
    """The appendix A model from ``robots/shoulder_muscles.json``.

    Parameters
    ----------
    arm : {"straight", "upper"}
        Inertia of the whole straight arm (upper arm + forearm + hand; default: the thesis
        moves the extended arm) or of the humerus alone (DAS3 segments).
    wrap : bool
        Wrap the deltoid and rotator-cuff paths around spheres (default) or use straight
        lines for every muscle (the data note's comparison case).
    lines : {"elements", "lumped"}
        Each muscle acts along its DAS3 elements (``robots/shoulder_elements.json``, force
        shared by the elements' ``f_max``; default: the lumped line loses up to 40 % of
        the elements' moment arm at neutral and more elsewhere) or
        along one lumped line (``shoulder_muscles.json``, the thesis's "one resultant line
        of action per muscle").
    **overrides
        Any :class:`ShoulderModel` keyword (``f_max``, ``stress``, ``lower``, ``upper``,
        ``mass``…) replacing the table's value.

    Raises
    ------
    ValueError
        Unknown ``arm`` or override, or invalid data (e.g. a negative ``f_max``, named).
    """
    table = _load_table()
    if arm not in ("straight", "upper"):
        raise ValueError(f"arm must be 'straight' or 'upper', got {arm!r}")
    if lines not in ("elements", "lumped"):
        raise ValueError(f"lines must be 'elements' or 'lumped', got {lines!r}")
    seg = table["arm" if arm == "straight" else "upper_arm"]
    muscles = table["muscles"]
    radii = table["wrap_spheres"]
    kw = dict(
        names=[m["name"] for m in muscles],
        f_max=[m["f_max"] for m in muscles],
        origins=[m["origin"] for m in muscles],
        insertions=[m["insertion"] for m in muscles],
        wrap_radii=[radii[m["wrap"]] if (wrap and m["wrap"]) else 0.0 for m in muscles],
        mass=seg["mass"],
        com_distance=seg["com_distance"],
        inertia_transverse_com=seg["inertia_transverse_com"],
        inertia_longitudinal_com=seg["inertia_longitudinal_com"],
        stress=table["muscle_stress_N_per_m2"],
    )
    if lines == "elements":
        el = _load_elements()
        kw["elements"] = [
            {
                "f_max": [e["f_max"] for e in el[m["name"]]],
                "origins": [e["origin"] for e in el[m["name"]]],
                "insertions": [e["insertion"] for e in el[m["name"]]],
            }
            for m in muscles
        ]
    allowed = set(kw) | {"lower", "upper", "gravity", "elements"}
    unknown = set(overrides) - allowed
    if unknown:
        raise ValueError(f"unknown shoulder option(s) {sorted(unknown)}; known: {sorted(allowed)}")
    kw.update(overrides)
    return ShoulderModel(**kw)
