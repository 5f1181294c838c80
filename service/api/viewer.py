"""Routes of the session viewer: the 3D page and the JSON it refreshes from.

They sit behind the same API-key rule as the rest of the API and answer 404 for unknown
sessions like every other session route.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Query
from fastapi.responses import HTMLResponse

from service.api.routes import ERROR_CODES, Core, json_errors, require_api_key
from service.core import PlanningService
from service.errors import ModelNotReady
from service.viewer.page import ViewerUnavailable, render_page
from service.viewer.scene import ViewQuery, build_scene

viewer = APIRouter(
    dependencies=[Depends(require_api_key)], responses=json_errors(*ERROR_CODES), tags=["viewer"]
)


def scene_of(service: PlanningService, session_id: str, query: ViewQuery) -> dict[str, Any]:
    """Plan (404 for an unknown session), then read the surface; without a model the page still
    shows the surface and says why there are no grasps."""
    try:
        result, error = service.plan(session_id, query.grasp_query()), None
    except ModelNotReady as why:
        result, error = None, str(why)
    return build_scene(service.session_info(session_id), service.cloud(session_id), result, query, error)


@viewer.get(
    "/sessions/{session_id}/view",
    response_class=HTMLResponse,
    responses={200: {"content": {"text/html": {}}}},
)
def view(service: Core, session_id: str, query: Annotated[ViewQuery, Query()]) -> HTMLResponse:
    """A self-contained HTML page (plotly.js inlined, works offline) showing the fused surface, the
    workspace cube and the best grasps as gripper outlines coloured by quality, with a grasp list.
    Takes the grasp query's options; with `refresh` > 0 it re-plans when new frames arrive."""
    scene = scene_of(service, session_id, query)
    try:
        return HTMLResponse(render_page(scene))
    except ViewerUnavailable as error:
        raise HTTPException(503, str(error)) from None


@viewer.get("/sessions/{session_id}/view/data")
def view_data(service: Core, session_id: str, query: Annotated[ViewQuery, Query()]) -> dict[str, Any]:
    """The viewer's data as JSON (what the page draws); the page fetches it to refresh."""
    return scene_of(service, session_id, query)
