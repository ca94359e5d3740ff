"""Chapter 4: pulling involutive fields back through J⁺ loses involutivity (Lemma 4.1,
Ex. 4.3); the dual fields of Thm 4.2 keep it (Ex. 4.4).

1. Lemma 4.1: the submersion ``x₁ = q₁, x₂ = q₂ + q₁q₃`` and the trivially involutive
   ``v₁ = (1, 0)``, ``v₂ = (0, 1)``: ``det[f₁, f₂, [f₁, f₂]]`` of ``fᵢ = J⁺vᵢ`` on a grid,
   against the thesis's printed fields and determinant ``−(1 + q₁²)²``.
2. Ex. 4.3: the 3R arm (absolute angles), ``fᵢ = J⁺eᵢ``: the same determinant on a grid of
   ``(q₁, q₂, q₃)``.
3. Ex. 4.4: the 5R arm along the Lissajous of Ex. 4.1: involutivity defect (Def. 3.13) of
   the J⁺-pulled sphere basis ``J⁺v₁, J⁺v₂`` (Prop. 4.1) and of the Thm 4.2 dual fields of
   ``(ω₁, ω₄, ω₅)``.

Measured (full run, 25 × 25 grids, 20 points of one period of the 5R path):

- Lemma 4.1, exact J⁺ fields ``J⁺e₁ = (1 + q₁², −q₃, −q₁q₃)/(1 + q₁²)``,
  ``J⁺e₂ = (0, 1, q₁)/(1 + q₁²)``: ``det = 1/(1 + q₁²)²`` (to 1e-15; ``−1/(1 + q₁²)²`` in
  the thesis's bracket sign), between 0.04 and 1.0 on the grid, never 0: the lemma holds.
  The printed fields ``(1 + q₃², q₃, q₁q₃)``, … are not ``J⁺eᵢ``; they give ``+(1 + q₁²)²``,
  the printed ``−(1 + q₁²)²`` up to the sign convention (our bracket is
  ``[f, g] = (∂g/∂q)f − (∂f/∂q)g``, the thesis uses the opposite): the printed formula is a
  thesis error.
- Ex. 4.3 (3R): ``|det|`` between 0.052 and 28.8 on the 550 grid points whose link
  angles are distinct; it vanishes (≤ 3.4e-15) exactly where two links are parallel
  (``qᵢ = qⱼ``, 66 points): a set of measure zero, not involutivity.
- Ex. 4.4 (5R): involutivity defect of the J⁺-pulled sphere basis 5e-4 to 0.49 along the
  path (not involutive); of the Thm 4.2 dual fields ≤ 5.7e-8 (the finite-difference
  floor of the Procrustes-aligned basis): involutive.

Claims (``summary["claims"]``, computed from the run): Lemma 4.1's determinant is non-zero;
the printed fields and ``−(1 + q₁²)²`` are not J⁺'s (differs, thesis error); Ex 4.3's
determinant is non-zero; Eqs 4.6–4.7 against ``J⁺e₁, J⁺e₂`` (differs: Eq 4.6's third row
has the wrong sign); the Thm 4.2 fields are involutive and the J⁺-pulled sphere basis is
not (Ex 4.4). ``--quick`` is the full run (25² grids, 20 samples of the 5R path, 1 s of
CPU): a rule that must hold at every point is not decided on a coarser grid.

Run: ``python examples/ch4_involutivity.py [--quick] [--out DIR]``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import qpcoord as qc
from qpcoord import geometry as g
from qpcoord.studies.claims import claim
from qpcoord.studies.files import TextLog, write_json

OMEGA_45 = np.array([[1.0, 0.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0, 0.0]])
DET_MIN = 1e-6  # |det[f1, f2, [f1, f2]]| above this: not involutive (rounding is ~1e-15)
DEFECT_FLOOR = 1e-6  # involutivity defect of exactly involutive fields (finite differences)
EQ_TOL = 1e-12  # printed formula vs computed J⁺ column


def printed_3r_fields(q) -> tuple[np.ndarray, np.ndarray]:
    """Thesis Eqs 4.6–4.7 as printed: ``f₁, f₂`` for the 3R arm with absolute angles."""
    q1, q2, q3 = q
    a = -3 + np.cos(2 * q1 - 2 * q2) + np.cos(2 * q1 - 2 * q3) + np.cos(2 * q2 - 2 * q3)
    f1 = [
        2 * np.sin(q1) + np.sin(q1 - 2 * q2) + np.sin(q1 - 2 * q3),
        -np.sin(2 * q1 - q2) + 2 * np.sin(q2) + np.sin(q2 - 2 * q3),
        np.sin(2 * q1 - q3) + np.sin(2 * q2 - q3) - 2 * np.sin(q3),
    ]
    f2 = [
        -2 * np.cos(q1) + np.cos(q1 - 2 * q2) + np.cos(q1 - 2 * q3),
        np.cos(2 * q1 - q2) - 2 * np.cos(q2) + np.cos(q2 - 2 * q3),
        np.cos(2 * q1 - q3) + np.cos(2 * q2 - q3) - 2 * np.cos(q3),
    ]
    return np.array(f1) / a, np.array(f2) / a


def _lemma41_field(e):
    def f(q):
        J = np.array([[1.0, 0.0, 0.0], [q[2], 1.0, q[0]]])
        return J.T @ np.linalg.solve(J @ J.T, e)

    return f


def lemma_4_1(grid: np.ndarray) -> dict:
    """Lemma 4.1's example on J⁺'s own fields ``fᵢ = J⁺eᵢ`` (grid of q₁, q₃ at q₂ = 0.3), and
    the thesis's printed fields and determinant against them."""
    f1, f2 = _lemma41_field([1.0, 0.0]), _lemma41_field([0.0, 1.0])
    pts = [(a, b) for a in grid for b in grid]
    dets = np.array([[g.bracket_determinant(f1, f2, [a, 0.3, b]) for b in grid] for a in grid])
    # the true determinant: +1/(1 + q₁²)² in qpcoord's bracket sign, −1/(1 + q₁²)² in the
    # thesis's (geometry.lie_bracket's docstring)
    true_det = 1.0 / (1.0 + grid[:, None] ** 2) ** 2
    printed_det = -((1.0 + grid[:, None] ** 2) ** 2)

    def t1(q):
        return np.array([1 + q[2] ** 2, q[2], q[0] * q[2]])

    def t2(q):
        s = 1 + q[0] ** 2 + q[2] ** 2
        return np.array([q[2] * (2 + q[0] ** 2 + q[2] ** 2), s, q[0] * s])

    # printed fields vs J⁺e₁, J⁺e₂, up to a positive factor per point (direction only)
    def direction_gap(printed, exact):
        gaps = []
        for a, b in pts:
            q = np.array([a, 0.3, b])
            u, v = printed(q), exact(q)
            gaps.append(np.linalg.norm(u / np.linalg.norm(u) - v / np.linalg.norm(v)))
        return float(max(gaps))

    printed = np.array([g.bracket_determinant(t1, t2, [a, 0.3, 0.7]) for a in grid])
    formula = -((1 + grid**2) ** 2)
    return {
        "grid_q1_q3": grid.tolist(),
        "abs_det_min": float(np.abs(dets).min()),
        "abs_det_max": float(np.abs(dets).max()),
        "det_over_true_formula_max_dev": float(np.abs(dets / true_det - 1.0).max()),
        "det_over_printed_formula_min": float((dets / printed_det).min()),
        "det_over_printed_formula_max": float((dets / printed_det).max()),
        "printed_f1_vs_pinv_e1_direction_gap": direction_gap(t1, f1),
        "printed_f2_vs_pinv_e2_direction_gap": direction_gap(t2, f2),
        "printed_fields_det_over_thesis_formula": (printed / formula).tolist(),
        "_dets": dets,
    }


def example_4_3(grid: np.ndarray) -> dict:
    arm = qc.robots.load("planar_3r")
    F1 = g.PseudoInverseField(arm, [1.0, 0.0])
    F2 = g.PseudoInverseField(arm, [0.0, 1.0])
    general, aligned, printed_gap, flipped_gap = [], [], [], []
    for a in grid:
        for b in grid:
            q = np.array([0.0, a, b])  # q1 = 0 without loss: rotating the arm changes nothing
            s = np.linalg.svd(arm.jacobian(q), compute_uv=False)
            if s[-1] < 1e-2:  # stretched or folded: J⁺ undefined
                continue
            d = abs(g.bracket_determinant(F1, F2, q))
            p1, p2 = printed_3r_fields(q)
            P = np.linalg.pinv(arm.jacobian(q))
            printed_gap.append(np.abs(np.stack([p1 - P[:, 0], p2 - P[:, 1]])))
            flipped_gap.append(np.abs(np.stack([p1 + P[:, 0], p2 + P[:, 1]])))
            gaps = np.abs(np.angle(np.exp(1j * (q[[0, 0, 1]] - q[[1, 2, 2]]))))
            (aligned if gaps.min() < 1e-9 else general).append(d)
    general, aligned = np.array(general), np.array(aligned)
    return {
        "points_with_distinct_link_angles": int(general.size),
        "abs_det_min": float(general.min()),
        "abs_det_max": float(general.max()),
        "points_with_two_parallel_links": int(aligned.size),
        "abs_det_max_with_two_parallel_links": float(aligned.max()) if aligned.size else None,
        # [field, row]: max |printed Eq 4.6/4.7 − J⁺ column| over the grid
        "eq46_47_printed_minus_pinv_max": np.max(printed_gap, axis=0).tolist(),
        "eq46_47_printed_plus_pinv_max": np.max(flipped_gap, axis=0).tolist(),  # sign flip
    }


def example_4_4(samples: int) -> dict:
    arm = qc.robots.load("spatial_5r")
    path = qc.paths.LissajousSphere()
    c = path.center
    forms = qc.schemes.sphere_forms(arm, c, OMEGA_45)

    scheme = qc.schemes.InvolutiveBasis(arm, OMEGA_45, gain=10.0)
    traj = qc.simulate(
        arm, scheme, path, qc.robots.spatial_5r.Q0_THESIS, path.period, path.period / 200
    )
    pinv_defect, thm_defect = [], []
    for q in traj.q[:: max(1, len(traj.q) // samples)]:
        y = arm.position(q)
        v1, v2 = qc.schemes.sphere_basis(y, c)
        pinv_defect.append(
            g.involutivity_defect([g.PseudoInverseField(arm, v1), g.PseudoInverseField(arm, v2)], q)
        )
        ref = g.dual_fields(forms, q)
        f1 = lambda x, ref=ref: g.dual_fields(forms, x, previous=ref)[:, 0]  # noqa: E731
        f2 = lambda x, ref=ref: g.dual_fields(forms, x, previous=ref)[:, 1]  # noqa: E731
        thm_defect.append(g.involutivity_defect([f1, f2], q))
    return {
        "samples": len(pinv_defect),
        "pinv_sphere_fields_defect_min": float(min(pinv_defect)),
        "pinv_sphere_fields_defect_max": float(max(pinv_defect)),
        "thm42_fields_defect_max": float(max(thm_defect)),
    }


def claims(l41: dict, e43: dict, e44: dict) -> list[dict]:
    """Claim rows computed from the run's numbers (see the module docstring)."""
    ratio = np.array(l41["printed_fields_det_over_thesis_formula"])
    on_pinv = (l41["det_over_printed_formula_min"], l41["det_over_printed_formula_max"])
    lemma_formula_status = (
        "reproduced" if np.allclose(np.abs(on_pinv), 1.0, atol=1e-6) else "differs"
    )
    gap = np.array(e43["eq46_47_printed_minus_pinv_max"])  # [f1 rows, f2 rows]
    flip = np.array(e43["eq46_47_printed_plus_pinv_max"])
    wrong = [
        f"f{i + 1} row {j + 1}"
        + (" (matches with its sign flipped)" if flip[i, j] < EQ_TOL else "")
        for i, j in zip(*np.nonzero(gap > EQ_TOL), strict=True)
    ]
    return [
        claim(
            "lemma4.1-not-involutive",
            "Pulling the involutive v₁ = e₁, v₂ = e₂ back through J⁺ of x = (q₁, q₂ + q₁q₃) "
            "gives non-involutive fields.",
            "Lemma 4.1: det[f₁, f₂, [f₁, f₂]] = −(1 + q₁²)² ≠ 0",
            f"|det| {l41['abs_det_min']:.3g}–{l41['abs_det_max']:.3g} on "
            f"{len(l41['grid_q1_q3'])}² grid points (q₂ = 0.3)",
            "reproduced" if l41["abs_det_min"] > DET_MIN else "differs",
            f"criterion: |det| > {DET_MIN:g} at every grid point",
        ),
        claim(
            "lemma4.1-formula",
            "For x = (q₁, q₂ + q₁q₃), f₁ = J⁺e₁ = (1 + q₃², q₃, q₁q₃) and f₂ = J⁺e₂ as "
            "printed, and det[f₁, f₂, [f₁, f₂]] = −(1 + q₁²)².",
            "Lemma 4.1 proof: printed f₁, f₂ and det = −(1 + q₁²)²",
            f"J⁺'s own fields: det = 1/(1 + q₁²)² (qpcoord's bracket sign; max relative "
            f"deviation {l41['det_over_true_formula_max_dev']:.1e}), i.e. det / (−(1 + q₁²)²) "
            f"from {l41['det_over_printed_formula_min']:.3g} to "
            f"{l41['det_over_printed_formula_max']:.3g}; the printed fields' directions are "
            f"{l41['printed_f1_vs_pinv_e1_direction_gap']:.2f} (f₁) and "
            f"{l41['printed_f2_vs_pinv_e2_direction_gap']:.2f} (f₂) from J⁺e₁, J⁺e₂ "
            "(unit vectors, max over the grid)",
            lemma_formula_status,
            "Criterion: the lemma's determinant, computed on J⁺'s own fields "
            "J⁺e₁ = (1 + q₁², −q₃, −q₁q₃)/(1 + q₁²), J⁺e₂ = (0, 1, q₁)/(1 + q₁²), equals "
            "±(1 + q₁²)² to 1e-6 (± for the bracket's sign convention). "
            + (
                "It does not: the printed f₁, f₂ are not J⁺e₁, J⁺e₂ and the true determinant "
                "is ±1/(1 + q₁²)² (−1/(1 + q₁²)² in the thesis's sign); it is still non-zero, "
                "so the lemma's conclusion stands (row lemma4.1-not-involutive). The printed "
                "fields do give −(1 + q₁²)² up to the sign convention (ratio "
                f"{ratio.min():.6g} … {ratio.max():.6g})."
                if lemma_formula_status == "differs"
                else ""
            ),
            cause="thesis error" if lemma_formula_status == "differs" else "",
        ),
        claim(
            "ex4.3-not-involutive",
            "On the 3R arm, J⁺e₁ and J⁺e₂ are not involutive.",
            "Ex 4.3, Eq 4.8: Det{f₁, f₂, [f₁, f₂]} ≠ 0",
            f"|det| {e43['abs_det_min']:.3g}–{e43['abs_det_max']:.3g} on "
            f"{e43['points_with_distinct_link_angles']} configurations with distinct link "
            f"angles; ≤ {e43['abs_det_max_with_two_parallel_links']:.1e} on the "
            f"{e43['points_with_two_parallel_links']} with two parallel links",
            "reproduced" if e43["abs_det_min"] > DET_MIN else "differs",
            f"criterion: |det| > {DET_MIN:g} wherever no two links are parallel (where two are, "
            "it vanishes: a measure-zero set the thesis does not mention)",
        ),
        claim(
            "ex4.3-eq4.6-4.7",
            "Eqs 4.6–4.7 are the columns of J⁺ for the 3R arm.",
            "Ex 4.3, Eqs 4.6, 4.7 (f₁ = J⁺e₁, f₂ = J⁺e₂)",
            f"max |printed − J⁺ column|: f₁ rows {', '.join(f'{x:.1e}' for x in gap[0])}; "
            f"f₂ rows {', '.join(f'{x:.1e}' for x in gap[1])}",
            "reproduced" if not wrong else "differs",
            f"criterion: every row within {EQ_TOL:g} on the grid"
            + (f"; mismatched: {', '.join(wrong)}" if wrong else ""),
        ),
        claim(
            "thm4.2-involutive",
            "The dual fields of (ω₁, ω₄, ω₅) are involutive.",
            "Thm 4.2, Ex 4.4: involutive by construction",
            f"involutivity defect ≤ {e44['thm42_fields_defect_max']:.2e} at "
            f"{e44['samples']} points of the 5R path",
            "reproduced" if e44["thm42_fields_defect_max"] < DEFECT_FLOOR else "differs",
            f"criterion: defect < {DEFECT_FLOOR:g} (the finite-difference floor) everywhere",
        ),
        claim(
            "sec4.3.3-pinv-basis-not-involutive",
            "The J⁺-pulled sphere basis J⁺v₁, J⁺v₂ need not be involutive.",
            "§4.3.3 after Thm 4.1: 'f₁ and f₂ could very well not be involutive'",
            f"involutivity defect {e44['pinv_sphere_fields_defect_min']:.2g}–"
            f"{e44['pinv_sphere_fields_defect_max']:.2g} at {e44['samples']} points",
            "reproduced"
            if e44["pinv_sphere_fields_defect_max"] > 100 * DEFECT_FLOOR
            else "differs",
            f"criterion: defect > {100 * DEFECT_FLOOR:g} (100× the floor) at some point",
        ),
    ]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="the full run (its grids are CI-sized)")
    p.add_argument("--out", type=Path, default=Path("out/ch4_involutivity"))
    args = p.parse_args(argv)
    log = TextLog()
    say = log.say

    n = 25
    grid = np.linspace(-2.0, 2.0, n)
    l41 = lemma_4_1(grid)
    e43 = example_4_3(np.linspace(-np.pi, np.pi, n))
    e44 = example_4_4(20)
    dets = l41.pop("_dets")
    say(
        f"Lemma 4.1: |det[f1, f2, [f1, f2]]| on the grid in [{l41['abs_det_min']:.3g}, "
        f"{l41['abs_det_max']:.3g}]; printed fields / printed formula: "
        f"{min(l41['printed_fields_det_over_thesis_formula']):.6g} … "
        f"{max(l41['printed_fields_det_over_thesis_formula']):.6g}"
    )
    say(
        f"Ex 4.3 (3R): |det| in [{e43['abs_det_min']:.3g}, {e43['abs_det_max']:.3g}] "
        f"over {e43['points_with_distinct_link_angles']} configurations with distinct link "
        f"angles; ≤ {e43['abs_det_max_with_two_parallel_links']:.1e} on the "
        f"{e43['points_with_two_parallel_links']} with two parallel links"
    )
    say(
        f"Ex 4.4 (5R): J⁺ sphere fields defect {e44['pinv_sphere_fields_defect_min']:.3g}"
        f"–{e44['pinv_sphere_fields_defect_max']:.3g}; Thm 4.2 fields defect ≤ "
        f"{e44['thm42_fields_defect_max']:.3g}"
    )
    try:
        from qpcoord.studies.figures import _pyplot, save
    except ImportError:  # pragma: no cover - matplotlib missing
        say("matplotlib not installed: figures skipped")
    else:
        plt = _pyplot()
        fig, ax = plt.subplots(figsize=(5, 4))
        im = ax.imshow(
            np.log10(np.abs(dets)),
            origin="lower",
            extent=[grid[0], grid[-1], grid[0], grid[-1]],
            cmap="viridis",
        )
        fig.colorbar(im, label="log10 |det[f1, f2, [f1, f2]]|")
        ax.set_xlabel("q3")
        ax.set_ylabel("q1")
        ax.set_title("Lemma 4.1: J⁺-pulled fields, q2 = 0.3")
        save(fig, args.out / "lemma41_det.png")
    rows = claims(l41, e43, e44)
    for c in rows:
        say(f"{c['id']}: {c['measured']} -> {c['status']}")
    log.write(args.out / "summary.txt")
    write_json(
        args.out / "summary.json",
        {"lemma_4_1": l41, "example_4_3": e43, "example_4_4": e44, "claims": rows},
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
