"""A headless Chromium for the tests that render a page, or the reason the test skips."""

from __future__ import annotations

import os
import shutil

import pytest


def chromium() -> str | None:
    """The browser: ``QPCOORD_CHROMIUM``, else the first Chromium or Chrome on the PATH."""
    exe = os.environ.get("QPCOORD_CHROMIUM")
    if exe:
        return exe
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


def need_browser(reason: str):
    """Skip -- or fail where CI promised a browser (QPCOORD_REQUIRE_BROWSER=1)."""
    if os.environ.get("QPCOORD_REQUIRE_BROWSER", "") not in ("", "0"):
        pytest.fail(f"QPCOORD_REQUIRE_BROWSER is set but {reason}")
    pytest.skip(reason)
