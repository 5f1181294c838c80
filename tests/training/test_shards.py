"""The repository's training data: packed shards (uint8 grids + every label), append-only,
with a manifest that names the hand, and training that reads them directly."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from tests.helpers.datasets import make_dataset
from training.augment import balanced_subset, height_range, random_placement
from training.cli import main as train_main
from training.dataset import SceneDataset, load_scenes
from training.grids import MAX_DEPTH, RESOLUTION, fuse_grid
from training.labels import LabelSet
from training.pack import main as pack_main
from training.shards import ShardError, ShardFolder, dequantize, quantize, sha256_of
from vgn_data.dataset import RawDataset


def with_generation(dataset: RawDataset, gripper: str | None = "franka-v2", **settings) -> RawDataset:
    generation = {"scene": "pile", "seed": 3, **settings}
    if gripper is not None:
        generation["gripper"] = gripper
    (dataset.root / "generation.json").write_text(json.dumps(generation))
    return dataset


@pytest.fixture(scope="module")
def raw(tmp_path_factory: pytest.TempPathFactory) -> RawDataset:
    return with_generation(make_dataset(tmp_path_factory.mktemp("raw") / "boxes", scenes=5))


def test_quantisation_error_is_at_most_half_a_level():
    grid = np.random.default_rng(0).random((8, 8, 8)).astype(np.float32)
    grid[0] = 0.0
    restored = dequantize(quantize(grid))
    assert np.abs(restored - grid).max() <= 0.5 / 255 + 1e-7
    assert np.all(restored[0] == 0.0), "unobserved stays exactly 0"


def test_pack_stores_fused_grids_and_every_label(raw: RawDataset, tmp_path: Path):
    folder = ShardFolder(tmp_path / "data")
    entries = folder.pack(raw, "pile", scenes_per_shard=3)
    assert [e["scenes"] for e in entries] == [3, 2]
    manifest = folder.manifest()
    assert manifest["gripper"] == "franka-v2" and manifest["sources"]["pile"]["seed"] == 3
    for entry in manifest["shards"]:
        assert sha256_of(folder.root / entry["file"]) == entry["sha256"]
    shards = folder.load()
    ids, rows = raw.grasps()
    assert sum(len(s.scene_ids) for s in shards) == 5 and sum(len(s.grasps) for s in shards) == len(rows)
    shard = shards[0]
    scene_id = str(shard.scene_ids[1])
    expected = fuse_grid(raw.read_scene(scene_id), raw.setup, RESOLUTION, MAX_DEPTH)
    assert np.abs(dequantize(shard.grids[1]) - expected).max() <= 0.5 / 255 + 1e-6
    stored = shard.rows_by_scene()[1]
    original = rows[[i for i, sid in enumerate(ids) if sid == scene_id]]
    np.testing.assert_allclose(stored, original, atol=2e-3)  # float16 labels


def test_packing_appends_and_never_rewrites(tmp_path: Path):
    raw = with_generation(make_dataset(tmp_path / "raw", scenes=3))
    folder = ShardFolder(tmp_path / "data")
    assert pack_main([str(raw.root), "--source", "pile", "--out", str(folder.root), "--limit", "2"]) == 0
    first = folder.manifest()["shards"][0]
    before = (folder.root / first["file"]).read_bytes()
    assert pack_main([str(raw.root), "--source", "pile", "--out", str(folder.root)]) == 0
    shards = folder.manifest()["shards"]
    assert len(shards) == 2 and shards[0] == first and (folder.root / first["file"]).read_bytes() == before
    ids = [str(i) for s in folder.load() for i in s.scene_ids]
    assert sorted(ids) == ["scene000", "scene001", "scene002"], "each scene once"
    assert pack_main([str(raw.root), "--source", "pile", "--out", str(folder.root)]) == 0
    assert len(folder.manifest()["shards"]) == 2, "nothing new: no new shard"


def test_data_of_another_hand_or_other_settings_is_refused(raw: RawDataset, tmp_path: Path, capsys):
    folder = ShardFolder(tmp_path / "data")
    folder.pack(raw, "pile")
    other_hand = with_generation(make_dataset(tmp_path / "old", scenes=1), gripper="box-v1")
    with pytest.raises(ShardError, match="gripper"):
        folder.pack(other_hand, "pile-old")
    unknown = with_generation(make_dataset(tmp_path / "unknown", scenes=1), gripper=None)
    with pytest.raises(ShardError, match="hand"):
        folder.pack(unknown, "more")
    other_settings = with_generation(make_dataset(tmp_path / "noisy", scenes=1), noise_fraction=0.5)
    with pytest.raises(ShardError, match="other settings"):
        folder.pack(other_settings, "pile")
    assert pack_main([str(other_hand.root), "--source", "x", "--out", str(folder.root)]) == 2
    assert "never mixed" in capsys.readouterr().err
    assert len(folder.manifest()["shards"]) == 1, "a refused pack adds nothing"


def test_a_damaged_shard_is_caught(raw: RawDataset, tmp_path: Path):
    folder = ShardFolder(tmp_path / "data")
    folder.pack(raw, "pile")
    path = folder.root / folder.manifest()["shards"][0]["file"]
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(ShardError, match="sha256"):
        folder.load()


def test_training_reads_shards_like_raw_data(raw: RawDataset, tmp_path: Path):
    folder = ShardFolder(tmp_path / "data")
    folder.pack(raw, "pile")
    packed, packed_summary = load_scenes([folder.root], RESOLUTION, MAX_DEPTH)
    direct, _ = load_scenes([raw.root], RESOLUTION, MAX_DEPTH, tmp_path / "cache")
    assert [s.scene_id for s in packed] == [s.scene_id for s in direct]
    assert packed_summary[0].grasps == sum(len(s.labels) for s in direct)
    out = tmp_path / "model" / "vgn.safetensors"
    args = ["--data", str(folder.root), "--out", str(out), "--epochs", "1", "--copies", "2"]
    evaluation = ["--eval-objects", "blocks", "--eval-scene", "blocks", "--eval-rounds", "1"]
    assert train_main([*args, "--val-fraction", "0.2", "--no-progress", "--threads", "1", *evaluation]) == 0
    card = json.loads(out.with_suffix(".card.json").read_text())
    executed = card["executed_grasps"]
    assert executed["rounds"] == 1 and executed["settings"]["scene"] == "blocks"
    assert executed["settings"]["threshold"] == card["threshold"], "at the card's operating threshold"
    assert sum(executed["outcomes"].values()) == executed["attempts"]
    shards = card["packed_data"][0]["shards"]
    assert [s["sha256"] for s in shards] == [e["sha256"] for e in folder.manifest()["shards"]]
    assert card["packed_data"][0]["gripper"] == "franka-v2"
    train_scenes = card["training"]["train_scenes"]
    assert card["history"][0]["steps"] == -(-2 * train_scenes // 4), "copies x scenes / batch steps"


def test_height_placement_keeps_labels_inside_and_aligned():
    rng = np.random.default_rng(0)
    grid = torch.from_numpy(rng.random((40, 40, 40)).astype(np.float32))
    voxels = torch.tensor([[5, 6, 7], [30, 20, 25]])
    labels = LabelSet(voxels, torch.tensor([[0, 0, 0, 1.0]] * 2), torch.ones(2), torch.tensor([1.0, 0.0]))
    assert height_range(labels, 40) == (-7, 14)
    seen = set()
    for _ in range(60):
        moved_grid, moved = random_placement(grid, labels, rng)
        assert len(moved) == 2, "no label leaves the grid"
        shift = int(moved.voxel[0, 2] - 7)
        seen.add(shift)
        assert -7 <= shift <= 14
    assert len(seen) > 10, "heights spread over the whole range"


def test_balanced_draws_keep_positives_and_as_many_negatives():
    label = torch.tensor([1.0, 0, 0, 0, 0, 1, 0, 0])
    labels = LabelSet(torch.zeros(8, 3, dtype=torch.long), torch.zeros(8, 4), torch.ones(8), label)
    draws = [balanced_subset(labels, np.random.default_rng(i)) for i in range(20)]
    assert all(int(d.label.sum()) == 2 and len(d) == 4 for d in draws)
    negatives_only = LabelSet(
        torch.zeros(3, 3, dtype=torch.long), torch.zeros(3, 4), torch.ones(3), torch.zeros(3)
    )
    assert len(balanced_subset(negatives_only, np.random.default_rng(0))) == 1


def test_copies_are_different_draws_of_the_same_scenes(raw: RawDataset, tmp_path: Path):
    scenes, _ = load_scenes([raw.root], RESOLUTION, MAX_DEPTH, tmp_path / "cache")
    data = SceneDataset(scenes, augment="height", seed=0, copies=3, balance=True)
    assert len(data) == 3 * len(scenes)
    first, again = data[0], data[len(scenes)]
    assert not torch.equal(first.grid, again.grid) or not torch.equal(first.labels.voxel, again.labels.voxel)
    assert torch.equal(data[0].grid, first.grid), "a draw is fixed by (seed, epoch, index)"


def test_training_records_the_hand_that_labelled_the_data_and_refuses_two_hands(
    raw: RawDataset, tmp_path: Path, capsys: pytest.CaptureFixture[str]
):
    folder = ShardFolder(tmp_path / "data")
    folder.pack(raw, "pile")
    out = tmp_path / "model" / "vgn.safetensors"
    args = ["--epochs", "1", "--no-progress", "--threads", "1"]
    assert train_main(["--data", str(folder.root), "--out", str(out), *args]) == 0
    card = json.loads(out.with_suffix(".card.json").read_text())
    assert card["gripper"] == "franka-v2" and card["datasets"][0]["gripper"] == "franka-v2"
    other = with_generation(make_dataset(tmp_path / "other", scenes=1), gripper="box-v1")
    mixed = [
        "--data",
        str(folder.root),
        "--data",
        str(other.root),
        "--out",
        str(tmp_path / "mixed.safetensors"),
    ]
    assert train_main([*mixed, *args]) == 2
    assert "labelled by different hands (box-v1, franka-v2)" in capsys.readouterr().err
