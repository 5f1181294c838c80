"""Grasp labels of one scene in voxel units: what the loss compares the network output with."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch


@dataclass(frozen=True)
class LabelSet:
    """Labelled grasps of one scene, on the voxel grid (docs/conventions.md, VGN's Eq. 1).

    voxel (L, 3) int64 indices [i, j, k]; quaternion (L, 4) float32 [x, y, z, w] grasp →
    workspace; width (L,) float32 in voxels; label (L,) float32, 1 = success, 0 = failure.
    """

    voxel: torch.Tensor
    quaternion: torch.Tensor
    width: torch.Tensor
    label: torch.Tensor

    def __len__(self) -> int:
        return int(self.voxel.shape[0])

    def select(self, keep: torch.Tensor) -> LabelSet:
        """The labels where the boolean mask ``keep`` is true."""
        return LabelSet(self.voxel[keep], self.quaternion[keep], self.width[keep], self.label[keep])

    @classmethod
    def from_rows(cls, rows: np.ndarray, voxel_size: float, resolution: int) -> tuple[LabelSet, int]:
        """Labels of grasps.csv rows (qx, qy, qz, qw, x, y, z, width, label; metres, workspace
        frame) and how many were dropped for lying outside the grid.

        A grasp's voxel is round(position / voxel_size), the inverse of detection's
        position = index × voxel_size (docs/conventions.md); generated positions are continuous, so this
        is the nearest voxel.
        """
        rows = np.asarray(rows, dtype=np.float64).reshape(-1, 9)
        voxel = np.rint(rows[:, 4:7] / voxel_size).astype(np.int64)
        inside = np.all((voxel >= 0) & (voxel < resolution), axis=1)
        quaternion = rows[:, 0:4] / np.linalg.norm(rows[:, 0:4], axis=1, keepdims=True)
        labels = cls(
            voxel=torch.from_numpy(voxel[inside]),
            quaternion=torch.from_numpy(quaternion[inside].astype(np.float32)),
            width=torch.from_numpy((rows[inside, 7] / voxel_size).astype(np.float32)),
            label=torch.from_numpy((rows[inside, 8] > 0.5).astype(np.float32)),
        )
        return labels, int((~inside).sum())
