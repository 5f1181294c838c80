"""Moved to ``vgn_contract.tracking`` (the wire contract); re-exported here for one release."""

from client.moved import warn_moved
from vgn_contract.tracking import (
    DEFAULT_MAX_ANGLE_DEG,
    DEFAULT_MAX_DISTANCE,
    GraspTracker,
    grasp_angle,
)

warn_moved("client.tracking", "vgn_contract.tracking")

__all__ = [
    "DEFAULT_MAX_ANGLE_DEG",
    "DEFAULT_MAX_DISTANCE",
    "GraspTracker",
    "grasp_angle",
]
