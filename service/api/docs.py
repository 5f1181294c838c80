"""The API documentation pages, ``/docs`` (Swagger UI) and ``/redoc``, with their scripts served
by this service instead of a CDN: a robot's network often has no route out, and FastAPI's
default pages are blank there.

The scripts and styles come from the ``fastapi-offline`` package (part of the service extra):
the Swagger UI 5 and ReDoc 2 builds that FastAPI's default pages load from jsDelivr.
"""

from __future__ import annotations

import importlib.resources
import logging
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles
from starlette.middleware.gzip import GZipMiddleware

log = logging.getLogger("vgn.service")

DOCS_URL = "/docs"
REDOC_URL = "/redoc"
#: Where the pages' scripts, styles and icon are served; outside the API document.
ASSETS_URL = "/docs/assets"
ASSET_FILES = ("swagger-ui-bundle.js", "swagger-ui.css", "redoc.standalone.js", "favicon.png")
#: Beside FastAPI's Swagger UI settings: no validator badge (it would ask swagger.io).
SWAGGER_PARAMETERS = {"validatorUrl": None}
#: The pages load nothing from elsewhere, not even the logo ReDoc's bundle fetches from its CDN
#: (it hides it when that fails): no requests leave the robot's network, none wait on a dead DNS.
#: Inline: FastAPI's page starts Swagger UI in a script of its own and both set styles inline;
#: blob: ReDoc's search runs in a worker made from a blob.
CONTENT_POLICY = (
    "default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
    "img-src 'self' data:; font-src 'self' data:; worker-src 'self' blob:; connect-src 'self'"
)


def asset_folder() -> Path | None:
    """The installed folder holding every file in ``ASSET_FILES``; None when it is missing."""
    try:
        folder = Path(str(importlib.resources.files("fastapi_offline") / "static"))
    except ModuleNotFoundError:
        return None
    return folder if all((folder / name).is_file() for name in ASSET_FILES) else None


def docs_urls() -> dict[str, str | None]:
    """``FastAPI(**docs_urls())``: its own CDN pages off when the local ones can be served, kept
    (with a warning) on an install that lacks the assets, which is no worse than before."""
    if asset_folder() is not None:
        return {"docs_url": None, "redoc_url": None}
    log.warning(
        "the API docs load their scripts from a CDN (blank without internet): "
        "pip install fastapi-offline, part of 'vgn-service[service]'"
    )
    return {"docs_url": DOCS_URL, "redoc_url": REDOC_URL}


def install_docs(app: FastAPI) -> None:
    """Serve ``/docs`` and ``/redoc`` from the local assets, if the app left them to us."""
    folder = asset_folder()
    if app.docs_url is not None or folder is None:
        return
    # Gzip: the Swagger UI bundle is 1.5 MB as installed, a third of that compressed.
    app.mount(ASSETS_URL, GZipMiddleware(StaticFiles(directory=folder)), name="docs-assets")

    @app.get(DOCS_URL, include_in_schema=False)
    async def swagger_ui(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "")
        page = get_swagger_ui_html(
            openapi_url=f"{root}{app.openapi_url}",
            title=f"{app.title} - Swagger UI",
            swagger_js_url=f"{root}{ASSETS_URL}/swagger-ui-bundle.js",
            swagger_css_url=f"{root}{ASSETS_URL}/swagger-ui.css",
            swagger_favicon_url=f"{root}{ASSETS_URL}/favicon.png",
            swagger_ui_parameters=SWAGGER_PARAMETERS,
        )
        return _contained(page)

    @app.get(REDOC_URL, include_in_schema=False)
    async def redoc(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "")
        page = get_redoc_html(
            openapi_url=f"{root}{app.openapi_url}",
            title=f"{app.title} - ReDoc",
            redoc_js_url=f"{root}{ASSETS_URL}/redoc.standalone.js",
            redoc_favicon_url=f"{root}{ASSETS_URL}/favicon.png",
            with_google_fonts=False,
        )
        return _contained(page)


def _contained(page: HTMLResponse) -> HTMLResponse:
    """The page, allowed to load only from this service (``CONTENT_POLICY``)."""
    page.headers["Content-Security-Policy"] = CONTENT_POLICY
    return page
