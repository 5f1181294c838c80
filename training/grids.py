"""Network input grids of dataset scenes, fused by the service's own TSDF code and cached.

A grid is derived data: it is rebuilt from the scene's depth images whenever its cache file
is missing, unreadable, or was made under another setup, resolution, depth cut-off or grid
format. Cache files are written atomically, so an interrupted run never leaves a torn one.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vgn_data.dataset import DatasetSetup, RawDataset, SceneViews
from vgn_data.files import atomic_writer

#: VGN's grid resolution (docs/conventions.md); the network needs a multiple of 8.
RESOLUTION = 40
#: Readings beyond this (metres) are ignored, as the service does by default.
MAX_DEPTH = 2.0
#: Bump when the grid semantics or the fusion change, so old caches stop matching.
GRID_FORMAT = 1


def fuse_grid(views: SceneViews, setup: DatasetSetup, resolution: int, max_depth: float) -> np.ndarray:
    """(N, N, N) float32 network input of one scene, indexed [x, y, z] in the workspace frame.

    The workspace frame is the dataset's world frame (as in VGN): ``views.camera_poses``
    (camera → world) are used as camera → workspace. Depth handling matches the service's
    ``add_frame``: NaN and inf readings count as no reading. Open3D is imported here, not at
    the top, so that training from cached or recipe observations runs where it is not installed
    (a GPU machine with only torch).
    """
    from service.tsdf import TSDFVolume

    volume = TSDFVolume(setup.size, resolution)
    for depth, camera_pose in zip(views.depth, views.camera_poses, strict=True):
        clean = np.where(np.isfinite(depth), depth, 0.0).astype(np.float32)
        volume.integrate(clean, setup.intrinsics, camera_pose, max_depth)
    return volume.grid()


def cache_key(setup: DatasetSetup, resolution: int, max_depth: float) -> str:
    """Short hash of everything a grid depends on besides the scene itself."""
    text = json.dumps(
        {"setup": setup.to_json(), "resolution": resolution, "max_depth": max_depth, "format": GRID_FORMAT},
        sort_keys=True,
    )
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def cache_dir(data_dir: Path, cache_root: Path | None, resolution: int, key: str) -> Path:
    """Where a dataset's grids live: ``<data>/.cache/grids-<N>-<key>`` by default, or under
    ``cache_root`` in a folder named after the dataset (name + path hash, so two datasets
    with equal scene ids never share files)."""
    leaf = f"grids-{resolution}-{key}"
    if cache_root is None:
        return data_dir / ".cache" / leaf
    resolved = data_dir.resolve()
    tag = hashlib.sha256(str(resolved).encode()).hexdigest()[:8]
    return cache_root.resolve() / f"{resolved.name}-{tag}" / leaf


@dataclass(frozen=True)
class GridSource:
    """Everything needed to produce one scene's grid, picklable for worker processes.

    A cache file records the key and the size of the scene file it came from, so a scene
    rewritten under the same id is fused again.
    """

    dataset: RawDataset
    scene_id: str
    cache_path: Path
    resolution: int
    max_depth: float
    key: str

    @property
    def scene_path(self) -> Path:
        """The raw scene file the grid is fused from."""
        return self.dataset.scenes_dir / f"{self.scene_id}.npz"

    def load(self) -> np.ndarray:
        """The cached grid, or a freshly fused one (then cached)."""
        grid = self.cached()
        if grid is None:
            grid = self.build()
        return grid

    def cached(self) -> np.ndarray | None:
        """The cached grid if its file is readable and matches this source; else ``None``."""
        try:
            with np.load(self.cache_path) as data:
                if not self._matches(data):
                    return None
                grid = data["grid"]
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            return None
        n = self.resolution
        return grid.astype(np.float32, copy=False) if grid.shape == (n, n, n) else None

    def is_cached(self) -> bool:
        """A cheap check that the cache file exists and matches, without decompressing the grid
        (a damaged grid member is still caught, and rebuilt, by ``load``)."""
        try:
            with np.load(self.cache_path) as data:
                return self._matches(data)
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            return False

    def _matches(self, data: np.lib.npyio.NpzFile) -> bool:
        return str(data["key"]) == self.key and int(data["scene_bytes"]) == self._scene_bytes()

    def build(self) -> np.ndarray:
        """Fuse the scene's depth images and write the cache file atomically."""
        views = self.dataset.read_scene(self.scene_id)
        grid = fuse_grid(views, self.dataset.setup, self.resolution, self.max_depth)
        with atomic_writer(self.cache_path) as stream:
            np.savez_compressed(
                stream, grid=grid, key=np.array(self.key), scene_bytes=np.array(self._scene_bytes())
            )
        return grid

    def _scene_bytes(self) -> int:
        return self.scene_path.stat().st_size


def ensure_cached(source: GridSource) -> bool:
    """Make sure ``source`` has a valid cache file; True when it had to be built."""
    if source.is_cached():
        return False
    source.build()
    return True
