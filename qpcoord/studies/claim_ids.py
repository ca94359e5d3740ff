"""One stable ID per thesis claim: which claim rows of which example scripts check it.

Several example scripts check the same thesis statement (Table 6.1's direct-coil RMSE in three
scripts, Def 5.4's decoupling on six stacks); the report counts each thesis claim once, under
the ID given here. A row of a script is keyed by ``(script stem, row id)``.

An entry also says whether the claim is *calibrated* -- an input taken from the thesis (the
piezo's 300 Hz, the coarse stage's 120 Hz, the 2.25 W of the field current, the ±150 N of the
flexure), shown in the report but never counted as reproduced -- or an *identity* -- a
statement that holds by construction in qpcoord (an identity of the scheme, our own solver's
residual or hard constraint), checked and shown but never counted as reproduced -- and the
*cause class* of a ``"differs"`` verdict when the row itself does not give one
(:data:`CAUSES`).

Rows with status ``"own check"`` (``"not in thesis"``) are qpcoord's own checks; they need no
entry and are counted by row, under the ID ``"own:<script>:<row>"``.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "CAUSES",
    "CONTRADICTIONS",
    "REGISTER",
    "Contradiction",
    "ThesisClaim",
    "claim_id",
    "lookup",
]

#: Why a ``"differs"`` verdict differs: the thesis is wrong (a printed formula, a conjecture a
#: counterexample refutes); the thesis's number comes from hardware we simulate (noise sources,
#: unmodelled modes, an unknown test signal); or a modelling choice of ours (a controller, an
#: arm, a plant the thesis does not specify).
CAUSES = ("thesis error", "hardware data", "our model")


@dataclass(frozen=True)
class ThesisClaim:
    """A thesis claim's ID, whether it is a calibrated input or an identity (holds by
    construction), and its default cause class."""

    id: str
    calibrated: bool = False
    cause: str = ""
    identity: bool = False

    def __post_init__(self) -> None:
        if self.cause and self.cause not in CAUSES:
            raise ValueError(f"cause must be one of {CAUSES} or empty, got {self.cause!r}")
        if self.calibrated and self.identity:
            raise ValueError(f"{self.id}: a claim is calibrated or an identity, not both")


def _c(cid: str, cause: str = "", calibrated: bool = False, identity: bool = False) -> ThesisClaim:
    return ThesisClaim(cid, calibrated, cause, identity)


def _i(cid: str) -> ThesisClaim:
    """An identity: holds by construction (its rows check it; a failure is a bug, differs)."""
    return ThesisClaim(cid, identity=True)


#: ``(script stem, row id) → ThesisClaim``. The first row listed for an ID is its home (the
#: chapter of the claim in the report's summary).
REGISTER: dict[tuple[str, str], ThesisClaim] = {
    # chapter 4
    ("ch4_periodicity", "fig4.3a-tracking"): _c("Fig4.3a-tracking"),
    ("ch4_periodicity", "fig4.3b-pinv-not-periodic"): _c("Fig4.3b-pinv-not-periodic"),
    ("ch4_periodicity", "fig4.4-basis-improves"): _c("Fig4.4-basis-improves", "thesis error"),
    ("ch4_periodicity", "thm4.2-fig4.6-periodic"): _c("Thm4.2-periodic"),
    ("ch4_involutivity", "lemma4.1-not-involutive"): _c("Lem4.1-not-involutive"),
    ("ch4_involutivity", "lemma4.1-formula"): _c("Lem4.1-det-formula", "thesis error"),
    ("ch4_involutivity", "ex4.3-not-involutive"): _c("Ex4.3-not-involutive"),
    ("ch4_involutivity", "ex4.3-eq4.6-4.7"): _c("Ex4.3-Eq4.6-4.7-fields", "thesis error"),
    ("ch4_involutivity", "thm4.2-involutive"): _c("Thm4.2-involutive"),
    ("ch4_involutivity", "sec4.3.3-pinv-basis-not-involutive"): _c(
        "Sec4.3.3-pinv-basis-not-involutive"
    ),
    ("ch4_leaves", "lemma4.2-leaf-changes"): _c("Lem4.2-leaf-changes"),
    ("ch4_leaves", "ex4.4-stays-on-leaf"): _i("Ex4.4-stays-on-leaf"),
    ("ch4_leaves", "lemma4.2-each-leaf-periodic"): _c("Lem4.2-each-leaf-periodic"),
    ("ch4_long_runs", "rem4.4-fig4.7-5r-closes"): _c("Rem4.4-Fig4.7-5r-closes", "our model"),
    ("ch4_long_runs", "conj4.1-delta1"): _c("Conj4.1-delta1", "thesis error"),
    ("ch4_long_runs", "conj4.1-delta2"): _c("Conj4.1-delta2", "thesis error"),
    ("ch4_long_runs", "conj4.1-delta3"): _c("Conj4.1-delta3", "thesis error"),
    # chapter 5
    ("ch5_task_manifold", "sec5.2.1-torus"): _c("Sec5.2.1-torus", "thesis error"),
    ("ch5_limit_cycle", "rem5.2-pinv-drifts"): _c("Rem5.2-pinv-drifts"),
    ("ch5_task_manifold", "fig5.1-pinv-not-closed"): _c("Rem5.2-pinv-drifts"),
    ("ch5_limit_cycle", "thm5.1-alpha0.3"): _c("Thm5.1-limit-cycle"),
    ("ch5_limit_cycle", "thm5.1-alpha1"): _c("Thm5.1-limit-cycle"),
    ("ch5_limit_cycle", "thm5.1-alpha3"): _c("Thm5.1-limit-cycle"),
    ("ch5_limit_cycle", "thm5.1-alpha10"): _c("Thm5.1-limit-cycle"),
    ("ch5_task_manifold", "fig5.3-limit-cycle"): _c("Thm5.1-limit-cycle"),
    ("ch5_limit_cycle", "eq5.13-band"): _c("Eq5.13-band", "thesis error"),
    ("ch5_fixed_point", "prop5.1-lyapunov"): _i("Prop5.1-lyapunov"),
    ("ch5_fixed_point", "prop5.1-fixed-point"): _c("Prop5.1-fixed-point"),
    ("ch5_5r_potentials", "fig5.4-two-potentials"): _c("Fig5.4-two-potentials", "our model"),
    ("ch5_5r_potentials", "conj5.1-one-potential"): _c("Conj5.1-one-potential", "thesis error"),
    ("ch5_hierarchy", "def5.4-level1-kept"): _i("Def5.4-decoupling"),
    ("ch5_hierarchy", "def5.4-level2-kept"): _i("Def5.4-decoupling"),
    ("core_priorities", "def5.4-strict-keeps-main"): _i("Def5.4-decoupling"),
    ("panda_circle_ik", "def5.4-ee-level-kept"): _i("Def5.4-decoupling"),
    ("panda_pose", "def5.4-table-kept"): _i("Def5.4-decoupling"),
    ("solo12_body", "def5.4-feet-kept"): _i("Def5.4-decoupling"),
    ("ch5_hierarchy", "sec5.3.5-limits-level"): _c("Sec5.3.5-limits-level"),
    ("ch5_hessian", "sec5.4-limit-cycle"): _c("Sec5.4-limit-cycle", "our model"),
    ("ch5_hessian", "sec5.4-no-singularity"): _c("Sec5.4-no-singularity", "our model"),
    ("ch5_compliant", "fig5.9-periodic"): _c("Fig5.9-periodic", "our model"),
    ("ch5_compliant", "eq5.20-plane"): _i("Eq5.20-plane"),
    ("ch5_compliant", "fig5.8a-cycle-per-qbar"): _c("Fig5.8a-cycle-per-qbar"),
    ("ch5_compliant", "fig5.8b-pinv-drifts"): _c("Fig5.8b-pinv-drifts"),
    # chapter 6
    ("ch6_tracking", "spec-rmse-70nm"): _c("Spec6.1.2-rmse-70nm", "our model"),
    ("ch6_tracking", "table6.1-rmse"): _c("T6.1-direct-coil-rmse", "our model"),
    ("ch6_compare", "table6.1-coordinator"): _c("T6.1-direct-coil-rmse", "our model"),
    ("sweep_ddl_seeds", "table6.1-rmse-nominal"): _c("T6.1-direct-coil-rmse", "our model"),
    ("ch6_tracking", "table6.1-max"): _c("T6.1-direct-coil-max", "our model"),
    ("ch6_tracking", "table6.1-mean"): _c("T6.1-direct-coil-mean", "our model"),
    ("ch6_tracking", "table6.1-power"): _c("T6.1-direct-coil-power-2.25W", calibrated=True),
    ("ch6_tracking", "fig6.7-coarse-resonance"): _c("Fig6.7-coarse-120Hz", calibrated=True),
    ("ch6_tracking", "fig6.6-piezo-bandwidth"): _c("Fig6.6-piezo-300Hz", calibrated=True),
    ("ch6_tracking", "fig6.16-fine-never-saturates"): _c("Fig6.16-fine-never-saturates"),
    ("ch6_tracking", "fig6.17-best-run"): _c("Fig6.17-best-run", "our model"),
    ("ch6_compare", "table6.1-FlatnessBased"): _c("T6.1-flatness-rmse", "our model"),
    ("ch6_compare", "table6.1-PILinearised"): _c("T6.1-pi-linearised-rmse", "our model"),
    ("ch6_compare", "table6.1-PQCurrent"): _c("T6.1-pq-rmse", "our model"),
    ("ch6_compare", "table6.1-LQRCurrent"): _c("T6.1-lqr-rmse", "our model"),
    ("ch6_compare", "table6.1-siso-similar"): _c("T6.1-siso-similar", "our model"),
    ("ch6_compare", "table6.1-linearised-power"): _c("T6.1-linearised-power", "our model"),
    ("ch6_compare", "table6.2-rms"): _c("T6.2-rms", "our model"),
    ("ch6_compare", "table6.2-emax"): _c("T6.2-emax", "our model"),
    ("ch6_compare", "table6.2-power"): _c("T6.2-power", "our model"),
    ("ch6_compare", "table6.2-step"): _c("T6.2-step", "our model"),
    ("ch6_compare", "table6.2-robustness"): _c("T6.2-robustness", "our model"),
    ("ch6_compare", "fig6.18b-fine-within-limits"): _c("Fig6.18b-fine-within-limits", "our model"),
    ("ch6_compare", "fig6.19a-lqr-desync"): _c("Fig6.19a-lqr-desync", "our model"),
    ("ch6_compare", "fig6.19b-linearised-stall"): _c("Fig6.19b-linearised-stall", "our model"),
    ("ch6_steps", "fig6.19a-step-centre"): _c("Fig6.19a-direct-coil-step-centre"),
    ("ch6_steps", "fig6.19b-step-extremity"): _c("Fig6.19b-direct-coil-step-extremity"),
    ("ch6_two_ddl", "fig6.14a-bandwidth-gain"): _c("Fig6.14a-bandwidth-gain-1.6", "our model"),
    ("ch6_two_ddl", "eq-two-ddl-combination"): _c("Eq6.3-two-ddl-combination"),
    ("ch6_two_ddl", "fig6.14b-step-faster"): _c("Fig6.14b-step-faster"),
    ("ch6_two_ddl", "fig6.14b-predictor-overshoot"): _c("Fig6.14b-predictor-overshoot"),
    # appendices
    ("appA_shoulder", "A.19-generalised-forces"): _i("EqA.19-generalised-forces"),
    ("appA_shoulder", "A.24-force-bounds"): _i("EqA.24-force-bounds"),
    ("appA_shoulder", "A.22-pseudo-inverse-pushes"): _c("SecA.3.2-pinv-pushes"),
    ("appA_shoulder", "A.28-stress-optimal"): _i("EqA.28-stress-optimal"),
    ("appA_shoulder", "A.3-forward-tracking"): _c("FigA.3-forward-tracking", "our model"),
    ("ch6_flexure", "appB-flexure-load"): _c("AppB-flexure-150N", calibrated=True),
    ("ch6_flexure", "figB.2-shape"): _c("FigB.2-shape"),
    ("ch6_flexure", "figB.2-magnitude"): _c("FigB.2-magnitude", "our model"),
    ("appC_preisach", "figC.8-sine-improvement"): _c("FigC.8-sine-improvement", "our model"),
    ("appC_preisach", "figC.8-sine-residual"): _c("FigC.8-sine-residual", "our model"),
    ("appC_preisach", "figC.10-stochastic-improvement"): _c(
        "FigC.10-stochastic-improvement", "our model"
    ),
    ("appC_preisach", "figC.10-stochastic-levels"): _c("FigC.10-stochastic-levels", "our model"),
}


def lookup(script: str, row_id: str) -> ThesisClaim | None:
    """The register's entry for a row, or None."""
    return REGISTER.get((script, row_id))


def claim_id(script: str, row_id: str, status: str) -> str:
    """The thesis-claim ID of a row: its register entry, else ``own:<script>:<row>`` for an
    own check, else ``unregistered:<script>:<row>`` (a thesis row nobody gave an ID)."""
    entry = REGISTER.get((script, row_id))
    if entry is not None:
        return entry.id
    if status in ("own check", "not in thesis"):
        return f"own:{script}:{row_id}"
    return f"unregistered:{script}:{row_id}"


@dataclass(frozen=True)
class Contradiction:
    """Two or more places of the thesis that state incompatible things about one quantity.

    ``says`` pairs each place (section, table, figure) with what it states; ``claims`` are the
    thesis-claim IDs whose verdict it bears on (their notes repeat it).
    """

    id: str
    about: str
    says: tuple[tuple[str, str], ...]
    claims: tuple[str, ...]


#: The thesis's internal contradictions, listed as such in the report (not counted as
#: claims: no run can decide which place is right).
CONTRADICTIONS: tuple[Contradiction, ...] = (
    Contradiction(
        "T6.1-vs-Sec6.4.2-Fig6.17",
        "Kolmogorov tracking error of the direct-coil coordinator (the same controller, the "
        "same kind of reference, on the same prototype)",
        (
            ("Table 6.1, Direct Coil", "25 nm RMS, 308 nm max, 19.6 nm mean"),
            (
                "§6.4.2, 'Final decoupled parallel SISO control scheme'",
                "'the rms residual tracking error is as low as the measurement noise "
                "(E < 8 nm rms)'",
            ),
            (
                "Fig 6.17 caption",
                "'a residual rms error less than 8 nm rms and a maximum instantaneous error "
                "of 30 nm' (content up to 200 Hz)",
            ),
        ),
        ("T6.1-direct-coil-rmse", "T6.1-direct-coil-max", "Fig6.17-best-run"),
    ),
)
