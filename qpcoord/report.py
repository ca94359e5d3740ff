"""Deprecated alias: :mod:`qpcoord.studies.claims` (``claim``, ``CLAIM_STATUSES``) and
:mod:`qpcoord.studies.files` (``write_json``, ``write_text``, ``TextLog``); removed in the next
release."""

from ._deprecated import warn_moved
from .studies.claims import CLAIM_STATUSES, claim
from .studies.files import TextLog, write_json, write_text

__all__ = ["write_json", "write_text", "TextLog", "claim", "CLAIM_STATUSES"]

warn_moved(__name__, "qpcoord.studies.claims and qpcoord.studies.files")
