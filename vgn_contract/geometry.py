"""Rigid-transform helpers shared by the client, the service and the simulator.

Conventions (docs/conventions.md): quaternions are ``[x, y, z, w]`` (scalar last, as scipy and ROS),
poses are 4×4 homogeneous matrices mapping points from a child frame into a parent frame.
"""

from __future__ import annotations

import inspect

import numpy as np
from scipy.spatial.transform import Rotation

from vgn_contract.gripper_description import default_gripper

#: How far a quaternion's norm may stray from 1 before it is refused rather than trusted.
UNIT_QUATERNION_TOLERANCE = 1e-3
#: How far ``RᵀR`` may stray from the identity before a matrix counts as non-rigid.
ORTHONORMAL_TOLERANCE = 1e-4
#: The last row of every homogeneous rigid transform.
_HOMOGENEOUS_ROW = np.array([0.0, 0.0, 0.0, 1.0])
#: Newer scipy (1.17.1 here) can skip re-orthonormalising a matrix the caller has checked: for
#: a single matrix ~22 instead of ~90 us, which every frame upload pays for its camera pose.
_CHECKED_MATRIX = (
    {"assume_valid": True} if "assume_valid" in inspect.signature(Rotation.from_matrix).parameters else {}
)


def check_unit_quaternion(quaternion: np.ndarray) -> None:
    """Raise ``ValueError`` unless ``quaternion`` is a finite unit ``[x, y, z, w]``."""
    q = np.asarray(quaternion, dtype=np.float64)
    if q.shape != (4,):
        raise ValueError(f"quaternion must have 4 elements [x, y, z, w], got shape {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError("quaternion contains NaN or inf")
    with np.errstate(over="ignore"):  # a norm beyond a double is inf, and refused as such
        norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > UNIT_QUATERNION_TOLERANCE:
        raise ValueError(f"quaternion must have unit length, its norm is {norm:.6g}")


def check_rigid_matrix(matrix: np.ndarray) -> None:
    """Raise ``ValueError`` unless ``matrix`` is a finite 4×4 rigid transform (rotation + translation)."""
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4):
        raise ValueError(f"pose matrix must be 4x4, got shape {m.shape}")
    if not np.isfinite(m).all():
        raise ValueError("pose matrix contains NaN or inf")
    if np.abs(m[3] - _HOMOGENEOUS_ROW).max() > 1e-9:
        raise ValueError(f"pose matrix last row must be [0, 0, 0, 1], got {m[3].tolist()}")
    rotation = m[:3, :3]
    error = float(np.abs(rotation.T @ rotation - np.eye(3)).max())
    if error > ORTHONORMAL_TOLERANCE:
        raise ValueError(f"pose matrix is not rigid: rotation part is not orthonormal (error {error:.3g})")
    if np.linalg.det(rotation) < 0:
        raise ValueError("pose matrix is not rigid: rotation part is a reflection (det < 0)")


def matrix_from_pose(position: np.ndarray, quaternion: np.ndarray) -> np.ndarray:
    """4×4 transform from a position and an ``[x, y, z, w]`` quaternion."""
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_quat(np.asarray(quaternion, dtype=np.float64)).as_matrix()
    matrix[:3, 3] = position
    return matrix


def pose_from_matrix(matrix: np.ndarray, checked: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``(position, quaternion [x, y, z, w])`` of a 4×4 rigid transform. ``checked``: the matrix
    passed ``check_rigid_matrix`` (orthonormal within ``ORTHONORMAL_TOLERANCE``), so the
    quaternion is read off without re-orthonormalising the rotation first."""
    m = np.asarray(matrix, dtype=np.float64)
    options = _CHECKED_MATRIX if checked else {}
    return m[:3, 3].copy(), Rotation.from_matrix(m[:3, :3], **options).as_quat()


def invert(matrix: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform, without a general matrix inversion."""
    inverse = np.eye(4)
    rotation_t = matrix[:3, :3].T
    inverse[:3, :3] = rotation_t
    inverse[:3, 3] = -rotation_t @ matrix[:3, 3]
    return inverse


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera→world pose of an OpenCV camera at ``eye`` looking at ``target``.

    The optical frame has x right, y down and z forward (docs/conventions.md). ``up`` is a world
    direction that should appear upwards in the image; it must not be parallel to the view.
    """
    eye = np.asarray(eye, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(right) < 1e-9:
        raise ValueError("look_at: the up vector is parallel to the viewing direction")
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, down, forward, eye
    return pose


#: A stem drawn behind the palm so the approach direction reads at a glance (metres).
STEM_LENGTH = 0.03


def gripper_outline(grasp_pose: np.ndarray, width: float, finger_depth: float | None = None) -> np.ndarray:
    """(7, 3) world points outlining a parallel-jaw grasp, for drawing: finger tip, palm, palm,
    finger tip (one stroke), a NaN row (pen up), then the stem from the palm backwards. Grasp
    frame as everywhere: +z approach, y the closing axis, origin between the finger bases; the
    fingers are ``finger_depth`` long (m; default: the default gripper description's)."""
    depth = default_gripper().finger_depth if finger_depth is None else finger_depth
    half = width / 2
    local = np.array(
        [
            [0, -half, depth],
            [0, -half, 0],
            [0, half, 0],
            [0, half, depth],
            [np.nan, np.nan, np.nan],
            [0, 0, 0],
            [0, 0, -STEM_LENGTH],
        ]
    )
    return local @ grasp_pose[:3, :3].T + grasp_pose[:3, 3]
