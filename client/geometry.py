"""Moved to ``vgn_contract.geometry`` (the wire contract); re-exported here for one release."""

from client.moved import warn_moved
from vgn_contract.geometry import (
    ORTHONORMAL_TOLERANCE,
    STEM_LENGTH,
    UNIT_QUATERNION_TOLERANCE,
    check_rigid_matrix,
    check_unit_quaternion,
    gripper_outline,
    invert,
    look_at,
    matrix_from_pose,
    pose_from_matrix,
)

warn_moved("client.geometry", "vgn_contract.geometry")

__all__ = [
    "ORTHONORMAL_TOLERANCE",
    "STEM_LENGTH",
    "UNIT_QUATERNION_TOLERANCE",
    "check_rigid_matrix",
    "check_unit_quaternion",
    "gripper_outline",
    "invert",
    "look_at",
    "matrix_from_pose",
    "pose_from_matrix",
]
