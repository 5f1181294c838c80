"""VGN's loss (docs/conventions.md), read only at labelled voxels.

Per label: BCE(q̂, y) + y · (min(1 - |q̂·q|, 1 - |q̂·q_π|) + 0.01 · (ŵ - w)²), with q_π the
same grasp turned by π about its approach axis and widths in voxels; the batch loss is the
mean over labels. Unlabelled voxels never enter it, so they get no gradient, unless the run
distils a teacher: then its soft labels at the grasp-region voxels add the same terms
(``distillation_loss``).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from training.dataset import Batch
from training.quaternions import flipped

#: Weight of the width term (VGN's).
WIDTH_WEIGHT = 0.01


@dataclass
class Predictions:
    """Network output at the labelled voxels: quality (L,), quaternion (L, 4), width (L,)."""

    quality: torch.Tensor
    quaternion: torch.Tensor
    width: torch.Tensor


def gather(output: tuple[torch.Tensor, torch.Tensor, torch.Tensor], batch: Batch) -> Predictions:
    """Pick the network's (quality (B,1,N,N,N), rotation (B,4,...), width (B,1,...)) at the
    batch's labelled voxels."""
    return gather_at(output, batch.scene, batch.voxel)


def gather_at(
    output: tuple[torch.Tensor, torch.Tensor, torch.Tensor], scene: torch.Tensor, voxel: torch.Tensor
) -> Predictions:
    """The network's output at (scene index, flat voxel index) pairs."""
    quality, rotation, width = (t.flatten(2) for t in output)
    return Predictions(
        quality=quality[scene, 0, voxel],
        quaternion=rotation[scene, :, voxel],
        width=width[scene, 0, voxel],
    )


def rotation_loss(predicted: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """(L,) min(1 - |p·q|, 1 - |p·q_π|): zero for either of the two equivalent grasps."""
    direct = 1.0 - (predicted * target).sum(-1).abs()
    turned = 1.0 - (predicted * flipped(target)).sum(-1).abs()
    return torch.minimum(direct, turned)


def per_label_loss(predictions: Predictions, batch: Batch) -> torch.Tensor:
    """(L,) VGN loss of each label; only positives add the rotation and width terms."""
    quality = F.binary_cross_entropy(predictions.quality, batch.label, reduction="none")
    rotation = rotation_loss(predictions.quaternion, batch.quaternion)
    width = WIDTH_WEIGHT * (predictions.width - batch.width).square()
    return quality + batch.label * (rotation + width)


def vgn_loss(predictions: Predictions, batch: Batch) -> torch.Tensor:
    """Mean loss over the batch's labelled voxels."""
    return per_label_loss(predictions, batch).mean()


def distillation_loss(output: tuple[torch.Tensor, torch.Tensor, torch.Tensor], batch: Batch) -> torch.Tensor:
    """(K,) VGN's loss at the batch's soft labels: BCE with the teacher's quality, and the
    rotation and width terms weighted by that quality (the trial-label loss weights them by
    the 0/1 label)."""
    predictions = gather_at(output, batch.soft_scene, batch.soft_voxel)
    target = batch.soft_quality
    quality = F.binary_cross_entropy(predictions.quality, target, reduction="none")
    rotation = rotation_loss(predictions.quaternion, batch.soft_quaternion)
    width = WIDTH_WEIGHT * (predictions.width - batch.soft_width).square()
    return quality + target * (rotation + width)
