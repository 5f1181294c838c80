"""Headless Chromium for page tests, driven through chromedriver (selenium).

The network is closed, so everything that would phone home is switched off, and WebGL runs on
SwiftShader (software) because there is no GPU. A missing browser is a test failure, not a
skip: CI installs it (``.ci/run``).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

CHROMIUM_FLAGS = [
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--enable-unsafe-swiftshader",  # software WebGL for our own loopback page (no GPU here)
    "--window-size=1280,800",
]


def _find(env: str, *names: str) -> str:
    for candidate in (os.environ.get(env), *names):
        path = candidate and shutil.which(candidate)
        if path:
            return path
    pytest.fail(
        f"{names[0]} not found (set {env} or install the Debian packages chromium and chromium-driver; "
        ".ci/run installs them)"
    )


@contextmanager
def headless_chromium() -> Iterator:
    """A fresh headless Chromium (own profile) that records the console."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        pytest.fail("selenium is missing: pip install 'vgn-service[dev]'")
    options = webdriver.ChromeOptions()
    options.binary_location = _find("CHROMIUM", "chromium", "chromium-browser")
    with tempfile.TemporaryDirectory(prefix="vgn-chromium-") as profile:
        for flag in [*CHROMIUM_FLAGS, f"--user-data-dir={profile}"]:
            options.add_argument(flag)
        options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
        driver = webdriver.Chrome(service=Service(_find("CHROMEDRIVER", "chromedriver")), options=options)
        try:
            yield driver
        finally:
            driver.quit()
