"""Crash safety as users meet it: SIGKILL a command, rerun it, get what an uninterrupted run gets.

Each command runs through its console script in a child process. Deaths "during a write" are
deterministic: ``VGN_CRASH_AT_WRITE=NAME[:N]`` (vgn_data/files.py) makes the writing process
SIGKILL itself on the N-th write of a file called NAME, after an atomic write's temporary file
is complete and before its rename, or halfway through an append. Deaths "during a scene" are
a plain ``kill -9`` of the command once its first unit of work has landed on disk.
"""

from __future__ import annotations

import csv
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from sim_worker.results import TIMING_COLUMNS
from tests.helpers.datasets import make_dataset
from tests.helpers.processes import wait_until_gone
from vgn_data.files import CRASH_VARIABLE

KILLED = -signal.SIGKILL


def command(name: str) -> str:
    """The installed console script; the tests run what users run, wherever the code lives."""
    path = shutil.which(name)
    assert path, f"{name} is not installed: run `pip install -e .` (install.sh does)"
    return path


def run(args: list[str], crash_at: str | None = None, env: dict[str, str] | None = None):
    environment = {k: v for k, v in os.environ.items() if k != CRASH_VARIABLE} | (env or {})
    if crash_at:
        environment[CRASH_VARIABLE] = crash_at
    return subprocess.run(args, capture_output=True, text=True, timeout=600, env=environment)


def children_of(pid: int) -> set[int]:
    """Process ids whose parent is ``pid`` (read from /proc)."""
    found = set()
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.add(int(entry.name))
    return found


def kill_when(process: subprocess.Popen, ready, timeout: float = 300.0) -> set[int]:
    """SIGKILL ``process`` as soon as ``ready()`` holds; returns the children it had then."""
    deadline = time.monotonic() + timeout
    while not ready():
        assert process.poll() is None, f"the command ended before the kill point: {process.returncode}"
        assert time.monotonic() < deadline, "the kill point never came"
        time.sleep(0.05)
    children = children_of(process.pid) | {
        c for child in children_of(process.pid) for c in children_of(child)
    }
    process.kill()
    process.wait()
    return children


def assert_no_orphans(pids: set[int], timeout: float = 30.0) -> None:
    """A killed command's workers and embedded service end with it instead of working on."""
    survivors = {
        pid: Path(f"/proc/{pid}/cmdline").read_bytes()[:120] for pid in wait_until_gone(pids, timeout)
    }
    for pid in survivors:
        os.kill(pid, signal.SIGKILL)
    assert not survivors, f"processes outlived the killed command: {survivors}"


def leftovers(root: Path) -> list[Path]:
    """Files a killed writer may leave: only its hidden temporaries, which no reader opens."""
    hidden = [p for p in root.rglob(".*") if p.is_file()]
    for path in hidden:
        assert path.name.endswith(".tmp"), f"unexpected hidden file {path}"
    return hidden


# generate-data ------------------------------------------------------------------------------


def generate(url: str | None, out: Path, scenes: int, crash_at: str | None = None, env=None):
    args = [command("vgn-client"), "generate-data", "--sim", "--scene", "pile", "--objects", "blocks",
            "--scenes", str(scenes), "--workers", "1", "--points", "4", "--renderer", "tiny",
            "--out", str(out)]  # fmt: skip
    return run([*args, "--url", url] if url else args, crash_at, env)


def assert_same_dataset(made: Path, reference: Path) -> None:
    """Same grasp rows in the same order, same scene files with the same arrays."""
    assert (made / "grasps.csv").read_text() == (reference / "grasps.csv").read_text()
    scenes = sorted(p.name for p in (reference / "scenes").glob("*.npz"))
    assert sorted(p.name for p in (made / "scenes").glob("*.npz")) == scenes and scenes
    for name in scenes:
        with np.load(made / "scenes" / name) as a, np.load(reference / "scenes" / name) as b:
            assert sorted(a.files) == sorted(b.files)
            for key in a.files:
                assert np.array_equal(a[key], b[key]), f"{name}: {key} differs"
    leftovers(made)


@pytest.fixture(scope="module")
def reference_datasets(server, tmp_path_factory: pytest.TempPathFactory) -> dict[int, Path]:
    """Uninterrupted runs, made on demand and shared by this module's tests."""
    made: dict[int, Path] = {}

    class Runs(dict):
        def __missing__(self, scenes: int) -> Path:
            out = tmp_path_factory.mktemp("reference") / f"scenes{scenes}"
            result = generate(server.url, out, scenes)
            assert result.returncode == 0, result.stderr
            made[scenes] = out
            return out

    return Runs()


def test_generate_data_killed_mid_append_resumes_to_the_same_dataset(server, reference_datasets, tmp_path):
    """The worker dies with half of a scene's grasp rows written: the rerun cuts the torn rows,
    labels that scene again and appends it once."""
    out = tmp_path / "data"
    # The folder made first, so that the only write of grasps.csv in the worker's process is its append
    assert generate(server.url, out, scenes=0).returncode == 0
    killed = generate(server.url, out, scenes=1, crash_at="grasps.csv:1")
    assert killed.returncode != 0 and "worker(s) failed (exit codes [-9])" in killed.stderr
    torn = (out / "grasps.csv").read_text()
    assert not torn.endswith("\n"), "the crash hook left a torn last line"
    again = generate(server.url, out, scenes=1)
    assert again.returncode == 0, again.stderr
    assert "0 of 1 scenes already" in again.stderr
    assert_same_dataset(out, reference_datasets[1])


@pytest.mark.slow
def test_generate_data_killed_before_a_scene_file_lands(server, reference_datasets, tmp_path):
    """Killed after the second scene's file is written but before it is renamed into place:
    the first scene is kept, the second made again."""
    out = tmp_path / "data"
    killed = generate(server.url, out, scenes=2, crash_at="s0-0000001.npz")
    assert killed.returncode != 0
    assert not (out / "scenes" / "s0-0000001.npz").exists() and leftovers(out)
    kept = (out / "grasps.csv").read_text()
    again = generate(server.url, out, scenes=2)
    assert again.returncode == 0, again.stderr
    assert "1 of 2 scenes already" in again.stderr
    assert (out / "grasps.csv").read_text().startswith(kept)
    assert_same_dataset(out, reference_datasets[2])
    assert not leftovers(out), "the rerun removes the killed writer's temporary file"


@pytest.mark.slow
def test_generate_data_killed_during_a_scene_leaves_no_orphans(reference_datasets, tmp_path):
    """``kill -9`` of the command (embedded service, one worker) while it labels its second
    scene: the worker and the service die with it, and the rerun completes the dataset."""
    out = tmp_path / "data"
    env = {"VGN_MODEL": "none"}  # generate-data needs the fused cloud only
    args = [command("vgn-client"), "generate-data", "--sim", "--scene", "pile", "--objects", "blocks",
            "--scenes", "2", "--workers", "1", "--points", "4", "--renderer", "tiny", "--out", str(out)]  # fmt: skip
    process = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               env=os.environ | env)  # fmt: skip
    grasps = out / "grasps.csv"
    children = kill_when(process, lambda: grasps.exists() and grasps.read_text().count("\n") > 1)
    assert len(children) >= 2, "a worker and the embedded service were running"
    assert_no_orphans(children)
    again = run(args, env=env)
    assert again.returncode == 0, again.stderr
    assert_same_dataset(out, reference_datasets[2])


# clear-scene --------------------------------------------------------------------------------

#: Columns that hold wall-clock times, which no two runs share.
TIMES = TIMING_COLUMNS


def clear_scene(url: str, results: Path, rounds: int, crash_at: str | None = None):
    """A clear-scene run that attempts grasps: without the clearance check, which drops every
    grasp of the random weights the test service loads."""
    args = [command("vgn-client"), "clear-scene", "--sim", "--renderer", "tiny", "--url", url,
            "--object-count", "2", "--threshold", "0.5", "--no-clearance", "--rounds", str(rounds),
            "--results", str(results)]  # fmt: skip
    return run(args, crash_at)


def results_table(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as stream:
        return [{k: v for k, v in row.items() if k not in TIMES} for row in csv.DictReader(stream)]


def assert_same_results(made: Path, reference: Path) -> None:
    for name in ("rounds.csv", "grasps.csv"):
        assert results_table(made / name) == results_table(reference / name), f"{name} differs"
    assert sorted(r["round_id"] for r in results_table(made / "rounds.csv")) == sorted(
        {r["round_id"] for r in results_table(made / "rounds.csv")}
    ), "a round was recorded twice"
    leftovers(made)


@pytest.fixture(scope="module")
def reference_results(server, tmp_path_factory: pytest.TempPathFactory) -> Path:
    results = tmp_path_factory.mktemp("reference") / "clear"
    done = clear_scene(server.url, results, rounds=2)
    assert done.returncode == 0, done.stderr
    assert results_table(results / "grasps.csv"), "the reference run attempted grasps"
    return results


def test_clear_scene_killed_between_its_two_result_files(server, reference_results, tmp_path):
    """Killed after round 0's grasps.csv is renamed into place but before rounds.csv: the round
    does not count, so the rerun plays it again and its grasps are not recorded twice."""
    results = tmp_path / "run"
    killed = clear_scene(server.url, results, rounds=2, crash_at="rounds.csv:1")
    assert killed.returncode == KILLED
    assert (results / "grasps.csv").exists() and not (results / "rounds.csv").exists()
    again = clear_scene(server.url, results, rounds=2)
    assert again.returncode == 0, again.stderr
    assert "resuming" not in again.stderr, "no round had finished"
    assert_same_results(results, reference_results)
    assert not leftovers(results), "the rerun removes the killed writer's temporary file"


@pytest.mark.slow
def test_clear_scene_killed_during_a_round(server, reference_results, tmp_path):
    """``kill -9`` while round 1 plays: round 0 is kept, round 1 is played again from its start."""
    results = tmp_path / "run"
    args = [command("vgn-client"), "clear-scene", "--sim", "--renderer", "tiny", "--url", server.url,
            "--object-count", "2", "--threshold", "0.5", "--no-clearance", "--rounds", "2",
            "--results", str(results)]  # fmt: skip
    process = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    kill_when(process, lambda: (results / "rounds.csv").exists())
    kept = (results / "rounds.csv").read_text()
    again = run(args)
    assert again.returncode == 0, again.stderr
    assert "1 of 2 rounds already done" in again.stderr
    assert (results / "rounds.csv").read_text().startswith(kept)
    assert_same_results(results, reference_results)


@pytest.mark.slow
def test_clear_scene_killed_while_rewriting_the_grasps(server, reference_results, tmp_path):
    """Killed in round 1's commit before its grasps.csv lands: the file still holds round 0's
    rows only, whole, and the rerun adds round 1 once."""
    results = tmp_path / "run"
    killed = clear_scene(server.url, results, rounds=2, crash_at="grasps.csv:2")
    assert killed.returncode == KILLED
    assert {r["round_id"] for r in results_table(results / "grasps.csv")} == {"0"}
    again = clear_scene(server.url, results, rounds=2)
    assert again.returncode == 0, again.stderr
    assert_same_results(results, reference_results)


# vgn-train ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def boxes(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_dataset(tmp_path_factory.mktemp("raw") / "boxes", scenes=3).root


def train_args(data: Path, out: Path, epochs: int, *extra: str) -> list[str]:
    """A tiny run; the grid cache beside the data is shared by every run (each fuses nothing twice)."""
    return ["--data", str(data), "--out", str(out), "--cache", str(data.parent / "cache"), "--batch-scenes", "1",
            "--val-fraction", "0.34", "--no-progress", "--threads", "1", "--lr", "1e-3", "--threshold", "0.9",
            "--epochs", str(epochs), *extra]  # fmt: skip


def train(data: Path, out: Path, epochs: int, *extra: str, crash_at: str | None = None):
    return run([command("vgn-train"), *train_args(data, out, epochs, *extra)], crash_at)


def assert_same_training(made: Path, reference: Path) -> None:
    """Same final weights, checkpoint state and history (but wall-clock seconds)."""
    from safetensors.torch import load_file

    a, b = load_file(made), load_file(reference)
    assert a.keys() == b.keys()
    for name in a:
        assert torch.equal(a[name], b[name]), f"{name} differs"
    states = [torch.load(p.with_suffix(".ckpt.pt"), weights_only=True) for p in (made, reference)]
    assert states[0]["epoch"] == states[1]["epoch"]
    for name, tensor in states[0]["model"].items():
        assert torch.equal(tensor, states[1]["model"][name])
    histories = [[{k: v for k, v in e.items() if k != "seconds"} for e in s["history"]] for s in states]
    assert histories[0] == histories[1]
    leftovers(made.parent)


@pytest.fixture(scope="module")
def reference_training(boxes: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The uninterrupted run, in this process (what the console script calls; it saves a
    process start): single-threaded torch computes the same numbers in any process."""
    from training.cli import main

    out = tmp_path_factory.mktemp("reference") / "vgn.safetensors"
    threads = torch.get_num_threads()
    try:
        assert main(train_args(boxes, out, 2)) == 0
    finally:
        torch.set_num_threads(threads)
    return out


def test_train_killed_during_a_checkpoint_write(boxes, reference_training, tmp_path):
    """Killed while writing epoch 2's checkpoint: epoch 1's checkpoint is intact, and
    ``--resume`` retrains epoch 2 to the uninterrupted run's weights."""
    out = tmp_path / "vgn.safetensors"
    killed = train(boxes, out, 2, crash_at="vgn.ckpt.pt:2")
    assert killed.returncode == KILLED
    assert torch.load(out.with_suffix(".ckpt.pt"), weights_only=True)["epoch"] == 1
    again = train(boxes, out, 2, "--resume")
    assert again.returncode == 0, again.stderr
    assert_same_training(out, reference_training)
    assert not leftovers(tmp_path), "the rerun removes the killed writer's temporary file"


@pytest.mark.slow
@pytest.mark.parametrize("crash_at", ["vgn.ckpt.pt:1", "vgn.safetensors:2", "vgn.card.json"])
def test_train_killed_at_other_writes(boxes, reference_training, tmp_path, crash_at: str):
    """Before the first checkpoint lands (the rerun starts afresh), while the weights are
    written, and after training but before the card: each rerun ends with the same run."""
    out = tmp_path / "vgn.safetensors"
    killed = train(boxes, out, 2, crash_at=crash_at)
    assert killed.returncode == KILLED
    resume = ["--resume"] if out.with_suffix(".ckpt.pt").exists() else []
    again = train(boxes, out, 2, *resume)
    assert again.returncode == 0, again.stderr
    assert_same_training(out, reference_training)
    assert out.with_suffix(".card.json").is_file()
