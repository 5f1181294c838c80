"""The network's output as detection reads it: quality at every voxel, rotation and width
where asked.

Detection reads quality everywhere, widths only where the smoothed quality passes the threshold
near the surface, and orientations only where a grasp may be returned: a few hundred of a 40³
grid's 64,000 voxels. So the fast network (:class:`service.vgn.fast.FastVGN`) runs its quality
head alone and computes rotation and width from the decoder's features when they are read
(:class:`HeadsOnDemand`); the reference network's heads come whole (:class:`ComputedHeads`).
"""

from __future__ import annotations

import numpy as np
import torch

from service.vgn.fast import FastVGN
from service.vgn.turns import average_turned_rotation

#: Above this many voxels a :class:`HeadsOnDemand` computes its whole rotation and width heads
#: once instead of voxel by voxel (which gathers a 432-value neighbourhood per voxel).
WHOLE_HEAD_VOXELS = 4096


class ComputedHeads:
    """Rotation (4, N³) and width (N³) computed for every voxel (the reference network)."""

    def __init__(self, rotation: np.ndarray, width: np.ndarray) -> None:
        self.rotation, self.width = rotation, width

    def rotation_at(self, i: np.ndarray, j: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """(4, M) unit quaternions at the M voxels (i, j, depth)."""
        return self.rotation[:, i, j, depth]

    def width_at(self, i: np.ndarray, j: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """(M,) widths (voxels) at the M voxels (i, j, depth)."""
        return self.width[i, j, depth]

    def whole(self) -> tuple[np.ndarray, np.ndarray]:
        """Rotation and width of every voxel."""
        return self.rotation, self.width


class HeadsOnDemand:
    """One grid's rotation and width, computed from its decoder features where they are read.

    Why: detection reads quality everywhere but width only where quality passes the threshold
    and orientation only where a grasp may be returned, a few hundred of 64,000 voxels, so the
    whole heads' convolution and the activation of all six channels would mostly go unread
    (figures: docs/performance.md)."""

    def __init__(self, network: FastVGN, features: torch.Tensor) -> None:
        self._network = network
        self._features = features  # (16, N/2, N/2, N/2), the grid's own copy
        self._padded = network.padded_features(features)
        self._whole: tuple[np.ndarray, np.ndarray] | None = None
        # The voxels last computed (sorted flat indices) and their heads: detection reads the
        # widths where quality passes, then orientations at a subset of those voxels.
        self._last: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def rotation_at(self, i: np.ndarray, j: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """(4, M) unit quaternions at the M voxels (i, j, depth)."""
        return self._at(i, j, depth)[0]

    def width_at(self, i: np.ndarray, j: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """(M,) widths (voxels) at the M voxels (i, j, depth)."""
        return self._at(i, j, depth)[1]

    def whole(self) -> tuple[np.ndarray, np.ndarray]:
        """Rotation (4, N³) and width (N³) of every voxel, computed once."""
        if self._whole is None:
            with torch.inference_mode():
                rotation, width = self._network.rotation_and_width_from(self._features[None])
            self._whole = rotation[0].cpu().numpy(), width[0, 0].cpu().numpy()
        return self._whole

    def _at(self, i: np.ndarray, j: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self._whole is not None or len(i) > WHOLE_HEAD_VOXELS:
            rotation, width = self.whole()
            return rotation[:, i, j, depth], width[i, j, depth]
        n = self._padded.shape[0] - 2  # features are at half the output resolution, padded by one
        flat = (i.astype(np.int64) * 2 * n + j) * 2 * n + depth
        last = self._last
        if last is not None and len(last[0]):
            at = np.minimum(np.searchsorted(last[0], flat), len(last[0]) - 1)
            if np.array_equal(last[0][at], flat):
                return last[1][:, at], last[2][at]
        rotation, width = self._network.heads_at(self._padded, np.stack([i, j, depth], axis=1))
        order = np.argsort(flat)
        self._last = flat[order], rotation[:, order], width[order]
        return rotation, width


class NetworkOutput:
    """Voxel-wise network output: quality (N³) as numpy; rotation (4, N³, unit quaternions) and
    width (N³, voxels) read where needed (:meth:`rotation_where`, :meth:`width_at`) or whole
    (:attr:`rotation`, :attr:`width`), from heads that the fast network computes on demand.

    A turn-averaged output also keeps the four turns' rotations (``turned_rotations``) and
    averages them only where asked (:meth:`rotation_where`): a request reads the orientation
    of a few hundred voxels, and averaging all 64,000 would cost more than the rest of the
    averaging together. Its widths are the unturned grid's."""

    def __init__(
        self,
        quality: np.ndarray,
        heads: ComputedHeads | HeadsOnDemand,
        turned_rotations: tuple[ComputedHeads | HeadsOnDemand, ...] | None = None,
    ) -> None:
        self.quality = quality
        self.heads = heads
        self.turned_rotations = turned_rotations

    @property
    def rotation(self) -> np.ndarray:
        """(4, N, N, N) orientations of the unturned grid at every voxel."""
        return self.heads.whole()[0]

    @property
    def width(self) -> np.ndarray:
        """(N, N, N) widths (voxels) at every voxel."""
        return self.heads.whole()[1]

    def width_at(self, i: np.ndarray, j: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """(M,) widths (voxels) at the M voxels (i, j, depth)."""
        return self.heads.width_at(i, j, depth)

    def rotation_where(self, where: np.ndarray | None = None) -> np.ndarray:
        """Orientations (4, N³), turn-averaged for a turn-averaged output, at the voxels
        ``where`` marks (all voxels when ``None``). Elsewhere: zero, except for a plain output
        whose heads were computed whole (the reference network), which returns them all;
        detection reads only ``where``."""
        if self.turned_rotations is None:
            if where is None or isinstance(self.heads, ComputedHeads):
                return self.rotation
            rotation = np.zeros((4, *self.quality.shape), dtype=np.float32)
            index = np.nonzero(where)
            rotation[(slice(None), *index)] = self.heads.rotation_at(*index)
            return rotation
        return average_turned_rotation(self.turned_rotations, where, n=self.quality.shape[0])
