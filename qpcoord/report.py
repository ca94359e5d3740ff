"""Deprecated alias: :mod:`qpcoord.studies.claims` (``claim``, ``CLAIM_STATUSES``, …) and
:mod:`qpcoord.studies.files` (``write_json``, ``write_text``, ``TextLog``); removed in the next
release."""

from ._deprecated import warn_moved
from .studies import claims as _claims
from .studies.claims import *  # noqa: F403 (every public name of the new module)
from .studies.files import TextLog, write_json, write_text

__all__ = ["write_json", "write_text", "TextLog", *_claims.__all__]

warn_moved(__name__, "qpcoord.studies.claims and qpcoord.studies.files")
