"""TSDF fusion of an analytic scene (a box on a table) checked against the known surface."""

from __future__ import annotations

import numpy as np
import pytest

from service.tsdf import SceneVolume, TSDFVolume
from tests.helpers.scenes import INTRINSICS, TABLE_Z, BoxScene, circle_views
from vgn_contract.geometry import matrix_from_pose

SCENE = BoxScene()


def fused(workspace_pose: np.ndarray | None = None, views: int = 6, resolution: int = 40) -> SceneVolume:
    volume = SceneVolume(
        0.3, resolution, np.eye(4) if workspace_pose is None else workspace_pose, cloud_resolution=120
    )
    for camera_pose in circle_views(views):
        volume.integrate(SCENE.depth(camera_pose), INTRINSICS, camera_pose, max_depth=2.0)
    return volume


def test_analytic_depth_matches_geometry():
    """Guard for the test scene itself: the centre ray of a top-down camera hits the box top."""
    from vgn_contract.geometry import look_at

    pose = look_at([0.15, 0.15, 0.6], [0.15, 0.15, 0.0], up=[0, 1, 0])
    depth = SCENE.depth(pose)
    assert depth[240, 320] == pytest.approx(0.6 - SCENE.upper[2], abs=1e-4)
    assert depth[5, 5] == pytest.approx(0.6 - TABLE_Z, abs=2e-3)


def test_grid_has_vgn_semantics():
    grid = fused().grid()
    voxel = 0.3 / 40
    assert grid.shape == (40, 40, 40) and grid.dtype == np.float32
    assert grid.min() >= 0.0 and grid.max() <= 1.0
    # Column through the box centre: voxel centres sit at (k + 0.5) * voxel.
    column = grid[20, 20]
    z = (np.arange(40) + 0.5) * voxel
    top = SCENE.upper[2]
    in_front = (z > top + 0.5 * voxel) & (z < top + 3.5 * voxel)
    assert np.all(column[in_front] > 0.5), "voxels just above the box top are in free space"
    assert np.all(column[z > top + 4.5 * voxel] == 0.0), "beyond the truncation band the grid is 0"
    behind = (z < top - 0.5 * voxel) & (z > top - 3.5 * voxel)
    assert np.all((column[behind] > 0.0) & (column[behind] < 0.5)), (
        "just inside the box is behind the surface"
    )
    # The 0.5 crossing lies on the analytic surface within half a voxel.
    band = behind | in_front  # grid values rise with z through the surface
    crossing = np.interp(0.5, column[band], z[band])
    assert crossing == pytest.approx(top, abs=0.5 * voxel)


def test_unobserved_space_is_zero():
    grid = fused().grid()
    # Deep inside the table (z < 0.05 - truncation) nothing is observed.
    assert np.all(grid[:, :, :2] == 0.0)


def test_cloud_lies_on_the_surface_with_outward_normals():
    cloud = fused().cloud()
    points, normals = cloud[:, :3].astype(np.float64), cloud[:, 3:].astype(np.float64)
    assert len(points) > 1000
    distance = SCENE.distance_to_surface(points)
    assert np.percentile(distance, 95) < 0.003, "fine cloud within 3 mm of the true surface"
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-3)
    on_box_top = (np.abs(points[:, 2] - SCENE.upper[2]) < 0.002) & np.all(
        (points[:, :2] > np.add(SCENE.lower[:2], 0.01))
        & (points[:, :2] < np.subtract(SCENE.upper[:2], 0.01)),
        axis=1,
    )
    assert on_box_top.sum() > 50
    assert np.all(normals[on_box_top, 2] > 0.95), "normals on the box top point up, towards the camera side"


def test_workspace_pose_moves_the_volume_not_the_world():
    """A workspace shifted in the world sees the scene at shifted grid indices, and the cloud
    comes back in world coordinates either way."""
    voxel = 0.3 / 40
    shift = np.array([-4 * voxel, -2 * voxel, 0.0])  # workspace corner moved to negative x, y
    pose = matrix_from_pose(shift, [0, 0, 0, 1])
    reference, moved = fused().grid(), fused(pose).grid()
    assert np.allclose(moved[4:, 2:, :], reference[:-4, :-2, :], atol=0.02)
    cloud = fused(pose).cloud()
    assert np.percentile(SCENE.distance_to_surface(cloud[:, :3].astype(np.float64)), 95) < 0.003


def test_rotated_workspace_cloud_is_in_world_frame():
    yaw = matrix_from_pose([0.3, 0.0, 0.0], [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)])  # 90° about z
    cloud = fused(yaw).cloud()
    assert len(cloud) > 500
    assert np.percentile(SCENE.distance_to_surface(cloud[:, :3].astype(np.float64)), 95) < 0.003


def test_one_read_of_the_surface_gives_both_of_its_forms_in_the_world_frame():
    """``surface()`` is what a checked request reads in place of ``surface_points()`` and
    ``surface_cloud()``: the same arrays, bit for bit, in a turned and shifted workspace too."""
    pose = matrix_from_pose([0.3, -0.1, 0.02], [0, 0, np.sin(np.pi / 8), np.cos(np.pi / 8)])
    volume = fused(pose)
    points, cloud = volume.surface()
    assert len(points) > 500
    np.testing.assert_array_equal(points, volume.surface_points())
    np.testing.assert_array_equal(cloud, volume.surface_cloud())
    assert np.percentile(SCENE.distance_to_surface(points), 95) < 0.004


def test_reset_empties_the_volume():
    volume = fused(views=1)
    assert volume.grid().any()
    volume.reset()
    assert not volume.grid().any()
    assert len(volume.cloud()) == 0


def test_invalid_depth_is_ignored():
    """0 and readings beyond max_depth add nothing."""
    volume = TSDFVolume(0.3, 40)
    camera_pose = circle_views(1)[0]
    volume.integrate(np.zeros((480, 640), np.float32), INTRINSICS, camera_pose, max_depth=2.0)
    assert not volume.grid().any()
    volume.integrate(SCENE.depth(camera_pose), INTRINSICS, camera_pose, max_depth=0.3)
    assert not volume.grid().any()


def test_frame_size_can_change_between_frames():
    from vgn_contract.schemas import Intrinsics

    small = Intrinsics(width=320, height=240, fx=270.0, fy=270.0, cx=159.75, cy=119.75)
    volume = SceneVolume(0.3, 40, np.eye(4), cloud_resolution=120)
    camera_pose = circle_views(1)[0]
    volume.integrate(SCENE.depth(camera_pose, small), small, camera_pose, 2.0)
    first = volume.grid().copy()
    volume.integrate(SCENE.depth(camera_pose), INTRINSICS, camera_pose, 2.0)
    assert not np.array_equal(volume.grid(), first), "the second, larger frame was fused too"
    cloud = volume.cloud()
    assert len(cloud) > 500, "both frames put the surface where it is"
    assert np.percentile(SCENE.distance_to_surface(cloud[:, :3].astype(np.float64)), 95) < 0.003
