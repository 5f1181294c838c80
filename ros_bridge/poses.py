"""Where each frame's camera pose comes from: TF, a pose topic, or one fixed pose.

Every source answers ``at(stamp, camera_frame)`` with the camera → world pose at the frame's time,
raises ``Waiting`` while it may still arrive, and ``Refused`` when it cannot be had.
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any, Protocol

from geometry_msgs.msg import PoseStamped, TransformStamped

from ros_bridge.convert import camera_pose, seconds
from ros_bridge.problems import Refused, Waiting
from vgn_contract.schemas import Pose

if TYPE_CHECKING:
    from rclpy.node import Node


class PoseSource(Protocol):
    """The camera → world pose of a frame taken at ``stamp`` by the camera ``camera_frame``."""

    def at(self, stamp: float, camera_frame: str) -> Pose:
        """The pose, or ``Waiting`` / ``Refused`` saying why there is none."""
        ...


class FixedPose:
    """A camera that does not move: every frame has the same pose (the ``camera_pose`` parameter)."""

    def __init__(self, pose: Pose) -> None:
        self._pose = pose

    def at(self, stamp: float, camera_frame: str) -> Pose:
        """The fixed pose, whatever the frame."""
        return self._pose


class TopicPoses:
    """Camera poses published on a topic (PoseStamped, or TransformStamped world → camera), kept
    for a while and matched to each frame by stamp: the nearest within ``tolerance`` seconds."""

    def __init__(self, topic: str, world_frame: str, tolerance: float, keep: int = 200) -> None:
        self._topic, self._world, self._tolerance = topic, world_frame, tolerance
        self._poses: deque[tuple[float, str, Pose]] = deque(maxlen=keep)

    def __len__(self) -> int:
        return len(self._poses)

    def add(self, msg: PoseStamped | TransformStamped) -> None:
        """Keep a pose; ``Refused`` for one in another frame than the world frame, or not rigid."""
        frame = msg.header.frame_id
        if self._world and frame != self._world:
            raise Refused(
                "pose_frame",
                f"camera pose on {self._topic} is in frame {frame!r}, expected world_frame {self._world!r}",
            )
        child = msg.child_frame_id if isinstance(msg, TransformStamped) else ""
        self._poses.append((seconds(msg.header.stamp), child, camera_pose(msg)))

    def at(self, stamp: float, camera_frame: str) -> Pose:
        """The pose nearest ``stamp``; ``Waiting`` while every pose is older than the frame."""
        if not self._poses:
            raise Waiting("pose", f"no camera pose received on {self._topic}")
        taken, child, pose = min(self._poses, key=lambda entry: abs(entry[0] - stamp))
        gap = stamp - taken
        if abs(gap) <= self._tolerance:
            if child and camera_frame and child != camera_frame:
                raise Refused(
                    "pose_frame",
                    f"camera pose on {self._topic} is for frame {child!r}, the depth image is in {camera_frame!r}",
                )
            return pose
        newest = max(entry[0] for entry in self._poses)
        if newest < stamp:
            raise Waiting(
                "pose",
                f"the newest camera pose on {self._topic} is {stamp - newest:.3f} s older than the frame "
                f"(pose_tolerance {self._tolerance:g} s)",
            )
        raise Refused(
            "pose",
            f"no camera pose on {self._topic} within pose_tolerance {self._tolerance:g} s of the frame: "
            f"the nearest is {abs(gap):.3f} s {'older' if gap > 0 else 'newer'}",
        )


class TfPoses:
    """The camera's pose from TF (``world_frame`` ← the image's ``header.frame_id``) at the frame's
    stamp, or the newest transform when it is within ``tolerance`` of it. Needs tf2_ros."""

    def __init__(self, node: Node, world_frame: str, tolerance: float) -> None:
        import tf2_ros

        self._tf2, self._world, self._tolerance = tf2_ros, world_frame, tolerance
        self._buffer = tf2_ros.Buffer()
        self._listener = tf2_ros.TransformListener(self._buffer, node)

    def at(self, stamp: float, camera_frame: str) -> Pose:
        """The transform at ``stamp``; ``Waiting`` while TF has none that recent."""
        from rclpy.time import Time

        if not camera_frame:
            raise Refused("pose", "the depth image has no header.frame_id to look its camera up in TF")
        try:
            found: Any = self._buffer.lookup_transform(
                self._world, camera_frame, Time(nanoseconds=round(stamp * 1e9))
            )
            return camera_pose(found)
        except self._tf2.TransformException:
            pass
        try:
            found = self._buffer.lookup_transform(self._world, camera_frame, Time())
        except self._tf2.TransformException as error:
            raise Waiting("pose", f"no transform {self._world} <- {camera_frame} in TF: {error}") from None
        gap = stamp - seconds(found.header.stamp)
        if abs(gap) <= self._tolerance:
            return camera_pose(found)
        raise Waiting(
            "pose",
            f"the newest transform {self._world} <- {camera_frame} in TF is {gap:.3f} s older than the frame "
            f"(pose_tolerance {self._tolerance:g} s)",
        )
