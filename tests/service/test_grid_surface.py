"""The grid's own surface points are the ones Open3D extracts from the fused volume, so that
checks run on training grids see the geometry the service's checks see."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from service.grid_surface import grid_surface_points
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


def test_an_empty_or_one_sided_grid_has_no_surface():
    assert grid_surface_points(np.zeros((40, 40, 40), np.float32), 0.0075).shape == (0, 3)
    free = np.full((40, 40, 40), 0.9, np.float32)  # observed free space only: nothing crosses zero
    assert grid_surface_points(free, 0.0075).shape == (0, 3)


def test_a_crossing_lies_where_the_line_between_the_two_values_is_zero():
    grid = np.zeros((8, 8, 8), np.float32)
    grid[3, 3, 3], grid[3, 3, 4] = 0.75, 0.25  # tsdf 0.5 and -0.5: the zero is half way
    points = grid_surface_points(grid, 0.01)
    np.testing.assert_allclose(points, [[0.035, 0.035, 0.04]], atol=1e-9)
