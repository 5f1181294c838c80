"""Training checkpoints: everything needed to continue a run exactly where it stopped.

Only tensors and plain Python values are stored, so the file loads with
``torch.load(..., weights_only=True)``: reading a checkpoint never runs pickled code.
Written atomically after every epoch (temp file + rename).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from vgn_data.files import atomic_writer

#: Bump when the layout below changes incompatibly.
CHECKPOINT_FORMAT = 1


class CheckpointMismatch(Exception):
    """The checkpoint belongs to another run (other data, seed, resolution or split)."""


@dataclass
class TrainingState:
    """A run after ``epoch`` completed epochs.

    ``identity`` holds what must not change on resume (data, seed, resolution, split);
    ``history`` one dict per epoch (metrics, seconds); ``rng`` the torch generator states.
    """

    epoch: int
    model: dict[str, torch.Tensor]
    optimizer: dict[str, Any]
    history: list[dict[str, Any]]
    identity: dict[str, Any]
    rng: dict[str, Any] = field(default_factory=dict)


def checkpoint_path(out: Path) -> Path:
    """``vgn.safetensors`` → ``vgn.ckpt.pt`` beside it."""
    return out.with_suffix(".ckpt.pt")


def teacher_targets_path(out: Path) -> Path:
    """``vgn.safetensors`` → ``vgn.teacher.npz`` beside it: the teacher's soft labels, kept for
    a resume."""
    return out.with_suffix(".teacher.npz")


def capture_rng() -> dict[str, Any]:
    """The torch (and CUDA) random states, so a resumed run draws what an uninterrupted one would."""
    state: dict[str, Any] = {"torch": torch.get_rng_state()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def restore_rng(state: dict[str, Any]) -> None:
    """Put back what ``capture_rng`` saved; CUDA states only where CUDA is present."""
    if "torch" in state:
        torch.set_rng_state(state["torch"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


def save_state(state: TrainingState, path: Path) -> None:
    """Write ``state`` to ``path`` atomically."""
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "format": CHECKPOINT_FORMAT,
        "epoch": state.epoch,
        "model": {k: v.detach().cpu() for k, v in state.model.items()},
        "optimizer": state.optimizer,
        "history": state.history,
        "identity": state.identity,
        "rng": state.rng,
    }
    with atomic_writer(path) as stream:
        torch.save(payload, stream)


def load_state(path: Path, identity: dict[str, Any]) -> TrainingState:
    """Read a checkpoint (weights only: no code runs) and check it belongs to this run."""
    payload = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointMismatch(f"{path} is not a vgn-train checkpoint (format {CHECKPOINT_FORMAT})")
    stored = payload["identity"]
    differences = [
        f"{key}: checkpoint {stored.get(key)!r}, now {identity.get(key)!r}"
        for key in sorted(set(stored) | set(identity))
        if stored.get(key) != identity.get(key)
    ]
    if differences:
        raise CheckpointMismatch(
            f"{path} was made by another run:\n  "
            + "\n  ".join(differences)
            + "\nresuming needs the same datasets (unchanged), seed, resolution and split; "
            "start over with --fresh or write to another --out"
        )
    return TrainingState(
        epoch=int(payload["epoch"]),
        model=payload["model"],
        optimizer=payload["optimizer"],
        history=list(payload["history"]),
        identity=stored,
        rng=payload.get("rng", {}),
    )
