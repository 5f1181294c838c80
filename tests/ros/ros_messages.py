"""Building the camera messages a robot publishes, for the bridge's tests."""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from vgn_contract.schemas import Intrinsics, Pose


def stamp(seconds: float) -> Time:
    whole = int(np.floor(seconds))
    return Time(sec=whole, nanosec=int(round((seconds - whole) * 1e9)))


def image(
    depth: np.ndarray, at: float, frame_id: str = "camera_optical", encoding: str | None = None
) -> Image:
    """A depth Image of ``depth``: uint16 as 16UC1, float32 as 32FC1 (or ``encoding`` as given)."""
    if encoding is None:
        encoding = {np.dtype(np.uint16): "16UC1", np.dtype(np.float32): "32FC1"}[depth.dtype]
    height, width = depth.shape
    return Image(
        header=Header(frame_id=frame_id, stamp=stamp(at)),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=width * depth.dtype.itemsize,
        data=np.ascontiguousarray(depth).tobytes(),
    )


def camera_info(camera: Intrinsics, at: float, frame_id: str = "camera_optical") -> CameraInfo:
    info = CameraInfo(
        header=Header(frame_id=frame_id, stamp=stamp(at)), width=camera.width, height=camera.height
    )
    info.k = [camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0]
    info.distortion_model = "plumb_bob"
    info.d = [0.0] * 5
    return info


def pose_stamped(matrix: np.ndarray, at: float, frame_id: str = "world") -> PoseStamped:
    pose = Pose.from_matrix(matrix)
    msg = PoseStamped(header=Header(frame_id=frame_id, stamp=stamp(at)))
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = pose.position
    q = msg.pose.orientation
    q.x, q.y, q.z, q.w = pose.orientation
    return msg
