"""The model that ships in the package: the service loads it when nothing else is configured,
it carries a card that belongs to it, and it clears a simulated table out of the box."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from service.core import PlanningService
from service.planner import GraspPlanner
from service.settings import PACKAGED_HAND_MODELS, PACKAGED_MODEL, Settings
from service.vgn.checkpoint import card_path, weights_id
from tests.helpers.apps import serve
from tests.helpers.frames import frame_files, meta_json
from tests.helpers.runs import check_results, clear_scene
from tests.helpers.scenes import INTRINSICS, TABLE_Z, BoxScene, circle_views
from vgn_contract.gripper_description import builtin_gripper


def fused_session(http: TestClient, session_id: str, scene: BoxScene) -> str:
    """A session that fused six views of ``scene`` around the workspace."""
    created = http.post("/sessions", json={"session_id": session_id, "intrinsics": INTRINSICS.model_dump()})
    assert created.status_code == 201, created.text
    for pose in circle_views(6):
        files = frame_files(meta_json({"matrix": pose.tolist()}), scene.depth(pose).astype("<f4").tobytes())
        answer = http.post(f"/sessions/{session_id}/frames", files=files)
        assert answer.status_code == 200, answer.text
    return session_id


def test_the_service_loads_the_packaged_model_by_default(monkeypatch):
    monkeypatch.delenv("VGN_MODEL", raising=False)
    assert PACKAGED_MODEL.is_file(), "the package ships trained weights"
    assert Settings().model_path() == PACKAGED_MODEL
    with serve(PACKAGED_MODEL) as http:
        model = http.get("/model").json()
    assert model["loaded"] and model["source"] == str(PACKAGED_MODEL) and model["card"]["matches_weights"]


def test_the_packaged_model_grasps_a_box_and_not_an_empty_table():
    with serve(PACKAGED_MODEL) as http:
        box = fused_session(http, "box", BoxScene())
        grasps = http.get(f"/sessions/{box}/grasps").json()["grasps"]
        assert grasps, "a lone 8 x 6 x 6 cm box is graspable"
        # The origin is between the finger bases (docs/conventions.md): up to a finger depth from the contacts.
        x, y, z = grasps[0]["position"]
        assert 0.09 <= x <= 0.21 and 0.10 <= y <= 0.20 and TABLE_Z < z <= TABLE_Z + 0.11, (
            "the best grasp is at the box"
        )
        empty = fused_session(
            http, "empty", BoxScene(lower=(2.0, 2.0, TABLE_Z), upper=(2.01, 2.01, TABLE_Z + 0.01))
        )
        assert http.get(f"/sessions/{empty}/grasps").json()["grasps"] == [], (
            "nothing to grasp on a bare table"
        )


def test_the_packaged_card_belongs_to_the_weights_and_says_how_to_rebuild_them():
    card = json.loads(card_path(PACKAGED_MODEL).read_text())
    assert card["model"]["weights_id"] == weights_id(PACKAGED_MODEL)
    assert sum(d["scenes"] for d in card["datasets"]) >= 1000, "trained on at least 1,000 scenes"
    assert 0.0 < card["threshold"] <= 1.0
    assert card["command"].startswith("vgn-train ")
    steps = "\n".join(card["reproduce"])
    for step in ("object_split", "generate-data", "vgn-train"):
        assert step in steps, f"the card's reproduce steps lack {step}"
    assert "vgn-data pack" in steps or "vgn-pack-data" in steps, "the card's reproduce steps lack packing"
    shards = [shard for data in card["packed_data"] for shard in data["shards"]]
    assert shards and all(len(shard["sha256"]) == 64 for shard in shards), "the card names its shards by hash"
    assert card["history"][-1]["steps"] > 0, "the card counts the optimizer steps"
    assert card["executed_grasps"]["rounds"] > 0, "the card says how the model grasped held-out objects"


def test_the_shards_the_packaged_model_learned_from_can_be_found():
    """The card names its data by sha256: each shard is in ``data/`` unchanged, or was converted to
    scene recipes, is recorded as such in the manifest and comes back unchanged from the history."""
    import subprocess

    from training.verify_recipes import grids_from_history

    card = json.loads(card_path(PACKAGED_MODEL).read_text())
    repository = PACKAGED_MODEL.parents[2]
    for data in card["packed_data"]:
        folder = repository / data["folder"]
        manifest = json.loads((folder / "manifest.json").read_text())
        migrated = {
            name for record in manifest.get("migration", {}).values() for name in record["grid_shards"]
        }
        gone = []
        for shard in data["shards"]:
            path = folder / shard["file"]
            if path.is_file():
                assert hashlib.sha256(path.read_bytes()).hexdigest() == shard["sha256"], f"{path} changed"
            else:
                assert shard["file"] in migrated, f"{path} is missing and was not converted to recipes"
                gone.append(shard)
        inside_git = (
            subprocess.run(["git", "-C", str(folder), "rev-parse"], capture_output=True).returncode == 0
        )
        if gone and inside_git:
            found = grids_from_history(folder, [gone[0]["file"]])
            assert found is not None, "the converted grid shards are not in the repository's history"
            restored = found.root / gone[0]["file"]
            assert hashlib.sha256(restored.read_bytes()).hexdigest() == gone[0]["sha256"]


def test_clear_scene_out_of_the_box(tmp_path: Path, monkeypatch):
    """The README's first command, short: no --model, no --threshold, an embedded service."""
    monkeypatch.delenv("VGN_MODEL", raising=False)
    monkeypatch.setenv("VGN_TORCH_THREADS", "1")
    results = tmp_path / "blocks"
    run = clear_scene("--scene", "blocks", "--rounds", "2", "--object-count", "3", "--results", str(results))
    assert run.returncode == 0, run.stderr
    summary = check_results(results, 2)
    config = json.loads((results / "config.json").read_text())
    assert (
        config["model"] == weights_id(PACKAGED_MODEL)
        and config["threshold"] == GraspPlanner.from_path(PACKAGED_MODEL, device="cpu").default_threshold
    )
    assert summary["successes"] >= 2, "the trained model removes objects from a simulated table"


def packaged_hand_networks() -> list[Path]:
    """The hand networks the package ships (``service/models/grippers/<hand>.safetensors``)."""
    return sorted(PACKAGED_HAND_MODELS.glob("*.safetensors"))


@pytest.mark.parametrize("weights", packaged_hand_networks(), ids=lambda path: path.stem)
def test_a_packaged_hand_network_belongs_to_its_hand_and_its_data(weights: Path):
    """Its card names its weights, the hand whose trials labelled its data (the description's
    version) and the shards of that data, each in the repository unchanged, and says how to rebuild it."""
    card = json.loads(card_path(weights).read_text())
    assert card["model"]["weights_id"] == weights_id(weights)
    assert card["gripper"] == builtin_gripper(weights.stem).version
    assert 0.0 < card["threshold"] <= 1.0 and card["command"].startswith("vgn-train ")
    steps = "\n".join(card["reproduce"])
    for step in (f"generate-data --sim --gripper {weights.stem}", "vgn-data pack", "vgn-train", "--init"):
        assert step in steps, f"the card's reproduce steps lack {step}"
    repository = PACKAGED_MODEL.parents[2]
    for data in card["packed_data"]:
        folder = repository / data["folder"]
        assert json.loads((folder / "manifest.json").read_text())["gripper"] == card["gripper"]
        for shard in data["shards"]:
            path = folder / shard["file"]
            assert hashlib.sha256(path.read_bytes()).hexdigest() == shard["sha256"], f"{path} changed"
    assert card["executed_grasps"]["rounds"] > 0, "the card says how the network grasped held-out objects"


@pytest.mark.parametrize("weights", packaged_hand_networks(), ids=lambda path: path.stem)
def test_the_service_serves_a_packaged_hand_network_by_default(weights: Path):
    service = PlanningService.from_settings(Settings(api_key=None, grpc_port=0))
    try:
        served = service.served_by(weights.stem)
        assert served is not None and served.model_id == weights_id(weights)
        assert served.default_threshold == json.loads(card_path(weights).read_text())["threshold"]
    finally:
        service.close()
