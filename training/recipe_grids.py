"""Network input grids rendered from scene recipes: the one path from a recipe to what the
network sees, shared by migration, verification, the render cache and training.

A recipe's observation is a list of depth images and their camera poses; it is fused with the
service's own TSDF code, exactly as packing fused raw depth (``training.grids``), so a
grid rendered from a recipe and a grid stored earlier compare voxel for voxel.
"""

from __future__ import annotations

import hashlib

import numpy as np

from training.grids import MAX_DEPTH, RESOLUTION, fuse_grid
from vgn_data.dataset import DatasetSetup, SceneViews

#: How a grid's digest is taken (recorded in the manifest).
DIGEST = "blake2b-128 of round(255 * grid) as uint8, indexed [x, y, z], C order"


def observation_grid(
    depths: np.ndarray,
    views: np.ndarray,
    setup: DatasetSetup | None = None,
    resolution: int = RESOLUTION,
    max_depth: float = MAX_DEPTH,
) -> np.ndarray:
    """(N, N, N) float32 network input fused from ``depths`` (V, H, W) seen from ``views``
    (V, 7) camera → world ``[x, y, z, qx, qy, qz, qw]`` (the workspace corner at the world origin)."""
    from sim_worker.recipes import pose_matrix

    poses = np.stack([pose_matrix(v) for v in np.asarray(views).reshape(-1, 7)])
    return fuse_grid(SceneViews(depths, poses), setup or DatasetSetup(), resolution, max_depth)


def grid_digest(quantised: np.ndarray) -> np.ndarray:
    """(16,) uint8 digest of a quantised grid (see ``DIGEST``)."""
    data = np.ascontiguousarray(quantised, dtype=np.uint8).tobytes()
    return np.frombuffer(hashlib.blake2b(data, digest_size=16).digest(), dtype=np.uint8).copy()
