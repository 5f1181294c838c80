"""Runs with another hand: ``generate-data --gripper`` labels with it and records it, clear-scene and
the benchmark execute with it and name it to the service, and folders of the franka hand resume."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.clutter import combinations, markdown_table, parse_args, scenario_config
from sim_worker.clutter import ClutterConfig, ClutterRemoval
from sim_worker.datagen import DataGenConfig
from sim_worker.generate_data import _check_settings
from vgn_contract.gripper_description import (
    GripperDescriptionError,
    builtin_gripper,
    check_version,
    default_gripper,
)
from vgn_data.dataset import RawDataset

ROBOTIQ = builtin_gripper("robotiq-2f85")


def test_generate_data_with_the_robotiq_hand_labels_and_records_it(server, tmp_path: Path):
    """The service plans for franka only: a run that labels no answers asks it for no hand."""
    out = tmp_path / "data"
    command = [sys.executable, "-m", "client.cli", "generate-data", "--sim", "--url", server.url, "--gripper",
               "robotiq-2f85", "--scene", "pile", "--objects", "blocks", "--scenes", "1", "--points", "4",
               "--renderer", "tiny", "--out", str(out)]  # fmt: skip
    env = {**os.environ, "VGN_CACHE_DIR": str(tmp_path / "cache")}
    run = subprocess.run(command, capture_output=True, text=True, timeout=600, env=env)
    assert run.returncode == 0, run.stderr
    generation = json.loads((out / "generation.json").read_text())
    assert generation["gripper"] == "robotiq-2f85-v1", "the label training reads: not franka's"
    assert (generation["gripper_name"], generation["gripper_digest"]) == ("robotiq-2f85", ROBOTIQ.digest)
    setup = json.loads((out / "setup.json").read_text())
    assert (setup["max_opening_width"], setup["finger_depth"]) == (0.085, 0.04)
    ids, grasps = RawDataset(out).grasps()
    assert len(grasps) == 4 and set(grasps[:, 8]) <= {0.0, 1.0}
    assert np.all(grasps[:, 7] <= 0.085 + 1e-9), "widths within the robotiq hand's stroke"
    assert list((tmp_path / "cache" / "grippers").glob("robotiq-2f85-*.urdf"))


def test_a_franka_folder_from_before_the_digest_resumes_and_then_holds_it(tmp_path: Path):
    config = DataGenConfig()
    (tmp_path / "generation.json").write_text(json.dumps(config.recorded() | {"gripper": "franka-v2"}))
    assert _check_settings(tmp_path, config) == 0
    generation = json.loads((tmp_path / "generation.json").read_text())
    assert (generation["gripper_name"], generation["gripper_digest"]) == ("franka", default_gripper().digest)
    assert _check_settings(tmp_path, config) == 0, "and resumes again"
    other = default_gripper().model_copy(update={"opening": ROBOTIQ.opening})  # franka-v2, another hand
    generation["gripper_digest"] = other.digest
    (tmp_path / "generation.json").write_text(json.dumps(generation))
    assert _check_settings(tmp_path, config) == 2, "a recorded digest must match"


def test_a_robotiq_folder_is_never_resumed_with_franka(tmp_path: Path):
    assert _check_settings(tmp_path, DataGenConfig(hand=ROBOTIQ)) == 0
    assert _check_settings(tmp_path, DataGenConfig()) == 2


def test_another_hand_may_not_borrow_a_built_in_version():
    check_version(ROBOTIQ)
    borrowed = ROBOTIQ.model_copy(update={"name": "mine", "version": "franka-v2"})
    with pytest.raises(GripperDescriptionError, match="version of its own"):
        check_version(borrowed)


class Sessions:
    """Records the sessions a clutter run opens; nothing else is asked of it here."""

    def __init__(self) -> None:
        self.created: list[dict] = []

    def create_session(self, **options: object) -> SimpleNamespace:
        self.created.append(options)
        return SimpleNamespace(session_id=f"s{len(self.created)}")

    def delete_session(self, session_id: str) -> None:
        pass


def test_a_clutter_run_executes_with_its_hand_and_names_it_to_the_service(tmp_path: Path, monkeypatch):
    monkeypatch.setenv("VGN_CACHE_DIR", str(tmp_path))  # the blocks and the built hand
    service = Sessions()
    episode = ClutterRemoval(ClutterConfig(renderer="tiny", hand=ROBOTIQ), service, results=None)
    try:
        assert episode.gripper.spec.hand is ROBOTIQ and episode.gripper.opening() == pytest.approx(0.085)
        episode.new_scene(0)
        assert episode.gripper.spec.hand is ROBOTIQ, "a new scene keeps the hand"
    finally:
        episode.close()
    assert service.created == [{"intrinsics": service.created[0]["intrinsics"], "gripper": "robotiq-2f85"}]


def test_a_clutter_run_records_a_hand_other_than_franka():
    assert "gripper" not in ClutterConfig().as_json(), "franka folders of earlier runs still resume"
    recorded = ClutterConfig(hand=ROBOTIQ).as_json()
    assert (recorded["gripper"], recorded["gripper_digest"]) == ("robotiq-2f85", ROBOTIQ.digest)


def test_the_benchmark_takes_the_hand_and_keeps_its_runs_apart(tmp_path: Path):
    args = parse_args(["--gripper", "robotiq-2f85", "--planners", "antipodal", "--selections", "best",
                       "--scenarios", "pile-5", "--no-turn-average", "--no-clearance", "--no-grip",
                       "--out", str(tmp_path)])  # fmt: skip
    assert scenario_config(args, "antipodal", "best", "pile-5").hand == ROBOTIQ
    ((*_, folder),) = combinations(args)
    assert folder.name == "antipodal-best-pile-5-robotiq-2f85"
    assert "gripper robotiq-2f85" in markdown_table([], args).splitlines()[0]
    assert parse_args([]).gripper == default_gripper()
