"""Per-epoch metrics over labelled voxels, accumulated batch by batch.

Quality is judged at the detection threshold (0.9, as the service uses by default);
rotation and width errors only make sense for positive labels, where a target exists.
A ratio whose denominator is zero is ``None`` (JSON null), not 0 or NaN.
"""

from __future__ import annotations

import math

import torch

from service.training.dataset import Batch
from service.training.loss import Predictions
from service.training.quaternions import flipped

#: Quality at or above this counts as a predicted success.
THRESHOLD = 0.9
#: Thresholds at which precision and recall are also kept, to choose a model's operating point.
CURVE_THRESHOLDS = (0.5, 0.6, 0.7, 0.8, 0.9)

#: Metric names in display order, with a short column title and format.
COLUMNS: dict[str, tuple[str, str]] = {
    "loss": ("loss", "{:.4f}"),
    "accuracy": ("acc", "{:.3f}"),
    "precision": ("prec", "{:.3f}"),
    "recall": ("recall", "{:.3f}"),
    "rotation_error_deg": ("rot°", "{:.1f}"),
    "width_error_mm": ("width mm", "{:.2f}"),
}


def rotation_error_deg(predicted: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """(L,) angle in degrees between ``predicted`` and the nearer of ``target`` and its π-turn."""
    cosine = torch.maximum((predicted * target).sum(-1).abs(), (predicted * flipped(target)).sum(-1).abs())
    return torch.rad2deg(2.0 * torch.acos(cosine.clamp(max=1.0)))


class MetricAccumulator:
    """Sums over an epoch; ``result()`` turns them into the metrics of ``COLUMNS``."""

    def __init__(self) -> None:
        self.loss_sum = 0.0
        self.labels = 0
        self.true_positives = self.false_positives = self.false_negatives = self.true_negatives = 0
        self.positives = 0
        self.rotation_error_sum = 0.0
        self.width_error_sum = 0.0
        #: threshold -> [true positives, predicted positives]
        self.curve = {t: [0, 0] for t in CURVE_THRESHOLDS}

    @torch.no_grad()
    def update(self, predictions: Predictions, batch: Batch, losses: torch.Tensor) -> None:
        """Add one batch: its predictions, targets and (L,) per-label losses."""
        predicted = predictions.quality >= THRESHOLD
        actual = batch.label > 0.5
        self.loss_sum += float(losses.sum())
        self.labels += len(batch)
        self.true_positives += int((predicted & actual).sum())
        self.false_positives += int((predicted & ~actual).sum())
        self.false_negatives += int((~predicted & actual).sum())
        self.true_negatives += int((~predicted & ~actual).sum())
        self.positives += int(actual.sum())
        for threshold, counts in self.curve.items():
            predicted_at = predictions.quality >= threshold
            counts[0] += int((predicted_at & actual).sum())
            counts[1] += int(predicted_at.sum())
        if actual.any():
            errors = rotation_error_deg(predictions.quaternion[actual], batch.quaternion[actual])
            self.rotation_error_sum += float(errors.sum())
            width_m = (predictions.width[actual] - batch.width[actual]).abs() * batch.voxel_size[actual]
            self.width_error_sum += float(width_m.sum()) * 1e3

    def result(self) -> dict[str, float | int | None]:
        tp, fp, fn = self.true_positives, self.false_positives, self.false_negatives
        return {
            "loss": _ratio(self.loss_sum, self.labels),
            "accuracy": _ratio(tp + self.true_negatives, self.labels),
            "precision": _ratio(tp, tp + fp),
            "recall": _ratio(tp, tp + fn),
            "rotation_error_deg": _ratio(self.rotation_error_sum, self.positives),
            "width_error_mm": _ratio(self.width_error_sum, self.positives),
            "labels": self.labels,
            "positives": self.positives,
            "curve": {
                f"{threshold:.1f}": {
                    "precision": _ratio(tp_at, predicted_at),
                    "recall": _ratio(tp_at, self.positives),
                }
                for threshold, (tp_at, predicted_at) in self.curve.items()
            },
        }


def _ratio(numerator: float, denominator: float) -> float | None:
    if not denominator:
        return None
    value = numerator / denominator
    return value if math.isfinite(value) else None


def format_metric(name: str, value: float | None) -> str:
    """A metric value as shown in the tables; '-' when undefined."""
    return "-" if value is None else COLUMNS[name][1].format(value)
