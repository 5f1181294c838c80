"""Map the planning core's errors to gRPC status codes, with the HTTP API's messages.

Every error also carries the HTTP status the same failure gets over HTTP, as trailing
metadata ``vgn-http-status``, so a client can raise the same exception type for both.
"""

from __future__ import annotations

import functools
import secrets
from collections.abc import Callable
from typing import Any, TypeVar

import grpc
from pydantic import ValidationError

from service.api.errors import STATUS_OF, field_errors
from service.errors import (
    CapacityExceeded,
    InvalidInput,
    ModelNotReady,
    ServiceError,
    SessionExists,
    SessionNotFound,
    UnsupportedMediaType,
)
from service.vgn.checkpoint import CheckpointError

HTTP_STATUS_KEY = "vgn-http-status"
API_KEY_MESSAGE = "missing or wrong API key (x-api-key or authorization: Bearer metadata)"

CODE_OF: dict[type[ServiceError], grpc.StatusCode] = {
    InvalidInput: grpc.StatusCode.INVALID_ARGUMENT,
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


def abort(context: grpc.ServicerContext, code: grpc.StatusCode, message: str, http_status: int) -> None:
    context.set_trailing_metadata(((HTTP_STATUS_KEY, str(http_status)),))
    context.abort(code, message)


def api_key_of(context: grpc.ServicerContext) -> str | None:
    metadata = {key.lower(): value for key, value in context.invocation_metadata()}
    given = metadata.get("x-api-key")
    authorization = metadata.get("authorization", "")
    if given is None and authorization.lower().startswith("bearer "):
        given = authorization[7:].strip()
    return given


F = TypeVar("F", bound=Callable[..., Any])


def rpc(method: F) -> F:
    """Run a servicer method with the API key checked, the client's deadline respected and
    every error turned into a status code (never an unexplained INTERNAL for bad input)."""

    @functools.wraps(method)
    def wrapper(self, request: Any, context: grpc.ServicerContext) -> Any:
        expected = self.settings.api_key
        if expected is not None:
            given = api_key_of(context)
            if given is None or not secrets.compare_digest(given.encode(), expected.encode()):
                abort(context, grpc.StatusCode.UNAUTHENTICATED, API_KEY_MESSAGE, 401)
        remaining = context.time_remaining()
        if remaining is not None and remaining <= 0:
            abort(context, grpc.StatusCode.DEADLINE_EXCEEDED, "the deadline passed before the call ran", 504)
        try:
            return method(self, request, context)
        except ServiceError as error:
            kind = next((k for k in CODE_OF if isinstance(error, k)), InvalidInput)
            abort(context, CODE_OF[kind], str(error), HTTP_STATUS_OF.get(kind, 400))
        except ValidationError as error:
            abort(context, grpc.StatusCode.INVALID_ARGUMENT, validation_message(error), 422)
        except CheckpointError as error:
            abort(context, grpc.StatusCode.UNAVAILABLE, str(error), 503)

    return wrapper  # type: ignore[return-value]
