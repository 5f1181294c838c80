"""A checked pose matrix's quaternion, read off without re-orthonormalising, is the rotation's."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vgn_contract.geometry import ORTHONORMAL_TOLERANCE, check_rigid_matrix, pose_from_matrix
from vgn_contract.schemas import Pose


def rigid(rotation: np.ndarray, position: np.ndarray) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3], matrix[:3, 3] = rotation, position
    return matrix


def angle_between(a: np.ndarray, b: np.ndarray) -> float:
    return float((Rotation.from_quat(a).inv() * Rotation.from_quat(b)).magnitude())


def test_exact_rotations_give_the_same_pose_both_ways():
    rng = np.random.default_rng(3)
    for rotation in Rotation.random(50, random_state=4).as_matrix():
        matrix = rigid(rotation, rng.uniform(-1, 1, 3))
        position, quaternion = pose_from_matrix(matrix, checked=True)
        reference_position, reference_quaternion = pose_from_matrix(matrix)
        assert np.array_equal(position, reference_position)
        assert angle_between(quaternion, reference_quaternion) < 1e-9


def test_a_rotation_just_inside_the_tolerance_gives_a_unit_quaternion_near_the_nearest_rotation():
    rng = np.random.default_rng(5)
    for rotation in Rotation.random(50, random_state=6).as_matrix():
        matrix = rigid(rotation + rng.normal(0, ORTHONORMAL_TOLERANCE / 8, (3, 3)), np.zeros(3))
        check_rigid_matrix(matrix)  # still counts as rigid
        _, quaternion = pose_from_matrix(matrix, checked=True)
        assert abs(np.linalg.norm(quaternion) - 1) < 1e-12
        assert angle_between(quaternion, pose_from_matrix(matrix)[1]) < ORTHONORMAL_TOLERANCE
        pose = Pose.from_matrix(matrix)  # and the schema takes it
        assert angle_between(np.asarray(pose.orientation), quaternion) < 1e-12


def test_pose_from_matrix_builds_what_validating_the_matrix_builds():
    rng = np.random.default_rng(7)
    for rotation in Rotation.random(20, random_state=8).as_matrix():
        matrix = rigid(rotation, rng.uniform(-1, 1, 3))
        built = Pose.from_matrix(matrix)
        assert built == Pose.model_validate({"matrix": matrix.tolist()})
        assert Pose.model_validate_json(built.model_dump_json()) == built  # valid on the wire too


def test_pose_from_matrix_refuses_what_validation_refuses():
    reflection = rigid(np.diag([1.0, 1.0, -1.0]), np.zeros(3))
    sheared = rigid(np.array([[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), np.zeros(3))
    infinite = rigid(np.eye(3), np.array([0.0, np.inf, 0.0]))
    for bad, message in [
        (np.eye(3), "must be 4x4"),
        (reflection, "reflection"),
        (sheared, "not orthonormal"),
        (infinite, "NaN or inf"),
        ([["a"] * 4] * 4, "4x4 array of numbers"),
    ]:
        with pytest.raises(ValueError, match=message):
            Pose.from_matrix(bad)
        with pytest.raises(ValueError, match=message):
            Pose.model_validate({"matrix": bad.tolist() if isinstance(bad, np.ndarray) else bad})
