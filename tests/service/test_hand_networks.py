"""Each hand's own network (``VGN_HAND_MODELS``): a real server answers a hand's sessions with its
network whatever their frame count, at its card's threshold, and every other hand's with the main
one, over HTTP and gRPC; ``/grippers`` and ``/model`` report it; ``none`` turns a packaged one off;
an unknown hand, weights that cannot be loaded and a card of another hand stop the start-up."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from safetensors.torch import load_file, save_file

from service.core import PlanningService
from service.errors import GripperNotServed
from service.launch.embedded import EmbeddedService
from service.settings import Settings
from service.vgn.checkpoint import CheckpointError, card_path, weights_id
from tests.helpers.scenes import INTRINSICS
from tests.service.test_one_view import DEPTHS, POSES, answers_by_frames
from vgn_contract.gripper_description import builtin_gripper
from vgn_contract.schemas import SessionCreate

HAND = "robotiq-2f85"
#: The hand network's card: its operating threshold (the main weights have no card: VGN's 0.9).
HAND_THRESHOLD = 0.7
#: The hand is also among the main network's: its own network wins.
ENV = {"VGN_API_KEY": "", "VGN_TORCH_THREADS": "1", "VGN_NETWORK_GRIPPERS": f'["franka", "{HAND}"]'}


def hand_weights_at(folder: Path, random_checkpoint: Path, card: dict, name: str = "hand") -> Path:
    """The main weights with one tensor changed (another weights id), with ``card`` beside them."""
    tensors = load_file(str(random_checkpoint))
    tensors["conv_qual.bias"] = tensors["conv_qual.bias"] - 0.01
    path = folder / f"{name}.safetensors"
    save_file(tensors, str(path))
    card_path(path).write_text(json.dumps(card))
    return path


@pytest.fixture(scope="module")
def hand_weights(random_checkpoint: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    card = {"threshold": HAND_THRESHOLD, "gripper": builtin_gripper(HAND).version}
    path = hand_weights_at(tmp_path_factory.mktemp("hand"), random_checkpoint, card)
    assert weights_id(path) != weights_id(random_checkpoint)
    return path


@pytest.fixture(scope="module")
def service(random_checkpoint: Path, hand_weights: Path) -> Iterator[EmbeddedService]:
    env = ENV | {"VGN_HAND_MODELS": json.dumps({HAND: str(hand_weights)})}
    with EmbeddedService(model=random_checkpoint, env=env, grpc=True) as running:
        yield running


def test_a_hands_sessions_get_its_own_network_and_the_others_the_main_one(
    clients, random_checkpoint, hand_weights
):
    main, own = weights_id(random_checkpoint), weights_id(hand_weights)
    for client in clients:
        assert answers_by_frames(client, HAND) == [(own, HAND_THRESHOLD)] * 2, type(client)
        assert answers_by_frames(client) == [(main, 0.9)] * 2, type(client)


def test_grippers_and_model_report_the_hand_network_over_http_and_grpc(
    clients, random_checkpoint, hand_weights
):
    http, rpc = clients
    listed = {g.name: (g.network, g.threshold) for g in http.grippers().grippers}
    assert listed == {
        "franka": (weights_id(random_checkpoint), 0.9),
        HAND: (weights_id(hand_weights), HAND_THRESHOLD),
    }
    assert rpc.grippers() == http.grippers()
    info = http.model()
    [network] = info.hand_models
    assert (network.gripper, network.model_id, network.source, network.threshold) == (
        HAND,
        weights_id(hand_weights),
        str(hand_weights),
        HAND_THRESHOLD,
    )
    assert network.card is not None and network.card["gripper"] == "robotiq-2f85-v1"
    assert info.hand_model(HAND) == network and info.hand_model("franka") is None
    assert info.defaults is not None and info.defaults.threshold == 0.9, "the main network's"
    assert rpc.model().hand_models == info.hand_models


def test_clear_scene_records_the_network_that_answers_its_hand(clients, random_checkpoint, hand_weights):
    """config.json names the hand network and its threshold, and its answers pass the record's check;
    the default hand's record is the main network's, as before."""
    from sim_worker.clear_scene import resolve_planner
    from sim_worker.clutter import ClutterConfig, check_answer

    http, _ = clients
    config = resolve_planner(ClutterConfig(hand=builtin_gripper(HAND)), http)
    recorded = config.as_json()
    assert (recorded["model"], recorded["threshold"], recorded["gripper"]) == (
        weights_id(hand_weights),
        HAND_THRESHOLD,
        HAND,
    )
    assert "one_view_model" not in recorded
    session_id = http.create_session(intrinsics=INTRINSICS, gripper=HAND).session_id
    http.add_frame(session_id, DEPTHS[0], POSES[0])
    check_answer(config, http.grasps(session_id, **config.grasp_options()))
    http.delete_session(session_id)
    franka = resolve_planner(ClutterConfig(), http).as_json()
    assert (franka["model"], franka["threshold"], "gripper" in franka) == (
        weights_id(random_checkpoint),
        0.9,
        False,
    )


# Packaged networks and start-up ---------------------------------------------------------------------
@pytest.fixture
def packaged(monkeypatch, tmp_path: Path, random_checkpoint: Path) -> Path:
    """A packaged network for the hand whose card does not record the hand (accepted)."""
    monkeypatch.setattr("service.settings.PACKAGED_HAND_MODELS", tmp_path)
    return hand_weights_at(tmp_path, random_checkpoint, {"threshold": HAND_THRESHOLD}, name=HAND)


def test_a_packaged_hand_network_serves_its_hand_unless_turned_off(packaged: Path, random_checkpoint):
    core = PlanningService.from_settings(Settings(model=random_checkpoint, api_key=None))
    try:
        assert core.hand_networks[HAND].source == str(packaged)
        assert core.create_session(SessionCreate(gripper=HAND)).gripper == HAND
    finally:
        core.close()
    core = PlanningService.from_settings(
        Settings(model=random_checkpoint, api_key=None, hand_models={HAND: "None"})
    )
    try:
        assert core.hand_networks == {} and core.model_info().hand_models == []
        with pytest.raises(GripperNotServed, match="hands with a network: franka"):
            core.create_session(SessionCreate(gripper=HAND))
    finally:
        core.close()


def test_the_setting_chooses_as_the_main_models_does(monkeypatch, packaged: Path, random_checkpoint):
    hands = ("franka", HAND)
    monkeypatch.setenv("VGN_MODEL", str(random_checkpoint))
    monkeypatch.delenv("VGN_HAND_MODELS", raising=False)
    assert Settings().hand_model_paths(hands) == {HAND: packaged}, "the packaged one, where it ships"
    monkeypatch.setenv("VGN_HAND_MODELS", json.dumps({HAND: ""}))
    assert Settings().hand_model_paths(hands) == {HAND: packaged}, "empty is unset"
    monkeypatch.setenv("VGN_HAND_MODELS", json.dumps({HAND: "none", "franka": "/m/franka.safetensors"}))
    assert Settings().hand_model_paths(hands) == {"franka": Path("/m/franka.safetensors")}
    monkeypatch.setenv("VGN_MODEL", "none")
    assert Settings().hand_model_paths(hands) == {}, "not without a main network"


def test_an_unknown_hand_stops_the_start_up_naming_the_setting(random_checkpoint, hand_weights):
    settings = Settings(model=random_checkpoint, api_key=None, hand_models={"schunk-egp": hand_weights})
    with pytest.raises(ValueError, match=r"VGN_HAND_MODELS names unknown hands \['schunk-egp'\]; known: "):
        PlanningService.from_settings(settings)


def test_weights_that_cannot_be_loaded_stop_the_start_up_naming_the_setting_and_hand(
    tmp_path: Path, random_checkpoint
):
    missing = tmp_path / "missing.safetensors"
    settings = Settings(model=random_checkpoint, api_key=None, hand_models={HAND: missing})
    with pytest.raises(
        CheckpointError, match=rf"VGN_HAND_MODELS: {HAND}: weights file .*missing.safetensors does not exist"
    ):
        PlanningService.from_settings(settings)
    garbage = tmp_path / "garbage.safetensors"
    garbage.write_bytes(b"not a safetensors file")
    env = ENV | {"VGN_HAND_MODELS": json.dumps({HAND: str(garbage)})}
    with pytest.raises(RuntimeError, match=rf"VGN_HAND_MODELS: {HAND}: cannot read weights from .*garbage"):
        EmbeddedService(model=random_checkpoint, env=env).start()


def test_a_card_of_another_hand_stops_the_start_up_naming_both(tmp_path: Path, random_checkpoint):
    franka_data = hand_weights_at(tmp_path, random_checkpoint, {"threshold": 0.8, "gripper": "franka-v2"})
    settings = Settings(model=random_checkpoint, api_key=None, hand_models={HAND: franka_data})
    with pytest.raises(
        CheckpointError, match=r"VGN_HAND_MODELS: robotiq-2f85: .*'franka-v2'.*'robotiq-2f85-v1'"
    ):
        PlanningService.from_settings(settings)


def test_the_networks_take_turns_on_the_same_lanes(random_checkpoint, hand_weights):
    core = PlanningService.from_settings(
        Settings(model=random_checkpoint, api_key=None, hand_models={HAND: hand_weights})
    )
    try:
        network = core.hand_networks[HAND]
        assert network._turn is core.planner._turn and network._lane_pool is core.planner._lane_pool
    finally:
        core.close()


def test_a_simulated_clear_scene_run_records_the_hand_network(service, hand_weights, tmp_path: Path):
    """``clear-scene --sim --gripper`` through the service: one round of one object, the real hand."""
    from tests.helpers.runs import check_results, clear_scene

    results = tmp_path / "run"
    run = clear_scene("--url", service.url, "--gripper", HAND, "--rounds", "1", "--object-count", "1",
                      "--results", str(results))  # fmt: skip
    assert run.returncode == 0, run.stderr
    check_results(results, 1)
    config = json.loads((results / "config.json").read_text())
    assert (config["model"], config["threshold"], config["gripper"]) == (
        weights_id(hand_weights),
        HAND_THRESHOLD,
        HAND,
    )


def test_answer_labelling_for_the_hand_labels_its_networks_answers(service, hand_weights, tmp_path: Path):
    """``generate-data --answer-grasps --gripper``: the answers it labels come from the hand's network,
    which generation.json records."""
    out = tmp_path / "data"
    command = [sys.executable, "-m", "client.cli", "generate-data", "--sim", "--url", service.url, "--gripper", HAND,
               "--scene", "pile", "--objects", "blocks", "--points", "4", "--answer-grasps", "3",
               "--answer-threshold", "0", "--renderer", "tiny", "--scenes", "1", "--out", str(out)]  # fmt: skip
    run = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert json.loads((out / "generation.json").read_text())["answer_model"] == weights_id(hand_weights)
