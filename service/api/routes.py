"""HTTP routes over the planning core. Handlers stay thin: parse, call the core, encode."""

from __future__ import annotations

import io
import secrets
from typing import Annotated

import numpy as np
from fastapi import APIRouter, Depends, Header, HTTPException, Path, Query, Request, Response
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse
from pydantic import ValidationError
from starlette.datastructures import FormData, UploadFile
from starlette.formparsers import MultiPartException

from service.api.errors import validation_response
from service.api.metrics import ServiceMetrics
from service.core import PlanningService
from service.errors import InvalidInput, UnsupportedMediaType
from vgn_contract.schemas import (
    SESSION_ID_PATTERN,
    ErrorResponse,
    FrameMeta,
    FrameResult,
    GraspQuery,
    GraspResult,
    GripperList,
    Health,
    ModelInfo,
    Readiness,
    SessionCreate,
    SessionInfo,
    SessionList,
)
from vgn_contract.snapshot import MEDIA_TYPE as SNAPSHOT_MEDIA_TYPE

NPY_MEDIA_TYPE = "application/x-npy"
#: A frame may also be sent as the bare depth image, its meta JSON in this header.
FRAME_META_HEADER = "X-Frame-Meta"
RAW_BODY_TYPES = ("application/octet-stream", "image/png")
PLY_MEDIA_TYPE = "application/x-ply"


async def core(request: Request) -> PlanningService:
    """The app's planning core, as a FastAPI dependency. Async because it never blocks: FastAPI
    runs a plain ``def`` dependency in its thread pool, a thread hop on every request."""
    return request.app.state.core


def metrics(request: Request) -> ServiceMetrics:
    """The app's Prometheus metrics, for routes that record their own figures."""
    return request.app.state.metrics


async def require_api_key(
    request: Request,
    x_api_key: Annotated[str | None, Header()] = None,
    authorization: Annotated[str | None, Header()] = None,
) -> None:
    """When ``VGN_API_KEY`` is set, every route but health checks needs it (async like ``core``)."""
    expected = request.app.state.settings.api_key
    if expected is None:
        return
    given = x_api_key
    if given is None and authorization and authorization.lower().startswith("bearer "):
        given = authorization[7:].strip()
    if given is None or not secrets.compare_digest(given.encode(), expected.encode()):
        raise HTTPException(
            401,
            "missing or wrong API key (X-API-Key or Authorization: Bearer)",
            headers={"WWW-Authenticate": "Bearer"},
        )


Core = Annotated[PlanningService, Depends(core)]
ERROR_CODES = (400, 401, 404, 413, 415, 422, 503)
ERRORS = {code: {"model": ErrorResponse} for code in ERROR_CODES}


def json_errors(*codes: int) -> dict[int | str, dict]:
    """Error responses documented as JSON whatever the route's own media type: FastAPI would
    otherwise give them the route's (text/html for a page), which is not what they send."""
    schema = {"$ref": "#/components/schemas/ErrorResponse"}
    return {
        code: {"description": "Error", "content": {"application/json": {"schema": schema}}} for code in codes
    }


health = APIRouter(tags=["health"])
api = APIRouter(dependencies=[Depends(require_api_key)], responses=ERRORS)


@health.get("/healthz", response_model=Health)
def healthz() -> Health:
    """The process is up (no model needed)."""
    return Health(status="ok")


@health.get("/readyz", response_model=Readiness, responses={503: {"model": Readiness}})
def readyz(service: Core, response: Response) -> Readiness:
    """Ready to plan: a model is loaded and warmed up."""
    info = service.model_info()
    if not info.loaded:
        response.status_code = 503
        return Readiness(ready=False, detail=info.detail or "no model")
    return Readiness(ready=True, detail=f"model {info.model_id} loaded on {info.device}")


@api.get("/metrics", response_class=Response, responses={200: {"content": {"text/plain": {}}}})
def prometheus_metrics(service: Core, request: Request) -> Response:
    """Prometheus text exposition."""
    registry = metrics(request)
    registry.sessions.set(len(service.sessions))
    registry.model_loaded.set(1 if service.planner.ready else 0)
    return Response(registry.render(), media_type="text/plain; version=0.0.4")


@api.get("/model", response_model=ModelInfo)
def model(service: Core) -> ModelInfo:
    """The loaded model: weights id, source, architecture, device and conventions."""
    return service.model_info()


@api.get("/grippers", response_model=GripperList)
def grippers(service: Core) -> GripperList:
    """The hands this service knows (built in, and the operator's `VGN_GRIPPERS` files), each with
    the network that plans for it (its own, `VGN_HAND_MODELS`, where it has one, else the main one)
    and that network's operating threshold; a session names one (`gripper`), a hand with no network
    is refused."""
    return service.grippers()


@api.post("/sessions", status_code=201, response_model=SessionInfo, responses={409: {"model": ErrorResponse}})
def create_session(service: Core, spec: SessionCreate | None = None) -> SessionInfo:
    """Open a session: an empty TSDF volume over the workspace (defaults: 0.30 m, 40³, at the world origin)."""
    return service.create_session(spec or SessionCreate())


SNAPSHOT_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            SNAPSHOT_MEDIA_TYPE: {
                "schema": {
                    "type": "string",
                    "format": "binary",
                    "description": "a snapshot from GET /sessions/{session_id}/snapshot",
                }
            }
        },
    }
}


@api.get("/sessions", response_model=SessionList)
def list_sessions(service: Core) -> SessionList:
    """Every live session, and how many the service keeps at most."""
    return SessionList(sessions=service.list_sessions(), max_sessions=service.sessions.max_sessions)


@api.get("/sessions/{session_id}", response_model=SessionInfo)
def get_session(service: Core, session_id: str) -> SessionInfo:
    """One session's workspace, intrinsics, frame count and expiry; 404 once it is gone."""
    return service.session_info(session_id)


@api.delete("/sessions/{session_id}", status_code=204, response_class=Response)
def delete_session(service: Core, session_id: str) -> Response:
    """Drop the session and free its volumes."""
    service.delete_session(session_id)
    return Response(status_code=204)


@api.get(
    "/sessions/{session_id}/snapshot",
    response_class=Response,
    responses={200: {"content": {SNAPSHOT_MEDIA_TYPE: {}}}},
)
def snapshot(service: Core, session_id: str) -> Response:
    """The session as one compact file (`.npz`: settings, frame count, the fused volumes), for
    `PUT /sessions/{session_id}/snapshot` on this or another service; the session stays as it was."""
    return Response(service.export_session(session_id), media_type=SNAPSHOT_MEDIA_TYPE)


@api.put(
    "/sessions/{session_id}/snapshot",
    status_code=201,
    response_model=SessionInfo,
    responses={409: {"model": ErrorResponse}},
    openapi_extra=SNAPSHOT_BODY,
)
async def import_session(
    service: Core,
    session_id: Annotated[str, Path(pattern=SESSION_ID_PATTERN, description="id of the new session")],
    request: Request,
) -> SessionInfo:
    """Open the session `session_id` from a snapshot (`GET /sessions/{id}/snapshot` of any
    session): the same volumes, settings and frame count; 400 for a damaged or foreign file,
    409 for a taken id (a snapshot never overwrites a session). Moves a session between
    services (draining a replica)."""
    media_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if media_type != SNAPSHOT_MEDIA_TYPE:
        raise UnsupportedMediaType(
            f"a snapshot is sent as {SNAPSHOT_MEDIA_TYPE}, got {media_type or 'no content type'!r}"
        )
    data = await request.body()
    return await run_in_threadpool(service.import_session, data, session_id)


@api.post("/sessions/{session_id}/reset", response_model=SessionInfo)
def reset_session(service: Core, session_id: str) -> SessionInfo:
    """Empty the session's volume, keeping its workspace and intrinsics."""
    return service.reset_session(session_id)


#: FrameMeta's schema, its nested models referred to in the document's components (where
#: SessionCreate already put them), so the meta part is described as what it must hold.
FRAME_META_SCHEMA = {
    key: value
    for key, value in FrameMeta.model_json_schema(ref_template="#/components/schemas/{model}").items()
    if key != "$defs"
}

FRAME_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "multipart/form-data": {
                "schema": {
                    "type": "object",
                    "required": ["meta", "depth"],
                    "properties": {
                        "meta": {
                            **FRAME_META_SCHEMA,
                            "description": "FrameMeta as JSON (camera_pose, intrinsics, depth_scale, max_depth)",
                        },
                        "depth": {
                            "type": "string",
                            "format": "binary",
                            "description": "16-bit PNG (image/png) or float32 metres (application/octet-stream)",
                        },
                    },
                },
                "encoding": {"meta": {"contentType": "application/json"}},
            },
            "application/octet-stream": {
                "schema": {
                    "type": "string",
                    "format": "binary",
                    "description": "float32 metres, meta in X-Frame-Meta",
                }
            },
            "image/png": {
                "schema": {
                    "type": "string",
                    "format": "binary",
                    "description": "16-bit PNG, meta in X-Frame-Meta",
                }
            },
        },
    },
    "parameters": [
        {
            "name": FRAME_META_HEADER,
            "in": "header",
            "required": False,
            "content": {"application/json": {"schema": FRAME_META_SCHEMA}},
            "description": "FrameMeta as JSON (see the multipart meta part), required when the body is the "
            "bare depth image",
        }
    ],
}


@api.post("/sessions/{session_id}/frames", response_model=FrameResult, openapi_extra=FRAME_BODY)
async def add_frame(service: Core, session_id: str, request: Request) -> FrameResult | JSONResponse:
    """Fuse one depth frame: multipart parts ``meta`` (JSON) and ``depth`` (a file part), or
    the depth image as the whole body (``application/octet-stream`` float32 or ``image/png``)
    with the meta JSON in the ``X-Frame-Meta`` header, which saves the multipart round."""
    media_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if media_type in RAW_BODY_TYPES:
        meta_text = request.headers.get(FRAME_META_HEADER)
        if meta_text is None:
            raise InvalidInput(
                f"a {media_type} frame body needs its meta as JSON in the {FRAME_META_HEADER} header"
            )
        data, content_type = await request.body(), media_type
    elif media_type == "multipart/form-data":
        meta_text, data, content_type = await _multipart_frame(request)
    else:
        raise UnsupportedMediaType(
            "frames must be multipart/form-data, or a raw depth body (application/octet-stream or "
            f"image/png) with the {FRAME_META_HEADER} header; got {media_type or 'no content type'!r}"
        )
    limit = request.app.state.settings.max_frame_bytes
    if len(data) > limit:
        raise HTTPException(
            413, f"depth image of {len(data)} bytes exceeds the limit of {limit} bytes (VGN_MAX_FRAME_BYTES)"
        )
    try:
        meta = FrameMeta.model_validate_json(meta_text)
    except ValidationError as error:
        return validation_response(list(error.errors()), prefix=("meta",))
    result = await run_in_threadpool(service.add_encoded_frame, session_id, data, content_type, meta)
    metrics(request).integration.observe(result.integration_ms / 1e3)
    return result


async def _multipart_frame(request: Request) -> tuple[str | bytes, bytes, str]:
    """The meta JSON, depth bytes and depth media type of a multipart frame upload."""
    try:
        form = await request.form(
            max_files=4, max_fields=8, max_part_size=request.app.state.settings.max_frame_bytes
        )
    except MultiPartException as error:
        raise InvalidInput(f"malformed multipart body: {error.message}") from None
    try:
        return await _frame_parts(form)
    finally:
        await form.close()


@api.get("/sessions/{session_id}/grasps", response_model=GraspResult)
def grasps(
    service: Core, session_id: str, request: Request, query: Annotated[GraspQuery, Query()]
) -> GraspResult:
    """Ranked grasps, best first, in the world frame, planned by VGN on the fused volume, or
    with `planner=antipodal` by a geometric baseline on the fused point cloud (no model needed)."""
    result = service.plan(session_id, query)
    metrics(request).planning.observe(result.planning_ms / 1e3)
    metrics(request).grasps.inc(len(result.grasps))
    return result


async def _frame_parts(form: FormData) -> tuple[str | bytes, bytes, str]:
    """The meta JSON, the depth bytes and the depth media type of a frame upload."""
    meta_part, depth_part = form.get("meta"), form.get("depth")
    missing = [name for name, part in (("meta", meta_part), ("depth", depth_part)) if part is None]
    if missing:
        raise InvalidInput(f"multipart body lacks the part(s) {missing}")
    if not isinstance(depth_part, UploadFile):
        raise InvalidInput("the depth part must be a file part (with a filename and a content type)")
    meta_text = await meta_part.read() if isinstance(meta_part, UploadFile) else meta_part
    return meta_text, await depth_part.read(), depth_part.content_type or ""


def _npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=False)
    return buffer.getvalue()


@api.get(
    "/sessions/{session_id}/tsdf", response_class=Response, responses={200: {"content": {NPY_MEDIA_TYPE: {}}}}
)
def tsdf(service: Core, session_id: str) -> Response:
    """The (N, N, N) float32 network input as ``.npy``, indexed [x, y, z] in the workspace frame."""
    return Response(_npy(service.grid(session_id)), media_type=NPY_MEDIA_TYPE)


@api.get(
    "/sessions/{session_id}/cloud",
    response_class=Response,
    responses={200: {"content": {NPY_MEDIA_TYPE: {}, PLY_MEDIA_TYPE: {}}}, 406: {"model": ErrorResponse}},
)
def cloud(service: Core, session_id: str, request: Request) -> Response:
    """Surface points and outward normals in the world frame: ``.npy`` (M, 6) float32 by
    default, binary PLY with ``Accept: application/x-ply``; 406 for an ``Accept`` naming neither.
    ``Accept`` is negotiated through the response media types, not declared as a parameter."""
    accept = request.headers.get("accept")
    wanted = (accept or "*/*").lower()
    if PLY_MEDIA_TYPE in wanted:
        return Response(_ply(service.cloud(session_id)), media_type=PLY_MEDIA_TYPE)
    if NPY_MEDIA_TYPE in wanted or "*/*" in wanted or "application/*" in wanted:
        return Response(_npy(service.cloud(session_id)), media_type=NPY_MEDIA_TYPE)
    raise HTTPException(406, f"cloud is served as {NPY_MEDIA_TYPE} or {PLY_MEDIA_TYPE}, not {accept!r}")


def _ply(cloud: np.ndarray) -> bytes:
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(cloud)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\nend_header\n"
    )
    return header.encode("ascii") + np.ascontiguousarray(cloud, dtype="<f4").tobytes()
