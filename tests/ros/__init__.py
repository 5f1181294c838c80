"""The ROS 2 bridge's tests (docs/ros2.md), which need the ``ros`` extra."""

from __future__ import annotations

import importlib.util
import os

import pytest


def need_ros() -> None:
    """Skip the calling test module without the ``ros`` extra, except in CI: install.sh --dev
    installs it there, and a broken install must fail the run instead of skipping the graph tests."""
    if importlib.util.find_spec("rclpy") is None and not os.environ.get("CI"):
        pytest.skip("the ros extra is not installed: pip install 'vgn-service[ros]'", allow_module_level=True)
