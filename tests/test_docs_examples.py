"""The documentation's Python examples run as written: those that plan on the sample scene with the
service's address put in for the one the page shows, the real-robot page's tool poses, and its
RealSense capture as far as it goes without a camera."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from service.launch.embedded import EmbeddedService

ROOT = Path(__file__).resolve().parent.parent
GRPC_PAGE = ROOT / "docs" / "grpc-api.md"
ROBOT_PAGE = ROOT / "docs" / "real-robot.md"


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmbeddedService]:
    log = tmp_path_factory.mktemp("docs") / "service.log"
    unset = ("VGN_MODEL", "VGN_API_KEY")
    with EmbeddedService(env={"VGN_TORCH_THREADS": "1"}, unset=unset, log_path=log, grpc=True) as running:
        yield running


def test_the_grpc_page_example_runs(service: EmbeddedService):
    blocks = re.findall(r"^```python\n(.*?)^```", GRPC_PAGE.read_text(), flags=re.S | re.M)
    example = next(block for block in blocks if "sample_scene.npz" in block)
    assert "grpc://127.0.0.1:50051" in example
    code = example.replace("grpc://127.0.0.1:50051", service.grpc_url)
    run = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    assert re.match(r"4 frames fused in [0-9.]+ ms", lines[0]), run.stdout
    assert len(lines) >= 2, "and at least one grasp"


def test_the_real_robot_page_example_runs():
    """The tool poses of a grasp, with no service: the block that uses the client's robot poses."""
    blocks = re.findall(r"^```python\n(.*?)^```", ROBOT_PAGE.read_text(), flags=re.S | re.M)
    example = next(block for block in blocks if "pregrasp_pose(" in block)
    assert "pyrealsense2" not in example
    run = subprocess.run(
        [sys.executable, "-c", example], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    assert [line.split()[0] for line in lines] == ["pre-grasp", "grasp", "lift"], run.stdout


#: What the RealSense example uses of pyrealsense2 once the pipeline has started, by class: the
#: example cannot get that far without a camera, so these are looked up instead.
REALSENSE_AFTER_START = {
    "pipeline_profile": ("get_device",),
    "device": ("first_depth_sensor",),
    "depth_sensor": ("get_depth_scale",),
    "pipeline": ("wait_for_frames", "stop"),
    "align": ("process",),
    "composite_frame": ("get_depth_frame",),
    "depth_frame": ("profile", "get_data"),
    "stream_profile": ("as_video_stream_profile",),
    "video_stream_profile": ("intrinsics",),
    "intrinsics": ("width", "height", "fx", "fy", "ppx", "ppy"),
}


def test_the_realsense_capture_example_runs_up_to_the_camera():
    """The capture example as written, with the locked pyrealsense2 and no camera: every name
    up to ``pipeline.start`` resolves and start says no device is connected; what it calls after
    start exists in the bindings."""
    if importlib.util.find_spec("pyrealsense2") is None and not os.environ.get("CI"):
        pytest.skip('pyrealsense2 is not installed: pip install ".[realsense]" (install.sh --dev does)')
    import pyrealsense2 as rs

    if len(rs.context().query_devices()):
        pytest.skip("a RealSense camera is connected: the example would capture from it")
    blocks = re.findall(r"^```python\n(.*?)^```", ROBOT_PAGE.read_text(), flags=re.S | re.M)
    example = next(block for block in blocks if "import pyrealsense2" in block)
    run = subprocess.run(
        [sys.executable, "-c", example], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert run.returncode != 0 and run.stderr.strip().endswith("RuntimeError: No device connected"), (
        run.stderr
    )
    for kind, names in REALSENSE_AFTER_START.items():
        for name in names:
            assert f".{name}" in example, f"{name} is no longer in the example: update REALSENSE_AFTER_START"
            assert hasattr(getattr(rs, kind), name), f"pyrealsense2.{kind} has no {name}"
