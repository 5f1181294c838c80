"""Turn averaging: VGN's grasp quality averaged over the grid turned about gravity.

VGN trains with the scene turned by quarter turns about the workspace z axis, so a well
trained network scores a grasp the same whichever way the scene is turned; where it does
not, the four scores disagree and their mean is the steadier estimate. Turning the grid is
``np.rot90`` over its x, y axes. Network outputs sit at grasp positions ``index × voxel``
(docs/conventions.md), which a quarter turn about the workspace centre takes from (i, j) to
(N - j, i): one index away from where ``rot90`` moves the grid's cells, the same rule the
training augmentation applies to its labels. Voxels that a turn takes off the grid (one
row per turn) keep the scores of the turns that keep them.
"""

from __future__ import annotations

import numpy as np

#: Quarter turns about +z whose network outputs are averaged: 0°, 90°, 180°, 270°.
TURNS = (0, 1, 2, 3)


def turned_grids(grid: np.ndarray) -> np.ndarray:
    """(4, N, N, N): ``grid`` turned by each of :data:`TURNS` quarter turns about +z."""
    return np.stack([np.rot90(grid, k, axes=(0, 1)) for k in TURNS])


def turned_index(n: int, quarter_turns: int) -> tuple[np.ndarray, np.ndarray]:
    """Where each grasp position (i, j) of an N-wide grid lands after ``quarter_turns``
    quarter turns about +z: two (N, N) index arrays, values outside [0, N) off the grid."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    for _ in range(quarter_turns % 4):
        i, j = n - j, i
    return i, j


def average_turned_quality(qualities: np.ndarray) -> np.ndarray:
    """(N, N, N) mean quality, in the unturned grid's voxels, of (4, N, N, N) network
    qualities on :func:`turned_grids` (each voxel averages the turns that keep it on the grid)."""
    n = qualities.shape[1]
    total = np.zeros(qualities.shape[1:], dtype=np.float64)
    count = np.zeros(qualities.shape[1:3] + (1,), dtype=np.float64)
    for k, quality in zip(TURNS, qualities, strict=True):
        i, j = turned_index(n, k)
        on_grid = (i >= 0) & (i < n) & (j >= 0) & (j < n)
        total[on_grid] += quality[i[on_grid], j[on_grid]]
        count[on_grid] += 1.0
    return (total / count).astype(qualities.dtype)
