"""The README's Python examples run as written, against a real service on loopback.

The first ``python`` block is the front-door example: it loads ``examples/sample_scene.npz``,
fuses its frames through ``VGNClient`` at the URL in ``VGN_URL`` and prints the grasps the
packaged model finds. The other blocks (the workspace placement snippet) must run too.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from service.launch.embedded import EmbeddedService

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
SAMPLE = ROOT / "examples" / "sample_scene.npz"


def python_blocks() -> list[str]:
    """Every fenced ``python`` block of the README, verbatim."""
    return re.findall(r"^```python\n(.*?)^```", README.read_text(), flags=re.S | re.M)


def run_block(code: str, url: str) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter from the repository root, as a reader would run it."""
    env = {**os.environ, "VGN_URL": url, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300
    )


@pytest.fixture(scope="module")
def packaged_service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[EmbeddedService]:
    """The service as `vgn-client serve` starts it: the packaged model, default settings."""
    log = tmp_path_factory.mktemp("readme") / "service.log"
    unset = ("VGN_MODEL", "VGN_API_KEY", "VGN_TURN_AVERAGE", "VGN_CLEARANCE")
    with EmbeddedService(env={"VGN_TORCH_THREADS": "1"}, unset=unset, log_path=log) as service:
        yield service


def test_the_sample_scene_is_small_and_complete():
    scene = np.load(SAMPLE)
    assert SAMPLE.stat().st_size < 400 * 1024
    frames, height, width = scene["depth_mm"].shape
    assert scene["depth_mm"].dtype == np.uint16 and frames >= 3
    assert scene["camera_poses"].shape == (frames, 4, 4)
    assert np.allclose(scene["camera_poses"][:, 3], [0, 0, 0, 1])
    assert list(scene["intrinsics"][:2]) == [width, height]
    assert (scene["depth_mm"] > 0).mean() > 0.9, "the table fills the views"


def test_the_readme_example_prints_grasps(packaged_service: EmbeddedService):
    blocks = python_blocks()
    assert blocks, "the README has a python block"
    example = blocks[0]
    assert "examples/sample_scene.npz" in example and "VGN_URL" in example
    assert len(example.strip().splitlines()) <= 25, "the front-door example stays short"
    run = run_block(example, packaged_service.url)
    assert run.returncode == 0, run.stderr
    grasps = [line for line in run.stdout.splitlines() if line.startswith("quality")]
    assert grasps, f"the example printed no grasp: {run.stdout!r}"
    qualities = [float(re.match(r"quality (\S+)", line).group(1)) for line in grasps]
    assert qualities == sorted(qualities, reverse=True), "best first"
    assert packaged_service.url.startswith("http://127.0.0.1:")


def test_every_other_readme_block_runs(packaged_service: EmbeddedService):
    for code in python_blocks()[1:]:
        run = run_block(code, packaged_service.url)
        assert run.returncode == 0, f"{code}\n{run.stderr}"
