"""The robot-side poses of a grasp (client/robot.py): tool frame, the π turn, pre-grasp and lift,
checked against the geometry they stand for, and the inputs they refuse."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from client import Grasp, Pose
from client.robot import (
    HALF_TURN,
    nearest_turn,
    pregrasp_pose,
    retreat_pose,
    tool_offset,
    tool_pose,
)
from vgn_contract.geometry import invert, matrix_from_pose
from vgn_contract.gripper_description import builtin_gripper, default_gripper

#: The Franka hand's TCP (fingertip centre) from its flange, turned -45° about z (Franka's docs).
FLANGE_TO_TCP = 0.1034


def make_grasp(rotvec=(0.3, -2.5, 0.4), position=(0.12, 0.15, 0.09)) -> Grasp:
    rotation = Rotation.from_rotvec(rotvec)
    return Grasp(
        position=list(position),
        orientation=rotation.as_quat().tolist(),
        approach=rotation.as_matrix()[:, 2].tolist(),
        width=0.04,
        quality=0.9,
    )


@pytest.fixture
def grasp() -> Grasp:
    return make_grasp()


def test_the_pregrasp_is_the_grasp_moved_back_along_its_approach(grasp: Grasp) -> None:
    pose = grasp.as_matrix()
    pre = pregrasp_pose(grasp, 0.07)
    np.testing.assert_allclose(pre[:3, :3], pose[:3, :3], atol=1e-12)
    np.testing.assert_allclose(pre[:3, 3], pose[:3, 3] - 0.07 * np.asarray(grasp.approach), atol=1e-9)
    np.testing.assert_allclose(pre, pose @ tool_offset(-0.07), atol=1e-12)  # -d along its own z
    np.testing.assert_array_equal(pregrasp_pose(grasp, 0.0), pose)


def test_the_pregrasp_distance_defaults_to_the_hand_description(grasp: Grasp) -> None:
    pose = grasp.as_matrix()
    expected = pose[:3, 3] - default_gripper().pregrasp_distance * pose[:3, 2]
    np.testing.assert_allclose(pregrasp_pose(grasp)[:3, 3], expected, atol=1e-12)
    robotiq = builtin_gripper("robotiq-2f85")
    for hand in ("robotiq-2f85", robotiq):
        moved = pose[:3, 3] - pregrasp_pose(grasp, gripper=hand)[:3, 3]
        assert np.linalg.norm(moved) == pytest.approx(robotiq.pregrasp_distance)


def test_the_retreat_moves_straight_up_in_the_world(grasp: Grasp) -> None:
    pose = grasp.as_matrix()
    lift = retreat_pose(pose, 0.12)
    np.testing.assert_allclose(lift[:3, 3], pose[:3, 3] + [0.0, 0.0, 0.12], atol=1e-12)
    np.testing.assert_array_equal(lift[:3, :3], pose[:3, :3])
    np.testing.assert_allclose(retreat_pose(pose)[:3, 3] - pose[:3, 3], [0.0, 0.0, 0.10], atol=1e-12)
    sideways = retreat_pose(pose, 0.2, up=[0.0, 2.0, 0.0])  # normalised
    np.testing.assert_allclose(sideways[:3, 3] - pose[:3, 3], [0.0, 0.2, 0.0], atol=1e-12)
    assert not np.shares_memory(lift, pose)


def test_the_half_turn_keeps_position_and_approach_and_reverses_the_closing_axis(grasp: Grasp) -> None:
    pose = grasp.as_matrix()
    y = pose[:3, 1]
    np.testing.assert_array_equal(nearest_turn(grasp, y), pose)
    np.testing.assert_array_equal(nearest_turn(grasp, y + 0.1 * pose[:3, 2]), pose)
    turned = nearest_turn(grasp, -y)
    np.testing.assert_allclose(turned[:3, 3], pose[:3, 3], atol=0)
    np.testing.assert_allclose(turned[:3, 2], pose[:3, 2], atol=1e-12)
    np.testing.assert_allclose(turned[:3, 1], -y, atol=1e-12)
    np.testing.assert_allclose(turned[:3, 0], -pose[:3, 0], atol=1e-12)
    np.testing.assert_allclose(turned, pose @ tool_offset(about_approach=math.pi), atol=1e-12)
    np.testing.assert_allclose(nearest_turn(turned, y), pose, atol=1e-12)  # and back
    assert np.linalg.det(turned[:3, :3]) == pytest.approx(1.0)


def test_a_reference_across_both_forms_keeps_the_grasp(grasp: Grasp) -> None:
    pose = grasp.as_matrix()
    np.testing.assert_array_equal(nearest_turn(pose, pose[:3, 0]), pose)


def test_the_tool_pose_composes_the_grasp_with_the_tool_offset(grasp: Grasp) -> None:
    pose = grasp.as_matrix()
    np.testing.assert_array_equal(tool_pose(grasp), pose)
    tcp = tool_pose(grasp, tool_offset(0.05))  # fingertip centre: 0.05 m along the approach
    np.testing.assert_allclose(tcp[:3, 3], pose[:3, 3] + 0.05 * pose[:3, 2], atol=1e-12)
    np.testing.assert_allclose(tcp[:3, :3], pose[:3, :3], atol=1e-12)
    # The flange: 0.1034 m behind the TCP, the hand turned -45° about z from it.
    flange_in_grasp = (
        tool_offset(0.05) @ tool_offset(-FLANGE_TO_TCP) @ tool_offset(about_approach=math.pi / 4)
    )
    flange = tool_pose(grasp, flange_in_grasp)
    np.testing.assert_allclose(invert(flange) @ tcp, tool_offset(FLANGE_TO_TCP, -math.pi / 4), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(flange[:3, 3] - tcp[:3, 3]), FLANGE_TO_TCP, atol=1e-12)
    np.testing.assert_allclose(flange @ invert(flange_in_grasp), pose, atol=1e-12)  # round trip
    pose_offset = Pose.from_matrix(flange_in_grasp)
    np.testing.assert_allclose(tool_pose(grasp, pose_offset), flange, atol=1e-12)


def test_tool_offsets_commute_and_turn_about_the_approach() -> None:
    a = tool_offset(0.03, 0.7)
    np.testing.assert_allclose(a, tool_offset(0.03) @ tool_offset(about_approach=0.7), atol=1e-15)
    np.testing.assert_allclose(a, tool_offset(about_approach=0.7) @ tool_offset(0.03), atol=1e-15)
    np.testing.assert_allclose(tool_offset(about_approach=math.pi), HALF_TURN, atol=1e-15)
    expected = matrix_from_pose([0, 0, 0.03], Rotation.from_euler("z", 0.7).as_quat())
    np.testing.assert_allclose(a, expected, atol=1e-15)


def test_the_current_tool_picks_the_form_the_wrist_turns_least_to(grasp: Grasp) -> None:
    pose = grasp.as_matrix()
    offset = tool_offset(-0.0534, math.pi / 4)
    as_given, turned = pose @ offset, pose @ HALF_TURN @ offset
    # The wrist holds roughly the turned form now (a little off): it stays there.
    near_turned = turned @ tool_offset(about_approach=0.3)
    np.testing.assert_allclose(tool_pose(grasp, offset, current_tool=near_turned), turned, atol=1e-12)
    np.testing.assert_allclose(tool_pose(grasp, offset, current_tool=as_given), as_given, atol=1e-12)
    for current in (near_turned, as_given):  # the chosen form is the nearer rotation
        chosen = tool_pose(grasp, offset, current_tool=current)
        other = turned if np.allclose(chosen, as_given) else as_given
        angle = Rotation.from_matrix(current[:3, :3].T @ chosen[:3, :3]).magnitude()
        assert angle < Rotation.from_matrix(current[:3, :3].T @ other[:3, :3]).magnitude()


def test_the_pregrasp_of_the_tool_is_the_tool_pose_of_the_pregrasp(grasp: Grasp) -> None:
    offset = tool_offset(-0.0534, math.pi / 4)
    tool_pre = tool_pose(pregrasp_pose(grasp, 0.05), offset)
    tool = tool_pose(grasp, offset)
    np.testing.assert_allclose(tool_pre[:3, 3], tool[:3, 3] - 0.05 * np.asarray(grasp.approach), atol=1e-12)


def not_rigid() -> list[np.ndarray]:
    scaled, sheared, mirrored, last_row, nan = (np.eye(4) for _ in range(5))
    scaled[:3, :3] *= 1.1
    sheared[0, 1] = 0.2
    mirrored[2, 2] = -1.0
    last_row[3, 0] = 1.0
    nan[0, 3] = np.nan
    return [scaled, sheared, mirrored, last_row, nan, np.eye(3)]


@pytest.mark.parametrize(
    "matrix", not_rigid(), ids=["scaled", "sheared", "mirrored", "last-row", "nan", "3x3"]
)
def test_a_non_rigid_matrix_is_refused_with_its_name(matrix: np.ndarray, grasp: Grasp) -> None:
    with pytest.raises(ValueError, match="^grasp: "):
        pregrasp_pose(matrix, 0.05)
    with pytest.raises(ValueError, match="^grasp: "):
        nearest_turn(matrix, [0, 1, 0])
    with pytest.raises(ValueError, match="^tool_in_grasp: "):
        tool_pose(grasp, matrix)
    with pytest.raises(ValueError, match="^current_tool: "):
        tool_pose(grasp, None, current_tool=matrix)
    with pytest.raises(ValueError, match="^pose: "):
        retreat_pose(matrix)


@pytest.mark.parametrize("distance", [-0.01, float("nan"), float("inf")])
def test_a_negative_or_non_finite_distance_is_refused(distance: float, grasp: Grasp) -> None:
    with pytest.raises(ValueError, match="distance must be a finite distance >= 0"):
        pregrasp_pose(grasp, distance)
    with pytest.raises(ValueError, match="distance must be a finite distance >= 0"):
        retreat_pose(grasp, distance)


@pytest.mark.parametrize("direction", [[0.0, 0.0, 0.0], [0.0, 1.0], [np.nan, 0.0, 1.0]])
def test_a_degenerate_direction_is_refused(direction: list[float], grasp: Grasp) -> None:
    with pytest.raises(ValueError, match="closing_axis must be"):
        nearest_turn(grasp, direction)
    with pytest.raises(ValueError, match="up must be"):
        retreat_pose(grasp, 0.1, up=direction)


def test_a_non_finite_offset_is_refused() -> None:
    with pytest.raises(ValueError, match="along_approach must be finite"):
        tool_offset(float("nan"))
    with pytest.raises(ValueError, match="about_approach must be finite"):
        tool_offset(0.0, float("inf"))
