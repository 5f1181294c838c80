"""Grip check: will the closing fingers meet the observed surface squarely, on both sides?

Most grasps VGN is wrong about in clutter close on an edge, a corner or a slanted face and slip
out while lifting. This check closes the hand on the fused surface: rays march from each pad
along the closing axis through the coarse grid to the TSDF's zero crossing, whose gradient is the
normal the pad meets. Per finger, ``contact`` is the share of rays that meet the surface and
``alignment`` the mean cosine between those normals and the closing direction; a grasp passes
when both fingers reach :class:`GripConfig`'s thresholds, and square grips are kept over the
rest. A finger closing from an unseen side is left to the network, a single-frame volume is not
checked (:data:`MIN_GRIP_FRAMES`), and just above the table faces are judged by the horizontal
part of their normal (:func:`support_height`). Frames: docs/conventions.md; thresholds: docs/concepts.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.ndimage import map_coordinates
from scipy.spatial.transform import Rotation

from service.hands import active_hand
from vgn_contract.gripper_description import GripperDescription
from vgn_contract.schemas import Grasp

#: Ray step (m): a quarter of a default voxel.
STEP = 0.002
#: The check runs on volumes fused from at least this many frames. From one view the fused
#: surface misleads it: on simulated grasps on training objects seen from one side view
#: (``benchmarks.grasp_outcomes --views side``: 138 grasps, 43.5 % successful) the grasps it kept
#: succeeded 35 % of the time and the ones it dropped 54 %.
MIN_GRIP_FRAMES = 2
#: Hit points less than this many voxels above the support plane are judged by the horizontal part
#: of their normal: the grid blurs a thin object's side faces into the table, tilting them up.
SUPPORT_BAND_VOXELS = 2.0
#: The support plane must span at least this share of the workspace's floor to count as one.
MIN_SUPPORT_SHARE = 0.2
#: Grid value of the surface: the grid holds (tsdf + 1) / 2 where observed and 0 elsewhere, its
#: values at voxel centres ``(index + 0.5) * voxel_size``; the surface is at tsdf = 0.
SURFACE = 0.5


@dataclass(frozen=True)
class GripConfig:
    """Knobs of the check: the least share of each pad's rays that must meet the surface
    (``min_contact``), the least mean cosine between the surface normals they meet and the
    finger's closing direction (``min_alignment``), and the cosine of a square grip
    (``preferred_alignment``): when some grasps grip that squarely, only those are kept (at or
    below ``min_alignment`` it changes nothing).

    The thresholds were chosen on simulated grasps on *training* objects, never the benchmark's
    (``python -m benchmarks.grasp_outcomes``); the figures are in docs/concepts.md, "The grip
    check". ``preferred_alignment`` is a preference, not a threshold, because a hard one would
    leave many looks with no grasp at all."""

    min_contact: float = 1.0 / 3.0
    min_alignment: float = 0.5
    preferred_alignment: float = 0.7

    def __post_init__(self) -> None:
        alignments = (self.min_alignment, self.preferred_alignment)
        if not (0.0 <= self.min_contact <= 1.0 and all(-1.0 <= a <= 1.0 for a in alignments)):
            raise ValueError(f"invalid grip settings {self}")


@dataclass(frozen=True)
class GripMeasure:
    """What the closing fingers meet, (G, 2) arrays with columns (+y finger, -y finger):
    ``known`` share of rays whose path the volume shows (the first observation along the ray is
    free space), ``contact`` share of the known rays that met the surface, ``alignment`` their mean
    normal cosine (0 where none met), ``reach`` (m) the mean closing distance to the surface from
    the open pad (the open half-width where none met).

    A finger none of whose rays is known closes from a side no camera saw (the back of an object
    seen from one side, a hidden gap): the check cannot judge it and leaves it to the network."""

    known: np.ndarray
    contact: np.ndarray
    alignment: np.ndarray
    reach: np.ndarray

    def passes(self, config: GripConfig = GripConfig()) -> np.ndarray:
        """(G,) bool: every finger the volume shows meets enough surface, squarely enough."""
        return self._meets(config.min_contact, config.min_alignment)

    def square(self, config: GripConfig = GripConfig()) -> np.ndarray:
        """(G,) bool: the grasps that pass at the square grip (``config.preferred_alignment``)."""
        return self._meets(config.min_contact, max(config.min_alignment, config.preferred_alignment))

    def kept(self, config: GripConfig = GripConfig()) -> np.ndarray:
        """(G,) bool: the grasps that pass and, where any grips squarely, only those."""
        square = self.square(config)
        return square if square.any() else self.passes(config)

    def _meets(self, min_contact: float, min_alignment: float) -> np.ndarray:
        meets = (self.contact >= min_contact) & (self.alignment >= min_alignment)
        return np.all(meets | (self.known == 0.0), axis=1)


def measure_grip(
    grid: np.ndarray,
    voxel_size: float,
    positions: np.ndarray,
    orientations: np.ndarray,
    hand: GripperDescription | None = None,
    support: float | None | Literal["find"] = "find",
) -> GripMeasure:
    """Close the open hand of each grasp on the surface of ``grid``.

    Args:
        grid: (N, N, N) network input, indexed [x, y, z] in the workspace frame.
        voxel_size: edge of one voxel (m).
        positions: (G, 3) grasp origins, workspace frame (m).
        orientations: (G, 4) quaternions [x, y, z, w], grasp frame → workspace frame.
        hand: whose pads close (``pad.contact_x/z``) and from what opening; default the active hand.
        support: the support plane's height (:func:`support_height`, found when "find").
    """
    hand = hand or active_hand()
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    count = len(positions)
    if not count:
        empty = np.zeros((0, 2))
        return GripMeasure(empty, empty, empty, empty)
    rotations = Rotation.from_quat(np.asarray(orientations, dtype=np.float64).reshape(-1, 4)).as_matrix()
    half_open = 0.5 * hand.max_opening
    steps = np.arange(0.0, half_open + 1e-9, STEP)  # closing distance from the open pad
    pad_x, pad_z = (a.ravel() for a in np.meshgrid(hand.pad.contact_x, hand.pad.contact_z, indexing="ij"))
    sides = np.array([1.0, -1.0])
    # Ray samples in the grasp frame: (side, ray, step, 3); y runs from ±half_open to 0.
    local = np.zeros((2, len(pad_x), len(steps), 3))
    local[..., 0] = pad_x[None, :, None]
    local[..., 1] = sides[:, None, None] * (half_open - steps[None, None, :])
    local[..., 2] = pad_z[None, :, None]
    samples = positions[:, None, None, None, :] + np.einsum("gij,srkj->gsrki", rotations, local)
    coordinates = samples.reshape(-1, 3).T / voxel_size - 0.5  # grid values sit at voxel centres
    values = map_coordinates(grid, coordinates, order=1, mode="constant", cval=0.0)
    values = values.reshape(count, 2, len(pad_x), len(steps))
    # What the voxel each sample lies in holds: 0 is no observation (unobserved, or beyond the
    # truncation band), which trilinear reads would blend into the observed values beside it.
    voxels = map_coordinates(grid, coordinates, order=0, mode="constant", cval=0.0)
    voxels = voxels.reshape(values.shape)
    # A ray is known when the first thing the volume shows along it is free space: it closes
    # from an observed side. It meets the surface at its first step inside (value below the
    # surface level) after free space; unobserved voxels before that tell nothing.
    observed = voxels > 0.0
    first_observed = np.take_along_axis(voxels, observed.argmax(axis=-1)[..., None], axis=-1)[..., 0]
    known = observed.any(axis=-1) & (first_observed >= SURFACE)
    free_seen = np.maximum.accumulate(values >= SURFACE, axis=-1)
    inside = (values < SURFACE) & free_seen
    met = inside.any(axis=-1) & known
    first = np.where(met, inside.argmax(axis=-1), len(steps) - 1)  # (G, 2, R)
    hit_points = np.take_along_axis(samples, first[..., None, None], axis=3)[..., 0, :]  # (G, 2, R, 3)
    normals = _surface_normals(grid, voxel_size, hit_points.reshape(-1, 3)).reshape(hit_points.shape)
    if support == "find":
        support = support_height(grid, voxel_size)
    if support is not None:
        near_support = hit_points[..., 2] < support + SUPPORT_BAND_VOXELS * voxel_size
        horizontal = normals * np.array([1.0, 1.0, 0.0])
        horizontal /= np.maximum(np.linalg.norm(horizontal, axis=-1, keepdims=True), 1e-12)
        normals = np.where(near_support[..., None], horizontal, normals)
    # A pad meets the surface squarely when the normal there points back at the finger (+y side: +y).
    closing_axis = rotations[:, :, 1]  # (G, 3) the grasp frame's y in the workspace frame
    cosine = np.einsum("gsri,gi->gsr", normals, closing_axis) * sides[None, :, None]
    known_rays = known.sum(axis=-1)
    contact = met.sum(axis=-1) / np.maximum(known_rays, 1)
    hits = np.maximum(met.sum(axis=-1), 1)
    alignment = np.where(met, cosine, 0.0).sum(axis=-1) / hits
    reach = np.where(met, steps[first], half_open).mean(axis=-1)
    return GripMeasure(known.mean(axis=-1), contact, alignment, reach)


def support_height(grid: np.ndarray, voxel_size: float) -> float | None:
    """Height (m, workspace z, which points up) of the plane the scene stands on: the level where
    most of the surface crosses the vertical, when it spans :data:`MIN_SUPPORT_SHARE` of the floor.
    None when no level does (no table in view)."""
    grid = np.asarray(grid, dtype=np.float32)
    observed = grid > 0.0
    below, above = grid[:, :, :-1] - SURFACE, grid[:, :, 1:] - SURFACE
    crossing = observed[:, :, :-1] & observed[:, :, 1:] & (below * above < 0.0)
    counts = crossing.sum(axis=(0, 1))
    level = int(np.argmax(counts))
    if counts[level] < MIN_SUPPORT_SHARE * grid.shape[0] * grid.shape[1]:
        return None
    near, far = (
        np.abs(below[:, :, level][crossing[:, :, level]]),
        np.abs(above[:, :, level][crossing[:, :, level]]),
    )
    return float(np.median(level + 0.5 + near / (near + far)) * voxel_size)


def _surface_normals(grid: np.ndarray, voxel_size: float, points: np.ndarray) -> np.ndarray:
    """Unit gradients (M, 3) of ``grid`` at ``points`` (workspace frame): the outward surface
    normal, since values grow towards free space. Central differences of trilinear reads."""
    offsets = np.eye(3) * (0.5 * voxel_size)
    reads = np.stack([points + offsets[a] * sign for a in range(3) for sign in (1.0, -1.0)])  # (6, M, 3)
    coordinates = reads.reshape(-1, 3).T / voxel_size - 0.5
    values = map_coordinates(grid, coordinates, order=1, mode="nearest").reshape(6, -1)
    gradient = np.stack([values[2 * a] - values[2 * a + 1] for a in range(3)], axis=-1)
    return gradient / np.maximum(np.linalg.norm(gradient, axis=-1, keepdims=True), 1e-12)


def gripping_grasps(
    grasps: list[Grasp],
    grid: np.ndarray,
    voxel_size: float,
    workspace_pose: np.ndarray,
    config: GripConfig = GripConfig(),
    hand: GripperDescription | None = None,
) -> list[Grasp]:
    """The ``grasps`` (world frame, order kept) whose fingers (``hand``'s, default the active one)
    both meet the surface of ``grid`` squarely enough, the squarest only where there are any
    (:meth:`GripMeasure.kept`); ``workspace_pose`` (4×4) is the grid's corner in the world."""
    if not grasps:
        return []
    to_workspace = np.linalg.inv(np.asarray(workspace_pose, dtype=np.float64))
    positions = np.array([g.position for g in grasps]) @ to_workspace[:3, :3].T + to_workspace[:3, 3]
    turned = Rotation.from_matrix(to_workspace[:3, :3]) * Rotation.from_quat([g.orientation for g in grasps])
    kept = measure_grip(grid, voxel_size, positions, turned.as_quat(), hand).kept(config)
    return [g for g, ok in zip(grasps, kept, strict=True) if ok]
