"""``clear-scene --ray`` against a fleet: Ray workers (a real local instance) plan through HAProxy
in front of two replicas, which share the rounds' sessions; the results equal those of one
process running the same rounds through the same fleet."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from service.launch.embedded import free_port
from service.launch.fleet import Fleet, FleetConfig
from tests.helpers.runs import assert_same_results

pytest.importorskip("ray")
if shutil.which("haproxy") is None and not os.environ.get("CI"):
    pytest.skip(
        "HAProxy is not installed (apt-get install haproxy; install.sh --dev does)", allow_module_level=True
    )

ENV = {"VGN_API_KEY": "", "VGN_TORCH_THREADS": "1"}


@pytest.fixture(scope="module")
def fleet(random_checkpoint: Path) -> Iterator[Fleet]:
    config = FleetConfig(replicas=2, http_port=free_port(), grpc_port=free_port(), model=random_checkpoint,
                         env=ENV, restart=False)  # fmt: skip
    with Fleet(config) as running:
        yield running


def clear_scene(url: str, results: Path, *extra: str) -> subprocess.CompletedProcess:
    """Three rounds of three blocks; the random test weights' grasps are all dropped by the
    clearance and grip checks, so these are off."""
    command = [sys.executable, "-m", "client.cli", "clear-scene", "--sim", "--renderer", "tiny", "--url", url,
               "--object-count", "3", "--rounds", "3", "--threshold", "0.5", "--no-clearance", "--no-grip",
               "--results", str(results), *extra]  # fmt: skip
    return subprocess.run(command, capture_output=True, text=True, timeout=600)


def requests_per_replica(fleet: Fleet) -> dict[str, int]:
    """HTTP requests HAProxy sent to each replica so far."""
    return {
        row["svname"]: int(row["stot"] or 0)
        for row in fleet.stats()
        if row.get("pxname") == "vgn_http" and row.get("svname") not in ("FRONTEND", "BACKEND")
    }


def test_clear_scene_on_ray_through_the_fleet_equals_one_process(ray_address, fleet, tmp_path):
    single = clear_scene(fleet.url, tmp_path / "single")
    assert single.returncode == 0, single.stderr
    before = requests_per_replica(fleet)
    spread = clear_scene(fleet.url, tmp_path / "ray", "--ray", ray_address, "--workers", "2")
    assert spread.returncode == 0, spread.stderr
    assert "rounds per node" in spread.stderr and "success rate" in spread.stdout
    assert_same_results(tmp_path / "single", tmp_path / "ray")
    after = requests_per_replica(fleet)
    assert len(after) == 2 and all(after[name] > before.get(name, 0) for name in after), (
        f"both replicas served the Ray workers' sessions: {before} -> {after}"
    )
