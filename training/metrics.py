"""Per-epoch metrics over labelled voxels, accumulated batch by batch.

Quality is judged at the detection threshold (0.9, as the service uses by default);
rotation and width errors only make sense for positive labels, where a target exists.
A ratio whose denominator is zero is ``None`` (JSON null), not 0 or NaN.

Precision depends on the mix of labels it is measured on. The curve keeps it as measured
(``precision``: on validation scenes with all their labels, mostly failures, as a robot meets
them) and as it would be on balanced classes (``balanced_precision`` = TPR / (TPR + FPR)),
which is what a balanced validation set shows. ``balanced_loss`` (the mean of the positives'
and the negatives' mean loss) compares epochs whatever the mix.
"""

from __future__ import annotations

import math

import torch

from training.dataset import Batch
from training.loss import Predictions
from training.quaternions import flipped

#: Quality at or above this counts as a predicted success.
THRESHOLD = 0.9
#: Thresholds at which precision and recall are also kept, to choose a model's operating point.
CURVE_THRESHOLDS = (0.5, 0.55, 0.6, 0.65, 0.7, 0.75, 0.8, 0.85, 0.9, 0.95)

#: Metric names in display order, with a short column title and format.
COLUMNS: dict[str, tuple[str, str]] = {
    "loss": ("loss", "{:.4f}"),
    "balanced_loss": ("bal loss", "{:.4f}"),  # what picks the best epoch
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
        self.positive_loss_sum = 0.0
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
        self.positive_loss_sum += float(losses[actual].sum())
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
        """The epoch's means: losses, accuracy, precision and recall, pose errors on positives and the
        precision-recall curve; ``None`` where nothing was counted."""
        tp, fp, fn = self.true_positives, self.false_positives, self.false_negatives
        negatives = self.labels - self.positives
        positive_loss = _ratio(self.positive_loss_sum, self.positives)
        negative_loss = _ratio(self.loss_sum - self.positive_loss_sum, negatives)
        return {
            "loss": _ratio(self.loss_sum, self.labels),
            "balanced_loss": None
            if positive_loss is None or negative_loss is None
            else 0.5 * (positive_loss + negative_loss),
            "accuracy": _ratio(tp + self.true_negatives, self.labels),
            "precision": _ratio(tp, tp + fp),
            "recall": _ratio(tp, tp + fn),
            "rotation_error_deg": _ratio(self.rotation_error_sum, self.positives),
            "width_error_mm": _ratio(self.width_error_sum, self.positives),
            "labels": self.labels,
            "positives": self.positives,
            "curve": {
                f"{threshold:.2f}": {
                    "precision": _ratio(tp_at, predicted_at),
                    "recall": _ratio(tp_at, self.positives),
                    "balanced_precision": _balanced_precision(
                        tp_at, predicted_at - tp_at, self.positives, negatives
                    ),
                }
                for threshold, (tp_at, predicted_at) in self.curve.items()
            },
        }


def _balanced_precision(tp: int, fp: int, positives: int, negatives: int) -> float | None:
    """Precision on equal numbers of positives and negatives: TPR / (TPR + FPR)."""
    if not positives or not negatives:
        return None
    tpr, fpr = tp / positives, fp / negatives
    return _ratio(tpr, tpr + fpr)


def choose_threshold(curve: dict[str, dict[str, float | None]], target_precision: float) -> dict[str, float]:
    """The lowest threshold whose measured precision (on the real mix of labels) reaches
    ``target_precision``; the most precise one when none does. Returns the threshold with its
    precision and recall."""
    points = sorted((float(t), v) for t, v in curve.items() if v.get("precision") is not None)
    if not points:
        raise ValueError("no threshold predicted any success on the validation labels")
    reached = [(t, v) for t, v in points if v["precision"] >= target_precision]
    threshold, values = reached[0] if reached else max(points, key=lambda p: (p[1]["precision"], -p[0]))
    return {
        "threshold": threshold,
        "precision": values["precision"],
        "recall": values["recall"],
        "target_precision": target_precision,
        "target_reached": bool(reached),
    }


def _ratio(numerator: float, denominator: float) -> float | None:
    if not denominator:
        return None
    value = numerator / denominator
    return value if math.isfinite(value) else None


def format_metric(name: str, value: float | None) -> str:
    """A metric value as shown in the tables; '-' when undefined."""
    return "-" if value is None else COLUMNS[name][1].format(value)
