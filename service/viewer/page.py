"""The viewer's HTML: one self-contained page with plotly.js inlined, so it works offline and
can be saved to a file and opened later (no CDN, no second request for scripts)."""

from __future__ import annotations

import functools
import html
import json
import re
from importlib import resources
from typing import Any

PLACEHOLDER = re.compile(r"__(TITLE|PLOTLY|SCENE|VIEWER)__")
SCRIPT_END = re.compile(r"</(script)", re.IGNORECASE)
PLOTLY_MISSING = "the session viewer needs plotly: pip install 'vgn-service[viewer]'"


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
def _asset(name: str) -> str:
    return resources.files("service.viewer").joinpath("assets", name).read_text(encoding="utf-8")


def _inline_script(text: str) -> str:
    r"""Script text that cannot close its <script> element early (``<\/`` reads as ``</`` in JS strings)."""
    return SCRIPT_END.sub(r"<\\/\1", text)


def _inline_json(value: Any) -> str:
    """JSON for a <script> data block: ``<`` escaped, so no tag can start inside it."""
    return json.dumps(value, separators=(",", ":"), allow_nan=False).replace("<", "\\u003c")


def render_page(scene: dict[str, Any]) -> str:
    """The viewer page with ``scene`` (see ``service.viewer.scene.build_scene``) embedded."""
    template = _asset("viewer.html")
    parts = {
        "__TITLE__": html.escape(scene["session_id"]),
        "__PLOTLY__": _inline_script(plotly_js()),
        "__SCENE__": _inline_json(scene),
        "__VIEWER__": _inline_script(_asset("viewer.js")),
    }
    # One pass over the template: text inside the scene or the library is never rescanned.
    return PLACEHOLDER.sub(lambda match: parts[match.group(0)], template)
