"""Routes of the session viewer: the 3D page and the JSON it refreshes from.

They sit behind the same API-key rule as the rest of the API and answer 404 for unknown
sessions like every other session route.
"""

from __future__ import annotations

import gzip
import json
from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Query, Request
from fastapi.responses import HTMLResponse, Response

from service.api.routes import ERROR_CODES, Core, json_errors, require_api_key
from service.core import PlanningService
from service.errors import ModelNotReady
from service.viewer.page import (
    PLOTLY_ROUTE,
    ViewerUnavailable,
    plotly_bytes,
    plotly_gzip,
    plotly_tag,
    render_page,
)
from service.viewer.scene import ViewQuery, build_scene

viewer = APIRouter(
    dependencies=[Depends(require_api_key)], responses=json_errors(*ERROR_CODES), tags=["viewer"]
)
#: The page's script library: public (it holds no session data, and a ``<script src>`` cannot
#: send an API key), outside the API document like any static file.
viewer_assets = APIRouter(include_in_schema=False)
#: zlib's fastest level: a 2 MB page in ~10 ms, most of the size gain of the slower ones.
GZIP_LEVEL = 1
#: The URL names the content, so a browser may keep it for good.
FOREVER = "public, max-age=31536000, immutable"


def scene_of(service: PlanningService, session_id: str, query: ViewQuery) -> dict[str, Any]:
    """Plan (404 for an unknown session), then read the surface; without a model the page still
    shows the surface and says why there are no grasps."""
    try:
        result, error = service.plan(session_id, query.grasp_query()), None
    except ModelNotReady as why:
        result, error = None, str(why)
    info = service.session_info(session_id)
    depth = service.hands.known[info.gripper].finger_depth
    return build_scene(info, service.cloud(session_id), result, query, error, depth)


@viewer.get(
    "/sessions/{session_id}/view",
    response_class=HTMLResponse,
    responses={200: {"content": {"text/html": {}}}},
)
def view(service: Core, session_id: str, query: Annotated[ViewQuery, Query()], request: Request) -> Response:
    """An HTML page showing the fused surface, the workspace cube and the best grasps as gripper
    outlines coloured by quality, with a grasp list. It loads plotly.js from this service
    (cached by the browser), or inlines it with `standalone=true`. Takes the grasp query's
    options; with `refresh` > 0 it re-plans when new frames arrive."""
    scene = scene_of(service, session_id, query)
    try:
        page = render_page(scene, query.standalone)
    except ViewerUnavailable as error:
        raise HTTPException(503, str(error)) from None
    return compressed(page.encode(), "text/html; charset=utf-8", request)


@viewer.get(
    "/sessions/{session_id}/view/data",
    responses={200: {"content": {"application/json": {"schema": {"type": "object"}}}}},
)
def view_data(
    service: Core, session_id: str, query: Annotated[ViewQuery, Query()], request: Request
) -> Response:
    """The viewer's data as JSON (what the page draws); the page fetches it to refresh."""
    scene = json.dumps(scene_of(service, session_id, query), separators=(",", ":"), allow_nan=False)
    return compressed(scene.encode(), "application/json", request)


def accepts_gzip(request: Request) -> bool:
    """Whether the client said it takes gzip-compressed bodies."""
    return "gzip" in request.headers.get("accept-encoding", "")


def compressed(body: bytes, media_type: str, request: Request) -> Response:
    """``body``, gzip-compressed (fast level) when the client accepts it: the surface points make
    a page or its data 1-2 MB of JSON, which compresses about fourfold."""
    if not accepts_gzip(request):
        return Response(body, media_type=media_type, headers={"Vary": "Accept-Encoding"})
    packed = gzip.compress(body, compresslevel=GZIP_LEVEL, mtime=0)
    headers = {"Content-Encoding": "gzip", "Vary": "Accept-Encoding"}
    return Response(packed, media_type=media_type, headers=headers)


@viewer_assets.get(PLOTLY_ROUTE.format(tag="{tag}"))
def plotly_script(tag: str, request: Request) -> Response:
    """plotly.js for the viewer page, gzip-compressed when the browser accepts it."""
    try:
        current = plotly_tag()
    except ViewerUnavailable as error:
        raise HTTPException(503, str(error)) from None
    if tag != current:
        raise HTTPException(
            404, f"no plotly.js {tag!r} here: this service ships {current!r}; reload the page"
        )
    headers = {"Cache-Control": FOREVER, "ETag": f'"{current}"', "Vary": "Accept-Encoding"}
    if request.headers.get("if-none-match") == headers["ETag"]:
        return Response(status_code=304, headers=headers)
    media_type = "text/javascript; charset=utf-8"
    if accepts_gzip(request):
        return Response(plotly_gzip(), media_type=media_type, headers={**headers, "Content-Encoding": "gzip"})
    return Response(plotly_bytes(), media_type=media_type, headers=headers)
