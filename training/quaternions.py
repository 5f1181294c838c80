"""Quaternion algebra for the loss and the augmentations, on ``[x, y, z, w]`` tensors
(docs/conventions.md), so both sides share one (tested) convention."""

from __future__ import annotations

import math

import torch


def multiply(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product ``a ⊗ b`` (rotation ``b`` first, then ``a``), broadcast over leading dims."""
    ax, ay, az, aw = a.unbind(-1)
    bx, by, bz, bw = b.unbind(-1)
    return torch.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        dim=-1,
    )


def about_z(angle: float, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """The rotation by ``angle`` radians about +z."""
    return torch.tensor([0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)], dtype=dtype)


def flipped(q: torch.Tensor) -> torch.Tensor:
    """``q ⊗ [0, 0, 1, 0]``: the grasp turned by π about its own z (approach) axis, which a
    parallel-jaw gripper cannot tell apart from ``q``. Closed form of the product: (y, -x, w, -z)."""
    x, y, z, w = q.unbind(-1)
    return torch.stack([y, -x, w, -z], dim=-1)
