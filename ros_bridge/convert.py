"""ROS messages in, client values out: depth images, camera info and camera poses.

Each function checks what it reads and raises ``Refused`` with what is wrong, so the node can say
why a frame was not fused instead of sending the service something it would misread.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, TransformStamped
from pydantic import ValidationError
from sensor_msgs.msg import CameraInfo, Image

from ros_bridge.problems import Refused
from vgn_contract.schemas import Intrinsics, Pose

#: Depth encodings the bridge fuses (REP 118): unsigned 16-bit millimetres or float32 metres.
DEPTH_ENCODINGS = {"16UC1": np.dtype(np.uint16), "mono16": np.dtype(np.uint16), "32FC1": np.dtype(np.float32)}


def seconds(stamp: Time) -> float:
    """A message stamp in seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def depth_array(image: Image) -> np.ndarray:
    """The image as an (H, W) array: uint16 for 16UC1/mono16 (units of ``depth_scale``), float32
    metres for 32FC1; rows are read by ``step``, so padded rows and either byte order work."""
    dtype = DEPTH_ENCODINGS.get(image.encoding)
    if dtype is None:
        raise Refused(
            "encoding",
            f"depth image encoding {image.encoding!r} is not supported: publish 16UC1 (millimetres) "
            "or 32FC1 (metres)",
        )
    height, width, step = image.height, image.width, image.step
    if height == 0 or width == 0:
        raise Refused("image", f"depth image is empty ({width}x{height})")
    row = width * dtype.itemsize
    if step < row:
        raise Refused(
            "image", f"depth image step {step} is shorter than a row of {width} {image.encoding} pixels"
        )
    if len(image.data) != step * height:
        raise Refused(
            "image", f"depth image holds {len(image.data)} bytes, expected step x height = {step * height}"
        )
    raw = np.frombuffer(image.data, dtype=np.uint8).reshape(height, step)[:, :row]
    ordered = dtype.newbyteorder(">" if image.is_bigendian else "<")
    return np.ascontiguousarray(raw).view(ordered).reshape(height, width).astype(dtype)


def intrinsics(info: CameraInfo, image: Image) -> Intrinsics:
    """The pinhole intrinsics of ``info`` (its K matrix) for ``image``, whose size it must have."""
    if (info.width, info.height) != (image.width, image.height):
        raise Refused(
            "camera_info",
            f"camera info is for {info.width}x{info.height} images, the depth image is {image.width}x{image.height}",
        )
    k = info.k
    try:
        return Intrinsics(width=info.width, height=info.height, fx=k[0], fy=k[4], cx=k[2], cy=k[5])
    except ValidationError as error:
        problems = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in error.errors())
        raise Refused(
            "camera_info", f"camera info K is not a pinhole camera the service takes ({problems})"
        ) from None


def _pose(position: Sequence[float], orientation: Sequence[float], what: str) -> Pose:
    try:
        return Pose(position=list(position), orientation=list(orientation))
    except ValidationError as error:
        problems = "; ".join(e["msg"] for e in error.errors())
        raise Refused("pose", f"{what} is not a valid camera pose ({problems})") from None


def camera_pose(msg: PoseStamped | TransformStamped) -> Pose:
    """The camera → world pose a PoseStamped or TransformStamped carries."""
    if isinstance(msg, TransformStamped):
        t, q = msg.transform.translation, msg.transform.rotation
        return _pose([t.x, t.y, t.z], [q.x, q.y, q.z, q.w], "the TransformStamped")
    p, q = msg.pose.position, msg.pose.orientation
    return _pose([p.x, p.y, p.z], [q.x, q.y, q.z, q.w], "the PoseStamped")


def fixed_pose(values: Sequence[float]) -> Pose:
    """The ``camera_pose`` parameter ``[x, y, z, qx, qy, qz, qw]`` as a pose."""
    if len(values) != 7:
        raise ValueError(f"camera_pose must be 7 numbers [x, y, z, qx, qy, qz, qw], got {len(values)}")
    try:
        return _pose(values[:3], values[3:], "the camera_pose parameter")
    except Refused as error:
        raise ValueError(str(error)) from None
