"""VGN's augmentations, applied to a grid and its labels together so they stay aligned.

Grids are indexed [x, y, z] (docs/conventions.md). A z-rotation by k × 90° about the workspace centre
is ``torch.rot90`` over the x, y axes: grid *cells* describe the space around their centres
(i + 0.5) × voxel, so a quarter turn maps cell (i, j) to (N-1-j, i). A grasp label sits at
i × voxel (its corner), and the same physical turn takes it to index (N-j, i): labels and
cells differ by one index so that the augmented sample is exactly the rotated scene with its
rotated grasps. Orientations turn by the same rotation (q' = R_z ⊗ q).
A z shift moves grid and labels by whole voxels, filling with 0 (unobserved) and dropping
labels that leave the grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from training.labels import LabelSet
from training.quaternions import about_z, multiply

#: Largest z shift in voxels (both ways).
MAX_Z_SHIFT = 4


def rotate_z(grid: torch.Tensor, labels: LabelSet, quarter_turns: int) -> tuple[torch.Tensor, LabelSet]:
    """Turn the (N, N, N) grid and its labels by ``quarter_turns`` × 90° about +z."""
    k = quarter_turns % 4
    if k == 0:
        return grid, labels
    return torch.rot90(grid, k, dims=(0, 1)), rotate_labels_z(labels, grid.shape[0], k)


def rotate_labels_z(labels: LabelSet, n: int, quarter_turns: int) -> LabelSet:
    """Labels of an ``n``-wide grid turned by ``quarter_turns`` × 90° about +z; those the turn
    takes off the grid are dropped."""
    k = quarter_turns % 4
    if k == 0:
        return labels
    i, j, z = labels.voxel.unbind(-1)
    for _ in range(k):
        i, j = n - j, i  # the label convention: position = index × voxel (see the module docstring)
    turn = about_z(k * math.pi / 2, labels.quaternion.dtype)
    quaternion = multiply(turn.expand_as(labels.quaternion), labels.quaternion)
    voxel = torch.stack([i, j, z], dim=-1)
    moved = LabelSet(voxel, quaternion, labels.width, labels.label)
    return moved.select(torch.all((voxel[:, :2] >= 0) & (voxel[:, :2] < n), dim=1))


def shift_z(grid: torch.Tensor, labels: LabelSet, voxels: int) -> tuple[torch.Tensor, LabelSet]:
    """Move the grid and its labels ``voxels`` along +z (negative: down), zero-filling."""
    if voxels == 0:
        return grid, labels
    n = grid.shape[2]
    shifted = torch.zeros_like(grid)
    if voxels > 0:
        shifted[:, :, voxels:] = grid[:, :, : n - voxels]
    else:
        shifted[:, :, : n + voxels] = grid[:, :, -voxels:]
    return shifted, shift_labels_z(labels, n, voxels)


def shift_labels_z(labels: LabelSet, n: int, voxels: int) -> LabelSet:
    """Labels moved ``voxels`` along +z; those leaving the ``n``-high grid are dropped."""
    if voxels == 0:
        return labels
    voxel = labels.voxel.clone()
    voxel[:, 2] += voxels
    moved = LabelSet(voxel, labels.quaternion, labels.width, labels.label)
    return moved.select((voxel[:, 2] >= 0) & (voxel[:, 2] < n))


@dataclass(frozen=True)
class Placement:
    """One draw's augmentation: quarter turns about +z, then a z shift in voxels. Kept apart
    from the grid so that other voxel-wise targets of the same scene move with it."""

    quarter_turns: int
    shift: int

    def apply(self, grid: torch.Tensor, labels: LabelSet) -> tuple[torch.Tensor, LabelSet]:
        """The grid and its labels moved by this placement."""
        grid, labels = rotate_z(grid, labels, self.quarter_turns)
        return shift_z(grid, labels, self.shift)

    def apply_labels(self, labels: LabelSet, n: int) -> LabelSet:
        """Labels alone (of an ``n``-wide grid) moved by this placement."""
        return shift_labels_z(rotate_labels_z(labels, n, self.quarter_turns), n, self.shift)


def draw_shift(rng: np.random.Generator, max_shift: int = MAX_Z_SHIFT) -> Placement:
    """A uniformly random quarter-turn about z, then a shift in U{-max_shift..max_shift}."""
    return Placement(int(rng.integers(4)), int(rng.integers(-max_shift, max_shift + 1)))


def draw_height(labels: LabelSet, n: int, rng: np.random.Generator) -> Placement:
    """A random quarter-turn about z, then a height uniform over every shift that keeps all the
    (turned) labels inside an ``n``-high grid: the placement of :func:`random_placement`."""
    quarter_turns = int(rng.integers(4))
    low, high = height_range(rotate_labels_z(labels, n, quarter_turns), n)
    return Placement(quarter_turns, int(rng.integers(low, high + 1)))


def random_augment(
    grid: torch.Tensor, labels: LabelSet, rng: np.random.Generator, max_shift: int = MAX_Z_SHIFT
) -> tuple[torch.Tensor, LabelSet]:
    """A uniformly random quarter-turn about z, then a shift in U{-max_shift..max_shift}."""
    return draw_shift(rng, max_shift).apply(grid, labels)


def height_range(labels: LabelSet, n: int) -> tuple[int, int]:
    """The z shifts (voxels, inclusive) that keep every label inside an ``n``-voxel grid."""
    if not len(labels):
        return 0, 0
    z = labels.voxel[:, 2]
    return -int(z.min()), n - 1 - int(z.max())


def random_placement(
    grid: torch.Tensor, labels: LabelSet, rng: np.random.Generator
) -> tuple[torch.Tensor, LabelSet]:
    """VGN's augmentation for whole scenes: a random quarter-turn about z, then the scene
    placed at a random height, uniform over every shift that keeps all its labels in the
    grid. The table then appears anywhere from the grid's floor to high up, so the network
    cannot learn "grasps live just above z = 0.05 m" and score empty space by height alone."""
    return draw_height(labels, grid.shape[2], rng).apply(grid, labels)


def balanced_subset(labels: LabelSet, rng: np.random.Generator) -> LabelSet:
    """Every positive and as many randomly drawn negatives (at least one): the raw labels are
    mostly failures, and VGN trains on balanced classes. A new draw each step means every
    negative is seen over the epochs."""
    positive = labels.label > 0.5
    negatives = torch.nonzero(~positive).flatten()
    count = min(len(negatives), max(int(positive.sum()), 1))
    chosen = negatives[torch.from_numpy(rng.permutation(len(negatives))[:count])]
    keep = positive.clone()
    keep[chosen] = True
    return labels.select(keep)
