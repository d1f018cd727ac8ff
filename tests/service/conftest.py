"""Fixtures the service's browser tests share."""

from __future__ import annotations

import pytest

from service_helpers import CHROMIUM, CHROMIUM_ARGS


@pytest.fixture(scope="module")
def browser():
    """Debian's chromium through Playwright, one per test module (a module that needs other
    flags, such as a fake camera, defines its own)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield browser
        browser.close()
