"""Debian's Chromium for the tests that look at a page: where it is, how it is started (the
background-networking flags keep it off the closed network), and a wait on meshcat's tree."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest

CHROMIUM = shutil.which("chromium")
CHROME_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]

NEEDS_CHROMIUM = [
    pytest.mark.browser,
    pytest.mark.skipif(
        CHROMIUM is None,
        reason="Debian's chromium is not installed (`make test` installs it when run as root)",
    ),
]


def wait_for_scene_nodes(page: Any, names: list[str], timeout_ms: int) -> None:
    """Until meshcat's control panel lists every name (one leaf element per scene node)."""
    page.wait_for_function(
        """names => names.every(n => [...document.querySelectorAll('*')].some(
            e => e.childElementCount === 0 && e.textContent === n))""",
        arg=names,
        timeout=timeout_ms,
    )


@contextmanager
def chromium_page(url: str, width: int, height: int) -> Iterator[Any]:
    """A headless Chromium page (Playwright) that has loaded ``url``; closed on exit."""
    from playwright.sync_api import sync_playwright

    assert CHROMIUM is not None, "needs Debian's chromium"
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROME_FLAGS[1:])
        try:
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(url, timeout=60_000)
            yield page
        finally:
            browser.close()
