"""The one service session a simulator keeps across scenes, reopened when the service forgot it."""

from __future__ import annotations

from client.http import NotFound, VGNClient
from sim_worker.camera import SIM_INTRINSICS


def fresh_session(
    vgn: VGNClient, session_id: str, decay: float | None = None, gripper: str | None = None
) -> str:
    """Empty ``session_id`` for a new observation and return the id to use. When the service
    no longer has it (idle past ``VGN_SESSION_TTL_S``, e.g. a paused run, evicted, or the
    service restarted), a new session is opened, for the hand ``gripper`` names (default: the
    service's), instead of failing a long run."""
    try:
        vgn.reset_session(session_id)
        return session_id
    except NotFound:
        return vgn.create_session(intrinsics=SIM_INTRINSICS, decay=decay, gripper=gripper).session_id
