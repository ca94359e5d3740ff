"""Decision rules of the reproduction that more than one script, or a test, applies.

Each rule takes measured values and returns a claim status (:data:`.claims.CLAIM_STATUSES`)
with the reason in one sentence, so that a test can feed it a case that must fail
(tests/studies/test_criteria.py).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

__all__ = [
    "across_assumptions",
    "coordination_spec",
    "fine_never_saturates",
    "needs_both_stages",
    "within",
]


def within(value: float, target: float, rel: float) -> bool:
    """``|value − target| ≤ rel · |target|``; False for a non-finite value.

    Raises
    ------
    ValueError
        If ``rel`` is negative or ``target`` is not finite.
    """
    if not rel >= 0.0:
        raise ValueError(f"rel must be >= 0, got {rel!r}")
    if not math.isfinite(target):
        raise ValueError(f"target must be finite, got {target!r}")
    return math.isfinite(value) and abs(value - target) <= rel * abs(target)


def needs_both_stages(reference_ptp: float, fine_stroke: float) -> bool:
    """A reference needs both stages if its peak-to-peak excursion exceeds the fine stroke
    (m): no placement of the fine stage alone could follow it."""
    if not fine_stroke > 0.0:
        raise ValueError(f"fine_stroke must be > 0 m, got {fine_stroke!r}")
    return bool(reference_ptp > fine_stroke)


def _checked(name: str, runs: Sequence[Mapping]) -> None:
    if not runs:
        raise ValueError(f"{name} must hold at least one run, got {runs!r}")


def _fine_stage_alone_copes(frozen: Sequence[Mapping], limit: float) -> list[int]:
    """Indices of the frozen-coarse control runs that still meet the spec."""
    return [
        i
        for i, m in enumerate(frozen)
        if m["rmse"] < limit and m["saturated_steps"] == 0 and not m["lost_sync"]
    ]


def coordination_spec(
    runs: Sequence[Mapping], frozen: Sequence[Mapping], limit: float = 70e-9
) -> tuple[str, str]:
    """The tracking spec judged on references that need coordination.

    Parameters
    ----------
    runs : sequence of mapping
        Metrics (``rmse`` m, ``saturated_steps``, ``lost_sync``) of the coordinator's runs,
        one per reference.
    frozen : sequence of mapping
        The same references with the coarse stage frozen (the control).
    limit : float
        RMSE limit, m (§6.1.2: 70 nm).

    Returns
    -------
    (status, reason)
        ``"differs"`` if some run's RMSE reaches ``limit``; else ``"inconclusive"`` if the
        fine stage alone (frozen control) meets the spec on some reference -- that
        reference does not test coordination; else ``"reproduced"``.
    """
    _checked("runs", runs)
    _checked("frozen", frozen)
    bad = [i for i, m in enumerate(runs) if not m["rmse"] < limit]
    if bad:
        return "differs", f"RMSE ≥ {limit * 1e9:g} nm on reference(s) {bad}"
    alone = _fine_stage_alone_copes(frozen, limit)
    if alone:
        return "inconclusive", (
            f"the fine stage alone (coarse frozen) meets the spec on reference(s) {alone}: "
            "they do not need coordination"
        )
    return "reproduced", "met on every reference; the frozen-coarse control fails on every one"


def fine_never_saturates(runs: Sequence[Mapping], frozen: Sequence[Mapping]) -> tuple[str, str]:
    """Fig 6.16's "the fine stage never saturates", on references that need coordination.

    ``"differs"`` if a coordinator run has a saturated step or lost synchronism; else
    ``"inconclusive"`` if a frozen-coarse control run never saturates (that reference stays
    inside the fine stroke by itself); else ``"reproduced"``. Arguments as
    :func:`coordination_spec`.
    """
    _checked("runs", runs)
    _checked("frozen", frozen)
    bad = [i for i, m in enumerate(runs) if m["saturated_steps"] > 0 or m["lost_sync"]]
    if bad:
        return "differs", f"saturated or lost synchronism on reference(s) {bad}"
    alone = [i for i, m in enumerate(frozen) if m["saturated_steps"] == 0]
    if alone:
        return "inconclusive", (
            f"with the coarse stage frozen the fine stage does not saturate either on "
            f"reference(s) {alone}: they do not need coordination"
        )
    return "reproduced", "no saturation on any reference; the frozen-coarse control saturates"


def across_assumptions(values: Mapping[str, float], target: float, rel: float) -> tuple[str, str]:
    """A thesis number judged over a range of assumptions it depends on.

    Parameters
    ----------
    values : mapping
        The measured value under each plausible assumption (e.g. the test signal's vibration
        lines absent, as shipped, doubled).
    target, rel : float
        The thesis's number and the relative tolerance (:func:`within`).

    Returns
    -------
    (status, reason)
        ``"reproduced"`` if every value is within the tolerance, ``"differs"`` if none is,
        else ``"inconclusive"``: the number depends on the assumption the thesis does not fix.
    """
    if not values:
        raise ValueError(f"values must name at least one assumption, got {values!r}")
    inside = {k: within(v, target, rel) for k, v in values.items()}
    if all(inside.values()):
        return "reproduced", f"within ±{100 * rel:g} % under every assumption"
    if not any(inside.values()):
        return "differs", f"outside ±{100 * rel:g} % under every assumption"
    yes = ", ".join(k for k, v in inside.items() if v)
    no = ", ".join(k for k, v in inside.items() if not v)
    return "inconclusive", (
        f"inside ±{100 * rel:g} % for {yes}, outside for {no}: the value depends on an "
        "assumption the thesis does not fix"
    )
