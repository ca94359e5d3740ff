"""Rows of a reproduction's claims table, and the thesis claims they add up to.

A *row* is what one example script checked (:func:`claim`); a *thesis claim* is one statement
of the thesis under one stable ID (:mod:`qpcoord.studies.claim_ids`), which several rows may
check. :func:`thesis_claims` merges rows into claims: the report counts claims, not rows.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

from .claim_ids import CAUSES, REGISTER, claim_id

__all__ = [
    "claim",
    "thesis_claims",
    "CLAIM_STATUSES",
    "QUICK",
    "CAUSES",
    "count_claims",
    "load_verdicts",
    "verdict_mismatches",
]

#: What a claim row can say about the thesis: its number or behaviour was reproduced; we
#: measured something different (``note`` says why, ``cause`` classes it, :data:`CAUSES`); it
#: cannot be decided -- the thesis gives too little to compare with, or the result depends on
#: an assumption it does not fix (``inconclusive``, ``note`` says what would decide it); this
#: ``--quick`` run cannot apply the full run's rule (:data:`QUICK`: shorter runs, fewer seeds or
#: cases -- never decided differently from the full run); the statement holds by construction
#: (``identity``: an identity, or our own solver's residual or constraint -- checked, shown,
#: never counted as reproduced); the number is an input taken from the thesis
#: (``calibrated``: shown, never counted as reproduced); or the row is our own check with no
#: thesis number (``own check``; the older spelling ``"not in thesis"`` is accepted).
CLAIM_STATUSES = (
    "reproduced",
    "differs",
    "inconclusive",
    "inconclusive (quick)",
    "identity",
    "calibrated",
    "own check",
)

#: The status of a row a ``--quick`` run cannot decide with the full run's rule.
QUICK = "inconclusive (quick)"

_ALIASES = {"not in thesis": "own check"}


def claim(
    id: str,
    claim: str,
    thesis: str,
    measured: str,
    status: str,
    note: str = "",
    cause: str = "",
) -> dict:
    """One row of a reproduction's claims table, as stored in an example's ``summary.json``.

    Every example lists what it checked against the thesis under ``summary["claims"]``;
    ``qpcoord reproduce`` gathers these rows into its report.

    Parameters
    ----------
    id : str
        Short stable key, unique within the example (e.g. ``"thm4.2-closure"``). The thesis
        claim it checks is given by :data:`qpcoord.studies.claim_ids.REGISTER`.
    claim : str
        What the thesis asserts, in one sentence.
    thesis : str
        Where and what the thesis says (figure, table, equation and its number).
    measured : str
        What this run measured, with units (a number formatted as text).
    status : str
        One of :data:`CLAIM_STATUSES` (``"not in thesis"`` is read as ``"own check"``).
    note : str, optional
        Why a ``"differs"`` row differs, what an ``"inconclusive"`` row (or :data:`QUICK`)
        would need, where a ``"calibrated"`` input comes from, why an ``"identity"`` holds by
        construction, or how the number was measured. Required for those statuses.
    cause : str, optional
        For a ``"differs"`` row: one of :data:`CAUSES` (else the register's default applies).

    Returns
    -------
    dict
        ``{"id", "claim", "thesis", "measured", "status", "note", "cause"}``.

    Raises
    ------
    ValueError
        If ``status`` is not one of :data:`CLAIM_STATUSES`, a text field is empty, a row
        other than ``"reproduced"`` or ``"own check"`` has no ``note``, or ``cause``
        is not one of :data:`CAUSES` (or is given for a row that does not differ).
    """
    fields = {"id": id, "claim": claim, "thesis": thesis, "measured": measured}
    for name, value in fields.items():
        if not isinstance(value, str) or not value.strip():
            raise ValueError(f"claim {name} must be a non-empty string, got {value!r}")
    status = _ALIASES.get(status, status)
    if status not in CLAIM_STATUSES:
        raise ValueError(f"claim status must be one of {CLAIM_STATUSES}, got {status!r}")
    if status not in ("reproduced", "own check") and not str(note).strip():
        raise ValueError(f"claim {id!r} has status {status!r} but no note saying why")
    if cause and cause not in CAUSES:
        raise ValueError(f"claim cause must be one of {CAUSES} or empty, got {cause!r}")
    if cause and status != "differs":
        raise ValueError(f"claim {id!r}: a cause is only given for 'differs', not {status!r}")
    return {**fields, "status": status, "note": note, "cause": cause}


def thesis_claims(rows: Iterable[tuple[str, str, dict]]) -> dict[str, dict]:
    """Merge claim rows into thesis claims, one per ID.

    Parameters
    ----------
    rows : iterable of (chapter, script, row)
        Every row of every script, ``row`` as written by :func:`claim`.

    Returns
    -------
    dict
        ``ID → {"id", "chapter", "status", "cause", "rows"}``, where ``rows`` lists
        ``{"script", "id", "status"}`` of the rows checking it. The status of a claim: an
        own check's own; otherwise ``"differs"`` if any row differs (a calibrated input
        whose check fails too); else ``"calibrated"`` for an input taken from the thesis;
        else ``"identity"`` for a claim that holds by
        construction (the register's ``identity``, or a row saying so); else ``"reproduced"``
        if every row of the claim's *home* script (the script of its first registered row,
        where the claim is judged in full, e.g. with a sensitivity sweep) reproduced it --
        or, the home script not run, if any row did; else :data:`QUICK` if a row says so;
        else ``"inconclusive"``. The chapter is
        the home row's, else the first row's. ``cause`` (for ``"differs"``) is the first
        differing row's, else the register's, else ``"unclassified"``.
    """
    home = {}
    for (script, _), entry in REGISTER.items():
        home.setdefault(entry.id, script)
    out: dict[str, dict] = {}
    for chapter, script, row in rows:
        status = _ALIASES.get(row.get("status", ""), row.get("status", ""))
        cid = claim_id(script, row.get("id", "?"), status)
        c = out.setdefault(cid, {"id": cid, "chapter": chapter, "rows": [], "_causes": []})
        if home.get(cid) == script:
            c["chapter"] = chapter
        c["rows"].append({"script": script, "id": row.get("id", "?"), "status": status})
        if status == "differs":
            c["_causes"].append(row.get("cause") or "")
    for cid, c in out.items():
        entry = next((e for e in REGISTER.values() if e.id == cid), None)
        statuses = [r["status"] for r in c["rows"]]
        at_home = [r["status"] for r in c["rows"] if r["script"] == home.get(cid)]
        if cid.startswith("own:"):
            status = statuses[0]
        elif "differs" in statuses:  # a failed calibration or identity check is shown
            status = "differs"
        elif (entry is not None and entry.calibrated) or "calibrated" in statuses:
            status = "calibrated"
        elif (entry is not None and entry.identity) or "identity" in statuses:
            status = "identity"
        elif all(s == "reproduced" for s in at_home) if at_home else "reproduced" in statuses:
            status = "reproduced"
        elif QUICK in statuses:
            status = QUICK
        elif all(s in CLAIM_STATUSES for s in statuses):
            status = "inconclusive"
        else:
            status = "invalid"
        cause = ""
        if status == "differs":
            given = [x for x in c.pop("_causes") if x]
            cause = given[0] if given else (entry.cause if entry and entry.cause else "")
            cause = cause or "unclassified"
        else:
            c.pop("_causes")
        c["status"], c["cause"] = status, cause
    return out


def count_claims(claims: Iterable[dict]) -> dict[str, int]:
    """Counts of thesis claims per status, with ``"differs: <cause>"`` per cause class."""
    out = dict.fromkeys(CLAIM_STATUSES, 0)
    out.update({f"differs: {c}": 0 for c in (*CAUSES, "unclassified")})
    for c in claims:
        out[c["status"]] = out.get(c["status"], 0) + 1
        if c["status"] == "differs":
            key = f"differs: {c['cause']}"
            out[key] = out.get(key, 0) + 1
    return out


def load_verdicts(path) -> dict[str, dict]:
    """Read a verdict file: a JSON object ``{"<claim ID>": {"quick": ..., "full": ...}}`` of
    expected statuses, with an optional ``cause`` (of a ``"differs"``) and ``why`` (text).
    Keys starting with ``"_"`` are comments.

    Raises
    ------
    ValueError
        If a status is not one of :data:`CLAIM_STATUSES`, a cause not one of :data:`CAUSES`,
        a ``"differs"`` entry has no cause, or the quick status is neither the full one nor
        :data:`QUICK` (quick never decides differently from the full run).
    """
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    data = {k: v for k, v in data.items() if not k.startswith("_")}
    for cid, entry in data.items():
        if not isinstance(entry, dict):
            raise ValueError(f"verdict {cid!r} must be a table, got {entry!r}")
        for mode in ("quick", "full"):
            st = entry.get(mode)
            if st not in CLAIM_STATUSES:
                raise ValueError(
                    f"verdict {cid!r}: {mode} must be one of {CLAIM_STATUSES}, got {st!r}"
                )
        cause = entry.get("cause", "")
        if cause and cause not in CAUSES:
            raise ValueError(f"verdict {cid!r}: cause must be one of {CAUSES}, got {cause!r}")
        if "differs" in (entry["quick"], entry["full"]) and not cause:
            raise ValueError(f"verdict {cid!r} differs but gives no cause")
        if entry["full"] == QUICK:
            raise ValueError(f"verdict {cid!r}: the full run is never {QUICK!r}")
        if entry["quick"] not in (entry["full"], QUICK):
            raise ValueError(
                f"verdict {cid!r}: quick {entry['quick']!r} decides differently from full "
                f"{entry['full']!r} (a quick run that cannot apply the full rule says {QUICK!r})"
            )
    return data


def verdict_mismatches(claims: dict[str, dict], verdicts: dict[str, dict], mode: str) -> list[str]:
    """What differs between a run's thesis claims and the verdict file, one line each.

    Parameters
    ----------
    claims : dict
        :func:`thesis_claims` of a run (own checks are ignored).
    verdicts : dict
        :func:`load_verdicts`.
    mode : {"quick", "full"}
        Which expected status to compare with.

    Returns
    -------
    list of str
        Empty if every claim of the run has the expected status (and cause), every claim is
        in the file and every claim of the file was checked by the run.
    """
    if mode not in ("quick", "full"):
        raise ValueError(f"mode must be 'quick' or 'full', got {mode!r}")
    out = []
    for cid, c in sorted(claims.items()):
        if c["status"] == "own check":
            continue
        want = verdicts.get(cid)
        if want is None:
            out.append(f"{cid}: {c['status']} in this run, not in the verdict file")
            continue
        if c["status"] != want[mode]:
            out.append(f"{cid}: {c['status']} in this run, the verdict file says {want[mode]}")
        elif c["status"] == "differs" and c["cause"] != want.get("cause", ""):
            out.append(f"{cid}: cause {c['cause']!r}, the verdict file says {want.get('cause')!r}")
    for cid in sorted(set(verdicts) - set(claims)):
        out.append(f"{cid}: in the verdict file, not checked by this run")
    return out
