"""Self-distillation of turn averaging: a trained model's turn-averaged output as dense soft targets.

Turn averaging (``service.vgn.turns``) makes a model's grasps markedly better, at four forward
passes a request. Training a network to give that averaged answer in one pass moves the gain
into the weights. The teacher is a trained model run on each training scene turned by 0°, 90°,
180° and 270°; its averaged quality, orientation and (unturned) width become soft labels at every
voxel of the scene where detection may place a grasp (``grasp_region``), not only at the ~100
voxels with trial labels. The soft labels are moved with the training augmentation like trial
labels. The averaged quality is the same whichever way the scene is turned; the averaged
orientation nearly so (it is aligned to the unturned grid's prediction, which matters where the
four turns disagree).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from service.planner import GraspPlanner, InferenceOptions
from service.vgn.detection import grasp_region
from training.labels import LabelSet


@dataclass(frozen=True)
class SoftTargets:
    """One scene's teacher answer at its grasp-region voxels, kept compact in memory.

    voxel (K, 3) uint8 grid indices; quality (K,) float16 in [0, 1]; quaternion (K, 4)
    float16 ``[x, y, z, w]``; width (K,) float16 in voxels.
    """

    voxel: np.ndarray
    quality: np.ndarray
    quaternion: np.ndarray
    width: np.ndarray

    def __len__(self) -> int:
        return int(self.voxel.shape[0])

    def draw(self, count: int, rng: np.random.Generator) -> LabelSet:
        """``count`` of the targets drawn without replacement (all when fewer), as a label set
        whose ``label`` is the teacher's soft quality."""
        chosen = np.sort(rng.permutation(len(self))[:count]) if count < len(self) else np.arange(len(self))
        quaternion = torch.from_numpy(self.quaternion[chosen].astype(np.float32))
        return LabelSet(
            voxel=torch.from_numpy(self.voxel[chosen].astype(np.int64)),
            quaternion=quaternion / quaternion.norm(dim=-1, keepdim=True),
            width=torch.from_numpy(self.width[chosen].astype(np.float32)),
            label=torch.from_numpy(self.quality[chosen].astype(np.float32)),
        )


def soft_targets(teacher: GraspPlanner, grid: np.ndarray) -> SoftTargets:
    """The teacher's turn-averaged answer for one (N, N, N) grid at its grasp-region voxels."""
    output = teacher.infer(grid, turn_average=True)
    region = grasp_region(grid)
    voxel = np.argwhere(region)
    index = tuple(voxel.T)
    rotation = output.rotation_where(region)
    return SoftTargets(
        voxel=voxel.astype(np.uint8),
        quality=output.quality[index].astype(np.float16),
        quaternion=rotation[(slice(None), *index)].T.astype(np.float16),
        width=output.width[index].astype(np.float16),
    )


def teach(weights: Path, grids: Sequence[object], device: str, progress: bool = True) -> list[SoftTargets]:
    """Soft targets of every scene from the weights at ``weights``, run as the service runs them
    (the fast form, in float32); ``grids`` are sources with ``load() -> (N, N, N) array``."""
    teacher = GraspPlanner.from_path(
        weights, device, InferenceOptions(precision="float32", batch_window_ms=0.0)
    )
    bar = tqdm(grids, desc="teacher", unit="scene", disable=not progress, leave=False)
    return [soft_targets(teacher, source.load()) for source in bar]
