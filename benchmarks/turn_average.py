"""Turn averaging on labelled validation scenes: does the mean quality over the grid's four
quarter turns rank VGN's labelled grasps better than the quality of the unturned grid, and is
the mean orientation nearer the successful grasps' orientations?

    python -m benchmarks.turn_average --data data [--model WEIGHTS] [--scenes 200]

The validation scenes are the ones ``vgn-train`` holds out (same fraction and seed), with all
their labels (unbalanced, as a robot meets them). Printed overall and per scene-id seed (one
seed per source, e.g. s21 pile and s22 packed in ``data/``): average precision, and precision / recall at a few thresholds. These are label figures, not success
rates: executed-grasp success comes from ``benchmarks/clutter.py --turn-average``.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import torch

from service.planner import GraspPlanner, InferenceOptions
from service.settings import PACKAGED_MODEL
from training.dataset import load_scenes, split_scenes
from training.metrics import rotation_error_deg
from training.train import TrainConfig

THRESHOLDS = (0.7, 0.8, 0.9)


def average_precision(labels: np.ndarray, scores: np.ndarray) -> float:
    """Mean precision at the rank of each positive, best score first."""
    ordered = labels[np.argsort(-scores, kind="stable")]
    hits = np.cumsum(ordered)
    return float((hits / np.arange(1, len(ordered) + 1))[ordered == 1].mean())


def report(name: str, labels: np.ndarray, scores: dict[str, np.ndarray]) -> None:
    """One block of figures for the labels of ``name``."""
    print(f"{name}: {len(labels)} labels, {labels.mean():.3f} positive")
    for form, score in scores.items():
        cells = [f"AP {average_precision(labels, score):.3f}"]
        for threshold in THRESHOLDS:
            chosen = score >= threshold
            precision = labels[chosen].mean() if chosen.any() else float("nan")
            recall = chosen[labels == 1].mean()
            cells.append(f"@{threshold}: P {precision:.3f} R {recall:.3f}")
        print(f"  {form:8s} " + "  ".join(cells))


def main(argv: list[str] | None = None) -> int:
    """Score every label of the validation scenes both ways and print the comparison."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--data", type=Path, default=Path("data"), help="packed shard folder or raw dataset")
    parser.add_argument(
        "--model", type=Path, default=PACKAGED_MODEL, help="weights (default: the shipped model)"
    )
    parser.add_argument("--scenes", type=int, help="use at most this many validation scenes")
    args = parser.parse_args(argv)

    default = {field.name: field.default for field in dataclasses.fields(TrainConfig)}
    scenes, _ = load_scenes([args.data], default["resolution"], default["max_depth"])
    _, validation = split_scenes(scenes, default["val_fraction"], default["seed"])
    validation = validation[: args.scenes]
    planner = GraspPlanner.from_path(args.model, "cpu", InferenceOptions(precision="fp32"))
    labels, sources = [], []
    scores: dict[str, list[np.ndarray]] = {"plain": [], "turns": []}
    errors: dict[str, list[np.ndarray]] = {"plain": [], "turns": []}
    for scene in validation:
        grid = scene.source.load()
        at_labels = tuple(scene.labels.voxel.numpy().T)
        positive = scene.labels.label.numpy() == 1
        target = scene.labels.quaternion[positive]
        for form, output in (
            ("plain", planner.infer(grid)),
            ("turns", planner.infer(grid, turn_average=True)),
        ):
            scores[form].append(output.quality[at_labels])
            rotation = output.rotation_where()  # every voxel: labels may lie outside the grasp region
            predicted = torch.from_numpy(rotation[(slice(None), *at_labels)].T[positive].copy())
            errors[form].append(rotation_error_deg(predicted, target).numpy())
        labels.append(scene.labels.label.numpy())
        sources.append(np.full(len(scene.labels), scene.scene_id.split("-")[0]))
    label = np.concatenate(labels)
    source = np.concatenate(sources)
    score = {form: np.concatenate(values) for form, values in scores.items()}
    print(f"model {planner.model_id}, {len(validation)} validation scenes of {args.data}")
    report("all", label, score)
    for form, values in errors.items():
        error = np.concatenate(values)
        print(
            f"  {form:8s} orientation error at the {len(error)} positives: mean {error.mean():.1f}°, "
            f"median {np.median(error):.1f}°, within 20° {np.mean(error < 20):.3f}"
        )
    for name in sorted(set(source)):
        keep = source == name
        report(f"scenes {name}-*", label[keep], {form: values[keep] for form, values in score.items()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
