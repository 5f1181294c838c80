"""The viewer's HTML. A browser pointed at the service gets a light page that loads plotly.js
from the service's own cacheable script route (fetched once, then cached for good; no CDN);
a standalone page inlines the library, so it can be saved to a file and opened offline."""

from __future__ import annotations

import functools
import gzip
import hashlib
import html
import json
import re
from importlib import resources
from typing import Any

PLACEHOLDER = re.compile(r"__(TITLE|PLOTLY|SCENE|VIEWER)__")
SCRIPT_END = re.compile(r"</(script)", re.IGNORECASE)
PLOTLY_MISSING = "the session viewer needs plotly: pip install 'vgn-service[viewer]'"
#: Where the script route lives, and how a page at /sessions/{id}/view reaches it: relative, so
#: the page also works behind a proxy that mounts the service under a path prefix.
PLOTLY_ROUTE = "/viewer/plotly-{tag}.min.js"
PLOTLY_FROM_PAGE = "../../viewer/plotly-{tag}.min.js"


class ViewerUnavailable(RuntimeError):
    """plotly (which ships the 3D library) is not installed."""


@functools.cache
def plotly_js() -> str:
    """plotly.js as shipped inside the installed plotly package."""
    try:
        from plotly.offline import get_plotlyjs
    except ImportError:
        raise ViewerUnavailable(PLOTLY_MISSING) from None
    return get_plotlyjs()


@functools.cache
def plotly_bytes() -> bytes:
    """plotly.js as the script route sends it, UTF-8."""
    return plotly_js().encode()


@functools.cache
def plotly_tag() -> str:
    """A content hash of plotly.js: part of the script's URL, so a cached copy is never stale."""
    return hashlib.sha256(plotly_bytes()).hexdigest()[:16]


@functools.cache
def plotly_gzip() -> bytes:
    """plotly.js gzip-compressed, once per process (about a quarter of its 4.6 MB)."""
    return gzip.compress(plotly_bytes(), compresslevel=6, mtime=0)


@functools.cache
def _asset(name: str) -> str:
    return resources.files("service.viewer").joinpath("assets", name).read_text(encoding="utf-8")


def _inline_script(text: str) -> str:
    r"""Script text that cannot close its <script> element early (``<\/`` reads as ``</`` in JS strings)."""
    return SCRIPT_END.sub(r"<\\/\1", text)


def _inline_json(value: Any) -> str:
    """JSON for a <script> data block: ``<`` escaped, so no tag can start inside it."""
    return json.dumps(value, separators=(",", ":"), allow_nan=False).replace("<", "\\u003c")


def render_page(scene: dict[str, Any], standalone: bool = False) -> str:
    """The viewer page with ``scene`` (see ``service.viewer.scene.build_scene``) embedded;
    ``standalone`` inlines plotly.js instead of loading it from the script route."""
    if standalone:
        library = f"<script>{_inline_script(plotly_js())}</script>"
    else:
        library = f'<script src="{PLOTLY_FROM_PAGE.format(tag=plotly_tag())}"></script>'
    template = _asset("viewer.html")
    parts = {
        "__TITLE__": html.escape(scene["session_id"]),
        "__PLOTLY__": library,
        "__SCENE__": _inline_json(scene),
        "__VIEWER__": _inline_script(_asset("viewer.js")),
    }
    # One pass over the template: text inside the scene or the library is never rescanned.
    return PLACEHOLDER.sub(lambda match: parts[match.group(0)], template)
