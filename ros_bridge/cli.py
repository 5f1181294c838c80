"""``vgn-ros``: run the bridge node until Ctrl-C (ROS arguments as usual, after ``--ros-args``)."""

from __future__ import annotations

import sys
from enum import Enum

from client.extras import missing_extra
from service.launch.lifetime import end_with_parent_if_asked


def usage() -> str:
    """What ``vgn-ros --help`` prints: how to pass parameters, and each one with its default."""
    from ros_bridge.settings import PARAMETERS

    lines = ["usage: vgn-ros [--ros-args (-p NAME:=VALUE | --params-file FILE) ...]", "",
             "A ROS 2 node: depth images, camera info and camera poses in; ranked grasps out (docs/ros2.md).",
             "", "parameters (default):"]  # fmt: skip
    for name, (default, description) in PARAMETERS.items():
        # An unset parameter's default is its ROS type, an IntEnum: not a value to show.
        unset = isinstance(default, Enum) or not isinstance(default, str | int | float | bool | list)
        shown = "unset" if unset else repr(default)
        lines.append(f"  {name} ({shown}): {description}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Start rclpy and spin the node; 2 with the reason for a missing extra or a bad parameter."""
    end_with_parent_if_asked()  # started by a test or a launcher that may be killed outright
    try:
        import rclpy
        from rclpy.executors import ExternalShutdownException

        from ros_bridge.node import BridgeNode
    except ImportError as error:
        print(missing_extra("vgn-ros", "ros", error), file=sys.stderr)
        return 2
    args = sys.argv if argv is None else argv
    ours = args[: args.index("--ros-args")] if "--ros-args" in args else args
    if "-h" in ours or "--help" in ours:
        print(usage())
        return 0
    rclpy.init(args=args)
    try:
        node = BridgeNode()
    except (ValueError, ImportError) as error:  # a bad parameter; grpc:// without the grpc extra
        print(f"vgn-ros: {error}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.close()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
