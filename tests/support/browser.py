"""A headless Chromium for the tests that render a page (a viewer page opened offline, its
screenshots), or the reason the test skips."""

from __future__ import annotations

import io
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
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


@contextmanager
def offline_viewer(path: Path) -> Iterator[tuple[object, list[str]]]:
    """The viewer page written at ``path`` in headless Chromium (software WebGL, a 480 x 360
    view, the network off), once its inlined scene has loaded (the animation, its last
    command, is in place): ``(page, urls)``, a playwright page and the URLs it has
    requested so far. The browser closes at the end of the block. Without a browser or
    playwright: :func:`need_browser`."""
    exe = chromium()
    if exe is None:
        need_browser(
            "no Chromium browser found (install Debian's `chromium` or set "
            "QPCOORD_CHROMIUM=/path/to/chrome): the offline screenshot test needs one"
        )
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        need_browser(
            "playwright is not installed (pip install playwright; it is in the test extra)"
        )
    urls: list[str] = []
    with sync_playwright() as p:
        browser = p.chromium.launch(
            executable_path=exe,
            args=["--use-angle=swiftshader", "--enable-unsafe-swiftshader"],
            timeout=30_000,
        )
        try:
            context = browser.new_context(viewport={"width": 480, "height": 360}, offline=True)
            page = context.new_page()
            page.on("request", lambda r: urls.append(r.url))
            page.goto(path.as_uri(), timeout=30_000)
            page.wait_for_function(
                "typeof viewer !== 'undefined' && viewer.animator.duration > 0", timeout=30_000
            )
            yield page, urls
        finally:
            browser.close()


def pixels(page) -> np.ndarray:
    """A screenshot of ``page``: its RGB values, (height, width, 3) integers."""
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB"), dtype=int)
