"""Retiring a source: its shards leave the folder, the manifest keeps what they were and why,
and nothing that reads the folder stumbles over the record or packs into the name again."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.report import training_data_page
from training.recipe_shards import RecipeFolder, RecipeRecord
from training.shards import ShardError, sha256_of
from vgn_data.dataset import DatasetSetup, RawDataset

GRIPPER = "franka-v2"


def record(scene_id: str, rng: np.random.Generator) -> RecipeRecord:
    """A scene as a shard stores it: one block at a random pose, one camera, a few labels."""
    arrays = {
        "objects": np.asarray(["builtin:block.urdf"]), "urdf_sha256": np.asarray(["u" * 64]),
        "mesh_sha256": np.asarray(["m" * 64]), "scales": np.ones(1), "poses": rng.random((1, 7)),
        "views": rng.random((1, 7)), "noise_state": np.zeros(0, np.uint64), "side_view": np.asarray(False),
        "renderer": np.asarray("tiny"),
    }  # fmt: skip
    labels = np.concatenate([rng.random((4, 8)), (rng.random((4, 1)) > 0.5)], axis=1)
    return RecipeRecord(scene_id, arrays, rng.integers(0, 255, 16, dtype=np.uint8), labels)


def append(folder: RecipeFolder, source: str, seed: int, scenes: int) -> dict:
    """A new shard of ``source`` written through the folder, with the source's settings."""
    manifest = folder.start(GRIPPER, DatasetSetup().to_json())
    manifest["sources"][source] = {"scene": "pile", "seed": seed, "objects": ["builtin:"]}
    rng = np.random.default_rng(seed)
    first = len(folder.scene_ids(source))
    return folder.append(manifest, source, [record(f"s{seed}-{first + i:07d}", rng) for i in range(scenes)])


@pytest.fixture
def data(tmp_path: Path) -> Path:
    """A folder with a source to keep (one shard) and one to retire (two shards)."""
    folder = RecipeFolder(tmp_path / "data")
    append(folder, "pile", seed=1, scenes=3)
    append(folder, "extra", seed=2, scenes=2)
    append(folder, "extra", seed=2, scenes=2)
    return folder.root


def vgn_data(*args: str | Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "training.data_cli", *map(str, args)], capture_output=True,
                          text=True, timeout=300)  # fmt: skip


def test_retire_removes_the_files_and_records_them(data: Path):
    before = RecipeFolder(data).manifest()
    extra = [entry for entry in before["shards"] if entry["source"] == "extra"]
    kept = [entry for entry in before["shards"] if entry["source"] == "pile"]
    done = vgn_data("retire", data, "--source", "extra", "--reason", "over the size cap")
    assert done.returncode == 0, done.stderr
    assert "retired extra" in done.stdout and "2 shards, 4 scenes" in done.stdout
    assert not any((data / entry["file"]).exists() for entry in extra)
    manifest = RecipeFolder(data).manifest()
    assert manifest["shards"] == kept and "extra" not in manifest["sources"]
    record = manifest["retired"]["extra"]
    assert record["shards"] == extra, "the entries are kept as they were, hashes and counts included"
    assert record["settings"] == before["sources"]["extra"] and record["reason"] == "over the size cap"
    assert len(record["retired"]) == len(before["created"]) and record["retired"].endswith("+00:00")
    assert manifest["updated"] >= record["retired"]
    # The other source is untouched and loads with its sha256 checked.
    (shard,) = RecipeFolder(data).load(verify=True)
    assert shard.source == "pile" and sha256_of(data / kept[0]["file"]) == kept[0]["sha256"]
    shown = vgn_data("show", data)
    assert shown.returncode == 0, shown.stderr
    lines = shown.stdout.splitlines()
    assert lines[1].startswith("  pile: 3 scenes, 12 labels") and lines[2].startswith("  total: 3 scenes")
    assert lines[-1] == f"  retired extra: 4 scenes, on {record['retired']}: over the size cap"
    page = training_data_page(manifest, data / "no-results")
    assert "| extra | 4 | 16 |" in page and "over the size cap" in page


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--source", "packed", "--reason", "x"], "has no source 'packed'; it has: extra, pile"),
        (["--source", "extra", "--reason", "  "], "give a reason for retiring source 'extra'"),
    ],
)
def test_unknown_sources_and_empty_reasons_are_refused(data: Path, args: list[str], message: str):
    before = (data / "manifest.json").read_text()
    refused = vgn_data("retire", data, *args)
    assert refused.returncode != 0 and message in refused.stderr and str(data) in refused.stderr
    assert (data / "manifest.json").read_text() == before


def test_a_folder_without_manifest_is_refused(tmp_path: Path):
    refused = vgn_data("retire", tmp_path, "--source", "extra", "--reason", "x")
    assert refused.returncode != 0
    assert f"cannot retire source 'extra': {tmp_path} has no manifest.json" in refused.stderr


def test_an_interrupted_retire_is_finished_by_a_rerun(data: Path):
    """A retire that died after writing the manifest left a shard file behind: the next run
    deletes it, and a run with nothing left to do says so."""
    (entry, *_) = [e for e in RecipeFolder(data).manifest()["shards"] if e["source"] == "extra"]
    left = (data / entry["file"]).read_bytes()
    assert vgn_data("retire", data, "--source", "extra", "--reason", "over the size cap").returncode == 0
    (data / entry["file"]).write_bytes(left)
    manifest = (data / "manifest.json").read_text()
    finished = vgn_data("retire", data, "--source", "extra", "--reason", "again")
    assert finished.returncode == 0, finished.stderr
    assert "deleted 1 leftover files" in finished.stdout and not (data / entry["file"]).exists()
    assert (data / "manifest.json").read_text() == manifest, "the record stays as first written"
    again = vgn_data("retire", data, "--source", "extra", "--reason", "again")
    assert again.returncode != 0
    assert "source 'extra' was retired on" in again.stderr and "nothing to do" in again.stderr


def test_packing_into_a_retired_name_is_refused(data: Path, tmp_path: Path):
    assert vgn_data("retire", data, "--source", "extra", "--reason", "over the size cap").returncode == 0
    raw = RawDataset(tmp_path / "raw", DatasetSetup())
    (raw.root / "generation.json").write_text(json.dumps({"gripper": GRIPPER, "scene": "pile"}))
    before = (data / "manifest.json").read_text()
    refused = vgn_data("pack", raw.root, "--source", "extra", "--out", data)
    assert refused.returncode != 0
    assert "source 'extra' was retired on" in refused.stderr and "over the size cap" in refused.stderr
    assert "pack under another source name" in refused.stderr and str(data) in refused.stderr
    assert (data / "manifest.json").read_text() == before
    with pytest.raises(ShardError, match="was retired"):  # nor through the folder itself
        append(RecipeFolder(data), "extra", seed=2, scenes=1)


def test_training_on_a_retired_source_says_it_was_retired_and_why(data: Path, tmp_path: Path):
    assert vgn_data("retire", data, "--source", "extra", "--reason", "over the size cap").returncode == 0
    refused = subprocess.run([sys.executable, "-m", "training.cli", "--data", str(data), "--source", "extra",
                              "--cache", str(tmp_path / "cache"), "--epochs", "1", "--out",
                              str(tmp_path / "w.safetensors"), "--no-progress"],
                             capture_output=True, text=True, timeout=300)  # fmt: skip
    assert refused.returncode != 0
    assert (
        f"{data}: source 'extra' was retired on" in refused.stderr and "over the size cap" in refused.stderr
    )
    assert not (tmp_path / "cache").exists(), "refused before anything was rendered"
