"""vgn-ros: a ROS 2 node that fuses a robot's depth camera topics into one service session and
publishes the planned grasps (docs/ros2.md).

It reaches the service through ``client`` like any robot program. The message conversions
(``convert``, ``outputs``) and the pairing of frames with their camera info and pose
(``assemble``, ``poses``) are plain functions and classes, testable without a ROS graph; ``node``
only wires them to topics, parameters and services. Needs the ``ros`` extra.
"""
