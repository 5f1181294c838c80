"""The one-view network (``VGN_ONE_VIEW_MODEL``): a real server answers grasp requests on a volume
fused from one frame with it, and from two frames on with the main network, over HTTP and gRPC;
``/model`` names it; ``none`` turns it off; weights that cannot be loaded stop the start-up."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest
from safetensors.torch import load_file, save_file

from client.grpc_client import GRPCClient
from client.http import VGNClient
from service.core import PlanningService
from service.launch.embedded import EmbeddedService
from service.settings import NO_MODEL, Settings
from service.vgn.checkpoint import CheckpointError, card_path, weights_id
from tests.helpers.scenes import INTRINSICS, BoxScene, circle_views

SCENE = BoxScene()
POSES = circle_views(2)
DEPTHS = [SCENE.depth(pose) for pose in POSES]
#: The one-view card's operating threshold (the main weights have no card: VGN's 0.9).
ONE_VIEW_THRESHOLD = 0.65
#: No check, so no fallback: the answer's threshold is the network's own.
UNCHECKED = {"clearance": False, "grip": False}
#: robotiq-2f85 is served by the main network here (its packaged network off), as a hand of the main network's.
ENV = {"VGN_API_KEY": "", "VGN_TORCH_THREADS": "1", "VGN_NETWORK_GRIPPERS": '["franka", "robotiq-2f85"]',
       "VGN_HAND_MODELS": '{"robotiq-2f85": "none"}'}  # fmt: skip


@pytest.fixture(scope="module")
def one_view_weights(random_checkpoint: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The main weights with one tensor changed (another weights id), with a card naming a threshold."""
    tensors = load_file(str(random_checkpoint))
    tensors["conv_qual.bias"] = tensors["conv_qual.bias"] + 0.01
    path = tmp_path_factory.mktemp("one-view") / "one-view.safetensors"
    save_file(tensors, str(path))
    card_path(path).write_text(json.dumps({"threshold": ONE_VIEW_THRESHOLD}))
    assert weights_id(path) != weights_id(random_checkpoint)
    return path


@pytest.fixture(scope="module")
def service(random_checkpoint: Path, one_view_weights: Path) -> Iterator[EmbeddedService]:
    env = ENV | {"VGN_ONE_VIEW_MODEL": str(one_view_weights)}
    with EmbeddedService(model=random_checkpoint, env=env, grpc=True) as running:
        yield running


def answers_by_frames(client: VGNClient | GRPCClient, gripper: str | None = None) -> list[tuple[str, float]]:
    """(model, threshold) of the answers after the first frame and after the second."""
    session_id = client.create_session(intrinsics=INTRINSICS, gripper=gripper).session_id
    answers = []
    for depth, pose in zip(DEPTHS, POSES, strict=True):
        client.add_frame(session_id, depth, pose)
        answer = client.grasps(session_id, **UNCHECKED)
        answers.append((answer.model, answer.threshold))
    client.delete_session(session_id)
    return answers


def test_one_frame_is_the_one_view_networks_and_two_the_main_ones(
    clients, random_checkpoint, one_view_weights
):
    main, one_view = weights_id(random_checkpoint), weights_id(one_view_weights)
    for client in clients:
        assert answers_by_frames(client) == [(one_view, ONE_VIEW_THRESHOLD), (main, 0.9)], type(client)


def test_a_request_threshold_and_the_checks_apply_to_the_one_view_network_alike(clients, one_view_weights):
    http, _ = clients
    session_id = http.create_session(intrinsics=INTRINSICS).session_id
    http.add_frame(session_id, DEPTHS[0], POSES[0])
    named = http.grasps(session_id, threshold=0.3, **UNCHECKED)
    assert (named.model, named.threshold) == (weights_id(one_view_weights), 0.3)
    checked = http.grasps(session_id)
    assert checked.model in (weights_id(one_view_weights), "antipodal")
    assert checked.grip_dropped is None, "one frame: no grip check, whichever network"


def test_other_hands_get_the_main_network(clients, random_checkpoint):
    main = weights_id(random_checkpoint)
    for client in clients:
        assert answers_by_frames(client, gripper="robotiq-2f85") == [(main, 0.9), (main, 0.9)]


def test_the_model_reports_the_one_view_network_over_http_and_grpc(clients, one_view_weights):
    http, rpc = clients
    info = http.model()
    assert info.one_view is not None
    assert (info.one_view.model_id, info.one_view.source) == (
        weights_id(one_view_weights),
        str(one_view_weights),
    )
    assert (info.one_view.threshold, info.one_view.gripper) == (ONE_VIEW_THRESHOLD, "franka")
    assert info.one_view.card is not None and info.one_view.card["threshold"] == ONE_VIEW_THRESHOLD
    assert info.defaults is not None and info.defaults.threshold == 0.9
    assert rpc.model().one_view == info.one_view


def test_a_track_stream_changes_network_with_its_second_frame(clients, random_checkpoint, one_view_weights):
    _, rpc = clients
    session_id = rpc.create_session(intrinsics=INTRINSICS).session_id
    updates = list(rpc.track(session_id, zip(DEPTHS, POSES, strict=True), **UNCHECKED))
    assert [u.model for u in updates] == [weights_id(one_view_weights), weights_id(random_checkpoint)]


def test_none_leaves_every_volume_to_the_main_network(random_checkpoint):
    env = ENV | {"VGN_ONE_VIEW_MODEL": NO_MODEL}
    with EmbeddedService(model=random_checkpoint, env=env) as running, VGNClient(running.url) as http:
        main = weights_id(random_checkpoint)
        assert answers_by_frames(http) == [(main, 0.9), (main, 0.9)]
        assert http.model().one_view is None


# Settings ------------------------------------------------------------------------------------------
def test_the_setting_chooses_as_the_main_models_does(monkeypatch, tmp_path: Path, random_checkpoint):
    packaged = tmp_path / "vgn-one-view.safetensors"
    monkeypatch.setattr("service.settings.PACKAGED_ONE_VIEW_MODEL", packaged)
    monkeypatch.setenv("VGN_MODEL", str(random_checkpoint))
    monkeypatch.delenv("VGN_ONE_VIEW_MODEL", raising=False)
    assert Settings().one_view_model_path() is None, "no packaged one-view weights: none"
    packaged.write_bytes(b"")
    assert Settings().one_view_model_path() == packaged, "the packaged weights, where they ship"
    monkeypatch.setenv("VGN_ONE_VIEW_MODEL", "")
    assert Settings().one_view_model_path() == packaged, "empty is unset"
    monkeypatch.setenv("VGN_ONE_VIEW_MODEL", "None")
    assert Settings().one_view_model_path() is None
    monkeypatch.setenv("VGN_ONE_VIEW_MODEL", str(tmp_path / "mine.safetensors"))
    assert Settings().one_view_model_path() == tmp_path / "mine.safetensors"
    monkeypatch.setenv("VGN_MODEL", "none")
    assert Settings().one_view_model_path() is None, "it stands in for a main network only"


def test_weights_that_cannot_be_loaded_stop_the_start_up_naming_the_setting(
    tmp_path: Path, random_checkpoint
):
    missing = tmp_path / "missing.safetensors"
    settings = Settings(model=random_checkpoint, one_view_model=missing, api_key=None)
    with pytest.raises(
        CheckpointError, match=r"VGN_ONE_VIEW_MODEL: weights file .*missing.safetensors does not exist"
    ):
        PlanningService.from_settings(settings)
    garbage = tmp_path / "garbage.safetensors"
    garbage.write_bytes(b"not a safetensors file")
    env = ENV | {"VGN_ONE_VIEW_MODEL": str(garbage)}
    with pytest.raises(RuntimeError, match=r"VGN_ONE_VIEW_MODEL: cannot read weights from .*garbage"):
        EmbeddedService(model=random_checkpoint, env=env).start()


def test_the_two_networks_take_turns_on_the_same_lanes(random_checkpoint, one_view_weights):
    core = PlanningService.from_settings(
        Settings(model=random_checkpoint, one_view_model=one_view_weights, api_key=None)
    )
    try:
        assert core.one_view is not None and core.one_view.lanes == core.planner.lanes
        assert core.one_view._turn is core.planner._turn
        assert core.one_view._lane_pool is core.planner._lane_pool
    finally:
        core.close()
