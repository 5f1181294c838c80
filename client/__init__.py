"""Typed client for vgn-service: ``VGNClient`` / ``AsyncVGNClient``, ``GRPCClient`` and the
schemas both sides share (defined in ``vgn_contract``), and the robot-side poses of a grasp
(``client.robot``).

Installs without torch, open3d or pybullet; ``GRPCClient`` (and ``connect(url)`` for
``grpc://`` URLs) needs the ``grpc`` extra, which is imported only when it is first used.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from client.connect import connect
from client.extras import missing_extra
from client.http import (
    AsyncVGNClient,
    BadRequest,
    Conflict,
    InvalidRequest,
    NotFound,
    PayloadTooLarge,
    ServiceUnavailable,
    Unauthorized,
    VGNClient,
    VGNError,
)
from client.robot import nearest_turn, pregrasp_pose, retreat_pose, tool_offset, tool_pose
from vgn_contract.schemas import Grasp, GraspQuery, GraspResult, Intrinsics, Pose, SessionInfo, Workspace

if TYPE_CHECKING:
    from client.grpc_client import GRPCClient as GRPCClient

# GRPCClient is left out, so that ``from client import *`` works without the grpc extra.
__all__ = [
    "AsyncVGNClient",
    "BadRequest",
    "Conflict",
    "Grasp",
    "GraspQuery",
    "GraspResult",
    "Intrinsics",
    "InvalidRequest",
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
    "nearest_turn",
    "pregrasp_pose",
    "retreat_pose",
    "tool_offset",
    "tool_pose",
]


def __getattr__(name: str) -> Any:
    """``client.GRPCClient`` on first use: importing ``client`` must not need grpcio."""
    if name != "GRPCClient":
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    try:
        from client.grpc_client import GRPCClient
    except ImportError as error:
        raise ImportError(missing_extra("GRPCClient", "grpc", error), name=name) from None
    globals()["GRPCClient"] = GRPCClient  # later look-ups skip this function
    return GRPCClient


def __dir__() -> list[str]:
    return sorted([*globals(), "GRPCClient"])
