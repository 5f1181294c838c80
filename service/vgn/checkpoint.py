"""Loading VGN weights safely: safetensors, or a plain PyTorch state_dict (never a pickle of
arbitrary objects)."""

from __future__ import annotations

import hashlib
import json
import logging
from pathlib import Path
from typing import Any

import torch
from safetensors.torch import load_file, save

from service.vgn.network import VGN
from vgn_data.files import write_atomically

STATE_DICT_SUFFIXES = {".pt", ".pth"}

log = logging.getLogger(__name__)


class CheckpointError(Exception):
    """The weights file is missing, unreadable, or does not fit the VGN architecture."""


def weights_id(path: Path) -> str:
    """Content id of a weights file: the first 12 hex digits of its sha256."""
    digest = hashlib.sha256()
    with path.open("rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()[:12]


def card_path(weights: Path) -> Path:
    """The model card beside a weights file: ``vgn.safetensors`` → ``vgn.card.json``."""
    return weights.with_suffix(".card.json")


def card_summary(weights: Path, content_id: str | None = None) -> dict[str, Any] | None:
    """What ``GET /model`` tells about the weights from their card: when and on what they were
    trained (and the version of the hand that labelled that data, ``None`` where the card does not
    record it), their validation figures and the command that reproduces them. ``None`` without a
    readable card (weights from elsewhere need none). ``content_id``: the weights' id, when the
    caller already has it (saves hashing the file again)."""
    try:
        card = json.loads(card_path(weights).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(card, dict):
        return None
    datasets = card.get("datasets") or []
    metrics = card.get("metrics") or {}
    # The weights are the best epoch's, not the last one's: report the figures that match them.
    shipped = metrics.get("best") or metrics.get("final") or {}
    executed = card.get("executed_grasps") or {}
    return {
        "date": card.get("date"),
        "matches_weights": (card.get("model") or {}).get("weights_id") == (content_id or weights_id(weights)),
        "scenes": sum(int(d.get("scenes", 0)) for d in datasets if isinstance(d, dict)),
        "grasps": sum(int(d.get("grasps", 0)) for d in datasets if isinstance(d, dict)),
        "epochs": card.get("epochs"),
        "threshold": card.get("threshold"),
        "gripper": card.get("gripper"),
        "epoch": shipped.get("epoch"),
        "steps": shipped.get("steps"),
        "validation": shipped.get("val"),
        "executed_grasps": _executed_summary(executed) if isinstance(executed, dict) else None,
        "command": card.get("command"),
        "code_version": card.get("code_version"),
    }


def _executed_summary(executed: dict[str, Any]) -> dict[str, Any] | None:
    """The card's clear-scene result in brief: the number that says how well the weights grasp."""
    if "success_rate" not in executed:
        return None
    keys = ("rounds", "attempts", "success_rate", "success_rate_ci95", "percent_cleared", "outcomes")
    return {"settings": executed.get("settings"), **{k: executed.get(k) for k in keys}}


def read_state_dict(path: Path) -> dict[str, torch.Tensor]:
    """Tensors of a ``.safetensors`` or ``.pt``/``.pth`` file (loaded with ``weights_only``)."""
    if not path.is_file():
        raise CheckpointError(f"weights file {path} does not exist")
    try:
        if path.suffix == ".safetensors":
            log.info("reading weights %s as safetensors", path)
            return load_file(str(path), device="cpu")
        if path.suffix in STATE_DICT_SUFFIXES:
            log.info("reading weights %s as a PyTorch state_dict (tensors only, no pickled code)", path)
            state = torch.load(path, map_location="cpu", weights_only=True)
            if isinstance(state, dict) and "state_dict" in state and isinstance(state["state_dict"], dict):
                state = state["state_dict"]
            if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
                raise CheckpointError(f"{path} does not hold a state_dict of tensors")
            return state
    except CheckpointError:
        raise
    except Exception as error:  # safetensors, pickle and zip errors have no common base
        raise CheckpointError(f"cannot read weights from {path}: {error}") from None
    raise CheckpointError(f"unknown weights format {path.suffix!r}: use .safetensors, .pt or .pth")


def load_vgn(path: Path) -> VGN:
    """A VGN network with the weights of ``path``, loaded strictly, in eval mode on the CPU."""
    network = VGN()
    try:
        network.load_state_dict(read_state_dict(path), strict=True)
    except RuntimeError as error:
        raise CheckpointError(f"{path} does not fit the VGN architecture: {error}") from None
    return network.eval()


def save_vgn(network: VGN, path: Path) -> None:
    """Write ``network``'s weights as safetensors, atomically, readable by a service running
    as another user."""
    tensors = {k: v.detach().cpu().contiguous() for k, v in network.state_dict().items()}
    write_atomically(path, save(tensors))
