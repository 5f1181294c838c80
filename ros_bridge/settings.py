"""The node's ROS parameters: declared with their defaults and descriptions, read and checked
into one ``Settings`` before the node touches the service or the graph."""

from __future__ import annotations

import importlib.util
import math
import os
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from pydantic import ValidationError
from rclpy.exceptions import ParameterException, ParameterUninitializedException
from rclpy.parameter import Parameter

from client.connect import is_grpc_url
from client.http import grasp_query
from ros_bridge.convert import fixed_pose
from vgn_contract.gripper_description import NAME_PATTERN
from vgn_contract.schemas import SWITCH_EFFECTS, SWITCHES, Pose, Workspace

if TYPE_CHECKING:
    from rclpy.node import Node

POSE_SOURCES = ("auto", "tf", "topic", "fixed")
POSE_TYPES = ("PoseStamped", "TransformStamped")

#: name -> (default, description). A ``Parameter.Type`` default declares a parameter without a value:
#: unset, the service's default applies.
PARAMETERS: dict[str, tuple[Any, str]] = {
    "service_url": (
        "",
        "http(s):// or grpc(s):// URL of vgn-service; empty: $VGN_URL or http://127.0.0.1:8000",
    ),
    "api_key": ("", "the service's API key; empty: $VGN_API_KEY or none"),
    "timeout": (30.0, "seconds a call to the service may take"),
    "session_id": ("", "the session to open on the service; empty: one the client picks"),
    "gripper": (
        "",
        "the hand the session plans for (the service lists its hands); empty: the service's default",
    ),
    "workspace.size": (0.30, "side of the workspace cube (m)"),
    "workspace.resolution": (40, "voxels a side"),
    "workspace.position": (
        [0.0, 0.0, 0.0],
        "the cube's corner in world_frame (m): a few cm below the table top",
    ),
    "workspace.orientation": (
        [0.0, 0.0, 0.0, 1.0],
        "the cube's orientation [x, y, z, w]; keep its z axis up",
    ),
    "world_frame": ("world", "frame of the camera poses, the workspace and the published grasps"),
    "pose_source": (
        "auto",
        "tf, topic or fixed; auto: fixed if camera_pose is set, else tf if tf2_ros imports, else topic",
    ),
    "pose_type": ("PoseStamped", "message type on the camera_pose topic: PoseStamped or TransformStamped"),
    "camera_pose": ([0.0], "fixed camera -> world pose [x, y, z, qx, qy, qz, qw] (OpenCV optical frame)"),
    "pose_tolerance": (0.05, "seconds a camera pose's stamp may be from its frame's"),
    "wait": (0.5, "seconds a frame waits for its camera info and pose before it is refused"),
    "depth_scale": (1000.0, "16UC1 units per metre (1000: millimetres)"),
    "max_depth": (2.0, "readings beyond this (m) are not fused"),
    "reliable": (False, "subscribe to the camera reliably (default: best effort, as sensor drivers publish)"),
    "planner": ("vgn", "vgn or antipodal"),
    "threshold": (Parameter.Type.DOUBLE, "minimum grasp quality; unset: the service's default"),
    "max_grasps": (Parameter.Type.INTEGER, "publish at most this many grasps; unset: all"),
    **{
        name: (Parameter.Type.BOOL, f"{SWITCH_EFFECTS[name]}; unset: the service's default")
        for name in SWITCHES
    },
    "fuse_on_request": (
        False,
        "fuse only the first frame after each ~/fuse call (a wrist camera held still), not every frame",
    ),
    "continuous": (
        False,
        "plan after every fused frame over a gRPC Track stream and publish as it goes, "
        "without ~/plan (needs a grpc:// or grpcs:// service_url)",
    ),
}

#: Parameters that are one number: declared so that an integer is taken for it too.
NUMBERS = frozenset(
    name
    for name, (default, _) in PARAMETERS.items()
    if isinstance(default, float) or default is Parameter.Type.DOUBLE
)


@dataclass(frozen=True)
class Settings:
    """What the node was configured with, checked."""

    service_url: str
    api_key: str | None
    timeout: float
    session_id: str | None
    gripper: str | None
    workspace: Workspace
    world_frame: str
    pose_source: str
    pose_type: str
    camera_pose: Pose | None
    pose_tolerance: float
    wait: float
    depth_scale: float
    max_depth: float
    reliable: bool
    grasp_options: dict[str, Any]
    fuse_on_request: bool
    continuous: bool


def declare(node: Node) -> None:
    """Declare every parameter of ``PARAMETERS`` on ``node``; ``ValueError`` names one given a
    value of the wrong type. Numbers take integers too: ``-p wait:=1`` means 1.0."""
    from rcl_interfaces.msg import ParameterDescriptor

    for name, (default, description) in PARAMETERS.items():
        number = name in NUMBERS
        descriptor = ParameterDescriptor(description=description, dynamic_typing=number)
        value = None if default is Parameter.Type.DOUBLE else default
        try:
            node.declare_parameter(name, value, descriptor)
        except ParameterException as error:
            raise ValueError(f"parameter {name}: {error}") from None


def _value(node: Node, name: str) -> Any:
    try:
        return node.get_parameter(name).value
    except ParameterUninitializedException:
        return None


def read(node: Node) -> Settings:
    """The declared parameters as ``Settings``; ``ValueError`` names the parameter that is wrong."""
    values = {name: _value(node, name) for name in PARAMETERS}
    for name in NUMBERS:
        value = values[name]
        if value is not None and (isinstance(value, bool) or not isinstance(value, int | float)):
            raise ValueError(f"{name} must be a number, got {value!r}")
        values[name] = None if value is None else float(value)
    return settings_from(values)


def tf_available() -> bool:
    """Whether tf2_ros can be imported (it has no wheel on PyPI; a ROS install brings it)."""
    return importlib.util.find_spec("tf2_ros") is not None


def settings_from(values: dict[str, Any]) -> Settings:
    """``Settings`` from parameter values by name (``None``: unset); ``ValueError`` says what is wrong."""
    url = values["service_url"] or os.environ.get("VGN_URL") or "http://127.0.0.1:8000"
    if not (url.lower().startswith(("http://", "https://")) or is_grpc_url(url)):
        raise ValueError(f"service_url must start with http://, https://, grpc:// or grpcs://, got {url!r}")
    if values["continuous"] and not is_grpc_url(url):
        raise ValueError(
            f"continuous needs a grpc:// or grpcs:// service_url (the Track stream is gRPC only), got {url!r}"
        )
    if values["continuous"] and values["fuse_on_request"]:
        raise ValueError(
            "continuous and fuse_on_request do not go together: a Track stream plans after every "
            "frame; with fuse_on_request, call ~/fuse and then ~/plan"
        )
    for name in ("timeout", "depth_scale", "max_depth"):
        _number(name, values[name], zero_allowed=False)
    for name in ("pose_tolerance", "wait"):
        _number(name, values[name], zero_allowed=True)
    try:
        workspace = Workspace(
            size=values["workspace.size"],
            resolution=values["workspace.resolution"],
            pose=Pose(
                position=list(values["workspace.position"]), orientation=list(values["workspace.orientation"])
            ),
        )
    except ValidationError as error:
        problems = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in error.errors())
        raise ValueError(f"workspace.* parameters are not a valid workspace ({problems})") from None
    fixed = None if list(values["camera_pose"]) == [0.0] else fixed_pose(list(values["camera_pose"]))
    return Settings(
        service_url=url,
        api_key=values["api_key"] or os.environ.get("VGN_API_KEY") or None,
        timeout=float(values["timeout"]),
        session_id=values["session_id"] or None,
        gripper=_gripper(values["gripper"]),
        workspace=workspace,
        world_frame=values["world_frame"],
        pose_source=_pose_source(values["pose_source"], fixed),
        pose_type=_choice("pose_type", values["pose_type"], POSE_TYPES),
        camera_pose=fixed,
        pose_tolerance=float(values["pose_tolerance"]),
        wait=float(values["wait"]),
        depth_scale=float(values["depth_scale"]),
        max_depth=float(values["max_depth"]),
        reliable=bool(values["reliable"]),
        grasp_options=_grasp_options(values),
        fuse_on_request=bool(values["fuse_on_request"]),
        continuous=bool(values["continuous"]),
    )


def _gripper(value: str) -> str | None:
    """A hand's name, or None (empty) for the service's default. A malformed name stops the node
    at start; one the service does not know is the service's to refuse, naming those it knows."""
    if not value:
        return None
    if not re.fullmatch(NAME_PATTERN, value):
        raise ValueError(f"gripper must be a hand's name ({NAME_PATTERN}), got {value!r}")
    return value


def _number(name: str, value: float, zero_allowed: bool) -> None:
    if not (math.isfinite(value) and (value >= 0 if zero_allowed else value > 0)):
        raise ValueError(
            f"{name} must be a finite number {'at least' if zero_allowed else 'above'} 0, got {value}"
        )


def _choice(name: str, value: str, allowed: tuple[str, ...]) -> str:
    if value not in allowed:
        raise ValueError(f"{name} must be one of {', '.join(allowed)}, got {value!r}")
    return value


def _pose_source(value: str, fixed: Pose | None) -> str:
    source = _choice("pose_source", value, POSE_SOURCES)
    if source == "auto":
        return "fixed" if fixed else "tf" if tf_available() else "topic"
    if source == "fixed" and fixed is None:
        raise ValueError("pose_source fixed needs the camera_pose parameter [x, y, z, qx, qy, qz, qw]")
    if source == "tf" and not tf_available():
        raise ValueError(
            "pose_source tf needs tf2_ros, which is not installed (it has no PyPI wheel): use topic or fixed"
        )
    return source


def _grasp_options(values: dict[str, Any]) -> dict[str, Any]:
    """The grasp query options that are set, checked as the service checks them."""
    options = {
        "planner": values["planner"],
        "threshold": values["threshold"],
        "max_grasps": values["max_grasps"],
    }
    options |= {name: values[name] for name in SWITCHES}
    options = {name: value for name, value in options.items() if value is not None}
    grasp_query(options)  # InvalidRequest (a ValueError) names the option that is wrong
    return options
