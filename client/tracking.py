"""Moved to ``vgn_contract.tracking`` (the wire contract); re-exported here for one release."""

from vgn_contract.tracking import (
    DEFAULT_MAX_ANGLE_DEG,
    DEFAULT_MAX_DISTANCE,
    GraspTracker,
    grasp_angle,
)

__all__ = [
    "DEFAULT_MAX_ANGLE_DEG",
    "DEFAULT_MAX_DISTANCE",
    "GraspTracker",
    "grasp_angle",
]
