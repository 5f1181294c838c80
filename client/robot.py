"""From a planned grasp to the poses a robot arm moves its tool to.

The service answers grasps in its own grasp frame (docs/conventions.md: +z the approach, y the
closing axis, the origin between the finger bases). A robot commands a tool frame of its own (a
TCP, or the flange): ``tool_pose`` applies the fixed transform between the two, ``nearest_turn``
picks which of a grasp's two equivalent forms (turned by π about the approach) the wrist turns
least to, and ``pregrasp_pose`` / ``retreat_pose`` give the approach and lift poses. Every pose
is a 4×4 matrix mapping its frame into the world; pure numpy, no robot library.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from vgn_contract.geometry import check_rigid_matrix, invert
from vgn_contract.gripper_description import GripperDescription, default_gripper, load_gripper
from vgn_contract.schemas import Grasp, Pose

#: A grasp or a pose given as the client's schema or as a 4×4 matrix.
PoseLike = Grasp | Pose | np.ndarray | Sequence[Sequence[float]]

#: A grasp turned by π about its approach: the same grasp with the closing axis reversed.
HALF_TURN = np.diag([-1.0, -1.0, 1.0, 1.0])
#: How near zero the cosine between the closing axis and a reference counts as "at right
#: angles", where rounding must not decide between two equally near forms.
ACROSS_TOLERANCE = 1e-9
#: The world's up direction in the service's frames (the workspace's z axis points up).
WORLD_UP = (0.0, 0.0, 1.0)


def as_pose_matrix(pose: PoseLike, name: str = "pose") -> np.ndarray:
    """A fresh 4×4 float64 matrix of ``pose``; ``ValueError`` naming ``name`` unless it is rigid."""
    matrix = pose.as_matrix() if isinstance(pose, (Grasp, Pose)) else np.array(pose, dtype=np.float64)
    try:
        check_rigid_matrix(matrix)
    except ValueError as error:
        raise ValueError(f"{name}: {error}") from None
    return matrix


def _distance(value: float, name: str) -> float:
    distance = float(value)
    if not math.isfinite(distance) or distance < 0.0:
        raise ValueError(f"{name} must be a finite distance >= 0 (metres), got {value!r}")
    return distance


def tool_offset(along_approach: float = 0.0, about_approach: float = 0.0) -> np.ndarray:
    """The tool frame's pose in the grasp frame (tool → grasp) for a tool on the approach axis:
    ``along_approach`` metres along +z from the finger bases (negative: behind them, as a flange
    is) and turned ``about_approach`` radians about z. Both commute, so the order is moot."""
    for value, name in ((along_approach, "along_approach"), (about_approach, "about_approach")):
        if not math.isfinite(float(value)):
            raise ValueError(f"{name} must be finite, got {value!r}")
    c, s = math.cos(about_approach), math.sin(about_approach)
    offset = np.eye(4)
    offset[:2, :2] = [[c, -s], [s, c]]
    offset[2, 3] = along_approach
    return offset


def nearest_turn(grasp: PoseLike, closing_axis: Sequence[float]) -> np.ndarray:
    """The grasp's 4×4 pose, turned by π about its approach when that brings its closing axis
    (y) nearer the world direction ``closing_axis``; position and approach never change. A
    reference at right angles to both forms keeps the grasp as given."""
    pose = as_pose_matrix(grasp, "grasp")
    reference = np.asarray(closing_axis, dtype=np.float64)
    if reference.shape != (3,) or not np.isfinite(reference).all() or not np.linalg.norm(reference) > 0:
        raise ValueError(f"closing_axis must be a finite, non-zero 3-vector, got {closing_axis!r}")
    cosine = float(pose[:3, 1] @ reference) / float(np.linalg.norm(reference))
    return pose @ HALF_TURN if cosine < -ACROSS_TOLERANCE else pose


def tool_pose(
    grasp: PoseLike, tool_in_grasp: PoseLike | None = None, current_tool: PoseLike | None = None
) -> np.ndarray:
    """The 4×4 world pose to send the tool frame to for ``grasp``: ``grasp @ tool_in_grasp``.

    ``tool_in_grasp`` is the tool frame's fixed pose in the grasp frame (tool → grasp, e.g. from
    ``tool_offset``; default: the grasp frame itself). With ``current_tool`` (the tool's world
    pose now), the grasp is first put in the form of the two whose closing axis is nearest the
    one the hand has now (``nearest_turn``), so the wrist need not make a half turn.
    """
    pose = as_pose_matrix(grasp, "grasp")
    offset = np.eye(4) if tool_in_grasp is None else as_pose_matrix(tool_in_grasp, "tool_in_grasp")
    if current_tool is not None:
        grasp_frame_now = as_pose_matrix(current_tool, "current_tool") @ invert(offset)
        pose = nearest_turn(pose, grasp_frame_now[:3, 1])
    return pose @ offset


def pregrasp_pose(
    grasp: PoseLike, distance: float | None = None, gripper: str | GripperDescription | None = None
) -> np.ndarray:
    """The 4×4 pose ``distance`` metres back along the approach from ``grasp`` (its own −z), the
    open hand's start before moving straight in. ``distance`` defaults to the hand description's
    ``pregrasp_distance`` (``gripper``: a built-in name, a path or a description; default the
    default hand). Works on a grasp pose; ``tool_pose`` then gives the tool's."""
    pose = as_pose_matrix(grasp, "grasp")
    if distance is None:
        hand = gripper if isinstance(gripper, GripperDescription) else None
        if hand is None:
            hand = default_gripper() if gripper is None else load_gripper(gripper)
        distance = hand.pregrasp_distance
    pose[:3, 3] -= _distance(distance, "distance") * pose[:3, 2]
    return pose


def retreat_pose(pose: PoseLike, distance: float = 0.10, up: Sequence[float] = WORLD_UP) -> np.ndarray:
    """The 4×4 pose moved ``distance`` metres straight up in the world (``up``: the world's up
    direction, normalised here), the orientation kept: the lift after closing, 0.10 m as in
    VGN's protocol unless given."""
    matrix = as_pose_matrix(pose)
    direction = np.asarray(up, dtype=np.float64)
    norm = float(np.linalg.norm(direction)) if direction.shape == (3,) else 0.0
    if not (math.isfinite(norm) and norm > 0.0):
        raise ValueError(f"up must be a finite, non-zero 3-vector, got {up!r}")
    matrix[:3, 3] += _distance(distance, "distance") * direction / norm
    return matrix
