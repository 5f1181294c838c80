"""Planned grasps out as ROS messages: poses for a motion planner, scores beside them, and
gripper outlines for RViz. Index i of each message is the i-th best grasp."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, PoseArray
from geometry_msgs.msg import Pose as PoseMsg
from std_msgs.msg import ColorRGBA, Float32MultiArray, Header, MultiArrayDimension
from visualization_msgs.msg import Marker, MarkerArray

from vgn_contract.geometry import gripper_outline, matrix_from_pose
from vgn_contract.schemas import Grasp

#: Line width of the drawn gripper outlines (metres).
LINE_WIDTH = 0.002
#: Track ids go out modulo this: float32 holds every integer below it exactly, so an id on
#: ``~/grasp_scores`` repeats only after this many newer tracks of the same stream.
TRACK_ID_MODULUS = 2**24


def pose_array(grasps: Sequence[Grasp], frame_id: str, stamp: Time) -> PoseArray:
    """The grasp poses (grasp frame → world, +z the approach), best first."""
    poses = []
    for grasp in grasps:
        pose = PoseMsg()
        pose.position.x, pose.position.y, pose.position.z = (float(v) for v in grasp.position)
        q = pose.orientation
        q.x, q.y, q.z, q.w = (float(v) for v in grasp.orientation)
        poses.append(pose)
    return PoseArray(header=Header(frame_id=frame_id, stamp=stamp), poses=poses)


def scores(grasps: Sequence[Grasp], track_ids: bool = False) -> Float32MultiArray:
    """An (n, 2) array of [quality, width (m)] per grasp, in the order of ``pose_array``; with
    ``track_ids`` (a Track stream's grasps) an (n, 3) array, each grasp's ``track_id`` third so
    that a closed loop can follow one grasp from plan to plan. The id is taken modulo
    ``TRACK_ID_MODULUS``, which float32 holds exactly; NaN for a grasp without one."""
    columns = ("quality", "width", "track_id") if track_ids else ("quality", "width")
    rows = [[grasp.quality, grasp.width] + ([_track_id(grasp)] if track_ids else []) for grasp in grasps]
    msg = Float32MultiArray(data=[float(v) for row in rows for v in row])
    width = len(columns)
    msg.layout.dim = [
        MultiArrayDimension(label="grasp", size=len(grasps), stride=width * len(grasps)),
        MultiArrayDimension(label="_".join(columns), size=width, stride=width),
    ]
    return msg


def _track_id(grasp: Grasp) -> float:
    return math.nan if grasp.track_id is None else float(grasp.track_id % TRACK_ID_MODULUS)


def quality_colour(quality: float) -> ColorRGBA:
    """Red at quality 0 through yellow to green at 1."""
    q = min(max(float(quality), 0.0), 1.0)
    return ColorRGBA(r=min(1.0, 2.0 * (1.0 - q)), g=min(1.0, 2.0 * q), b=0.0, a=1.0)


def markers(grasps: Sequence[Grasp], frame_id: str, stamp: Time, namespace: str = "grasps") -> MarkerArray:
    """A DELETEALL (the previous plan's outlines go) then one outline per grasp, coloured by quality."""
    header = Header(frame_id=frame_id, stamp=stamp)
    found = [Marker(header=header, ns=namespace, action=Marker.DELETEALL)]
    for index, grasp in enumerate(grasps):
        outline = gripper_outline(matrix_from_pose(grasp.position, grasp.orientation), grasp.width)
        # The outline is one stroke, a pen-up row, then the stem: LINE_LIST wants point pairs.
        strokes = [
            outline[i : i + 2] for i in range(len(outline) - 1) if not np.isnan(outline[i : i + 2]).any()
        ]
        marker = Marker(header=header, ns=namespace, id=index, type=Marker.LINE_LIST, action=Marker.ADD)
        marker.pose.orientation.w = 1.0
        marker.scale.x = LINE_WIDTH
        marker.color = quality_colour(grasp.quality)
        marker.points = [
            Point(x=float(x), y=float(y), z=float(z)) for stroke in strokes for x, y, z in stroke
        ]
        found.append(marker)
    return MarkerArray(markers=found)
