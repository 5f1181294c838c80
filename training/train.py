"""The training loop: data → epochs of Adam on VGN's loss → checkpoint, weights and card.

After every epoch the full training state is checkpointed, so an interrupted run resumes
(``resume=True``) at the next epoch with the same data order and augmentations.

VGN's scale of optimisation on little data comes from many small steps: each scene is drawn
``copies`` times an epoch, each draw with its own quarter-turn, height placement and balanced
subset of labels. With validation, the weights written are those of the epoch with the lowest
balanced validation loss, and ``patience`` stops a run that no longer improves.
"""

from __future__ import annotations

import argparse
import hashlib
import shlex
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
from tqdm import tqdm

from service.planner import resolve_device
from service.vgn.checkpoint import CheckpointError, card_path, load_vgn, save_vgn, weights_id
from service.vgn.network import VGN
from training import report
from training.augment import MAX_Z_SHIFT
from training.card import build_card, labelling_hand, portable_path, write_card, write_learning_curves
from training.checkpoint import (
    TrainingState,
    capture_rng,
    checkpoint_path,
    load_state,
    restore_rng,
    save_state,
    teacher_targets_path,
)
from training.dataset import (
    DatasetSummary,
    RenderedObservations,
    Scene,
    SceneDataset,
    load_scenes,
    make_loader,
    prepare_grids,
    split_scenes,
    subsample_scenes,
)
from training.distill import CHECKED_QUALITY, SoftTargets, load_targets, save_targets, teach, teaching_key
from training.grids import MAX_DEPTH, RESOLUTION
from training.loss import distillation_loss, gather, per_label_loss
from training.metrics import THRESHOLD, MetricAccumulator, choose_threshold
from training.observations import ObservationSettings
from training.options import option
from training.recipe_shards import RecipeFolder
from training.shards import ShardFolder, manifest_summary
from vgn_contract.schemas import VGN_DEFAULT_THRESHOLD
from vgn_data.files import remove_stale_temporaries

#: What a teacher may see of a scene (``TrainConfig.teacher_views``).
TEACHER_VIEWS = ("original", "six")
#: The teacher's privileged view: the scene rendered clean from VGN's six evaluation views.
TEACHER_SIX_VIEWS = ObservationSettings(
    per_scene=1, original=False, views="six", noise_fraction=0.0, side_view_fraction=0.0
)


def parse_threshold(text: str) -> float | None:
    """``--threshold``'s value: a number, or 'auto' (None: chosen on the validation labels)."""
    if text == "auto":
        return None
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1] or 'auto', got {text!r}") from None


class TrainingError(Exception):
    """A run cannot start or continue (no data, an existing checkpoint, a bad setting)."""


@dataclass
class TrainConfig:
    """One training run; each field's metadata is also its ``vgn-train`` option (``training.options``).
    Paths: ``data`` raw VGN datasets, ``out`` the ``.safetensors`` weights to write (checkpoint and
    card go beside it)."""

    data: list[Path] = field(
        metadata=option("data", "a raw VGN dataset folder; repeat to train on several", metavar="DIR")
    )
    out: Path = field(
        metadata=option(
            "training",
            "weights to write; the card and checkpoint go beside it",
            metavar="FILE.safetensors",
        )
    )
    epochs: int = field(
        default=10,
        metadata=option("training", "total epochs of the run (default %(default)s, VGN's)", metavar="N"),
    )
    lr: float = field(
        default=3e-4,
        metadata=option("training", "Adam learning rate (default %(default)s, VGN's)", metavar="LR"),
    )
    batch_scenes: int = field(
        default=4,
        metadata=option(
            "training",
            "scenes per optimiser step; each brings all its labels (default %(default)s)",
            metavar="B",
        ),
    )
    val_fraction: float = field(
        default=0.1,
        metadata=option(
            "data", "share of scenes held out for validation (default %(default)s; 0 = none)", metavar="F"
        ),
    )
    max_train_scenes: int | None = field(
        default=None,
        metadata=option(
            "data",
            "train on N of the training scenes, a subset fixed by --seed and nested across sizes "
            "(validation unchanged): points of a learning curve (default: all)",
            flag="--train-scenes",
            metavar="N",
        ),
    )
    sources: tuple[str, ...] | None = field(
        default=None,
        metadata=option(
            "data",
            "recipe folders: train on this source's scenes only (e.g. pile-answers; `vgn-data pack --source` "
            "named it); repeat for several (default: every source)",
            flag="--source",
            metavar="NAME",
        ),
    )
    seed: int = field(
        default=0,
        metadata=option(
            "training", "fixes split, order and augmentations (default %(default)s)", metavar="S"
        ),
    )
    device: str = field(
        default="auto",
        metadata=option(
            "machine", "auto = the GPU when there is one (default)", choices=("auto", "cpu", "cuda")
        ),
    )
    cache: Path | None = field(
        default=None,
        metadata=option(
            "data",
            "where to cache fused grids (default: <data>/.cache/grids-<N>-<key>) and recipe folders' "
            "rendered observations (default: ~/.cache/vgn-service/observations)",
            metavar="DIR",
        ),
    )
    workers: int = field(
        default=0,
        metadata=option(
            "machine",
            "processes fusing grids, loading batches and running the teacher's checks "
            "(default %(default)s = in this process)",
            metavar="W",
        ),
    )
    resolution: int = field(
        default=RESOLUTION,
        metadata=option(
            "data", "grid voxels a side (default %(default)s, VGN's; a multiple of 8)", metavar="N"
        ),
    )
    max_depth: float = field(
        default=MAX_DEPTH,
        metadata=option(
            "data",
            "ignore depth readings beyond this many metres (default %(default)s, as the service)",
            metavar="M",
        ),
    )
    augment: str | None = field(
        default="height",
        metadata=option(
            "data",
            "height (default, VGN's): quarter-turns about z and the scene at a random height; "
            "shift: quarter-turns and z shifts of up to 4 voxels; none",
            choices=("height", "shift"),
            none="none",
            off="--no-augment",
        ),
    )
    copies: int = field(
        default=1,
        metadata=option(
            "data",
            "draws of each training scene per epoch, each augmented and label-subsampled anew "
            "(default %(default)s)",
            metavar="K",
        ),
    )
    balance: bool = field(
        default=True,
        metadata=option(
            "data",
            "train on every label of a scene (default: each draw keeps the positives and as many negatives)",
        ),
    )
    patience: int | None = field(
        default=None,
        metadata=option(
            "training",
            "stop after P epochs without a lower balanced validation loss (default: run all epochs); "
            "the weights written are always the best epoch's",
            metavar="P",
        ),
    )
    threshold: float | None = field(
        default=None,
        metadata=option(
            "training",
            "operating threshold written to the card: the service applies it to grasp requests that "
            "give none. Default 'auto': the lowest threshold whose precision on the validation scenes' "
            "labels (their real, unbalanced mix) reaches --target-precision. A rerun with --resume and "
            "the same --epochs only rewrites the card",
            metavar="T",
            parse=parse_threshold,
        ),
    )
    target_precision: float = field(
        default=0.8,
        metadata=option(
            "training", "precision that --threshold auto aims for (default %(default)s)", metavar="P"
        ),
    )
    init: Path | None = field(
        default=None,
        metadata=option(
            "training",
            "start from these weights instead of random ones (fine-tuning; e.g. the shipped model, "
            "service/models/vgn.safetensors); recorded in the card",
            metavar="WEIGHTS",
        ),
    )
    #: distilled as soft labels by ``training.distill``
    teacher: Path | None = field(
        default=None,
        metadata=option(
            "training",
            "distil these weights' turn-averaged output (quality, orientation, width at every voxel "
            "where detection may place a grasp) into the trained network as soft labels beside the "
            "trial labels; usually the same weights as --init",
            metavar="WEIGHTS",
        ),
    )
    #: both losses are means over their labels
    distill_weight: float = field(
        default=1.0,
        metadata=option(
            "training",
            "weight of the soft-label loss against the trial-label loss (default %(default)s)",
            metavar="W",
        ),
    )
    soft_per_draw: int = field(
        default=512,
        metadata=option(
            "training",
            "soft labels drawn from a scene each time it is drawn (default %(default)s)",
            metavar="K",
        ),
    )
    #: "six" is ``TEACHER_SIX_VIEWS``: a view of the scene no stored grid holds, whatever the student is shown
    teacher_views: str = field(
        default="original",
        metadata=option(
            "training",
            "what the teacher sees of each scene: its first observation (the original one unless "
            "--no-original), or (recipe folders) the scene rendered clean from VGN's six evaluation "
            "views, cached beside the student's observations (default %(default)s)",
            choices=TEACHER_VIEWS,
        ),
    )
    #: the checks are ``training.distill.failing_checks``
    teacher_checks: bool = field(
        default=False,
        metadata=option(
            "training",
            "the teacher's quality is 0 wherever the service's clearance or grip check would drop "
            "its grasp, so that one plain pass learns what the default request's checks do (best "
            "with --teacher-views six: the grip check judges volumes fused from several views)",
        ),
    )
    observations: ObservationSettings = field(default_factory=ObservationSettings)
    resume: bool = field(
        default=False,
        metadata=option("training", "continue the run in OUT's checkpoint up to --epochs in total"),
    )
    fresh: bool = field(
        default=False, metadata=option("training", "start over even though a checkpoint exists")
    )
    progress: bool = field(default=True, metadata=option("machine", "no progress bars"))

    def __post_init__(self) -> None:
        self.check()

    def check(self) -> None:
        """Refuse settings that cannot train (raised as ``TrainingError``), before any data is read."""
        if self.out.suffix != ".safetensors":
            raise TrainingError(f"--out must end in .safetensors, got {self.out}")
        if self.epochs < 1 or self.batch_scenes < 1 or self.workers < 0 or self.lr <= 0:
            raise TrainingError("epochs and batch size must be >= 1, workers >= 0, lr > 0")
        if self.max_train_scenes is not None and self.max_train_scenes < 1:
            raise TrainingError(f"--train-scenes must be >= 1, got {self.max_train_scenes}")
        if self.copies < 1 or (self.patience is not None and self.patience < 1):
            raise TrainingError("--copies and --patience must be >= 1")
        if self.augment not in (None, "height", "shift"):
            raise TrainingError(f"--augment must be height, shift or none, got {self.augment!r}")
        if not 0.0 < self.target_precision <= 1.0:
            raise TrainingError(f"--target-precision must lie in (0, 1], got {self.target_precision}")
        if self.resolution % 8:
            raise TrainingError(f"resolution must be a multiple of 8 (VGN's encoder), got {self.resolution}")
        if self.threshold is not None and not 0.0 <= self.threshold <= 1.0:
            raise TrainingError(f"--threshold must lie in [0, 1], got {self.threshold}")
        if self.resume and self.fresh:
            raise TrainingError("give --resume or --fresh, not both")
        if self.init is not None and not Path(self.init).is_file():
            raise TrainingError(f"--init: no weights file at {self.init}")
        if self.teacher is not None and not Path(self.teacher).is_file():
            raise TrainingError(f"--teacher: no weights file at {self.teacher}")
        if self.distill_weight < 0 or self.soft_per_draw < 1:
            raise TrainingError("--distill-weight must be >= 0 and --soft-per-draw >= 1")
        if self.teacher_views not in TEACHER_VIEWS:
            raise TrainingError(f"--teacher-views must be one of {TEACHER_VIEWS}, got {self.teacher_views!r}")
        if self.teacher_views != "original" and self.teacher is None:
            raise TrainingError("--teacher-views needs --teacher")
        if self.teacher_checks and self.teacher is None:
            raise TrainingError("--teacher-checks needs --teacher")


@dataclass
class TrainResult:
    """What a run produced: files, per-epoch history and the data it saw."""

    weights: Path
    card: Path
    checkpoint: Path
    history: list[dict[str, Any]]
    best: dict[str, Any] | None
    datasets: list[DatasetSummary]
    train_scenes: int
    val_scenes: int
    grids_built: int
    device: str
    resumed_from: int = 0


def train(
    config: TrainConfig, command: str | None = None, log: Callable[[str], None] = tqdm.write
) -> TrainResult:
    """Run (or continue) training as ``config`` says and write weights, card and checkpoint."""
    config.check()
    _check_teacher_views(config)
    _check_checkpoint(config)
    # Only this run's own files (weights, card, checkpoint, curves): the folder may hold others.
    remove_stale_temporaries(config.out.parent, f".{config.out.stem}.*.tmp", recursive=False)
    device = resolve_device(config.device)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise TrainingError("--device cuda was asked for but torch sees no CUDA GPU")
    torch.manual_seed(config.seed)

    try:
        scenes, summaries = load_scenes(config.data, config.resolution, config.max_depth, config.cache,
                                        config.observations, config.workers, config.progress,
                                        config.sources)  # fmt: skip
    except ValueError as error:
        raise TrainingError(str(error)) from error
    if not scenes:
        raise TrainingError(f"no labelled scenes inside the grid in {', '.join(map(str, config.data))}")
    try:
        hand = labelling_hand(summary.gripper for summary in summaries)
    except ValueError as error:
        raise TrainingError(str(error)) from error
    train_scenes, val_scenes = split_scenes(scenes, config.val_fraction, config.seed)
    train_scenes = subsample_scenes(train_scenes, config.max_train_scenes, config.seed)
    for summary in summaries:
        log(
            f"data {summary.path}: {summary.scenes} scenes, {summary.grasps} grasps "
            f"({summary.positives} positive, {summary.negatives} negative, "
            f"{summary.outside_grid} outside the grid dropped); skipped {summary.scenes_without_labels} "
            f"scenes without labels in the grid, {summary.missing_scene_files} without a scene file"
        )
    built = prepare_grids(scenes, config.workers, config.progress)
    log(
        f"grids: {built} fused, {len(scenes) - built} from cache; split {len(train_scenes)} train / "
        f"{len(val_scenes)} val scenes; device {device}"
    )

    network = _initial_network(config).to(device, memory_format=_memory_format(device))
    optimizer = torch.optim.Adam(network.parameters(), lr=config.lr)
    state = _start(config, network, optimizer, _identity(config, val_scenes), log)
    resumed_from = state.epoch

    will_train = state.epoch < config.epochs and not _patience_ran_out(state.history, config.patience)
    # The teacher costs minutes; a resume that only rewrites the card needs none of it.
    soft = _teacher_targets(config, train_scenes, device, log) if will_train else None
    train_data = SceneDataset(
        train_scenes,
        augment=config.augment,
        seed=config.seed,
        copies=config.copies,
        balance=config.balance,
        soft=soft,
        soft_per_draw=config.soft_per_draw,
        fresh_observations=config.observations.per_scene > 1,
    )
    val_data = SceneDataset(val_scenes, augment=None, seed=config.seed)
    if will_train:
        log(report.header(validation=bool(val_scenes)))
    for epoch in range(state.epoch, config.epochs):
        if _patience_ran_out(state.history, config.patience):
            log(f"stopping: no lower validation loss in the last {config.patience} epoch(s)")
            break
        started = time.perf_counter()
        loader = make_loader(train_data, config.batch_scenes, True, epoch, config.workers)
        train_metrics = _run_epoch(
            network,
            loader,
            device,
            optimizer,
            f"epoch {epoch + 1}/{config.epochs}",
            config.progress,
            config.distill_weight if soft is not None else 0.0,
        )
        val_metrics = None
        if len(val_data):
            loader = make_loader(val_data, config.batch_scenes, False, epoch, config.workers)
            val_metrics = _run_epoch(network, loader, device, None, "  val", config.progress)
        steps = (state.history[-1]["steps"] if state.history else 0) + len(loader_steps(train_data, config))
        entry = {
            "epoch": epoch + 1,
            "train": train_metrics,
            "val": val_metrics,
            "seconds": round(time.perf_counter() - started, 3),
            "train_scenes": len(train_scenes),
            "steps": steps,
            "label_visits": (state.history[-1].get("label_visits", 0) if state.history else 0)
            + int(train_metrics["labels"] or 0),
        }
        state.history.append(entry)
        state.epoch = epoch + 1
        if val_metrics is None or best_epoch(state.history) is entry:  # these weights ship
            save_vgn(network, config.out)
        state.model, state.optimizer, state.rng = network.state_dict(), optimizer.state_dict(), capture_rng()
        save_state(state, checkpoint_path(config.out))
        log(report.row(entry))

    if not config.out.is_file():
        save_vgn(network, config.out)
    best = best_epoch(state.history)
    threshold, choice = _operating_threshold(config, best)
    curves = write_learning_curves(state.history, config.out.with_suffix(".curves.png"))
    if curves is None:
        log("learning curves: matplotlib is not installed, no PNG written (pip install matplotlib)")
    card = build_card(
        weights=config.out,
        datasets=[s.as_dict() for s in summaries],
        training=_training_settings(config, device, train_scenes, val_scenes),
        history=state.history,
        best=best,
        command=command if command is not None else shlex.join(sys.argv),
        threshold=threshold,
        gripper=hand,
    )
    card["threshold_choice"] = choice
    card["packed_data"] = _packed_data(config.data)
    card["learning_curves"] = curves.name if curves else None
    write_card(card, card_path(config.out))
    return TrainResult(
        weights=config.out,
        card=card_path(config.out),
        checkpoint=checkpoint_path(config.out),
        history=state.history,
        best=best,
        datasets=summaries,
        train_scenes=len(train_scenes),
        val_scenes=len(val_scenes),
        grids_built=built,
        device=str(device),
        resumed_from=resumed_from,
    )


def loader_steps(dataset: SceneDataset, config: TrainConfig) -> range:
    """The optimiser steps of one epoch (one per batch of scenes)."""
    return range(-(-len(dataset) // config.batch_scenes))


def _patience_ran_out(history: list[dict[str, Any]], patience: int | None) -> bool:
    """True when the last ``patience`` epochs brought no lower validation loss."""
    if patience is None or not history or history[0].get("val") is None:
        return False
    best = best_epoch(history)
    return best is not None and history[-1]["epoch"] - best["epoch"] >= patience


def _operating_threshold(config: TrainConfig, best: dict[str, Any] | None) -> tuple[float, dict[str, Any]]:
    """The threshold for the card and how it was chosen: given, or the lowest one whose
    precision on the validation labels (their real mix) reaches the target."""
    if config.threshold is not None:
        return config.threshold, {"rule": "given (--threshold)", "threshold": config.threshold}
    curve = ((best or {}).get("val") or {}).get("curve")
    try:
        if not curve:
            raise ValueError("the run has no validation scenes")
        chosen = choose_threshold(curve, config.target_precision)
    except ValueError as error:
        rule = f"VGN's {VGN_DEFAULT_THRESHOLD}: auto could not choose ({error})"
        return VGN_DEFAULT_THRESHOLD, {"rule": rule, "threshold": VGN_DEFAULT_THRESHOLD}
    rule = (
        f"lowest threshold whose precision on the validation scenes' labels (unbalanced, as generated) "
        f"reaches {config.target_precision}, at the best epoch"
    )
    return chosen["threshold"], {"rule": rule, **chosen}


def _packed_data(data: list[Path]) -> list[dict[str, Any]]:
    """The shards (by hash) of every packed folder the run read."""
    return [
        {"folder": str(Path(p)), **manifest_summary(ShardFolder(Path(p)).manifest())}
        for p in data
        if ShardFolder(Path(p)).exists()
    ]


def _start(
    config: TrainConfig,
    network: VGN,
    optimizer: torch.optim.Optimizer,
    identity: dict[str, Any],
    log: Callable[[str], None],
) -> TrainingState:
    """A fresh state, or the checkpoint's when resuming (its weights, optimizer, rng loaded)."""
    path = checkpoint_path(config.out)
    if config.resume:
        state = load_state(path, identity)
        network.load_state_dict(state.model, strict=True)
        optimizer.load_state_dict(state.optimizer)
        for group in optimizer.param_groups:
            group["lr"] = config.lr
        restore_rng(state.rng)
        log(f"resumed {path} after epoch {state.epoch}; training to epoch {config.epochs}")
        return state
    return TrainingState(epoch=0, model={}, optimizer={}, history=[], identity=identity)


def _teacher_targets(
    config: TrainConfig, scenes: list[Scene], device: torch.device, log: Callable[[str], None]
) -> list[SoftTargets] | None:
    """The teacher's soft labels for every training scene, or None without a teacher. They are
    saved beside the checkpoint and read back on resume while the teacher and the grids are
    unchanged; otherwise worked out again."""
    if config.teacher is None:
        return None
    started = time.perf_counter()
    sources = (
        [scene.source for scene in scenes]
        if config.teacher_views == "original"
        else _six_view_sources(config, scenes)
    )
    sizes = [scene.voxel_size for scene in scenes] if config.teacher_checks else None
    saved = teacher_targets_path(config.out)
    key = teaching_key(Path(config.teacher), sources, sizes)
    soft = load_targets(saved, key)
    if soft is None:
        try:
            soft = teach(Path(config.teacher), sources, str(device), config.progress, sizes, config.workers)
        except CheckpointError as error:
            raise TrainingError(f"--teacher: {error}") from None
        save_targets(saved, key, soft)
        how = "worked out"
    else:
        how = f"read from {saved.name}"
    log(
        f"teacher {weights_id(Path(config.teacher))}: {sum(map(len, soft))} soft labels in "
        f"{len(soft)} scenes, {how} ({time.perf_counter() - started:.0f} s)"
    )
    return soft


def _check_teacher_views(config: TrainConfig) -> None:
    """Refuse a teacher view the data cannot give, before any data is read: only recipe
    folders can be seen anew."""
    if config.teacher_views == "original":
        return
    others = [str(path) for path in config.data if not RecipeFolder(Path(path)).exists()]
    if others:
        raise TrainingError(f"--teacher-views six needs recipe folders; not recipes: {', '.join(others)}")


def _six_view_sources(config: TrainConfig, scenes: list[Scene]) -> list[Any]:
    """Each scene's clean six-view observation (rendered into the cache where missing), for the
    teacher."""
    seen, _ = load_scenes(config.data, config.resolution, config.max_depth, config.cache, TEACHER_SIX_VIEWS,
                          config.workers, config.progress, config.sources)  # fmt: skip
    by_key = {scene.key: scene.source for scene in seen}
    return [by_key[scene.key] for scene in scenes]


def _initial_network(config: TrainConfig) -> VGN:
    """Random weights, or ``config.init``'s: fine-tuning reuses what a model learned about
    geometry when new labels (another hand, a new scene type) are too few to learn it again."""
    if config.init is None:
        return VGN()
    try:
        return load_vgn(Path(config.init)).train()
    except CheckpointError as error:
        raise TrainingError(f"--init: {error}") from None


def _check_checkpoint(config: TrainConfig) -> None:
    """Refuse, before any slow work, to resume nothing or to overwrite an earlier run unasked."""
    path = checkpoint_path(config.out)
    if config.resume and not path.is_file():
        raise TrainingError(f"--resume: no checkpoint at {path}")
    if not config.resume and path.exists() and not config.fresh:
        raise TrainingError(
            f"a checkpoint of an earlier run exists at {path}: pass --resume to continue it "
            "or --fresh to start over (it will be replaced)"
        )


def _identity(config: TrainConfig, val_scenes: list[Scene]) -> dict[str, Any]:
    """What a resumed run must share with the checkpoint's: same data, split and grids."""
    split = hashlib.sha256("\n".join(sorted(s.key for s in val_scenes)).encode()).hexdigest()[:16]
    identity = {
        "data": [str(Path(p).resolve()) for p in config.data],
        "seed": config.seed,
        "resolution": config.resolution,
        "max_depth": config.max_depth,
        "val_fraction": config.val_fraction,
        "val_split": split,
    }
    if config.max_train_scenes is not None:  # absent otherwise, so earlier checkpoints still resume
        identity["max_train_scenes"] = config.max_train_scenes
    if config.sources is not None:  # the same
        identity["sources"] = sorted(config.sources)
    if config.teacher is not None:
        identity["teacher"] = weights_id(Path(config.teacher))
    if config.teacher_views != "original":  # absent otherwise, so earlier checkpoints still resume
        identity["teacher_views"] = config.teacher_views
    if config.teacher_checks:  # the same
        identity["teacher_checks"] = True
    if config.observations != ObservationSettings():  # the same: absent for the default
        identity["observations"] = config.observations.key()
    return identity


def _run_epoch(
    network: VGN,
    loader: torch.utils.data.DataLoader,
    device: torch.device,
    optimizer: torch.optim.Optimizer | None,
    description: str,
    progress: bool,
    distill_weight: float = 0.0,
) -> dict[str, float | int | None]:
    """One pass over ``loader``: trains when given an optimizer, else only evaluates. Metrics
    are those of the trial labels; the soft-label loss, when the batches carry soft labels and
    ``distill_weight`` > 0, adds to the optimised loss and is reported as ``distill_loss``."""
    network.train(optimizer is not None)
    metrics = MetricAccumulator()
    distill_total, distill_count = 0.0, 0
    bar = tqdm(loader, desc=description, unit="batch", disable=not progress, leave=False)
    with torch.set_grad_enabled(optimizer is not None):
        for batch in bar:
            if not len(batch):  # every label was shifted out of the grid
                continue
            batch = batch.to(device)
            grids = batch.grids.to(memory_format=_memory_format(device))
            output = network(grids)
            predictions = gather(output, batch)
            losses = per_label_loss(predictions, batch)
            loss = losses.mean()
            if distill_weight > 0 and len(batch.soft_scene):
                soft_losses = distillation_loss(output, batch)
                loss = loss + distill_weight * soft_losses.mean()
                distill_total += float(soft_losses.detach().sum())
                distill_count += len(soft_losses)
            if not torch.isfinite(loss):
                raise TrainingError(f"the loss became {loss.item()} ({description}); lower --lr?")
            if optimizer is not None:
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                optimizer.step()
            metrics.update(predictions, batch, losses.detach())
            bar.set_postfix(loss=f"{loss.item():.4f}")
    result = metrics.result()
    if distill_count:
        result["distill_loss"] = distill_total / distill_count
        result["soft_labels"] = distill_count
    return result


def _memory_format(device: torch.device) -> torch.memory_format:
    """The 3D layout oneDNN prefers on a CPU: it about halves a VGN training step there."""
    return torch.channels_last_3d if device.type == "cpu" else torch.contiguous_format


def best_epoch(history: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The entry with the lowest validation loss (training loss when there is no validation);
    balanced over the two classes where both occur, so the mix of labels does not decide."""

    def score(entry: dict[str, Any]) -> float:
        metrics = entry.get("val") or entry["train"]
        for key in ("balanced_loss", "loss"):  # the balanced loss when the labels have both classes
            if metrics.get(key) is not None:
                return metrics[key]
        return float("inf")

    return min(history, key=score) if history else None


def _training_settings(
    config: TrainConfig, device: torch.device, train_scenes: list[Scene], val_scenes: list[Scene]
) -> dict[str, Any]:
    return {
        "epochs": config.epochs,
        "lr": config.lr,
        "optimizer": "Adam",
        "batch_scenes": config.batch_scenes,
        "copies_per_epoch": config.copies,
        "balance": "per draw: all positives and as many random negatives" if config.balance else None,
        "patience": config.patience,
        "val_fraction": config.val_fraction,
        "max_train_scenes": config.max_train_scenes,
        "sources": None if config.sources is None else sorted(config.sources),
        "seed": config.seed,
        "augment": {
            "height": "z turns k*90 deg; random height: z shift uniform over all shifts keeping the labels in the grid",
            "shift": f"z turns k*90 deg, z shifts U{{-{MAX_Z_SHIFT}..{MAX_Z_SHIFT}}} voxels",
            None: None,
        }[config.augment],
        "init": None
        if config.init is None
        else {"path": portable_path(config.init), "weights_id": weights_id(Path(config.init))},
        "distillation": None
        if config.teacher is None
        else {
            "teacher": {
                "path": portable_path(config.teacher),
                "weights_id": weights_id(Path(config.teacher)),
            },
            "targets": "the teacher's turn-averaged quality, orientation and unturned width at every "
            "grasp-region voxel of each training scene, moved with the scene's augmentation",
            "weight": config.distill_weight,
            "soft_labels_per_draw": config.soft_per_draw,
            "teacher_views": "each scene's first observation (the original one unless --no-original)"
            if config.teacher_views == "original"
            else "each scene rendered clean from VGN's six evaluation views",
            "checks": "quality 0 where the clearance or grip check fails (teacher quality >= "
            f"{CHECKED_QUALITY})"
            if config.teacher_checks
            else None,
        },
        "observations": asdict(config.observations)
        if any(isinstance(s.source, RenderedObservations) for s in train_scenes)
        else None,  # fmt: skip
        "resolution": config.resolution,
        "max_depth": config.max_depth,
        "device": str(device),
        "metrics_threshold": THRESHOLD,
        "train_scenes": len(train_scenes),
        "val_scenes": len(val_scenes),
        "train_labels": sum(len(s.labels) for s in train_scenes),
        "val_labels": sum(len(s.labels) for s in val_scenes),
    }
