"""Map the planning core's errors to gRPC status codes, with the HTTP API's messages.

Every error also carries the HTTP status the same failure gets over HTTP, as trailing
metadata ``vgn-http-status``, so a client can raise the same exception type for both.
"""

from __future__ import annotations

import functools
import logging
import secrets
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

import grpc
from pydantic import ValidationError

from service.api.errors import STATUS_OF, field_errors
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
from service.grpc.handlers import MalformedRequest
from service.settings import Settings
from service.vgn.checkpoint import CheckpointError
from vgn_contract.grpc_api import grasp_planning_pb2 as pb

if TYPE_CHECKING:
    from service.api.metrics import ServiceMetrics

log = logging.getLogger("vgn.service")

HTTP_STATUS_KEY = "vgn-http-status"
#: Trailing metadata of a NOT_FOUND for a session that ended here (``SessionNotFound.ended``).
SESSION_ENDED_KEY = "vgn-session-ended"
API_KEY_MESSAGE = "missing or wrong API key (x-api-key or authorization: Bearer metadata)"

CODE_OF: dict[type[ServiceError], grpc.StatusCode] = {
    InvalidInput: grpc.StatusCode.INVALID_ARGUMENT,
    GripperNotServed: grpc.StatusCode.FAILED_PRECONDITION,
    UnsupportedMediaType: grpc.StatusCode.INVALID_ARGUMENT,
    SessionNotFound: grpc.StatusCode.NOT_FOUND,
    SessionExists: grpc.StatusCode.ALREADY_EXISTS,
    CapacityExceeded: grpc.StatusCode.RESOURCE_EXHAUSTED,
    ModelNotReady: grpc.StatusCode.UNAVAILABLE,
}


class PayloadTooLarge(ServiceError):
    """A frame's depth bytes exceed ``VGN_MAX_FRAME_BYTES`` (HTTP 413)."""


CODE_OF[PayloadTooLarge] = grpc.StatusCode.RESOURCE_EXHAUSTED
HTTP_STATUS_OF = {**STATUS_OF, PayloadTooLarge: 413}


def validation_message(error: ValidationError) -> str:
    """The one-line summary the HTTP API sends as a 422's ``message``."""
    return field_errors(list(error.errors()))[1]


def abort(
    context: grpc.ServicerContext,
    code: grpc.StatusCode,
    message: str,
    http_status: int,
    ended: str | None = None,
) -> None:
    """End the call with ``code`` and ``message``, naming in the trailers the HTTP status the
    same failure gets (and how a session that ended here ended)."""
    trailers = ((HTTP_STATUS_KEY, str(http_status)),) + (((SESSION_ENDED_KEY, ended),) if ended else ())
    context.set_trailing_metadata(trailers)
    context.abort(code, message)


def api_key_of(context: grpc.ServicerContext) -> str | None:
    """The key a call presents: ``x-api-key`` metadata, else an ``authorization: Bearer`` token."""
    metadata = {key.lower(): value for key, value in context.invocation_metadata()}
    given = metadata.get("x-api-key")
    authorization = metadata.get("authorization", "")
    if given is None and authorization.lower().startswith("bearer "):
        given = authorization[7:].strip()
    return given


F = TypeVar("F", bound=Callable[..., Any])
#: (code, message, HTTP status[, how the session ended]) of a refused call.
Failure = tuple[grpc.StatusCode, str, int] | tuple[grpc.StatusCode, str, int, str | None]
SERVICE_NAME = pb.DESCRIPTOR.services_by_name["GraspPlanning"].full_name


class Servicer(Protocol):
    """What ``rpc`` reads from the servicer it wraps the methods of."""

    settings: Settings
    metrics: ServiceMetrics | None


def refusal(settings: Settings, context: grpc.ServicerContext) -> Failure | None:
    """Why a call must not run: a missing or wrong API key, or a deadline already past."""
    expected = settings.api_key
    if expected is not None:
        given = api_key_of(context)
        if given is None or not secrets.compare_digest(given.encode(), expected.encode()):
            return grpc.StatusCode.UNAUTHENTICATED, API_KEY_MESSAGE, 401
    remaining = context.time_remaining()
    if remaining is not None and remaining <= 0:
        return grpc.StatusCode.DEADLINE_EXCEEDED, "the deadline passed before the call ran", 504
    return None


def failure_of(error: Exception, route: str) -> Failure:
    """The status a servicer's exception ends its call with (a bug is logged and INTERNAL)."""
    if isinstance(error, ServiceError):
        kind = next((k for k in CODE_OF if isinstance(error, k)), InvalidInput)
        return CODE_OF[kind], str(error), HTTP_STATUS_OF.get(kind, 400), getattr(error, "ended", None)
    if isinstance(error, ValidationError):
        return grpc.StatusCode.INVALID_ARGUMENT, validation_message(error), 422
    if isinstance(error, CheckpointError):
        return grpc.StatusCode.UNAVAILABLE, str(error), 503
    log.exception("unhandled error in %s", route, exc_info=error)  # as the HTTP app's 500 does
    return grpc.StatusCode.INTERNAL, f"internal error: {type(error).__name__}", 500


def _count(servicer: Servicer, route: str, failure: Failure | None, started: float) -> None:
    if servicer.metrics is not None:
        code = failure[0] if failure else grpc.StatusCode.OK
        servicer.metrics.requests.labels("GRPC", route, code.name).inc()
        servicer.metrics.latency.labels("GRPC", route).observe(time.perf_counter() - started)


def rpc(method: F) -> F:
    """Run a servicer method with the API key checked, the client's deadline respected and
    every error turned into a status code; counted in the app's request metrics (method
    ``GRPC``, route ``/vgn.v1.GraspPlanning/<Method>``, status the code's name)."""
    route = f"/{SERVICE_NAME}/{method.__name__}"

    @functools.wraps(method)
    def wrapper(self: Servicer, request: Any, context: grpc.ServicerContext) -> Any:
        started = time.perf_counter()
        failure, result = refusal(self.settings, context), None
        if failure is None and isinstance(request, MalformedRequest):
            failure = grpc.StatusCode.INVALID_ARGUMENT, request.describe(), 400
        if failure is None:
            try:
                result = method(self, request, context)
            except Exception as error:
                failure = failure_of(error, route)
        _count(self, route, failure, started)
        if failure is not None:
            abort(context, *failure)
        return result

    return wrapper  # type: ignore[return-value]


def streaming_rpc(method: F) -> F:
    """``rpc`` for a method that yields its replies (server streaming): the replies sent before
    an error stay sent, and the error ends the stream with its status code."""
    route = f"/{SERVICE_NAME}/{method.__name__}"

    @functools.wraps(method)
    def wrapper(self: Servicer, request: Any, context: grpc.ServicerContext) -> Any:
        started = time.perf_counter()
        failure = refusal(self.settings, context)
        if failure is None:
            try:
                yield from method(self, request, context)
            except Exception as error:
                failure = failure_of(error, route)
        _count(self, route, failure, started)
        if failure is not None:
            abort(context, *failure)

    return wrapper  # type: ignore[return-value]
