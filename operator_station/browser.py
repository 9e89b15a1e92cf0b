"""Headless Chromium through Selenium, for the end-to-end tests, the screenshots and the page benchmark.

Debian's ``chromium`` and ``chromium-driver`` (``.ci/run`` installs them); Selenium is told where
both are, so it never tries to download a browser.  :func:`missing` says why a driver cannot be
had here (then the tests are skipped with that reason), None when it can.
"""
from __future__ import annotations

import shutil
from typing import Any

CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome")
DRIVER_NAMES = ("chromedriver",)


def _find(names: tuple[str, ...]) -> str | None:
    return next((path for path in map(shutil.which, names) if path), None)


def missing() -> str | None:
    """Why no headless Chromium can be driven here, or None."""
    try:
        import selenium  # noqa: F401 - optional: pip extra 'test', only to drive a browser
    except ImportError:
        return "selenium is not installed (pip install '.[test]')"
    if _find(CHROMIUM_NAMES) is None:
        return "no Chromium on this machine (apt-get install chromium chromium-driver)"
    if _find(DRIVER_NAMES) is None:
        return "no chromedriver on this machine (apt-get install chromium-driver)"
    return None


def chromium(width: int = 1600, height: int = 1000, arguments: tuple[str, ...] = ()) -> Any:
    """A headless Chromium WebDriver with the browser's console log kept; ``arguments`` are added to Chromium's."""
    # optional: selenium (pip extra 'test'), only where a browser is driven (missing() says when it is not there)
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    binary, driver = _find(CHROMIUM_NAMES), _find(DRIVER_NAMES)
    if binary is None or driver is None:
        raise RuntimeError(missing() or "no Chromium")
    options = Options()
    options.binary_location = binary
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", f"--window-size={width},{height}", *arguments):
        options.add_argument(argument)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(driver), options=options)
