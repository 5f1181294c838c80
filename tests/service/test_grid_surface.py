"""The grid's own surface points are the ones Open3D extracts from the fused volume, and their
normals Open3D's, so that checks run on training grids see the geometry the service's checks see."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from service.grid_surface import grid_surface_cloud, grid_surface_points
from service.tsdf import TSDFVolume
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views


def test_the_grids_zero_crossings_are_open3ds_surface_points():
    volume = TSDFVolume(0.3, 40)
    scene = BoxScene()
    for pose in circle_views(3):
        volume.integrate(scene.depth(pose), INTRINSICS, pose, max_depth=2.0)
    expected = volume.surface_points()
    points = grid_surface_points(volume.grid(), volume.voxel_size)
    assert len(expected) > 500 and points.shape == expected.shape
    # One point for one point (grid values are float32, as Open3D keeps them).
    distance, nearest = cKDTree(expected).query(points)
    assert distance.max() < 1e-6 and len(set(nearest.tolist())) == len(expected)


def test_the_grids_normals_are_open3ds_but_about_the_edges_of_what_was_seen():
    volume = TSDFVolume(0.3, 40)
    scene = BoxScene()
    for pose in circle_views(6):
        volume.integrate(scene.depth(pose), INTRINSICS, pose, max_depth=2.0)
    points, normals = volume.surface_cloud()
    cloud = grid_surface_cloud(volume.grid(), volume.voxel_size)
    _, nearest = cKDTree(cloud[:, :3]).query(points)
    degrees = np.degrees(np.arccos(np.clip(np.sum(normals * cloud[nearest, 3:], axis=1), -1.0, 1.0)))
    assert np.percentile(degrees, 90) < 1.0 and np.median(degrees) < 0.1
    np.testing.assert_allclose(np.linalg.norm(cloud[:, 3:], axis=1), 1.0, atol=1e-9)
    lower, upper = np.asarray(scene.lower), np.asarray(scene.upper)
    lid = (cloud[:, 2] > upper[2] - 0.002) & np.all(
        np.abs(cloud[:, :2] - (lower + upper)[:2] / 2) < 0.02, axis=1
    )
    assert lid.sum() > 10 and np.all(cloud[lid, 5] > 0.95)  # the lid's middle faces up


def test_an_empty_or_one_sided_grid_has_no_surface():
    assert grid_surface_points(np.zeros((40, 40, 40), np.float32), 0.0075).shape == (0, 3)
    free = np.full((40, 40, 40), 0.9, np.float32)  # observed free space only: nothing crosses zero
    assert grid_surface_points(free, 0.0075).shape == (0, 3)


def test_a_crossing_lies_where_the_line_between_the_two_values_is_zero():
    grid = np.zeros((8, 8, 8), np.float32)
    grid[3, 3, 3], grid[3, 3, 4] = 0.75, 0.25  # tsdf 0.5 and -0.5: the zero is half way
    points = grid_surface_points(grid, 0.01)
    np.testing.assert_allclose(points, [[0.035, 0.035, 0.04]], atol=1e-9)
