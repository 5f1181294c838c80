"""What the latency benchmarks feed the service, so that their rows measure the same work.

``benchmarks.latency`` and ``benchmarks.grpc_latency`` upload the same depth frames into the
same workspace and grid, leave the threshold to the service (the model card's operating
threshold, as a plain client does), and start their servers in the same (default)
configuration; the HTTP and gRPC rows then differ only in the transport.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from client.http import encode_depth
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views  # INTRINSICS: every frame's camera

WORKSPACE_SIZE = 0.3
RESOLUTION = 40
MAX_DEPTH = 2.0
DEPTH_SCALE = 1000.0  # PNG units per metre: millimetres
VIEWS = 6
#: Variables that would override the service's own choice of runtime settings.
RUNTIME_VARIABLES = (
    "VGN_TORCH_THREADS",
    "VGN_PRECISION",
    "VGN_INFERENCE",
    "OMP_WAIT_POLICY",
    "GOMP_SPINCOUNT",
)


@dataclass(frozen=True)
class Frames:
    """The benchmark's depth frames, one per view, in every form the service accepts."""

    poses: list[np.ndarray]  # camera -> world (= workspace: the workspace sits at the origin)
    depths: list[np.ndarray]  # (H, W) float32 metres
    millimetres: list[np.ndarray]  # (H, W) uint16
    raw: list[bytes]  # little-endian float32
    png: list[bytes]  # 16-bit PNG of ``millimetres``

    def __len__(self) -> int:
        return len(self.poses)

    def fuse(self, add_frame: Callable[..., object], session_id: str) -> None:
        """Post every view to ``session_id`` through ``add_frame`` (``VGNClient.add_frame`` or
        ``PlanningService.add_frame``: both take the session, depth, pose and ``max_depth``)."""
        for depth, pose in zip(self.depths, self.poses, strict=True):
            add_frame(session_id, depth, pose, max_depth=MAX_DEPTH)


def render_frames(count: int = VIEWS) -> Frames:
    """The ``BoxScene`` rendered from ``count`` views around it, in every upload form."""
    scene = BoxScene()
    poses = circle_views(count)
    depths = [scene.depth(pose, INTRINSICS) for pose in poses]
    millimetres = [np.round(d * DEPTH_SCALE).astype(np.uint16) for d in depths]
    return Frames(
        poses,
        depths,
        millimetres,
        [encode_depth(d)[0] for d in depths],
        [encode_depth(m)[0] for m in millimetres],
    )
