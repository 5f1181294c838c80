"""VGN's raw dataset layout (``vgn_data.dataset``): round trip, torn writes, empty scenes, cleaning."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.helpers.scenes import circle_views
from vgn_data.dataset import VALID_LOWER, VALID_UPPER, DatasetSetup, RawDataset, SceneViews, clean_and_balance


def labelled_dataset(root: Path, labels: list[tuple[str, list[float], int]]) -> RawDataset:
    """A default-setup dataset holding ``labels`` (scene id, position, label), two flat views a scene."""
    dataset = RawDataset(root, DatasetSetup())
    poses = np.stack(circle_views(2))
    for sid in sorted({sid for sid, _, _ in labels}):
        rows = [[0, 0, 0, 1, *position, 0.05, label] for s, position, label in labels if s == sid]
        dataset.add_scene(sid, SceneViews(np.full((2, 480, 640), 0.5, np.float32), poses), np.asarray(rows))
    return dataset


def test_raw_layout_round_trip(tmp_path: Path):
    labelled_dataset(
        tmp_path, [("a", [0.1, 0.1, 0.1], 1), ("a", [0.2, 0.1, 0.1], 0), ("b", [0.1, 0.2, 0.1], 0)]
    )
    reopened = RawDataset(tmp_path)
    assert reopened.setup == DatasetSetup() and reopened.scene_ids() == ["a", "b"]
    ids, grasps = reopened.grasps()
    assert ids == ["a", "a", "b"] and grasps.shape == (3, 9) and grasps[:, 8].tolist() == [1, 0, 0]
    views = reopened.read_scene("a")
    np.testing.assert_allclose(views.camera_poses, np.stack(circle_views(2)), atol=1e-12)
    assert (tmp_path / "setup.json").exists() and not list(tmp_path.rglob(".*.tmp"))
    with pytest.raises(ValueError, match="another setup"):
        RawDataset(tmp_path, DatasetSetup(size=0.4))
    # A writer killed mid-line leaves a torn row: readers skip it.
    with (tmp_path / "grasps.csv").open("a") as stream:
        stream.write("c,0.1,0.2")
    assert RawDataset(tmp_path).scene_ids() == ["a", "b"]


def test_clean_and_balance(tmp_path: Path):
    labels = [("a", [0.1, 0.1, 0.1], 1), ("a", [0.15, 0.1, 0.1], 0), ("a", [0.2, 0.1, 0.1], 0),
              ("b", [0.1, 0.2, 0.1], 0), ("b", [0.01, 0.2, 0.1], 1), ("b", [0.1, 0.2, 0.2], 1)]  # fmt: skip
    labelled_dataset(tmp_path / "raw", labels)
    kept = clean_and_balance(tmp_path / "raw", tmp_path / "clean", seed=0)
    _, grasps = RawDataset(tmp_path / "clean").grasps()
    assert kept == len(grasps) == 4  # the (0.01, ...) positive lies outside: 2 positives + 2 negatives
    assert grasps[:, 8].sum() == 2
    assert np.all((grasps[:, 4:7] >= VALID_LOWER) & (grasps[:, 4:7] <= VALID_UPPER))
    assert len(RawDataset(tmp_path / "raw").grasps()[0]) == 6, "the raw folder is kept as it was"


def test_a_torn_write_is_healed_before_the_next_append(tmp_path: Path):
    """A writer killed mid-line leaves a partial row: the scene counts as not done at once (a
    resumed run generates it again), and the next append cuts the rest of its rows."""
    labelled_dataset(tmp_path, [("a", [0.1, 0.1, 0.1], 1), ("b", [0.1, 0.2, 0.1], 0)])
    with (tmp_path / "grasps.csv").open("a") as stream:
        stream.write("c,0,0,0,1,0.1,0.1,0.1,0.05,1\nc,0.1,0.2")  # scene c: one row, then torn
    dataset = RawDataset(tmp_path)
    assert dataset.done_scene_ids() == {"a", "b"}, "c is incomplete: not done, none of its rows read"
    assert dataset.grasps()[0] == ["a", "b"]
    poses = np.stack(circle_views(1))
    dataset.add_scene(
        "d",
        SceneViews(np.full((1, 480, 640), 0.5, np.float32), poses),
        np.array([[0, 0, 0, 1, 0.2, 0.2, 0.1, 0.05, 0]]),
    )
    ids, grasps = RawDataset(tmp_path).grasps()
    assert ids == ["a", "b", "d"] and grasps.shape == (3, 9)
    assert (tmp_path / "grasps.csv").read_text().endswith("\n")


def test_empty_scenes_count_as_done(tmp_path: Path):
    dataset = labelled_dataset(tmp_path, [("a", [0.1, 0.1, 0.1], 1)])
    dataset.mark_empty("e")
    assert RawDataset(tmp_path).done_scene_ids() == {"a", "e"}
    assert RawDataset(tmp_path).scene_ids() == ["a"]
