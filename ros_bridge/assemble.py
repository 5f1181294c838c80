"""Pairing each depth image with its camera info and pose before it is fused.

The three travel on separate topics and arrive in any order, so an image whose info or pose has
not come yet waits, for at most ``wait`` seconds, and is then refused with the reason. Images
are released in the order they arrived: fusion never reorders a camera's frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sensor_msgs.msg import CameraInfo, Image

from ros_bridge.convert import depth_array, intrinsics, seconds
from ros_bridge.poses import PoseSource
from ros_bridge.problems import Refused, Waiting
from vgn_contract.schemas import Intrinsics, Pose


@dataclass(frozen=True)
class Frame:
    """A depth frame ready to fuse: what ``VGNClient.add_frame`` takes."""

    depth: np.ndarray
    intrinsics: Intrinsics
    pose: Pose
    stamp: float


class FrameAssembler:
    """Images in, fusable frames or refusals out; the latest camera info is kept for all images."""

    def __init__(self, poses: PoseSource, info_topic: str, wait: float, backlog: int = 8) -> None:
        self._poses, self._info_topic, self._wait, self._backlog = poses, info_topic, wait, backlog
        self._pending: list[tuple[Image, float]] = []
        self.info: CameraInfo | None = None

    def add(self, image: Image, now: float) -> list[Frame | Refused]:
        """Take an image that arrived at ``now`` (monotonic seconds); what can be decided now."""
        self._pending.append((image, now))
        return self.poll(now)

    def poll(self, now: float) -> list[Frame | Refused]:
        """Frames that became fusable and refusals, oldest first; the rest keep waiting."""
        done: list[Frame | Refused] = []
        while self._pending:
            image, arrived = self._pending[0]
            try:
                done.append(self._assemble(image))
            except Waiting as waiting:
                if now - arrived < self._wait and len(self._pending) <= self._backlog:
                    break
                done.append(Refused(waiting.kind, f"{waiting} (the frame waited {now - arrived:.2f} s)"))
            except Refused as refused:
                done.append(refused)
            self._pending.pop(0)
        return done

    def _assemble(self, image: Image) -> Frame:
        depth = depth_array(image)
        if self.info is None:
            raise Waiting("camera_info", f"no CameraInfo received on {self._info_topic}")
        camera = intrinsics(self.info, image)
        stamp = seconds(image.header.stamp)
        return Frame(depth, camera, self._poses.at(stamp, image.header.frame_id), stamp)
