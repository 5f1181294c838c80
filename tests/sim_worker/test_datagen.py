"""Data generation through a real service: VGN's labelling, resume, the generation settings.

The raw dataset layout it writes is tested in ``tests/vgn_data/test_raw_dataset.py``."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sim_worker.datagen import DataGenConfig, grasp_frame, middle_of_widest_run
from sim_worker.gripper import GRIPPER_VERSION
from vgn_data.dataset import RawDataset


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


def test_answer_labels_are_the_services_plain_answers_tried_as_answered(server):
    """``answer_grasps``: after the point labels come rows for the service's own plain answers, each at
    the pose answered, with the label a replay of that pose gives; another model's answers are refused."""
    from client.http import VGNClient
    from sim_worker.datagen import SceneLabeller
    from sim_worker.grasping import execute_grasp

    with VGNClient(server.url) as vgn:
        model = vgn.model().model_id
        config = DataGenConfig(scene="pile", objects=("blocks",), points_per_scene=3, answer_grasps=5,
                               answer_threshold=0.0, answer_model=model, renderer="tiny")  # fmt: skip
        labeller = SceneLabeller(vgn, config)
        try:
            index, labelled = next(
                (i, found) for i in range(6) if (found := labeller.label_scene(i)) is not None
            )
            rows = labelled[1]
            answers = rows[3:]
            assert 1 <= len(answers) <= 5, "some of the random network's many answers, at most answer_grasps"
            answered = vgn.grasps(labeller.session_id, threshold=0.0, turn_average=False, clearance=False,
                                  grip=False).grasps  # fmt: skip
            poses = np.array([g.as_matrix() for g in answered])
            labeller.builder.build(index)  # the scene as it stood before its trials
            state = labeller.world.save_state()
            for row in answers:
                pose = np.eye(4)
                pose[:3, :3] = Rotation.from_quat(row[:4]).as_matrix()
                pose[:3, 3] = row[4:7]
                match = np.abs(poses - pose).max(axis=(1, 2)).min()
                assert match < 1e-5, "each answer row is an answered pose, orientation included"
                labeller.world.restore_state(state)
                trial = execute_grasp(labeller.world, labeller.gripper, pose, allow_contact=False,
                                      remove_grasped=False, fast=True)  # fmt: skip
                assert trial.label == row[8]
        finally:
            labeller.close()
        other = SceneLabeller(vgn, dataclasses.replace(config, answer_model="0" * 12))
        try:
            with pytest.raises(RuntimeError, match="answers with model"):
                for index in range(6):
                    other.label_scene(index)
        finally:
            other.close()


def test_answer_runs_record_the_answering_model_and_resume_only_with_it(server, tmp_path: Path):
    out = tmp_path / "data"
    command = [sys.executable, "-m", "client.cli", "generate-data", "--sim", "--url", server.url, "--scene", "pile",
               "--objects", "blocks", "--points", "4", "--answer-grasps", "3", "--answer-threshold", "0",
               "--renderer", "tiny", "--out", str(out)]  # fmt: skip
    first = subprocess.run([*command, "--scenes", "1"], capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    generation = json.loads((out / "generation.json").read_text())
    from client.http import VGNClient

    with VGNClient(server.url) as vgn:
        assert generation["answer_model"] == vgn.model().model_id
    assert (generation["answer_grasps"], generation["answer_threshold"]) == (3, 0.0)
    generation["answer_model"] = "0" * 12
    (out / "generation.json").write_text(json.dumps(generation))
    refused = subprocess.run([*command, "--scenes", "2"], capture_output=True, text=True, timeout=300)
    assert refused.returncode == 2 and "other settings (answer_model)" in refused.stderr
    plain = DataGenConfig().recorded()
    assert not any(key.startswith("answer") for key in plain), "folders made without answers still resume"
