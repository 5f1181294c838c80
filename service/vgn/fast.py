"""An inference-only form of VGN, derived from its weights at load, that computes the same
function with about a quarter of the arithmetic.

Why it is exact: VGN's decoder convolutions after the first, and its three 5³ heads, read a ×2
*nearest* upsampled tensor. Such a convolution equals, for each of the 8 output parities, a 3³
convolution over the low-resolution input whose taps are sums of the original taps
("polyphase" form); stacking the parities as channels and interleaving them afterwards gives
the upsampled result without convolving at the high resolution. The heads are fused into one
6-channel convolution, and the first convolution runs over the grid's 8 voxel parities as
channels ("space to depth"), which oneDNN handles better than a single channel. Only rounding
differs from :class:`service.vgn.network.VGN`. On CPUs with native bf16 support the
convolutions may run in bfloat16, inputs and outputs in float32 (docs/design.md).
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from service.vgn.network import VGN

#: Channel split of the fused head: quality, rotation (4), width.
HEAD_CHANNELS = (1, 4, 1)
#: The fused head's folded output rows of rotation and width (8 parities per channel).
LAZY_ROWS = slice(HEAD_CHANNELS[0] * 8, sum(HEAD_CHANNELS) * 8)
#: ``F.normalize``'s floor on the norm, kept so near-zero rotations come out alike.
NORM_EPS = 1e-12


def _phase_taps(kernel: int) -> torch.Tensor:
    """(2, 3, kernel) 0/1 matrix: for output parity p and low-resolution offset o ∈ {-1, 0, 1},
    which of the kernel's taps over the upsampled input land on low-resolution voxel i + o."""
    taps = torch.zeros(2, 3, kernel)
    half = kernel // 2
    for parity in range(2):
        for tap in range(kernel):
            offset = (parity + tap - half) // 2
            if not -1 <= offset <= 1:
                raise ValueError(f"kernel {kernel} reaches beyond one low-resolution neighbour")
            taps[parity, offset + 1, tap] = 1.0
    return taps


def _parity_taps(kernel: int) -> torch.Tensor:
    """(2, 3, kernel) 0/1 matrix: for input parity p and half-resolution offset o ∈ {-1, 0, 1},
    which taps of a stride-2 convolution (padding kernel // 2) read input voxel 2 (i + o) + p."""
    taps = torch.zeros(2, 3, kernel)
    for tap in range(kernel):
        offset, parity = divmod(tap - kernel // 2, 2)
        if not -1 <= offset <= 1:
            raise ValueError(f"kernel {kernel} reaches beyond one half-resolution neighbour")
        taps[parity, offset + 1, tap] = 1.0
    return taps


def space_to_depth_weights(weight: torch.Tensor) -> torch.Tensor:
    """Weights (O, 8·I, 3, 3, 3) of a 3³ convolution (padding 1) over :func:`space_to_depth`'s
    parity channels that equals a stride-2, padded odd-kernel convolution with ``weight``."""
    out_channels, in_channels, kernel = weight.shape[0], weight.shape[1], weight.shape[2]
    taps = _parity_taps(kernel).to(weight.dtype)
    # w[o, i, px, py, pz, a, b, c] = sum_t,u,v taps[px, a, t] taps[py, b, u] taps[pz, c, v] W[o, i, t, u, v]
    folded = torch.einsum("xat,ybu,zcv,oituv->oixyzabc", taps, taps, taps, weight)
    return folded.reshape(out_channels, in_channels * 8, 3, 3, 3).contiguous()


def space_to_depth(x: torch.Tensor) -> torch.Tensor:
    """(B, C, 2n, 2n, 2n) → (B, C·8, n, n, n), channel ``c * 8 + px * 4 + py * 2 + pz`` holding
    the voxels of parity (px, py, pz): the inverse of :func:`pixel_shuffle_3d`."""
    batch, channels, d, h, w = x.shape
    x = x.reshape(batch, channels, d // 2, 2, h // 2, 2, w // 2, 2).permute(0, 1, 3, 5, 7, 2, 4, 6)
    return x.reshape(batch, channels * 8, d // 2, h // 2, w // 2)


def polyphase_weights(weight: torch.Tensor, bias: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Weights of a 3³ convolution on the low-resolution input that yields, as 8 channel groups
    per output channel (channel ``c * 8 + px * 4 + py * 2 + pz``), a padded odd-kernel
    convolution of the ×2 nearest-upsampled input."""
    out_channels, in_channels, kernel = weight.shape[0], weight.shape[1], weight.shape[2]
    taps = _phase_taps(kernel).to(weight.dtype)
    # w[c, i, px, py, pz, a, b, c'] = sum_t,u,v taps[px, a, t] taps[py, b, u] taps[pz, c', v] W[c, i, t, u, v]
    phased = torch.einsum("xat,ybu,zcv->xyzabctuv", taps, taps, taps)
    folded = torch.einsum("xyzabctuv,oituv->oxyziabc", phased, weight)
    folded = folded.reshape(out_channels * 8, in_channels, 3, 3, 3)
    return folded.contiguous(), bias.repeat_interleave(8).contiguous()


def pixel_shuffle_3d(x: torch.Tensor, out: torch.Tensor | None = None) -> torch.Tensor:
    """(B, C·8, n, n, n) with parity channels → (B, C, 2n, 2n, 2n); written into ``out`` (a
    contiguous tensor of that shape, any dtype) when given, in the same single pass."""
    batch, channels, d, h, w = x.shape
    c = channels // 8
    x = x.reshape(batch, c, 2, 2, 2, d, h, w).permute(0, 1, 5, 2, 6, 3, 7, 4)
    if out is None:
        return x.reshape(batch, c, 2 * d, 2 * h, 2 * w)
    out.view(batch, c, d, 2, h, 2, w, 2).copy_(x)
    return out


def _fused_head(network: VGN) -> tuple[torch.Tensor, torch.Tensor]:
    heads = (network.conv_qual, network.conv_rot, network.conv_width)
    weight = torch.cat([head.weight for head in heads])
    bias = torch.cat([head.bias for head in heads])
    return weight, bias


class FastVGN(nn.Module):
    """Same input and outputs as :class:`VGN` (eval only); built with :meth:`from_vgn`."""

    def __init__(self, network: VGN, dtype: torch.dtype = torch.float32) -> None:
        super().__init__()
        self.dtype = dtype
        encoder, decoder = network.encoder, network.decoder
        with torch.no_grad():
            self._plain = [
                (space_to_depth_weights(encoder.conv1.weight), encoder.conv1.bias, 1, 1),
                (encoder.conv2.weight, encoder.conv2.bias, 2, 1),
                (encoder.conv3.weight, encoder.conv3.bias, 2, 1),
                (decoder.conv1.weight, decoder.conv1.bias, 1, 1),
            ]
            self._folded = [
                polyphase_weights(decoder.conv2.weight, decoder.conv2.bias),
                polyphase_weights(decoder.conv3.weight, decoder.conv3.bias),
                polyphase_weights(*_fused_head(network)),
            ]
        for index, (weight, bias, _, _) in enumerate(self._plain):
            self.register_buffer(f"plain{index}_w", weight.detach().to(dtype).clone())
            self.register_buffer(f"plain{index}_b", bias.detach().to(dtype).clone())
        for index, (weight, bias) in enumerate(self._folded):
            self.register_buffer(f"folded{index}_w", weight.detach().to(dtype))
            self.register_buffer(f"folded{index}_b", bias.detach().to(dtype))
        self._strides = [(stride, padding) for _, _, stride, padding in self._plain]
        # The rotation and width heads' folded taps as a (27·16, 5·8) matrix, for :meth:`heads_at`.
        weight, bias = (t.detach().to(dtype).float().numpy() for t in self._folded[2])
        taps = weight[LAZY_ROWS].transpose(0, 2, 3, 4, 1)  # (5·8, 3, 3, 3, 16): channels last
        self._lazy_taps = torch.from_numpy(taps.reshape(len(taps), -1).T.copy())
        self._lazy_bias = bias[LAZY_ROWS].reshape(5, 8)
        self._neighbourhood = np.stack(np.meshgrid(*(np.arange(3),) * 3, indexing="ij"), -1).reshape(27, 3)
        del self._plain, self._folded

    @classmethod
    def from_vgn(cls, network: VGN, dtype: torch.dtype = torch.float32) -> FastVGN:
        """The fast form of a ``VGN``'s weights, in eval mode;
        ``dtype`` is the compute precision (outputs stay float32)."""
        return cls(network.eval(), dtype).eval()

    def features(self, grid: torch.Tensor) -> torch.Tensor:
        """The decoder's output at ``dtype``, (B, 16, N/2, N/2, N/2): what the heads read,
        before the last ×2 upsampling (the heads' folded form reads it directly)."""
        x = space_to_depth(grid.to(self.dtype))  # encoder.conv1 reads the parity channels
        for index, (stride, padding) in enumerate(self._strides):
            weight, bias = getattr(self, f"plain{index}_w"), getattr(self, f"plain{index}_b")
            x = F.relu(F.conv3d(x, weight, bias, stride=stride, padding=padding))
        # decoder.conv2 and decoder.conv3 read upsampled inputs: each runs folded at the lower
        # resolution, and its 8 parities are interleaved afterwards.
        for index in range(2):
            weight, bias = getattr(self, f"folded{index}_w"), getattr(self, f"folded{index}_b")
            x = pixel_shuffle_3d(F.relu(F.conv3d(x, weight, bias, padding=1)))
        return x

    def head_logits(self, grid: torch.Tensor) -> torch.Tensor:
        """The fused heads before their activations, float32, (B, 6·8, N/2, N/2, N/2): channel
        ``c * 8 + parity`` of quality (c = 0), rotation (1-4) and width (5), not yet interleaved."""
        return F.conv3d(self.features(grid), self.folded2_w, self.folded2_b, padding=1).float()

    def forward(self, grid: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """What ``VGN.forward`` returns for ``grid``, as float32, computed at ``dtype``."""
        return self.outputs_from(self.features(grid))

    def outputs_from(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Quality, rotation and width, as ``forward`` returns them, from :meth:`features`."""
        heads = F.conv3d(features, self.folded2_w, self.folded2_b, padding=1).float()
        # The activations work per voxel, so they run in place on the contiguous parity groups,
        # and one pass then interleaves the parities (a copy per step, as torch.cat and a
        # reshaped shuffle made, cost as much as the last convolution).
        batch, _, d, h, w = heads.shape
        quality, rotation, _ = heads.view(batch, 6, 8, d, h, w).split(HEAD_CHANNELS, dim=1)
        quality.sigmoid_()
        _normalise_(rotation, dim=1)
        outputs = torch.empty((batch, 6, 2 * d, 2 * h, 2 * w), dtype=torch.float32, device=heads.device)
        return pixel_shuffle_3d(heads, out=outputs).split(HEAD_CHANNELS, dim=1)

    def quality_from(self, features: torch.Tensor) -> torch.Tensor:
        """Quality alone, (B, 1, N, N, N) float32, from :meth:`features`: its head is 8 of the
        fused head's 48 output channels, so this costs about a sixth of :meth:`outputs_from`."""
        logits = F.conv3d(features, self.folded2_w[:8], self.folded2_b[:8], padding=1).float()
        batch, _, d, h, w = logits.shape
        quality = torch.empty((batch, 1, 2 * d, 2 * h, 2 * w), dtype=torch.float32, device=logits.device)
        return pixel_shuffle_3d(logits.sigmoid_(), out=quality)

    def rotation_and_width_from(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Rotation (B, 4, N, N, N) unit quaternions and width (B, 1, N, N, N), float32, from
        :meth:`features`: the rest of what :meth:`outputs_from` gives beside quality."""
        logits = F.conv3d(features, self.folded2_w[LAZY_ROWS], self.folded2_b[LAZY_ROWS], padding=1).float()
        batch, _, d, h, w = logits.shape
        _normalise_(logits.view(batch, 5, 8, d, h, w)[:, :4], dim=1)
        heads = torch.empty((batch, 5, 2 * d, 2 * h, 2 * w), dtype=torch.float32, device=logits.device)
        rotation, width = pixel_shuffle_3d(logits, out=heads).split(HEAD_CHANNELS[1:], dim=1)
        return rotation, width

    def padded_features(self, features: torch.Tensor) -> np.ndarray:
        """One grid's (16, N/2, N/2, N/2) :meth:`features` as what :meth:`heads_at` reads:
        float32 numpy, zero-padded by one voxel on every side, channels last (so that a
        voxel's neighbourhood is 27 contiguous rows)."""
        return F.pad(features.float(), (1, 1, 1, 1, 1, 1)).permute(1, 2, 3, 0).contiguous().cpu().numpy()

    def heads_at(self, padded: np.ndarray, voxels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotations (4, M) and widths (M,) of one grid at M voxels ((M, 3) indices into the N³
        output), from its :meth:`padded_features`: the two heads evaluated at those voxels
        alone, which for a few hundred voxels is far cheaper than the whole heads.

        Output voxel v reads the 3³ feature neighbourhood of v // 2 through the folded taps of
        its parity v % 2 (:func:`polyphase_weights`); each neighbourhood is read once for all
        the voxels that share it, which in detection's clusters is a fraction of them."""
        _, h, w, channels = padded.shape
        strides = np.array([h * w, w, 1])
        corner = (voxels // 2) @ strides  # the padding shifts the neighbourhood to start there
        cells, cell_of_voxel = np.unique(corner, return_inverse=True)
        rows = padded.reshape(-1, channels)[cells[:, None] + self._neighbourhood @ strides]
        # torch's product, on the threads the service gave torch: numpy's BLAS starts its own
        # threads, which spin for a core that the other inference lane holds (8 ms, not 0.1).
        logits = (torch.from_numpy(rows.reshape(len(cells), 27 * channels)) @ self._lazy_taps).numpy()
        parity = voxels % 2
        phase = parity[:, 0] * 4 + parity[:, 1] * 2 + parity[:, 2]
        heads = logits.reshape(-1, 5, 8)[cell_of_voxel, :, phase].T + self._lazy_bias[:, phase]
        rotation = heads[:4] / np.maximum(np.linalg.norm(heads[:4], axis=0), NORM_EPS)
        return rotation, heads[4]


def _normalise_(quaternions: torch.Tensor, dim: int) -> None:
    """Scale the 4 components along ``dim`` to unit length in place (``F.normalize``'s rule)."""
    # Summed by hand: torch's norm over a short non-innermost dimension is ~100x slower.
    parts = quaternions.unbind(dim)
    norm = (parts[0].square() + parts[1].square() + parts[2].square() + parts[3].square()).sqrt_()
    quaternions.div_(norm.clamp_min_(NORM_EPS).unsqueeze(dim))
