"""Registering a depth frame's scale against what a volume already holds.

Depth sensors misjudge distance by a factor that drifts from frame to frame (temperature, exposure;
the Dex-Net noise model draws one per frame). Frames each off along their own rays fuse into
smeared, doubled surfaces on which neither the network nor the checks find a grip. Before a frame
is fused, ``depth_scale`` finds the factor that lays its points on the volume's surface (such an
error scales a frame about its camera), and ``SceneScale`` settles the scene's own scale over its
first frames, so that the volume does not keep the first frame's error.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TypeVar

import numpy as np
from scipy.ndimage import map_coordinates

from vgn_contract.schemas import Intrinsics


@dataclass(frozen=True)
class ScaleSearch:
    """How the factor is searched: every ``stride``-th pixel along rows and columns, factors within
    ``max_error`` of 1 in ``coarse_steps`` steps (judged on every third of those points), then
    ``fine_steps`` steps across the best coarse step (on all of them); at least ``min_points`` of the
    sampled points must fall in observed voxels of the volume."""

    stride: int = 10
    max_error: float = 0.10
    coarse_steps: int = 21
    fine_steps: int = 11
    min_points: int = 200


def depth_scale(
    depth: np.ndarray,
    intrinsics: Intrinsics,
    camera_in_volume: np.ndarray,
    tsdf: np.ndarray,
    voxel_size: float,
    max_depth: float,
    search: ScaleSearch = ScaleSearch(),
) -> float:
    """The factor to multiply ``depth`` ((H, W) metres, 0 = no reading) by so that its points, seen
    from ``camera_in_volume`` (camera → volume corner, OpenCV frame), meet the zero crossing of
    ``tsdf`` ((N, N, N, 2): truncated distance in [-1, 1] and weight per voxel, indexed along the
    volume's x, y, z). 1.0 where the frame sees too little of what the volume observed to tell."""
    rows, cols = np.mgrid[0 : depth.shape[0] : search.stride, 0 : depth.shape[1] : search.stride]
    sampled = depth[rows, cols].astype(np.float64)
    valid = np.isfinite(sampled) & (sampled > 0.0) & (sampled <= max_depth)
    if valid.sum() < search.min_points:
        return 1.0
    d = sampled[valid]
    rays = np.stack(
        [
            (cols[valid] - intrinsics.cx) / intrinsics.fx,
            (rows[valid] - intrinsics.cy) / intrinsics.fy,
            np.ones(d.shape),
        ]
    )
    # Volume-frame points for a factor s: origin + s * offsets (the camera's rays, scaled about it).
    offsets = (camera_in_volume[:3, :3] @ (rays * d)) / voxel_size
    origin = camera_in_volume[:3, 3, None] / voxel_size - 0.5  # voxel values sit at voxel centres
    distance, observed = tsdf[..., 0], (tsdf[..., 1] > 0).astype(np.float64)

    def costs(scales: np.ndarray, every: int = 1) -> np.ndarray:
        # All factors' points in one interpolation call for observed and one for distance: the
        # fixed cost of each scipy call, not the points, was much of a frame's search.
        points = offsets[:, ::every]
        at = (origin[:, None, :] + scales[None, :, None] * points[:, None, :]).reshape(3, -1)
        seen = map_coordinates(observed, at, order=1, mode="constant", cval=0.0) > 0.999
        near = np.abs(map_coordinates(distance, at[:, seen], order=1, mode="nearest"))
        seen = seen.reshape(len(scales), -1)
        counts = seen.sum(axis=1)
        result = np.full(len(scales), np.inf)
        for index, part in enumerate(np.split(near, np.cumsum(counts)[:-1])):
            if counts[index] * every >= search.min_points:
                result[index] = float(np.minimum(part, 1.0).sum() + (~seen[index]).sum()) / seen.shape[1]
        return result

    # The coarse steps only pick where to look closer: a third of the points tell them apart.
    coarse = np.linspace(1.0 - search.max_error, 1.0 + search.max_error, search.coarse_steps)
    coarse_costs = costs(coarse, every=3)
    if not np.isfinite(coarse_costs.min()):
        return 1.0
    step = coarse[1] - coarse[0]
    best = coarse[int(np.argmin(coarse_costs))]
    fine = np.linspace(best - step, best + step, search.fine_steps)
    scale = float(fine[int(np.argmin(costs(fine)))])
    return 1.0 if abs(scale - 1.0) < 1e-9 else scale  # linspace's 1 may be a rounding off


#: The first frames of a scene whose scale errors are averaged into the scene's scale; each later
#: frame is scaled onto the volume as it stands.
SETTLING_FRAMES = 6

Frame = TypeVar("Frame")


class SceneScale:
    """A scene's depth scale, settled over its first frames.

    A volume matched to its first frame keeps that frame's error: the whole scene a few per cent
    too near or far, and since each frame is scaled about its own camera, no later factor lays its
    surfaces exactly on the first frame's. Errors that average to none are best undone by their
    average, so each of the first :data:`SETTLING_FRAMES` frames is measured against the first one's
    scale, and all of them are scaled by their geometric mean's inverse; the volume is fused again
    from them whenever that mean moves. Frames are dataclasses with a ``scale`` field."""

    def __init__(self, settled: bool = False) -> None:
        self.settled = settled
        self._frames: list = []  # the first frames as they came
        self._relative: list[float] = []  # each one's factor onto the first frame's scale
        self._mean = 1.0  # their geometric mean: the volume holds the first frame's scale / this

    def add(self, frame: Frame, measured: float) -> list[Frame]:
        """Take ``frame`` whose factor onto the volume as it stands is ``measured``. Returns
        ``[frame]`` at its scale to fuse into the volume, or, when the scene's scale moved, every first
        frame at its new scale to fuse the volume again from."""
        if self.settled:
            return [replace(frame, scale=measured)]
        self._frames.append(frame)
        self._relative.append(measured * self._mean)
        mean = float(np.exp(np.mean(np.log(self._relative))))
        self.settled = len(self._frames) >= SETTLING_FRAMES
        if abs(mean - self._mean) < 1e-9:
            scaled = [replace(frame, scale=self._relative[-1] / mean)]
        else:
            self._mean = mean
            scaled = [replace(f, scale=r / mean) for f, r in zip(self._frames, self._relative, strict=True)]
        if self.settled:
            self._frames = []
        return scaled
