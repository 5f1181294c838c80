"""The VGN network's architecture and safe weight loading."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from service.planner import GraspPlanner
from service.vgn.checkpoint import CheckpointError, load_vgn, save_vgn, weights_id
from service.vgn.network import PARAMETER_COUNT, VGN

VGN_KEYS = {
    f"{layer}.{kind}"
    for layer in (
        "encoder.conv1",
        "encoder.conv2",
        "encoder.conv3",
        "decoder.conv1",
        "decoder.conv2",
        "decoder.conv3",
        "conv_qual",
        "conv_rot",
        "conv_width",
    )
    for kind in ("weight", "bias")
}


def test_architecture_matches_vgn():
    network = VGN()
    assert sum(p.numel() for p in network.parameters()) == PARAMETER_COUNT == 313_238
    assert set(network.state_dict()) == VGN_KEYS
    assert network.encoder.conv1.weight.shape == (16, 1, 5, 5, 5)
    assert network.conv_rot.weight.shape == (4, 16, 5, 5, 5)


@pytest.mark.parametrize("resolution", [40, 48])
def test_output_shapes_and_ranges(resolution):
    torch.manual_seed(1)
    with torch.inference_mode():
        quality, rotation, width = VGN()(torch.rand(2, 1, resolution, resolution, resolution))
    assert quality.shape == width.shape == (2, 1, resolution, resolution, resolution)
    assert rotation.shape == (2, 4, resolution, resolution, resolution)
    assert quality.min() >= 0 and quality.max() <= 1
    assert torch.allclose(rotation.norm(dim=1), torch.ones(()), atol=1e-5)


def test_safetensors_round_trip(tmp_path: Path):
    network = VGN()
    path = tmp_path / "w.safetensors"
    save_vgn(network, path)
    loaded = load_vgn(path)
    for key, value in network.state_dict().items():
        assert torch.equal(loaded.state_dict()[key], value)
    assert not loaded.training
    assert len(weights_id(path)) == 12


@pytest.mark.parametrize("wrapped", [False, True])
def test_pytorch_state_dict_loads(tmp_path: Path, wrapped: bool):
    network = VGN()
    path = tmp_path / "w.pt"
    state = network.state_dict()
    torch.save({"state_dict": state} if wrapped else state, path)
    assert torch.equal(load_vgn(path).conv_qual.weight, network.conv_qual.weight)


class Payload:
    """Any pickled object but tensors must be refused (weights_only)."""

    def __reduce__(self):
        return (print, ("this must never run",))


def test_the_weights_format_read_is_logged(tmp_path: Path, caplog: pytest.LogCaptureFixture):
    network = VGN()
    safetensors, state_dict = tmp_path / "w.safetensors", tmp_path / "w.pt"
    save_vgn(network, safetensors)
    torch.save(network.state_dict(), state_dict)
    with caplog.at_level("INFO", logger="service.vgn.checkpoint"):
        load_vgn(safetensors)
        load_vgn(state_dict)
    messages = [r.getMessage() for r in caplog.records if r.name == "service.vgn.checkpoint"]
    assert messages == [
        f"reading weights {safetensors} as safetensors",
        f"reading weights {state_dict} as a PyTorch state_dict (tensors only, no pickled code)",
    ]


def test_arbitrary_pickles_are_refused(tmp_path: Path):
    path = tmp_path / "evil.pt"
    torch.save({"encoder.conv1.weight": Payload()}, path)
    with pytest.raises(CheckpointError, match="cannot read weights"):
        load_vgn(path)


def test_mismatched_weights_are_refused(tmp_path: Path):
    state = VGN().state_dict()
    state["conv_qual.weight"] = torch.zeros(2, 16, 5, 5, 5)
    path = tmp_path / "bad.pt"
    torch.save(state, path)
    with pytest.raises(CheckpointError, match="does not fit the VGN architecture"):
        load_vgn(path)
    del state["conv_qual.weight"]
    torch.save(state, path)
    with pytest.raises(CheckpointError, match="conv_qual.weight"):
        load_vgn(path)


@pytest.mark.parametrize(
    "name, content, message",
    [
        ("missing.safetensors", None, "does not exist"),
        ("garbage.safetensors", b"not a safetensors file", "cannot read weights"),
        ("weights.onnx", b"x", "unknown weights format"),
    ],
)
def test_unreadable_files(tmp_path: Path, name, content, message):
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(CheckpointError, match=message):
        load_vgn(path)


def test_planner_without_model_is_not_ready():
    from service.errors import ModelNotReady

    planner = GraspPlanner.from_path(None, "cpu")
    assert not planner.ready
    with pytest.raises(ModelNotReady, match="VGN_MODEL"):
        planner.infer(np.zeros((40, 40, 40), np.float32))


def test_planner_infers_on_grids(random_checkpoint: Path):
    planner = GraspPlanner.from_path(random_checkpoint, "cpu")
    output = planner.infer(np.random.default_rng(0).random((40, 40, 40), dtype=np.float32))
    assert output.quality.shape == (40, 40, 40) and output.rotation.shape == (4, 40, 40, 40)
    assert planner.model_id == weights_id(random_checkpoint)
