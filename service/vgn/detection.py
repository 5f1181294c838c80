"""From the network's voxel-wise output to ranked grasps in the world frame (docs/conventions.md)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import ndimage
from scipy.spatial.transform import Rotation

from vgn_contract.schemas import Grasp

#: Grid values strictly between these are observed voxels behind (inside) the surface.
_INSIDE_LOW, _SURFACE = 1e-3, 0.5

#: Widths (voxels): an (N, N, N) array, or a function giving the widths at voxels (i, j, k), so
#: that a network computing its width head on demand computes it only where detection reads it.
Widths = np.ndarray | Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def _widths_at(width: Widths, index: tuple[np.ndarray, ...]) -> np.ndarray:
    return width[index] if isinstance(width, np.ndarray) else width(*index)


@dataclass(frozen=True)
class DetectionConfig:
    """Detection knobs. Defaults are VGN's; crop and cone are optional filters.

    ``crop_min``/``crop_max`` are corners of a box in the workspace frame (metres);
    ``approach`` is a world-frame direction and ``max_approach_angle_rad`` its cone half-angle
    in radians.
    """

    threshold: float = 0.9
    nms_size: int = 4
    max_grasps: int | None = None
    smoothing_sigma: float = 1.0
    min_width_voxels: float = 1.33
    max_width_voxels: float = 9.33
    surface_dilation: int = 2
    crop_min: tuple[float, float, float] | None = None
    crop_max: tuple[float, float, float] | None = None
    approach: tuple[float, float, float] | None = None
    max_approach_angle_rad: float | None = None


def detect_grasps(
    grid: np.ndarray,
    quality: np.ndarray,
    rotation: np.ndarray,
    width: np.ndarray,
    voxel_size: float,
    workspace_pose: np.ndarray,
    config: DetectionConfig = DetectionConfig(),
    near_surface: np.ndarray | None = None,
) -> list[Grasp]:
    """Ranked grasps, best first, in the world frame.

    Args:
        grid: (N, N, N) network input (semantics: docs/conventions.md), workspace frame.
        quality: (N, N, N) raw quality in [0, 1].
        rotation: (4, N, N, N) unit quaternions [x, y, z, w], grasp → workspace frame.
        width: (N, N, N) opening widths in voxels.
        voxel_size: metres per voxel; voxel (i, j, k) sits at (i, j, k) * voxel_size.
        workspace_pose: 4×4 workspace → world.
        config: threshold, suppression window, width limits and the optional crop and cone.
        near_surface: ``grasp_region(grid, config)`` when the caller computed it already
            (it depends on the grid only, so it can be worked out while the network runs).
    """
    score = grasp_scores(grid, quality, width, voxel_size, config, near_surface)
    return grasps_from_scores(score, rotation, width, voxel_size, workspace_pose, config)


def grasp_scores(
    grid: np.ndarray,
    quality: np.ndarray,
    width: Widths,
    voxel_size: float,
    config: DetectionConfig = DetectionConfig(),
    near_surface: np.ndarray | None = None,
) -> np.ndarray:
    """(N, N, N) smoothed quality where a grasp may be returned, zero elsewhere: the first
    half of :func:`detect_grasps`, which reads no orientation (so a caller can work out
    orientations only where this is positive) and widths only where quality passes."""
    if near_surface is None:
        near_surface = grasp_region(grid, config)
    score = _valid_quality(near_surface, quality, width, config)
    if config.crop_min is not None or config.crop_max is not None:
        score *= _crop_mask(score.shape, voxel_size, config)
    return score


def grasps_from_scores(
    score: np.ndarray,
    rotation: np.ndarray,
    width: Widths,
    voxel_size: float,
    workspace_pose: np.ndarray,
    config: DetectionConfig = DetectionConfig(),
) -> list[Grasp]:
    """The second half of :func:`detect_grasps`: the approach cone, non-maximum suppression
    and ranking over :func:`grasp_scores`' output; reads orientations where it is positive only."""
    score = score.copy()
    candidates = np.argwhere(score > 0)
    if config.approach is not None and len(candidates):
        outside_cone = ~_inside_cone(candidates, rotation, workspace_pose, config)
        score[tuple(candidates[outside_cone].T)] = 0.0
    indices = local_maxima(score, config.nms_size)
    order = np.argsort(-score[tuple(indices.T)], kind="stable")
    if config.max_grasps is not None:
        order = order[: config.max_grasps]
    return _to_world(indices[order], score, rotation, width, voxel_size, workspace_pose)


def grasp_region(grid: np.ndarray, config: DetectionConfig = DetectionConfig()) -> np.ndarray:
    """Voxels where a grasp may be: observed free space near the surface, grown by
    ``surface_dilation`` 6-connected steps that never enter the inside of objects.

    The same as ``ndimage.binary_dilation(outside, iterations=k, mask=~inside)`` (tested),
    done with shifted slices, which are much faster on the grids the network reads."""
    region = grid > _SURFACE
    allowed = ~((grid > _INSIDE_LOW) & (grid < _SURFACE))
    for _ in range(config.surface_dilation):
        grown = region.copy()
        for axis in range(region.ndim):
            lower = [slice(None)] * region.ndim
            upper = [slice(None)] * region.ndim
            lower[axis], upper[axis] = slice(None, -1), slice(1, None)
            grown[tuple(lower)] |= region[tuple(upper)]
            grown[tuple(upper)] |= region[tuple(lower)]
        region |= grown & allowed
    return region


def local_maxima(score: np.ndarray, size: int) -> np.ndarray:
    """Indices (K, 3) of positive voxels that equal the maximum of their ``size``³ window, as
    ``score == ndimage.maximum_filter(score, size)`` would find them, but looking only around
    the positive voxels, which are few. The window sits as scipy places it; its reflected
    border values all lie inside the window, so zero padding (scores are >= 0) gives the
    same maxima."""
    candidates = np.argwhere(score > 0)
    if not len(candidates):
        return candidates
    before = size // 2
    padded = np.zeros(tuple(n + size - 1 for n in score.shape), score.dtype)
    padded[tuple(slice(before, before + n) for n in score.shape)] = score
    windows = sliding_window_view(padded, (size,) * score.ndim)[tuple(candidates.T)]
    peaks = score[tuple(candidates.T)] == windows.reshape(len(candidates), -1).max(axis=1)
    return candidates[peaks]


def _valid_quality(
    near_surface: np.ndarray, quality: np.ndarray, width: Widths, config: DetectionConfig
) -> np.ndarray:
    """Smoothed quality, zero where no grasp may be: away from the observed free space near
    the surface, below the threshold, or at implausible widths (read only where the rest holds)."""
    score = ndimage.gaussian_filter(quality.astype(np.float32), config.smoothing_sigma, mode="nearest")
    valid = near_surface & (score >= config.threshold)
    index = np.nonzero(valid)
    widths = _widths_at(width, index)
    implausible = (widths < config.min_width_voxels) | (widths > config.max_width_voxels)
    valid[tuple(axis[implausible] for axis in index)] = False
    score[~valid] = 0.0
    return score


def _crop_mask(shape: tuple[int, ...], voxel_size: float, config: DetectionConfig) -> np.ndarray:
    positions = np.indices(shape).transpose(1, 2, 3, 0) * voxel_size
    mask = np.ones(shape, dtype=bool)
    if config.crop_min is not None:
        mask &= np.all(positions >= np.asarray(config.crop_min), axis=-1)
    if config.crop_max is not None:
        mask &= np.all(positions <= np.asarray(config.crop_max), axis=-1)
    return mask


def _inside_cone(
    candidates: np.ndarray, rotation: np.ndarray, workspace_pose: np.ndarray, config: DetectionConfig
) -> np.ndarray:
    quaternions = rotation[(slice(None), *candidates.T)].T
    approach_ws = Rotation.from_quat(quaternions).apply([0.0, 0.0, 1.0])
    approach_world = approach_ws @ workspace_pose[:3, :3].T
    direction = np.asarray(config.approach, dtype=np.float64)
    direction /= np.linalg.norm(direction)
    cosine = np.clip(approach_world @ direction, -1.0, 1.0)
    return np.arccos(cosine) <= config.max_approach_angle_rad


def _to_world(
    indices: np.ndarray,
    score: np.ndarray,
    rotation: np.ndarray,
    width: Widths,
    voxel_size: float,
    workspace_pose: np.ndarray,
) -> list[Grasp]:
    if not len(indices):
        return []
    index = tuple(indices.T)
    positions = indices * voxel_size @ workspace_pose[:3, :3].T + workspace_pose[:3, 3]
    orientations = Rotation.from_matrix(workspace_pose[:3, :3]) * Rotation.from_quat(
        rotation[(slice(None), *index)].T
    )
    approaches = orientations.apply([0.0, 0.0, 1.0])
    quaternions = orientations.as_quat()
    widths = _widths_at(width, index) * voxel_size
    qualities = np.clip(score[index], 0.0, 1.0)
    return [
        Grasp(
            position=positions[n].tolist(),
            orientation=quaternions[n].tolist(),
            approach=approaches[n].tolist(),
            width=float(widths[n]),
            quality=float(qualities[n]),
        )
        for n in range(len(indices))
    ]
