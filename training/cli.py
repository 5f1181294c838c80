"""``vgn-train``: train VGN weights from raw VGN datasets (see ``vgn-train --help``)."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from dataclasses import fields
from pathlib import Path

import torch

from client.log_level import add_log_level_option, configure_logging
from service.runtime import prepare_environment
from training import report
from training.card import write_card
from training.checkpoint import CheckpointMismatch, checkpoint_path
from training.evaluate import EvaluationConfig, executed_grasp_success
from training.observations import VIEWS, ObservationSettings
from training.train import TEACHER_VIEWS, TrainConfig, TrainingError, TrainResult, train

#: The run's defaults live on TrainConfig; the options show and use them.
DEFAULTS = {f.name: f.default for f in fields(TrainConfig)}

DESCRIPTION = """\
Train the Volumetric Grasping Network on one or more raw VGN datasets (the layout that
`setup.json`, `grasps.csv` and `scenes/*.npz` make up; the sim worker writes it, and public
VGN/GIGA raw datasets use it too).

A --data folder is a raw dataset, a folder of scene recipes (the repository's data/: each
scene's observations are rendered from its recipe and cached, see --observations) or of grid
shards (vgn-pack-data). Raw scenes' depth images are fused into a 40^3 TSDF grid with the service's own TSDF
code and cached (by default in <data>/.cache/). One forward pass per scene draw scores its
labels with VGN's loss; each draw is turned by a multiple of 90 degrees about z, placed at a
random height, and keeps its positives and as many random negatives. Scenes are split into
training and validation by scene, fixed by --seed; validation uses every label.

Writes OUT (.safetensors weights for the service: VGN_MODEL=OUT), OUT's .card.json (model
card: data, settings, metrics, command, code version) and OUT's .ckpt.pt (the training
state after each epoch, for --resume). With --teacher, OUT's .teacher.npz keeps the teacher's
soft labels, so a --resume with the same teacher and data does not work them out again
(delete it once the run is finished: it takes about 15 bytes a soft label).
"""

EPILOG = """\
examples:
  vgn-train --data data --epochs 40 --copies 4 --patience 6 --out models/vgn.safetensors
  vgn-train --data raw/pile --data raw/packed --epochs 10 --out models/vgn.safetensors
  vgn-train --data data/pile --epochs 20 --out models/vgn.safetensors --resume   # 10 more epochs
  VGN_MODEL=models/vgn.safetensors uvicorn service.app:app                   # serve them
"""


def build_parser() -> argparse.ArgumentParser:
    """The ``vgn-train`` command line, its options grouped: data, training, evaluation, machine."""
    parser = argparse.ArgumentParser(
        prog="vgn-train",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    data = parser.add_argument_group("data")
    data.add_argument(
        "--data",
        metavar="DIR",
        type=Path,
        action="append",
        required=True,
        help="a raw VGN dataset folder; repeat to train on several",
    )
    data.add_argument(
        "--cache",
        metavar="DIR",
        type=Path,
        default=None,
        help="where to cache fused grids (default: <data>/.cache/grids-<N>-<key>) and recipe folders' "
        "rendered observations (default: ~/.cache/vgn-service/observations)",
    )
    data.add_argument(
        "--val-fraction",
        metavar="F",
        type=float,
        default=DEFAULTS["val_fraction"],
        help="share of scenes held out for validation (default %(default)s; 0 = none)",
    )
    data.add_argument(
        "--train-scenes",
        dest="max_train_scenes",
        metavar="N",
        type=int,
        default=DEFAULTS["max_train_scenes"],
        help="train on N of the training scenes, a subset fixed by --seed and nested across sizes "
        "(validation unchanged): points of a learning curve (default: all)",
    )
    data.add_argument(
        "--source",
        dest="sources",
        metavar="NAME",
        action="append",
        help="recipe folders: train on this source's scenes only (e.g. pile-answers; `vgn-data pack --source` "
        "named it); repeat for several (default: every source)",
    )
    data.add_argument(
        "--resolution",
        metavar="N",
        type=int,
        default=DEFAULTS["resolution"],
        help="grid voxels a side (default %(default)s, VGN's; a multiple of 8)",
    )
    data.add_argument(
        "--max-depth",
        metavar="M",
        type=float,
        default=DEFAULTS["max_depth"],
        help="ignore depth readings beyond this many metres (default %(default)s, as the service)",
    )
    data.add_argument(
        "--augment",
        choices=["height", "shift", "none"],
        default=DEFAULTS["augment"] or "none",
        help="height (default, VGN's): quarter-turns about z and the scene at a random height; "
        "shift: quarter-turns and z shifts of up to 4 voxels; none",
    )
    data.add_argument(
        "--no-augment", dest="augment", action="store_const", const="none", help="same as --augment none"
    )
    data.add_argument(
        "--copies",
        metavar="K",
        type=int,
        default=DEFAULTS["copies"],
        help="draws of each training scene per epoch, each augmented and label-subsampled anew "
        "(default %(default)s)",
    )
    data.add_argument(
        "--observations",
        metavar="K",
        type=int,
        default=1,
        help="recipe folders: observations rendered per scene (cached, see --cache); with K > 1 every "
        "draw of a scene shows one of them at random (default %(default)s: the original observation only)",
    )
    data.add_argument(
        "--observation-noise",
        metavar="F",
        type=float,
        default=ObservationSettings.noise_fraction,
        help="share of fresh observations with Dex-Net depth noise (default %(default)s)",
    )
    data.add_argument(
        "--observation-sensor",
        choices=["dex", "structured-light"],
        default=ObservationSettings.sensor,
        help="the depth errors of noisy fresh observations: Dex-Net noise or a structured-light camera's "
        "(docs/sensors.md; default %(default)s)",
    )
    data.add_argument(
        "--observation-side-views",
        metavar="F",
        type=float,
        default=ObservationSettings.side_view_fraction,
        help="share of fresh observations that are one side view (default %(default)s)",
    )
    data.add_argument(
        "--observation-views",
        choices=VIEWS,
        default=ObservationSettings.views,
        help="where fresh observations' cameras stand: data generation's random views or VGN's six "
        "evaluation views, the benchmark's; six takes no side views (default %(default)s)",
    )
    data.add_argument(
        "--no-original",
        dest="original",
        action="store_false",
        help="recipe folders: every observation fresh (default: the first is the scene's original one)",
    )
    data.add_argument(
        "--no-balance",
        dest="balance",
        action="store_false",
        help="train on every label of a scene (default: each draw keeps the positives and as many negatives)",
    )

    run = parser.add_argument_group("training")
    run.add_argument(
        "--out",
        metavar="FILE.safetensors",
        type=Path,
        required=True,
        help="weights to write; the card and checkpoint go beside it",
    )
    run.add_argument(
        "--epochs",
        metavar="N",
        type=int,
        default=DEFAULTS["epochs"],
        help="total epochs of the run (default %(default)s, VGN's)",
    )
    run.add_argument(
        "--lr",
        metavar="LR",
        type=float,
        default=DEFAULTS["lr"],
        help="Adam learning rate (default %(default)s, VGN's)",
    )
    run.add_argument(
        "--batch-scenes",
        metavar="B",
        type=int,
        default=DEFAULTS["batch_scenes"],
        help="scenes per optimiser step; each brings all its labels (default %(default)s)",
    )
    run.add_argument(
        "--seed",
        metavar="S",
        type=int,
        default=DEFAULTS["seed"],
        help="fixes split, order and augmentations (default %(default)s)",
    )
    run.add_argument(
        "--resume", action="store_true", help="continue the run in OUT's checkpoint up to --epochs in total"
    )
    run.add_argument("--fresh", action="store_true", help="start over even though a checkpoint exists")
    run.add_argument(
        "--init",
        metavar="WEIGHTS",
        type=Path,
        default=None,
        help="start from these weights instead of random ones (fine-tuning; e.g. the shipped model, "
        "service/models/vgn.safetensors); recorded in the card",
    )
    run.add_argument(
        "--teacher",
        metavar="WEIGHTS",
        type=Path,
        default=None,
        help="distil these weights' turn-averaged output (quality, orientation, width at every voxel "
        "where detection may place a grasp) into the trained network as soft labels beside the "
        "trial labels; usually the same weights as --init",
    )
    run.add_argument(
        "--teacher-views",
        choices=TEACHER_VIEWS,
        default=DEFAULTS["teacher_views"],
        help="what the teacher sees of each scene: its first observation (the original one unless "
        "--no-original), or (recipe folders) the "
        "scene rendered clean from VGN's six evaluation views, cached beside the student's "
        "observations (default %(default)s)",
    )
    run.add_argument(
        "--teacher-checks",
        action="store_true",
        help="the teacher's quality is 0 wherever the service's clearance or grip check would drop "
        "its grasp, so that one plain pass learns what the default request's checks do (best "
        "with --teacher-views six: the grip check judges volumes fused from several views)",
    )
    run.add_argument(
        "--distill-weight",
        metavar="W",
        type=float,
        default=DEFAULTS["distill_weight"],
        help="weight of the soft-label loss against the trial-label loss (default %(default)s)",
    )
    run.add_argument(
        "--soft-per-draw",
        metavar="K",
        type=int,
        default=DEFAULTS["soft_per_draw"],
        help="soft labels drawn from a scene each time it is drawn (default %(default)s)",
    )
    run.add_argument(
        "--patience",
        metavar="P",
        type=int,
        default=None,
        help="stop after P epochs without a lower balanced validation loss (default: run all epochs); "
        "the weights written are always the best epoch's",
    )
    run.add_argument(
        "--threshold",
        metavar="T",
        type=_threshold,
        default=None,
        help="operating threshold written to the card: the service applies it to grasp requests that "
        "give none. Default 'auto': the lowest threshold whose precision on the validation scenes' labels "
        "(their real, unbalanced mix) reaches --target-precision. A rerun with --resume and the same "
        "--epochs only rewrites the card",
    )
    run.add_argument(
        "--target-precision",
        metavar="P",
        type=float,
        default=DEFAULTS["target_precision"],
        help="precision that --threshold auto aims for (default %(default)s)",
    )

    evaluation = parser.add_argument_group("executed-grasp evaluation (needs the simulator extra)")
    evaluation.add_argument(
        "--eval-objects",
        metavar="DIR",
        help="after training, run clear-scene rounds on these held-out objects with the new weights and "
        "record executed-grasp success in the card",
    )
    evaluation.add_argument("--eval-scene", choices=["blocks", "pile", "packed"], default="pile")
    evaluation.add_argument("--eval-rounds", metavar="R", type=int, default=10, help="(default %(default)s)")

    machine = parser.add_argument_group("machine")
    machine.add_argument(
        "--device",
        choices=["auto", "cpu", "cuda"],
        default=DEFAULTS["device"],
        help="auto = the GPU when there is one (default)",
    )
    machine.add_argument(
        "--workers",
        metavar="W",
        type=int,
        default=DEFAULTS["workers"],
        help="processes fusing grids, loading batches and running the teacher's checks "
        "(default %(default)s = in this process)",
    )
    machine.add_argument(
        "--threads",
        metavar="T",
        type=int,
        default=None,
        help="torch CPU threads (default: torch's; 1 is often faster on a busy or 2-core CPU)",
    )
    machine.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bars")
    add_log_level_option(machine)
    return parser


def _threshold(text: str) -> float | None:
    """A threshold in [0, 1], or 'auto' (None)."""
    if text == "auto":
        return None
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1] or 'auto', got {text!r}") from None


def config_from_args(args: argparse.Namespace) -> TrainConfig:
    """The parsed command line as a ``TrainConfig``; ``--augment none`` turns augmentation off."""
    return TrainConfig(
        data=args.data,
        out=args.out,
        epochs=args.epochs,
        lr=args.lr,
        batch_scenes=args.batch_scenes,
        val_fraction=args.val_fraction,
        max_train_scenes=args.max_train_scenes,
        sources=tuple(args.sources) if args.sources else None,
        seed=args.seed,
        device=args.device,
        cache=args.cache,
        workers=args.workers,
        resolution=args.resolution,
        max_depth=args.max_depth,
        augment=None if args.augment == "none" else args.augment,
        copies=args.copies,
        balance=args.balance,
        patience=args.patience,
        threshold=args.threshold,
        target_precision=args.target_precision,
        init=args.init,
        teacher=args.teacher,
        distill_weight=args.distill_weight,
        soft_per_draw=args.soft_per_draw,
        teacher_views=args.teacher_views,
        teacher_checks=args.teacher_checks,
        observations=ObservationSettings(
            per_scene=args.observations,
            original=args.original,
            noise_fraction=args.observation_noise,
            sensor=args.observation_sensor,
            side_view_fraction=args.observation_side_views,
            views=args.observation_views,
        ),  # fmt: skip
        resume=args.resume,
        fresh=args.fresh,
        progress=args.progress,
    )


def evaluate_into_card(result: TrainResult, config: EvaluationConfig) -> None:
    """Run the executed-grasp evaluation and add it to the card (and the printed summary)."""
    results = result.weights.with_suffix(".eval") / f"{config.scene}-{config.object_count}-seed{config.seed}"
    outcome = executed_grasp_success(result.weights, config, results)
    card = json.loads(result.card.read_text())
    card["executed_grasps"] = outcome
    write_card(card, result.card)
    from sim_worker.metrics import summary_table

    print(f"executed grasps ({config.scene}, {outcome['rounds']} rounds, held-out objects):")
    print(summary_table(outcome))


def summary(result: TrainResult) -> str:
    """The end-of-run report: the epoch table, the best epoch and the files written."""
    lines = ["", report.table(result.history)]
    if result.best is not None:
        lines.append(
            f"best epoch: {result.best['epoch']} (lowest {'val' if result.val_scenes else 'train'} loss)"
        )
    scenes = sum(d.scenes for d in result.datasets)
    grasps = sum(d.grasps for d in result.datasets)
    lines += [
        f"data: {len(result.datasets)} dataset(s), {scenes} scenes, {grasps} labels "
        f"({result.train_scenes} train / {result.val_scenes} val scenes)",
        f"weights:    {result.weights}",
        f"model card: {result.card}",
        f"checkpoint: {result.checkpoint}",
        f"serve with: VGN_MODEL={result.weights} uvicorn service.app:app",
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Train, optionally evaluate into the card, and print
    the summary; 2 for bad input, 130 when interrupted."""
    args = build_parser().parse_args(argv)
    configure_logging(args.log_level)
    # The service's OpenMP defaults, for the processes training starts (this one loaded torch already).
    prepare_environment()
    if args.threads:
        torch.set_num_threads(args.threads)
    command = ["vgn-train", *(sys.argv[1:] if argv is None else argv)]
    try:
        config = config_from_args(args)
        result = train(config, command=shlex.join(command))
        if args.eval_objects:
            evaluate_into_card(result, EvaluationConfig(args.eval_objects, args.eval_scene, args.eval_rounds))
    except (TrainingError, CheckpointMismatch, FileNotFoundError, ValueError, RuntimeError) as error:
        print(f"vgn-train: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        path = checkpoint_path(args.out)
        hint = f"continue with --resume (checkpoint: {path})" if path.exists() else "no epoch had finished"
        print(f"\nvgn-train: interrupted; {hint}", file=sys.stderr)
        return 130
    print(summary(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
