"""How well each signal the service has tells a network's successful answers from its failed ones.

    python -m benchmarks.answer_signal --data data --source pile-answers --model A.safetensors \
        [--model B.safetensors ...] [--scenes 300] [--out DIR]

Scenes labelled with ``generate-data --answer-grasps`` hold grasps one network answered, each tried
once as answered. On the validation scenes ``vgn-train`` holds out of those sources (same fraction
and seed, so a model fine-tuned on the others never saw them), every answer is scored by each
model's quality at its voxel, plain and turn-averaged, by whether it passes the service's
clearance and grip checks at its own orientation, and by the products; printed and written to
``DIR/answer_signal.json`` per score: the area under the ROC curve (AUC), average precision, the
success of the best-scored 20/40/60/80 % of the answers, and count and success at quality 0.5 and
0.8. A re-ranking of fixed answers in about a minute: it cannot see the new answers a changed
model would give, which only ``benchmarks/clutter.py`` executes.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch
from scipy.stats import mannwhitneyu

from benchmarks.report import this_machine
from benchmarks.turn_average import average_precision
from service.planner import GraspPlanner, InferenceOptions
from service.settings import PACKAGED_MODEL
from service.vgn.checkpoint import weights_id
from training.dataset import Scene, load_scenes, split_scenes
from training.distill import failing_checks
from training.train import TrainConfig
from vgn_data.files import write_atomically

#: Shares of the answers, best-scored first, whose success is reported.
TOP_SHARES = (0.2, 0.4, 0.6, 0.8)
THRESHOLDS = (0.5, 0.8)


def auc(labels: np.ndarray, scores: np.ndarray) -> float | None:
    """Probability that a random success scores above a random failure (ties count half); None
    without both."""
    positives, negatives = scores[labels == 1], scores[labels == 0]
    if not len(positives) or not len(negatives):
        return None
    return float(mannwhitneyu(positives, negatives).statistic / (len(positives) * len(negatives)))


def figures(labels: np.ndarray, score: np.ndarray, quality: np.ndarray | None) -> dict:
    """The figures of one score; the threshold ones only for a quality."""
    order = np.argsort(-score, kind="stable")
    result = {
        "auc": None if (area := auc(labels, score)) is None else round(area, 4),
        "average_precision": round(average_precision(labels, score), 4) if labels.any() else None,
        "top_success": {
            f"{share:.0%}": round(float(labels[order[: int(share * len(labels))]].mean()), 4)
            for share in TOP_SHARES
        },  # fmt: skip
    }
    if quality is not None:
        result["at_threshold"] = {
            str(t): {"count": int((quality >= t).sum()),
                     "success": round(float(labels[quality >= t].mean()), 4) if (quality >= t).any() else None}
            for t in THRESHOLDS
        }  # fmt: skip
    return result


def score_answers(planner: GraspPlanner, scenes: list[Scene]) -> dict[str, np.ndarray]:
    """Every answer's label and scores: plain and turned quality at its voxel, and the checks."""
    columns: dict[str, list[np.ndarray]] = {"label": [], "plain": [], "turned": [], "checks": []}
    for scene in scenes:
        grid = scene.source.load()
        voxel = scene.labels.voxel.numpy()
        index = tuple(voxel.T)
        quaternion = scene.labels.quaternion.numpy().astype(np.float64)
        columns["label"].append(scene.labels.label.numpy())
        columns["plain"].append(planner.infer(grid, turn_average=False).quality[index])
        columns["turned"].append(planner.infer(grid, turn_average=True).quality[index])
        every = np.ones(len(voxel))  # check every answer, whatever its quality
        columns["checks"].append(~failing_checks(grid, scene.voxel_size, voxel, quaternion, every))
    return {name: np.concatenate(parts).astype(np.float64) for name, parts in columns.items()}


def model_figures(scored: dict[str, np.ndarray]) -> dict:
    """Figures of each score: qualities alone, the checks alone, and the checks gating a quality."""
    labels, plain, turned, checks = scored["label"], scored["plain"], scored["turned"], scored["checks"]
    return {
        "plain": figures(labels, plain, plain),
        "turned": figures(labels, turned, turned),
        "checks": figures(labels, checks, None),
        "plain_checked": figures(labels, plain * checks, plain * checks),
        "turned_checked": figures(labels, turned * checks, turned * checks),
    }


def main(argv: list[str] | None = None) -> int:
    """Score the validation answers with each model and print (and write) the figures."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--data", type=Path, default=Path("data"), help="recipe folder")
    parser.add_argument("--source", action="append", required=True, help="answer-labelled source; repeatable")
    parser.add_argument(
        "--model", type=Path, action="append", help="weights; repeatable (default: the shipped)"
    )
    parser.add_argument("--cache", type=Path, help="observation cache (as vgn-train's --cache)")
    parser.add_argument("--every-scene", action="store_true",
                        help="score every scene, not only vgn-train's validation ones (for answers no compared "
                        "model was tuned on)")  # fmt: skip
    parser.add_argument("--scenes", type=int, help="use at most this many validation scenes")
    parser.add_argument("--out", type=Path, help="folder for answer_signal.json")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    defaults = TrainConfig(data=[args.data], out=Path("unused.safetensors"))
    scenes, _ = load_scenes([args.data], defaults.resolution, defaults.max_depth, args.cache,
                            sources=tuple(args.source))  # fmt: skip
    val = scenes if args.every_scene else split_scenes(scenes, defaults.val_fraction, defaults.seed)[1]
    val = val[: args.scenes] if args.scenes else val
    result = {"data": str(args.data), "sources": args.source, "scenes": len(val), "models": {},
              "measured": this_machine()}  # fmt: skip
    for model in args.model or [PACKAGED_MODEL]:
        planner = GraspPlanner.from_path(
            model, "cpu", InferenceOptions(precision="float32", batch_window_ms=0.0)
        )
        scored = score_answers(planner, val)
        result["answers"], result["success"] = len(scored["label"]), round(float(scored["label"].mean()), 4)
        result["models"][weights_id(model)] = model_figures(scored)
    print(f"{result['answers']} answers in {len(val)} {'' if args.every_scene else 'validation '}scenes of {', '.join(args.source)}; "
          f"{result['success']:.1%} succeeded")  # fmt: skip
    for model, by_score in result["models"].items():
        for name, got in by_score.items():
            top = " ".join(f"{share} {value:.3f}" for share, value in got["top_success"].items())
            at = "".join(
                f"  >={t}: {v['count']} at {v['success']}" for t, v in got.get("at_threshold", {}).items()
            )
            print(f"{model} {name:15s} AUC {got['auc']}  AP {got['average_precision']}  top {top}{at}")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        write_atomically(args.out / "answer_signal.json", json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
