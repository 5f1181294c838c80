"""Surface points of the network's input grid: where the fused TSDF crosses zero.

The clearance check tests the hand against the observed surface. The service reads that surface
from its Open3D volume (``TSDFVolume.surface_points``), but training only has the grid, which
keeps ``(tsdf + 1) / 2`` of every observed voxel (0 elsewhere, docs/conventions.md). The same
points follow from the grid alone: between two observed neighbours along an axis whose TSDF
values differ in sign, the point where the linear interpolation of the two is zero. This is
the rule Open3D's ``UniformTSDFVolume.extract_point_cloud`` applies (voxel values at voxel
centres, ``(index + 0.5) * voxel_size``; the grid's outermost layer of voxels is skipped), so a
teacher's checks during training see the geometry the service's checks see (a test compares
the two). Their normals follow from the grid's gradient, as Open3D's do from its volume's
(``grid_surface_cloud``), so the antipodal check on the grid's faces can be replayed offline.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates


def grid_surface_points(grid: np.ndarray, voxel_size: float) -> np.ndarray:
    """(M, 3) float64 zero crossings of the TSDF that ``grid`` (N, N, N) holds, in the
    workspace frame (metres), grouped by axis (x, then y, then z crossings)."""
    grid = np.asarray(grid, dtype=np.float64)
    observed = np.zeros(grid.shape, dtype=bool)
    interior = (slice(1, -1),) * 3  # as Open3D, which never reads the outermost voxels
    observed[interior] = grid[interior] > 0.0
    tsdf = 2.0 * grid - 1.0
    points = []
    for axis in range(3):
        lower = [slice(None)] * 3
        upper = [slice(None)] * 3
        lower[axis], upper[axis] = slice(None, -1), slice(1, None)
        first, second = tsdf[tuple(lower)], tsdf[tuple(upper)]
        crossing = observed[tuple(lower)] & observed[tuple(upper)] & (first * second < 0.0)
        index = np.argwhere(crossing).astype(np.float64)
        near, far = np.abs(first[crossing]), np.abs(second[crossing])
        index[:, axis] += near / (near + far)  # the zero of the line between the two values
        points.append((index + 0.5) * voxel_size)
    return np.concatenate(points)


def grid_surface_cloud(grid: np.ndarray, voxel_size: float) -> np.ndarray:
    """(M, 6) float64 ``grid_surface_points`` and their unit normals, out of the surface towards free
    space: the TSDF's gradient (central differences), interpolated at each point. Open3D's
    ``extract_point_cloud`` normals agree except about the edges of what was observed, where the
    grid's unobserved voxels (0) read as deep inside a surface."""
    points = grid_surface_points(grid, voxel_size)
    gradient = np.gradient(2.0 * np.asarray(grid, dtype=np.float64) - 1.0)
    indices = (points / voxel_size - 0.5).T  # voxel values sit at voxel centres
    normals = np.stack([map_coordinates(axis, indices, order=1) for axis in gradient], axis=1)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    return np.hstack([points, normals])
