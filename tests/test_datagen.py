"""Data generation through a real service: VGN's labelling, the raw layout, resume, cleaning."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sim_worker.datagen import DataGenConfig, grasp_frame, middle_of_widest_run
from sim_worker.gripper import GRIPPER_VERSION
from tests.scenes import circle_views
from vgn_data.dataset import VALID_LOWER, VALID_UPPER, DatasetSetup, RawDataset, SceneViews, clean_and_balance


@pytest.mark.parametrize(
    "successes, expected",
    [
        ([0, 0, 0, 0, 0, 0], None),
        ([1, 0, 0, 0, 0, 0], 0),
        ([0, 1, 1, 1, 0, 0], 2),
        ([1, 1, 0, 1, 1, 1], 4),  # widest run wins
        ([1, 1, 0, 0, 1, 1], 0),  # ties: the first
        ([1, 1, 1, 1, 1, 1], 2),
    ],
)
def test_middle_of_widest_run(successes, expected):
    assert middle_of_widest_run(np.asarray(successes, dtype=bool)) == expected


@pytest.mark.parametrize("normal", [(0, 0, 1), (1, 0, 0), (0.3, -0.4, 0.8), (0, 0, -1)])
def test_grasp_frame_approaches_against_the_normal(normal):
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    matrix = grasp_frame(normal).as_matrix()
    np.testing.assert_allclose(matrix[:, 2], -normal, atol=1e-9)
    assert np.linalg.det(matrix) == pytest.approx(1.0)


def make_dataset(root: Path, labels: list[tuple[str, list[float], int]]) -> RawDataset:
    dataset = RawDataset(root, DatasetSetup())
    poses = np.stack(circle_views(2))
    for sid in sorted({sid for sid, _, _ in labels}):
        rows = [[0, 0, 0, 1, *position, 0.05, label] for s, position, label in labels if s == sid]
        dataset.add_scene(sid, SceneViews(np.full((2, 480, 640), 0.5, np.float32), poses), np.asarray(rows))
    return dataset


def test_raw_layout_round_trip(tmp_path: Path):
    make_dataset(tmp_path, [("a", [0.1, 0.1, 0.1], 1), ("a", [0.2, 0.1, 0.1], 0), ("b", [0.1, 0.2, 0.1], 0)])
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
    make_dataset(tmp_path / "raw", labels)
    kept = clean_and_balance(tmp_path / "raw", tmp_path / "clean", seed=0)
    _, grasps = RawDataset(tmp_path / "clean").grasps()
    assert kept == len(grasps) == 4  # the (0.01, ...) positive lies outside: 2 positives + 2 negatives
    assert grasps[:, 8].sum() == 2
    assert np.all((grasps[:, 4:7] >= VALID_LOWER) & (grasps[:, 4:7] <= VALID_UPPER))
    assert len(RawDataset(tmp_path / "raw").grasps()[0]) == 6, "the raw folder is kept as it was"


def generate(server_url: str, out: Path, scenes: int, workers: int = 1) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "client.cli", "generate-data", "--sim", "--url", server_url, "--scene", "pile",
               "--objects", "blocks", "--scenes", str(scenes), "--workers", str(workers), "--points", "8",
               "--renderer", "tiny", "--out", str(out)]  # fmt: skip
    return subprocess.run(command, capture_output=True, text=True, timeout=600)


def test_generate_through_a_real_service_and_resume(server, tmp_path: Path):
    out = tmp_path / "data"
    first = generate(server.url, out, scenes=2, workers=2)
    assert first.returncode == 0, first.stderr
    assert "grasps/s per worker" in first.stdout
    dataset = RawDataset(out)
    ids, grasps = dataset.grasps()
    assert sorted(set(ids)) == ["s0-0000000", "s0-0000001"] and len(grasps) == 16
    assert np.allclose(np.linalg.norm(grasps[:, :4], axis=1), 1.0, atol=1e-5)
    assert set(grasps[:, 8]) <= {0.0, 1.0}
    positives = grasps[grasps[:, 8] == 1]
    assert np.all((positives[:, 7] > 0) & (positives[:, 7] <= 0.08)), "positive widths fit the gripper"
    for sid in set(ids):
        views = dataset.read_scene(sid)
        assert 1 <= len(views.depth) <= 6 and views.depth.shape[1:] == (480, 640)
        assert views.depth.max() > 0
    rows_before = (out / "grasps.csv").read_text()
    again = generate(server.url, out, scenes=3)
    assert again.returncode == 0, again.stderr
    assert "2 of 3 scenes already" in again.stderr
    text = (out / "grasps.csv").read_text()
    assert text.startswith(rows_before), "earlier rows are untouched"
    ids, _ = RawDataset(out).grasps()
    assert sorted(set(ids)) == ["s0-0000000", "s0-0000001", "s0-0000002"] and len(ids) == 24, "no duplicates"


def test_labels_of_a_generated_scene_replay(server, tmp_path: Path):
    """A stored positive label is a grasp that succeeds when replayed in the same scene."""
    from client.http import VGNClient
    from sim_worker.datagen import DataGenConfig, SceneLabeller
    from sim_worker.grasping import execute_grasp

    with VGNClient(server.url) as vgn:
        labeller = SceneLabeller(vgn, DataGenConfig(scene="pile", objects=("blocks",), points_per_scene=12,
                                                    renderer="tiny"))  # fmt: skip
        try:
            labelled = None
            for index in range(6):
                labelled = labeller.label_scene(index)
                if labelled is not None and labelled[1][:, 8].any():
                    break
            assert labelled is not None and labelled[1][:, 8].any(), "some positive among 6 small scenes"
            row = labelled[1][labelled[1][:, 8] == 1][0]
            labeller.world.clear_objects()
            labeller.label_scene(index)  # rebuild the same scene (same seed, same index)
            pose = np.eye(4)
            pose[:3, :3] = Rotation.from_quat(row[:4]).as_matrix()
            pose[:3, 3] = row[4:7]
            trial = execute_grasp(
                labeller.world, labeller.gripper, pose, allow_contact=False, remove_grasped=False
            )
            assert trial.label == 1
        finally:
            labeller.close()


def test_a_torn_write_is_healed_before_the_next_append(tmp_path: Path):
    """A writer killed mid-line leaves a partial row: the scene counts as not done at once (a
    resumed run generates it again), and the next append cuts the rest of its rows."""
    make_dataset(tmp_path, [("a", [0.1, 0.1, 0.1], 1), ("b", [0.1, 0.2, 0.1], 0)])
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
    dataset = make_dataset(tmp_path, [("a", [0.1, 0.1, 0.1], 1)])
    dataset.mark_empty("e")
    assert RawDataset(tmp_path).done_scene_ids() == {"a", "e"}
    assert RawDataset(tmp_path).scene_ids() == ["a"]


def test_resume_with_other_generation_settings_is_refused(server, tmp_path: Path):
    out = tmp_path / "data"
    assert generate(server.url, out, scenes=1).returncode == 0
    command = [sys.executable, "-m", "client.cli", "generate-data", "--sim", "--url", server.url, "--scene", "packed",
               "--objects", "blocks", "--scenes", "2", "--points", "8", "--out", str(out)]  # fmt: skip
    refused = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert refused.returncode == 2 and "other settings (scene)" in refused.stderr
    generation = json.loads((out / "generation.json").read_text())
    assert generation["gripper"] == GRIPPER_VERSION, "the dataset names the hand that labelled it"
    generation["gripper"] = "box-v1"
    (out / "generation.json").write_text(json.dumps(generation))
    again = generate(server.url, out, scenes=2)
    assert again.returncode == 2 and "gripper" in again.stderr, "labels of another hand are never mixed"


def test_noisy_and_side_view_scenes_are_fixed_by_the_seed():
    config = DataGenConfig(seed=4, noise_fraction=0.33, side_view_fraction=0.2)
    conditions = [config.scene_conditions(i) for i in range(600)]
    assert conditions == [DataGenConfig(seed=4, noise_fraction=0.33, side_view_fraction=0.2).scene_conditions(i)
                          for i in range(600)]  # fmt: skip
    noisy = np.mean([n for n, _ in conditions])
    side = np.mean([s for _, s in conditions])
    assert 0.27 < noisy < 0.39 and 0.15 < side < 0.25
    assert not any(n or s for n, s in (DataGenConfig(seed=4).scene_conditions(i) for i in range(50)))
    assert all(DataGenConfig(noise=True).scene_conditions(i)[0] for i in range(20)), "--noise: every scene"
    with pytest.raises(ValueError, match="noise_fraction"):
        DataGenConfig(noise_fraction=1.5)


def test_a_session_the_service_forgot_is_reopened(server):
    """A paused run outlives VGN_SESSION_TTL_S: the next scene opens a new session instead of
    failing the worker with 404."""
    from client.http import VGNClient
    from sim_worker.datagen import DataGenConfig, SceneLabeller

    with VGNClient(server.url) as vgn:
        labeller = SceneLabeller(vgn, DataGenConfig(scene="packed", objects=("blocks",), points_per_scene=2,
                                                    renderer="tiny"))  # fmt: skip
        try:
            forgotten = labeller.session_id
            vgn.delete_session(forgotten)  # what expiry does
            labelled = next(r for r in map(labeller.label_scene, range(4)) if r is not None)
            assert labeller.session_id != forgotten and len(labelled[1]) == 2
            assert vgn.session(labeller.session_id).frame_count == len(labelled[0].depth)
        finally:
            labeller.close()
