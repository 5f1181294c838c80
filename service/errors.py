"""Domain errors of the planning core; the HTTP and gRPC front ends map them to their codes."""

from __future__ import annotations


class ServiceError(Exception):
    """Base class: ``str(error)`` is a message fit to show the caller."""


class InvalidInput(ServiceError):
    """The caller sent something malformed (HTTP 400)."""


class UnsupportedMediaType(ServiceError):
    """A depth encoding we do not read (HTTP 415)."""


class SessionNotFound(ServiceError):
    """No session with that id, or it expired (HTTP 404). ``ended`` says how, when this service
    held the session and it ended here ("deleted", "expired", "evicted"): a client then knows
    the session is gone, not held by another replica it should rebuild it on."""

    def __init__(self, message: str, ended: str | None = None) -> None:
        super().__init__(message)
        self.ended = ended


class SessionExists(ServiceError):
    """A session with the requested id already exists (HTTP 409)."""


class CapacityExceeded(ServiceError):
    """The session limit is reached and no session is idle to evict (HTTP 503)."""


class ModelNotReady(ServiceError):
    """No model is loaded, so grasps cannot be planned (HTTP 503)."""


class GripperNotServed(ServiceError):
    """The session names a hand the service knows but no loaded network was trained for (HTTP 400,
    gRPC FAILED_PRECONDITION): its grasps would be another hand's."""
