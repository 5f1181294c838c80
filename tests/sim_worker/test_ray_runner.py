"""``--ray``: scenes and clear-scene rounds on a real local Ray instance (2 CPUs), shared by the
module; the commands run as subprocesses that join it, as they would join a cluster."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from client.cli import main as cli_main
from tests.helpers.runs import assert_same_results, rows_without_timings
from vgn_data.dataset import RawDataset

ray = pytest.importorskip("ray")

SCENES = 3


def generate(address: str, url: str, out: Path, *extra: str) -> subprocess.Popen:
    command = [sys.executable, "-m", "client.cli", "generate-data", "--sim", "--url", url, "--scene", "pile",
               "--objects", "blocks", "--scenes", str(SCENES), "--points", "4", "--renderer", "tiny",
               "--out", str(out), "--ray", address, *extra]  # fmt: skip
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def finish(process: subprocess.Popen) -> str:
    stdout, stderr = process.communicate(timeout=600)
    assert process.returncode == 0, stderr
    return stdout + stderr


def assert_same_dataset(first: Path, second: Path) -> None:
    """Byte for byte the same grasps (the driver writes scenes in index order) and views."""
    assert (first / "grasps.csv").read_text() == (second / "grasps.csv").read_text()
    a, b = RawDataset(first), RawDataset(second)
    assert a.scene_ids() == b.scene_ids()
    for sid in a.scene_ids():
        views_a, views_b = a.read_scene(sid), b.read_scene(sid)
        assert np.array_equal(views_a.depth, views_b.depth)
        assert np.allclose(views_a.camera_poses, views_b.camera_poses, atol=1e-12)
    assert not list(second.rglob(".*.tmp")), "no torn temporary file is left"


@pytest.fixture(scope="module")
def one_worker_dataset(ray_address: str, server, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("ray") / "one"
    log = finish(generate(ray_address, server.url, out, "--workers", "1"))
    assert f"labelling {SCENES} with 1 Ray worker(s)" in log
    ids = RawDataset(out).done_scene_ids()
    assert ids == {f"s0-{i:07d}" for i in range(SCENES)}
    return out


def test_two_workers_write_the_same_dataset_as_one(one_worker_dataset: Path, ray_address, server, tmp_path):
    out = tmp_path / "two"
    log = finish(generate(ray_address, server.url, out, "--workers", "2"))
    assert "grasps/s per worker (2 Ray worker(s))" in log
    assert_same_dataset(one_worker_dataset, out)
    again = finish(generate(ray_address, server.url, out, "--workers", "2"))
    assert f"{SCENES} of {SCENES} scenes already" in again, "a rerun adds only what is missing"
    assert_same_dataset(one_worker_dataset, out)


def worker_pids(method: str) -> list[int]:
    """Ray actor processes of this test's Ray instance (descendants of this process) that are
    running ``SimWorker.<method>`` (Ray names the process after the call it executes)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            title = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
            if f"SimWorker.{method}" in title and _descends_from(int(entry.name), os.getpid()):
                found.append(int(entry.name))
        except (OSError, ValueError):
            continue
    return found


def _descends_from(pid: int, ancestor: int) -> bool:
    while pid > 1:
        if pid == ancestor:
            return True
        stat = Path(f"/proc/{pid}/stat").read_text()
        pid = int(stat.rsplit(")", 1)[1].split()[1])
    return False


def test_a_worker_killed_mid_scene_still_gives_the_whole_dataset(
    one_worker_dataset: Path, ray_address, server, tmp_path
):
    out = tmp_path / "killed"
    process = generate(ray_address, server.url, out, "--workers", "2")
    deadline, killed = time.monotonic() + 300, None
    while killed is None and time.monotonic() < deadline and process.poll() is None:
        pids = worker_pids("label_scene")
        if pids:
            killed = pids[0]
            os.kill(killed, signal.SIGKILL)
        time.sleep(0.05)
    assert killed is not None, "no worker was seen labelling a scene"
    finish(process)
    assert_same_dataset(one_worker_dataset, out)
    ids, _ = RawDataset(out).grasps()
    per_scene = {sid: ids.count(sid) for sid in set(ids)}
    assert all(count == 4 for count in per_scene.values()), "no scene is written twice"


def clear_scene(results: Path, *extra: str, url: str) -> subprocess.CompletedProcess:
    """Three rounds of three blocks; the random test weights' grasps are all dropped by the
    clearance and grip checks, so these are off."""
    command = [sys.executable, "-m", "client.cli", "clear-scene", "--sim", "--renderer", "tiny", "--url", url,
               "--object-count", "3", "--rounds", "3", "--threshold", "0.5", "--no-clearance", "--no-grip",
               "--results", str(results), *extra]  # fmt: skip
    return subprocess.run(command, capture_output=True, text=True, timeout=600)


@pytest.mark.slow
def test_clear_scene_on_ray_equals_a_single_process_run(ray_address, server, tmp_path):
    single = clear_scene(tmp_path / "single", url=server.url)
    assert single.returncode == 0, single.stderr
    spread = clear_scene(tmp_path / "ray", "--ray", ray_address, "--workers", "2", url=server.url)
    assert spread.returncode == 0, spread.stderr
    assert "rounds per node" in spread.stderr and "success rate" in spread.stdout
    assert_same_results(tmp_path / "single", tmp_path / "ray")
    assert [row["round_id"] for row in rows_without_timings(tmp_path / "ray" / "rounds.csv")] == [
        "0",
        "1",
        "2",
    ]


def test_without_the_extra_ray_is_named(tmp_path, monkeypatch, capsys):
    """Where ray is not installed (an import of it fails), --ray says which extra is missing."""
    monkeypatch.setitem(sys.modules, "ray", None)
    code = cli_main(["generate-data", "--sim", "--ray", "--url", "http://127.0.0.1:9", "--scenes", "1",
                     "--out", str(tmp_path / "data")])  # fmt: skip
    assert code == 2
    assert "pip install 'vgn-service[ray]'" in capsys.readouterr().err


@pytest.mark.slow
def test_benchmark_on_ray_equals_a_single_process_run(ray_address, tmp_path):
    from benchmarks.clutter import main

    common = ["--planners", "antipodal", "--selections", "best", "--scenarios", "blocks-5", "--rounds", "2",
              "--renderer", "tiny"]  # fmt: skip
    assert main([*common, "--out", str(tmp_path / "single")]) == 0
    assert main([*common, "--out", str(tmp_path / "ray"), "--ray", ray_address, "--workers", "2"]) == 0
    folder = "antipodal-best-blocks-5-clearance-grip"  # the embedded services' default: both checks on
    assert_same_results(tmp_path / "single" / folder, tmp_path / "ray" / folder)
