"""Detection on hand-made network outputs: validity mask, threshold, NMS, filters, and the
voxel → world conversion of positions, orientations and widths."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from service.vgn.detection import DetectionConfig, detect_grasps
from vgn_contract.geometry import matrix_from_pose

N, VOXEL = 40, 0.3 / 40
SHARP = DetectionConfig(smoothing_sigma=0.0)  # no smoothing: peaks stay where they are put
DOWN = Rotation.from_euler("x", np.pi)  # grasp z axis (approach) pointing to -z


def free_space_grid(surface_k: int = 10) -> np.ndarray:
    """Observed free space above a flat surface at layer ``surface_k``, solid below."""
    grid = np.zeros((N, N, N), np.float32)
    grid[:, :, surface_k - 3 : surface_k] = 0.3  # inside, behind the surface
    grid[:, :, surface_k : surface_k + 4] = 0.8  # in front, within the truncation band
    return grid


def outputs(peaks: dict[tuple[int, int, int], float], rotation: Rotation = DOWN, width: float = 4.0):
    quality = np.zeros((N, N, N), np.float32)
    for index, value in peaks.items():
        quality[index] = value
    rot = np.broadcast_to(rotation.as_quat()[:, None, None, None], (4, N, N, N)).copy()
    return quality, rot, np.full((N, N, N), width, np.float32)


IDENTITY = np.eye(4)


def detect(grid, quality, rotation, width, pose=IDENTITY, config=SHARP):
    return detect_grasps(grid, quality, rotation, width, VOXEL, pose, config)


def test_voxel_to_world_conversion():
    yaw = Rotation.from_euler("z", 90, degrees=True)
    workspace_pose = matrix_from_pose([1.0, -0.5, 0.7], yaw.as_quat())
    grasps = detect(free_space_grid(), *outputs({(12, 7, 11): 0.97}), pose=workspace_pose)
    assert len(grasps) == 1
    grasp = grasps[0]
    expected_position = yaw.apply(np.array([12, 7, 11]) * VOXEL) + [1.0, -0.5, 0.7]
    np.testing.assert_allclose(grasp.position, expected_position, atol=1e-9)
    expected = yaw * DOWN
    assert abs(np.dot(grasp.orientation, expected.as_quat())) == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(grasp.approach, expected.apply([0, 0, 1]), atol=1e-9)
    np.testing.assert_allclose(grasp.approach, [0, 0, -1], atol=1e-9)  # yaw keeps "down" down
    assert grasp.width == pytest.approx(4.0 * VOXEL)
    assert grasp.quality == pytest.approx(0.97, abs=1e-6)


def test_smoothing_is_part_of_the_score():
    """With VGN's σ = 1 an isolated high voxel is smoothed below threshold; a broad peak survives."""
    grid = free_space_grid()
    assert detect(grid, *outputs({(20, 20, 11): 1.0}), config=DetectionConfig()) == []
    quality, rotation, width = outputs({})
    quality[17:24, 17:24, 10:14] = 1.0
    grasps = detect(grid, quality, rotation, width, config=DetectionConfig())
    assert grasps and all(g.quality >= 0.9 for g in grasps)


@pytest.mark.parametrize("threshold, expected", [(0.9, 0), (0.8, 1)])
def test_threshold(threshold, expected):
    grasps = detect(
        free_space_grid(), *outputs({(20, 20, 11): 0.85}), config=replace(SHARP, threshold=threshold)
    )
    assert len(grasps) == expected


@pytest.mark.parametrize("width, kept", [(1.0, False), (1.33, True), (9.33, True), (10.0, False)])
def test_width_range_in_voxels(width, kept):
    grasps = detect(free_space_grid(), *outputs({(20, 20, 11): 0.95}, width=width))
    assert bool(grasps) is kept


@pytest.mark.parametrize(
    "k, kept, why",
    [
        (11, True, "observed free space in front of the surface"),
        (8, False, "inside the object, behind the surface"),
        (15, True, "unobserved, 2 voxels from free space (dilation)"),
        (16, False, "unobserved, 3 voxels from free space"),
    ],
)
def test_only_voxels_near_observed_free_space(k, kept, why):
    grasps = detect(free_space_grid(), *outputs({(20, 20, k): 0.95}))
    assert bool(grasps) is kept, why


def test_dilation_does_not_cross_into_the_object():
    grid = free_space_grid()
    grid[:, :, 5:7] = 0.0  # unobserved pocket below the inside band
    assert detect(grid, *outputs({(20, 20, 6): 0.95})) == []


def test_non_maximum_suppression_and_ranking():
    peaks = {(10, 10, 11): 0.92, (11, 10, 11): 0.95, (30, 30, 12): 0.99, (20, 20, 11): 0.93}
    grasps = detect(free_space_grid(), *outputs(peaks))
    qualities = [round(g.quality, 2) for g in grasps]
    assert qualities == [0.99, 0.95, 0.93], "neighbours within the NMS window are suppressed, best first"


def test_max_grasps():
    peaks = {(5 + 6 * i, 20, 11): 0.91 + 0.01 * i for i in range(5)}
    grasps = detect(free_space_grid(), *outputs(peaks), config=replace(SHARP, max_grasps=2))
    assert [round(g.quality, 2) for g in grasps] == [0.95, 0.94]


def test_crop_box_in_workspace_frame():
    peaks = {(5, 5, 11): 0.95, (30, 30, 11): 0.96}
    crop = replace(SHARP, crop_min=(0.0, 0.0, 0.0), crop_max=(0.1, 0.1, 0.3))
    workspace_pose = matrix_from_pose([5.0, 5.0, 0.0], [0, 0, 0, 1])  # the crop moves with the workspace
    grasps = detect(free_space_grid(), *outputs(peaks), pose=workspace_pose, config=crop)
    assert len(grasps) == 1
    np.testing.assert_allclose(grasps[0].position, [5.0 + 5 * VOXEL, 5.0 + 5 * VOXEL, 11 * VOXEL])


@pytest.mark.parametrize(
    "direction, kept", [((0, 0, -1), True), ((0.3, 0, -1), True), ((1, 0, 0), False), ((0, 0, 1), False)]
)
def test_approach_cone_in_world_frame(direction, kept):
    cone = replace(SHARP, approach=direction, max_approach_angle_rad=np.radians(30))
    grasps = detect(free_space_grid(), *outputs({(20, 20, 11): 0.95}), config=cone)
    assert bool(grasps) is kept


def test_empty_output():
    assert detect(free_space_grid(), *outputs({})) == []
    assert detect(np.zeros((N, N, N), np.float32), *outputs({(20, 20, 11): 0.99})) == []


@pytest.mark.parametrize("size", [2, 3, 4, 5])
def test_local_maxima_are_those_of_scipy_s_maximum_filter(size):
    """NMS looks only around positive voxels; it must find what the full filter finds,
    borders (reflected) and ties included."""
    from scipy import ndimage

    from service.vgn.detection import local_maxima

    rng = np.random.default_rng(size)
    score = np.where(rng.random((N, N, N)) < 0.05, rng.random((N, N, N)), 0.0).astype(np.float32)
    score[0, 0, :3] = 0.7  # ties at a corner
    score[N - 1, 5, N - 1] = 0.9
    expected = np.argwhere((score == ndimage.maximum_filter(score, size=size)) & (score > 0))
    actual = local_maxima(score, size)
    assert sorted(map(tuple, actual)) == sorted(map(tuple, expected))
    assert len(local_maxima(np.zeros((N, N, N), np.float32), size)) == 0


def test_the_grasp_region_is_scipy_s_masked_dilation():
    from scipy import ndimage

    from service.vgn.detection import grasp_region

    rng = np.random.default_rng(7)
    grid = rng.choice([0.0, 0.3, 0.8], size=(N, N, N), p=[0.6, 0.2, 0.2]).astype(np.float32)
    grid[0, :, :] = 0.8  # borders
    for steps in (1, 2, 3):
        config = DetectionConfig(surface_dilation=steps)
        inside = (grid > 1e-3) & (grid < 0.5)
        expected = ndimage.binary_dilation(grid > 0.5, iterations=steps, mask=~inside)
        assert np.array_equal(grasp_region(grid, config), expected)
