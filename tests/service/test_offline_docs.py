"""The API docs pages (``/docs``: Swagger UI, ``/redoc``: ReDoc) work with no route to the
internet: their scripts, styles and icon come from the service itself, rendered in headless
Chromium against a real server on loopback."""

from __future__ import annotations

import logging
import re
import time
from collections.abc import Callable, Iterator
from urllib.parse import urljoin, urlsplit

import httpx
import pytest

from service.api import docs
from service.http_app import create_app
from service.launch.embedded import EmbeddedService
from service.settings import Settings
from tests.helpers.browser import headless_chromium

#: Any absolute http(s) URL in a page's markup.
EXTERNAL = re.compile(r"https?://", re.IGNORECASE)


@pytest.fixture(scope="module")
def docs_server() -> Iterator[EmbeddedService]:
    env = {"VGN_API_KEY": "", "VGN_TORCH_THREADS": "1", "VGN_MODEL": "none"}
    with EmbeddedService(env=env) as service:
        yield service


@pytest.fixture(scope="module")
def browser() -> Iterator:
    with headless_chromium() as driver:
        yield driver


def wait_for(check: Callable[[], object], timeout: float = 30.0) -> object:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = check()
        if value:
            return value
        time.sleep(0.2)
    raise AssertionError(f"not within {timeout:g} s: {check.__doc__ or check}")


def loaded_resources(driver) -> list[str]:
    return driver.execute_script("return performance.getEntriesByType('resource').map(e => e.name)")


@pytest.mark.parametrize("path", ["/docs", "/redoc"])
def test_the_pages_name_no_other_host(docs_server: EmbeddedService, path: str) -> None:
    page = httpx.get(f"{docs_server.url}{path}")
    assert page.status_code == 200 and page.headers["content-type"].startswith("text/html")
    assert not EXTERNAL.search(page.text), EXTERNAL.findall(page.text)
    assert "default-src 'self'" in page.headers["content-security-policy"]
    assets = re.findall(r'(?:src|href)="([^"]+)"', page.text)
    assert assets and all(a.startswith("/docs/assets/") for a in assets), assets
    for asset in assets:
        response = httpx.get(urljoin(docs_server.url, asset), headers={"Accept-Encoding": "gzip"})
        assert response.status_code == 200 and len(response.content) > 1000, asset
        if asset.endswith(".js"):
            assert response.headers["content-encoding"] == "gzip", "1.5 MB of script goes compressed"


def test_swagger_ui_renders_offline(docs_server: EmbeddedService, browser) -> None:
    browser.get(f"{docs_server.url}/docs")

    def session_operations() -> int:
        """Swagger UI drew the operations on /sessions"""
        return browser.execute_script(
            "return document.querySelectorAll("
            "'.swagger-ui .opblock .opblock-summary-path[data-path=\"/sessions\"]').length"
        )

    assert wait_for(session_operations) >= 2, "GET and POST /sessions"
    assert browser.find_element("css selector", ".swagger-ui .info .title").text.startswith("vgn-service")
    origin = urlsplit(docs_server.url).netloc
    assert all(urlsplit(url).netloc == origin for url in loaded_resources(browser)), loaded_resources(browser)
    errors = [entry for entry in browser.get_log("browser") if entry["level"] == "SEVERE"]
    assert not errors, errors


def test_redoc_renders_offline(docs_server: EmbeddedService, browser) -> None:
    browser.get(f"{docs_server.url}/redoc")

    def operations() -> int:
        """ReDoc drew the API's operations"""
        return browser.execute_script(
            "return document.querySelectorAll('[data-section-id^=\"operation/\"]').length"
        )

    assert wait_for(operations) >= 10
    assert "/sessions" in browser.find_element("css selector", ".api-content").text
    origin = urlsplit(docs_server.url).netloc
    elsewhere = [url for url in loaded_resources(browser) if urlsplit(url).netloc != origin]
    log = browser.get_log("browser")
    assert not [entry for entry in log if entry["source"] == "network"], log
    # ReDoc's bundle asks its CDN for a logo; the page's policy refuses it before any request.
    refused = " ".join(entry["message"] for entry in log if "Content Security Policy" in entry["message"])
    assert all(url in refused for url in elsewhere), (elsewhere, log)


def test_without_the_assets_the_app_keeps_fastapis_pages(monkeypatch, caplog) -> None:
    """An install that lacks them (an old environment) still starts, and says what to install."""
    assert docs.asset_folder() is not None, "the service extra ships them"
    monkeypatch.setattr(docs, "asset_folder", lambda: None)
    with caplog.at_level(logging.WARNING, logger="vgn.service"):
        app = create_app(Settings(model="none", api_key=None))
    assert app.docs_url == "/docs" and app.redoc_url == "/redoc"
    assert "fastapi-offline" in caplog.text
