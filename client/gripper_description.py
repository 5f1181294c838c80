"""Moved to ``vgn_contract.gripper_description`` (the wire contract); re-exported here for one release."""

from client.moved import warn_moved
from vgn_contract.gripper_description import (
    BUILTIN_DIR,
    DEFAULT_GRIPPER,
    NAME_PATTERN,
    TOLERANCE,
    Box,
    FingerBox,
    Force,
    GraspFrame,
    GripperDescription,
    GripperDescriptionError,
    Mass,
    Opening,
    Pad,
    Triple,
    builtin_gripper,
    builtin_grippers,
    check_version,
    default_gripper,
    load_gripper,
    parse_gripper,
    read_gripper,
)

warn_moved("client.gripper_description", "vgn_contract.gripper_description")

__all__ = [
    "BUILTIN_DIR",
    "Box",
    "DEFAULT_GRIPPER",
    "FingerBox",
    "Force",
    "GraspFrame",
    "GripperDescription",
    "GripperDescriptionError",
    "Mass",
    "NAME_PATTERN",
    "Opening",
    "Pad",
    "TOLERANCE",
    "Triple",
    "builtin_gripper",
    "builtin_grippers",
    "check_version",
    "default_gripper",
    "load_gripper",
    "parse_gripper",
    "read_gripper",
]
