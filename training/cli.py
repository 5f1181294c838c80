"""``vgn-train``: train VGN weights from raw VGN datasets (see ``vgn-train --help``)."""

from __future__ import annotations

import argparse
import json
import shlex
import sys

import torch

from client.log_level import add_log_level_option, configure_logging
from service.runtime import prepare_environment
from training import report
from training.card import write_card
from training.checkpoint import CheckpointMismatch, checkpoint_path
from training.evaluate import EvaluationConfig, executed_grasp_success
from training.options import add_options, config_values
from training.train import TrainConfig, TrainingError, TrainResult, train

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
    """The ``vgn-train`` command line: one option per ``TrainConfig`` field (``training.options``),
    grouped as data, observations, training and machine, and the few switches of the command itself."""
    parser = argparse.ArgumentParser(
        prog="vgn-train",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    groups = {
        "data": parser.add_argument_group("data"),
        "observations": parser.add_argument_group(
            "observations", "recipe folders: each scene's observations, rendered from its recipe and\n"
            "cached (see --cache)"
        ),
        "training": parser.add_argument_group("training"),
    }  # fmt: skip
    evaluation = parser.add_argument_group("executed-grasp evaluation (needs the simulator extra)")
    groups["machine"] = parser.add_argument_group("machine")
    add_options(groups, TrainConfig)
    _add_evaluation_options(evaluation)
    groups["machine"].add_argument(
        "--threads",
        metavar="T",
        type=int,
        default=None,
        help="torch CPU threads (default: torch's; 1 is often faster on a busy or 2-core CPU)",
    )
    add_log_level_option(groups["machine"])
    return parser


def _add_evaluation_options(group: argparse._ArgumentGroup) -> None:
    """The executed-grasp evaluation after training (``EvaluationConfig``), not part of the run."""
    group.add_argument(
        "--eval-objects",
        metavar="DIR",
        help="after training, run clear-scene rounds on these held-out objects with the new weights and "
        "record executed-grasp success in the card",
    )
    group.add_argument("--eval-scene", choices=["blocks", "pile", "packed"], default="pile")
    group.add_argument("--eval-rounds", metavar="R", type=int, default=10, help="(default %(default)s)")


def config_from_args(args: argparse.Namespace) -> TrainConfig:
    """The parsed command line as a ``TrainConfig``."""
    return TrainConfig(**config_values(args, TrainConfig))


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
