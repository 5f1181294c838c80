"""Typed client for vgn-service: ``VGNClient`` / ``AsyncVGNClient`` and the shared schemas.

Installs without torch, open3d or pybullet; ``connect(url)`` also gives the gRPC client for
``grpc://`` URLs (with the ``grpc`` extra).
"""

from client.connect import connect
from client.http import (
    AsyncVGNClient,
    BadRequest,
    Conflict,
    NotFound,
    PayloadTooLarge,
    ServiceUnavailable,
    Unauthorized,
    VGNClient,
    VGNError,
)
from client.schemas import Grasp, GraspQuery, GraspResult, Intrinsics, Pose, SessionInfo, Workspace

__all__ = [
    "AsyncVGNClient",
    "BadRequest",
    "Conflict",
    "Grasp",
    "GraspQuery",
    "GraspResult",
    "Intrinsics",
    "NotFound",
    "PayloadTooLarge",
    "Pose",
    "ServiceUnavailable",
    "SessionInfo",
    "Unauthorized",
    "VGNClient",
    "VGNError",
    "Workspace",
    "connect",
]
