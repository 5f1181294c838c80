"""Launch vgn-ros beside a depth camera driver (docs/ros2.md); needs a ROS 2 install for ``launch``.

vgn-ros is a Python console script, not a ROS package, so it runs as a process; the remappings
point its camera topics at the driver's.
"""

from pathlib import Path

from launch import LaunchDescription
from launch.actions import ExecuteProcess

PARAMETERS = Path(__file__).with_name("vgn_bridge.yaml")


def generate_launch_description() -> LaunchDescription:
    """vgn-ros with the parameters beside this file, on a RealSense's aligned depth topics."""
    bridge = [
        "vgn-ros",
        "--ros-args",
        "--params-file",
        str(PARAMETERS),
        "-r",
        "depth/image_rect:=/camera/camera/aligned_depth_to_color/image_raw",
        "-r",
        "depth/camera_info:=/camera/camera/aligned_depth_to_color/camera_info",
        "-r",
        "camera_pose:=/camera/pose",
    ]
    return LaunchDescription([ExecuteProcess(cmd=bridge, output="screen")])
