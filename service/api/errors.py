"""Every error leaves as JSON ``{detail, ...}`` with the right status; bad input never gives a 500."""

from __future__ import annotations

import logging

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from service.errors import (
    CapacityExceeded,
    GripperNotServed,
    InvalidInput,
    ModelNotReady,
    ServiceError,
    SessionExists,
    SessionNotFound,
    UnsupportedMediaType,
)
from service.vgn.checkpoint import CheckpointError

log = logging.getLogger("vgn.service")

STATUS_OF: dict[type[ServiceError], int] = {
    InvalidInput: 400,
    GripperNotServed: 400,
    SessionNotFound: 404,
    SessionExists: 409,
    UnsupportedMediaType: 415,
    CapacityExceeded: 503,
    ModelNotReady: 503,
}


def field_errors(errors: list) -> tuple[list[dict], str]:
    """JSON-safe field errors and a one-line summary naming each bad field."""
    cleaned = [
        {"loc": list(e.get("loc", ())), "msg": str(e.get("msg", "")), "type": str(e.get("type", ""))}
        for e in errors
    ]
    summary = "; ".join(".".join(str(p) for p in e["loc"]) + ": " + e["msg"] for e in cleaned)
    return cleaned, summary


def validation_response(errors: list, prefix: tuple[str, ...] = ()) -> JSONResponse:
    """The 422 answer for pydantic field errors; ``prefix``
    roots their locations (e.g. in the ``meta`` part)."""
    cleaned, summary = field_errors([{**e, "loc": (*prefix, *e.get("loc", ()))} for e in errors])
    return JSONResponse(status_code=422, content={"detail": cleaned, "message": summary})


#: Methods a 405 may name in its Allow header.
HTTP_METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")


def allowed_methods(request: Request) -> list[str]:
    """Every method some route serves at this path, found by asking the app's routes whether
    they would take the request under each method. Starlette's own 405 names only the first
    route whose path matched, e.g. GET for /sessions/{id} although DELETE is there too."""
    routes = request.app.router.routes
    return [
        method
        for method in HTTP_METHODS
        if any(route.matches({**request.scope, "method": method})[0] == Match.FULL for route in routes)
    ]


def install_error_handlers(app: FastAPI) -> None:
    """Map every error to a JSON answer: service errors to their
    status, validation to 422, the unexpected to a logged 500."""

    @app.exception_handler(ServiceError)
    async def _service_error(_: Request, error: ServiceError) -> JSONResponse:
        status = next((code for kind, code in STATUS_OF.items() if isinstance(error, kind)), 400)
        headers = {"Retry-After": "5"} if isinstance(error, CapacityExceeded) else None
        content = {"detail": str(error)}
        if isinstance(error, SessionNotFound) and error.ended:
            content["ended"] = error.ended
        return JSONResponse(status_code=status, content=content, headers=headers)

    @app.exception_handler(RequestValidationError)
    async def _request_validation(_: Request, error: RequestValidationError) -> JSONResponse:
        return validation_response(list(error.errors()))

    @app.exception_handler(ValidationError)
    async def _model_validation(_: Request, error: ValidationError) -> JSONResponse:
        return validation_response(list(error.errors()))

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, error: StarletteHTTPException) -> JSONResponse:
        headers = dict(getattr(error, "headers", None) or {})
        if error.status_code == 405:
            headers["Allow"] = ", ".join(allowed_methods(request))
        return JSONResponse(status_code=error.status_code, content={"detail": error.detail}, headers=headers)

    @app.exception_handler(CheckpointError)
    async def _checkpoint(_: Request, error: CheckpointError) -> JSONResponse:
        return JSONResponse(status_code=503, content={"detail": str(error)})

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, error: Exception) -> JSONResponse:
        log.exception("unhandled error on %s %s", request.method, request.url.path)
        return JSONResponse(status_code=500, content={"detail": f"internal error: {type(error).__name__}"})
