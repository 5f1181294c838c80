"""The Volumetric Grasping Network (Breyer et al., CoRL 2020); its layout is in docs/conventions.md.

Layer names match VGN's published state_dict (``encoder.conv1.weight`` ... ``conv_width.bias``)
so its checkpoints load strictly.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

PARAMETER_COUNT = 313_238


def _conv(in_channels: int, out_channels: int, kernel: int, stride: int = 1) -> nn.Conv3d:
    return nn.Conv3d(in_channels, out_channels, kernel, stride=stride, padding=kernel // 2)


class Encoder(nn.Module):
    """Three strided convolutions: N³ → (N/8)³ with 64 channels."""

    def __init__(self) -> None:
        super().__init__()
        self.conv1 = _conv(1, 16, 5, stride=2)
        self.conv2 = _conv(16, 32, 3, stride=2)
        self.conv3 = _conv(32, 64, 3, stride=2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, 1, N, N, N) grids → (B, 64, N/8, N/8, N/8) features."""
        return F.relu(self.conv3(F.relu(self.conv2(F.relu(self.conv1(x))))))


class Decoder(nn.Module):
    """Convolutions each followed by a ×2 nearest upsampling: back to N³ with 16 channels."""

    def __init__(self) -> None:
        super().__init__()
        self.conv1 = _conv(64, 64, 3)
        self.conv2 = _conv(64, 32, 3)
        self.conv3 = _conv(32, 16, 5)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, 64, N/8, N/8, N/8) features → (B, 16, N, N, N)."""
        for conv in (self.conv1, self.conv2, self.conv3):
            x = F.interpolate(F.relu(conv(x)), scale_factor=2)
        return x


class VGN(nn.Module):
    """Grid (B, 1, N, N, N) → quality (B, 1, N³) in [0, 1], rotation (B, 4, N³) unit
    quaternions [x, y, z, w], width (B, 1, N³) in voxels. N must be a multiple of 8."""

    def __init__(self) -> None:
        super().__init__()
        self.encoder = Encoder()
        self.decoder = Decoder()
        self.conv_qual = _conv(16, 1, 5)
        self.conv_rot = _conv(16, 4, 5)
        self.conv_width = _conv(16, 1, 5)

    def forward(self, grid: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Quality, rotation and width of every voxel, as the class docstring lays them out."""
        features = self.decoder(self.encoder(grid))
        quality = torch.sigmoid(self.conv_qual(features))
        rotation = F.normalize(self.conv_rot(features), dim=1)
        width = self.conv_width(features)
        return quality, rotation, width
