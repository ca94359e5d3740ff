"""Rows of a reproduction's claims table: what an example checked against the thesis."""

from __future__ import annotations

__all__ = ["claim", "CLAIM_STATUSES"]

#: What a claim row can say about the thesis: its number or behaviour was reproduced; we
#: measured something different (``note`` says why); it cannot be decided -- the run was too
#: short (e.g. ``--quick``) or the thesis gives too little to compare with (``note`` says
#: what would decide it); or the row is ours (no thesis number).
CLAIM_STATUSES = ("reproduced", "differs", "inconclusive", "not in thesis")


def claim(
    id: str,
    claim: str,
    thesis: str,
    measured: str,
    status: str,
    note: str = "",
) -> dict:
    """One row of a reproduction's claims table, as stored in an example's ``summary.json``.

    Every example lists what it checked against the thesis under ``summary["claims"]``;
    ``qpcoord reproduce`` gathers these rows into its report.

    Parameters
    ----------
    id : str
        Short stable key, unique within the example (e.g. ``"thm4.2-closure"``).
    claim : str
        What the thesis asserts, in one sentence.
    thesis : str
        Where and what the thesis says (figure, table, equation and its number).
    measured : str
        What this run measured, with units (a number formatted as text).
    status : str
        One of :data:`CLAIM_STATUSES`.
    note : str, optional
        Why a ``"differs"`` row differs, what an ``"inconclusive"`` row would need, or how
        the number was measured. Required for those two statuses.

    Returns
    -------
    dict
        ``{"id", "claim", "thesis", "measured", "status", "note"}``.

    Raises
    ------
    ValueError
        If ``status`` is not one of :data:`CLAIM_STATUSES`, a text field is empty, or a
        ``"differs"`` or ``"inconclusive"`` row has no ``note``.
    """
    fields = {"id": id, "claim": claim, "thesis": thesis, "measured": measured}
    for name, value in fields.items():
        if not isinstance(value, str) or not value.strip():
            raise ValueError(f"claim {name} must be a non-empty string, got {value!r}")
    if status not in CLAIM_STATUSES:
        raise ValueError(f"claim status must be one of {CLAIM_STATUSES}, got {status!r}")
    if status in ("differs", "inconclusive") and not note.strip():
        raise ValueError(f"claim {id!r} has status {status!r} but no note saying why")
    return {**fields, "status": status, "note": note}
