"""The model card: a JSON file beside the weights saying what they were trained on and how
well they did, so a weights file is never an anonymous blob.

A card travels with its weights (one ships in the package), so it names no machine: paths are
written relative to the directory the command ran in, or as ``~/...`` under the home directory,
and that directory itself is not recorded (cards written before say ``working_directory``)."""

from __future__ import annotations

import datetime as dt
import json
import os
import subprocess
from collections.abc import Iterable
from importlib import metadata
from pathlib import Path
from typing import Any

from service.vgn.checkpoint import weights_id
from service.vgn.network import PARAMETER_COUNT
from vgn_data.files import atomic_writer, write_atomically

CARD_FORMAT = 1
#: The fields of a dataset's entry in the card that hold a path (``cache`` may hold a note instead).
DATASET_PATHS = ("path", "cache")


def portable_path(path: str | Path, cwd: Path | None = None, home: Path | None = None) -> str:
    """``path`` as a card records it: relative to ``cwd`` (the working directory) when inside it,
    ``~/...`` when under ``home`` (the home directory), else unchanged, as is text that is not an
    absolute path ("packed shards"). A working directory that is the file system's root does not
    count: every path would be relative to it."""
    text = str(path)
    target = Path(text)
    if not target.is_absolute():
        return text
    for base, prefix in ((cwd or Path.cwd(), ""), (home or Path(os.path.expanduser("~")), "~/")):
        if not base.is_absolute() or base == Path(base.anchor):  # "~" when no home is known
            continue
        for root in dict.fromkeys((base, base.resolve())):
            if target == root:
                return "." if not prefix else "~"
            if target.is_relative_to(root):
                return prefix + target.relative_to(root).as_posix()
    return text


def code_version() -> dict[str, str | None]:
    """The package version and, when running from a git checkout, ``git describe``."""
    try:
        package = metadata.version("vgn-service")
    except metadata.PackageNotFoundError:
        package = None
    try:
        described = subprocess.run(
            ["git", "describe", "--always", "--dirty", "--tags"],
            cwd=Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        described = None
    return {"package": package, "git": described or None}


def labelling_hand(grippers: Iterable[str | None]) -> str | None:
    """The version of the hand that labelled every dataset of a run, from each one's record
    (``None``: not recorded); ``None`` when one does not record it. ``ValueError`` for datasets of
    different hands: a network learns what one hand can hold, so their labels are never mixed."""
    recorded = list(grippers)
    hands = sorted(set(recorded) - {None})
    if len(hands) > 1:
        raise ValueError(
            f"the data was labelled by different hands ({', '.join(hands)}): train on one hand's data"
        )
    return hands[0] if hands and None not in recorded else None


def build_card(
    *,
    weights: Path,
    datasets: list[dict[str, Any]],
    training: dict[str, Any],
    history: list[dict[str, Any]],
    best: dict[str, Any] | None,
    command: str,
    threshold: float,
    gripper: str | None = None,
) -> dict[str, Any]:
    """The card's content; ``weights`` must already be written (its content id is recorded).
    ``threshold`` is the operating threshold the service applies to requests that give none;
    ``gripper`` the version of the hand that labelled the data (:func:`labelling_hand`), which the
    service checks against the hand a network is loaded for. The datasets' paths are made portable
    here; ``training`` holds its own (:func:`portable_path`)."""
    return {
        "format": CARD_FORMAT,
        "model": {
            "architecture": "VGN (Breyer et al., CoRL 2020)",
            "parameters": PARAMETER_COUNT,
            "weights": weights.name,
            "weights_id": weights_id(weights),
            "resolution": training.get("resolution"),
            "input": "TSDF grid (N,N,N) indexed [x,y,z], (tsdf+1)/2 where observed, else 0",
        },
        "threshold": threshold,
        "gripper": gripper,
        "datasets": [_portable_dataset(dataset) for dataset in datasets],
        "training": training,
        "epochs": len(history),
        "metrics": {"final": history[-1] if history else None, "best": best},
        "history": history,
        "code_version": code_version(),
        "command": command,
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
    }


def _portable_dataset(dataset: dict[str, Any]) -> dict[str, Any]:
    """A dataset's entry with its paths as :func:`portable_path` writes them."""
    return {key: portable_path(v) if key in DATASET_PATHS and v else v for key, v in dataset.items()}


def write_learning_curves(history: list[dict[str, Any]], path: Path) -> Path | None:
    """A PNG of the run: training and validation loss per epoch against optimiser steps, and
    validation precision/recall at 0.9. ``None`` (nothing written) without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    steps = [entry.get("steps", entry["epoch"]) for entry in history]
    figure, (losses, quality) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    losses.plot(steps, [e["train"].get("loss") for e in history], "o-", label="train loss")
    if history and history[0].get("val"):
        val = [e["val"] for e in history]
        losses.plot(steps, [v.get("loss") for v in val], "s-", label="val loss (all labels)")
        losses.plot(steps, [v.get("balanced_loss") for v in val], "^-", label="val loss (balanced)")
        quality.plot(steps, [v.get("precision") for v in val], "o-", label="val precision @0.9")
        quality.plot(steps, [v.get("recall") for v in val], "s-", label="val recall @0.9")
        quality.set_ylim(0, 1)
        quality.legend()
    losses.set_xlabel("optimiser steps")
    quality.set_xlabel("optimiser steps")
    losses.set_title("loss")
    quality.set_title("validation (unbalanced labels)")
    losses.legend()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_writer(path) as stream:
        figure.savefig(stream, format="png", dpi=80)
    plt.close(figure)
    return path


def write_card(card: dict[str, Any], path: Path) -> None:
    """Write the card as strict JSON (no NaN), atomically."""
    write_atomically(path, json.dumps(card, indent=2, allow_nan=False) + "\n")
